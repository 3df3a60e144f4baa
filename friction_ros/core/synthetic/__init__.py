"""Synthetic truths: simulated joints and logs with a known truth, for tests, benchmarks and demos.

The fitter (:mod:`friction_ros.core.identification`) never imports this package; the tests and the
benchmarks fit what it generates and compare with its truth.

``plant_runs`` (known-truth runs of the simulated plant: ABB M19-S paper excitation, plateaus, as
records or bags), ``realistic_joint`` with ``joint_truth`` (a realistic robot joint: gravity,
load-dependent and rippling friction, noise), ``ga_thesis_loop`` with ``ga_thesis_loop_kernels`` (GA
friction thesis 2002's unity-feedback loop and its GA fit) and ``logs`` (seeded logs of the machines users
bring: the gauntlet of friction-fit).
"""
