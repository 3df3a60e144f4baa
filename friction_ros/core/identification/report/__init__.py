"""The outputs of a fit: files for users and nodes (imports fit and data).

``report`` (``report.md``, ``summary.json``), ``report_plots`` (the PNG plots), ``export`` (the ROS
parameter file), ``fit_logs`` (logs in, files out: :func:`~.fit_logs.fit_bag`) and ``multi_joint``
(every joint of a bag, one parameter file).
"""
