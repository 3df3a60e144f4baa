"""The simulated gearhead DC servo plant (pure core).

* :mod:`~friction_ros.core.plant.params`: :class:`PlantParams`, the validated plant parameters;
* :mod:`~friction_ros.core.plant.servo`: :class:`GearheadServoPlant`, the model (equations in its
  docstring), ``step(command, dt) -> Measurement``, ``command_scale``;
* :mod:`~friction_ros.core.plant.kernels`: the compiled (numba) integration of one control period;
* :mod:`~friction_ros.core.plant.sensing`: encoder, velocity and current sensing (``Measurement``).

A plant is built from a preset or a parameter file that overrides one, in one way:
:func:`friction_ros.core.presets.resolve_preset` -> :meth:`~friction_ros.core.presets.Preset.make_plant`.
"""
