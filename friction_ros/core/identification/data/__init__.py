"""The data of a fit: logs in, the uniform record and what it contains (imports no fit or report).

``records`` (time alignment, differentiation: the uniform record), ``bag_loading`` (a joint of a
bag), ``csv_loading`` (a CSV log), ``log_loading`` (either, by file), ``joint_selection`` (which
joints of a bag), ``data_scale`` (the log's speed and effort scales), ``velocity_regimes``,
``plateau_detection``, ``breakaway_detection``, ``plateau_map`` (the static map printed after an
experiment), ``training_split``, ``excitation_checks`` (what a record excites) and ``decimation``
(a bounded, informative selection of a long log's samples).
"""
