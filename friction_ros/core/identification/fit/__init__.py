"""The fit: records in, fitted and compared models out (imports data, never report).

``fit_model`` (the plugin every fittable family implements) with ``fit_families`` (the built-in
families) and ``fit_registry`` (lookup by name, library configs), ``models`` (fit specifications),
``load_terms`` (gravity, offset, spring, load- and position-dependent regressors), ``search_space``,
``static_fit`` (robust LS on the plateau map), ``dynamic_fit`` (output error with DE/GA +
Nelder-Mead, inertia jointly) on ``kernels`` (compiled simulation) and ``linsolve``, ``ga`` (GA
friction thesis 2002's genetic algorithm), ``learned`` (ANFIS, nu-SVR per direction),
``residual_learning`` (learned residual on a physics backbone), ``identifiability``, ``metrics``
(ABB M19-S paper eq. 4 NMSE, AIC/BIC), ``baseline``, ``model_status``, ``diagnosis``,
``recommendation``, ``gating`` (the closed-loop safety gate), ``fit_units``; the pipeline
``pipeline`` (:func:`~friction_ros.core.identification.fit.pipeline.fit_records`) with its stages
``fit_context``, ``fit_data``, ``model_fits``, its ``fit_options`` and its ``fit_results``.
"""
