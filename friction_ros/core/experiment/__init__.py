"""Experiments on a joint (pure core): what is commanded and what is recorded about it.

- :mod:`~friction_ros.core.experiment.excitation`: identification programs (plateaus, breakaway
  ramps, random velocity, chirp, presliding) with their safety limits and motion check, built from
  :mod:`~.excitation_config`, :mod:`~.segments`, :mod:`~.velocity_programs` and :mod:`~.torque_programs`.
- :mod:`~friction_ros.core.experiment.events`: the START/END/ABORT markers a program emits and
  identification reads back.
- :mod:`~friction_ros.core.experiment.references` and :mod:`~.trajectory`: reference signals the
  compensating controller tracks (generated, or from waypoints).
- :mod:`~friction_ros.core.experiment.joint_scale` (what a joint is: inertia, friction, limits,
  encoder), :mod:`~.tracking_design` (tracking gains and reference sized to it) and
  :mod:`~.experiment_sizing` (excitation programs sized to it).
"""
