"""Seeded synthetic logs of machines users bring (the "gauntlet" of friction-fit), pure numpy/scipy.

Each generator ``f(seed=0, seconds=...) -> GauntletLog`` returns CSV-ready columns (time,
position, velocity, effort under the names a user's logger would give them), their units, the
known truth and the friction-fit options that read the file
(:meth:`~friction_ros.core.synthetic.logs.tables.GauntletLog.cli_args`). The same seed gives the
same CSV bytes.

=====================  =======================================================================
prismatic_ballscrew    linear axis in m and N (M 12 kg, Fc 20 N, Fv 200 N*s/m), + validation run
hobby_servo            0.01-0.1 N*m servo, 100 Hz millis() stamps, 10-bit pot, no velocity column
coupled_arm            shoulder of a two-link arm: its torque carries the elbow link's dynamics
lugre_creep            LuGre joint creeping under a dithered torque near breakaway
coarse_encoder         2^10 counts per revolution at the joint
jitter_gaps            jittered 500 Hz stamps, dropped rows, gaps, empty cells, epoch stamps
saturation             drive torque clipped at its limit for half the run
one_direction          a joint that never reverses (conveyor roller, wheel): 0.5-4 rad/s
=====================  =======================================================================
"""

from __future__ import annotations

from friction_ros.core.synthetic.logs.artifacts import (
    coarse_encoder,
    jitter_gaps,
    lugre_creep,
    one_direction,
    saturation,
)
from friction_ros.core.synthetic.logs.machines import coupled_arm, hobby_servo, prismatic_ballscrew
from friction_ros.core.synthetic.logs.tables import GauntletLog

#: class name -> generator ``f(seed=0, seconds=...)``
GENERATORS = {
    "prismatic_ballscrew": prismatic_ballscrew,
    "hobby_servo": hobby_servo,
    "coupled_arm": coupled_arm,
    "lugre_creep": lugre_creep,
    "coarse_encoder": coarse_encoder,
    "jitter_gaps": jitter_gaps,
    "saturation": saturation,
    "one_direction": one_direction,
}


def make_log(name: str, seed: int = 0, seconds: float | None = None) -> GauntletLog:
    """The log of class ``name`` (see :data:`GENERATORS`); ``seconds`` None: the generator's default."""
    from friction_ros.core.validation import check_choice

    check_choice("gauntlet log", name, list(GENERATORS))
    return GENERATORS[name](seed=seed) if seconds is None else GENERATORS[name](seed=seed, seconds=seconds)


__all__ = ["GENERATORS", "GauntletLog", "make_log", *GENERATORS]
