"""What a record excites, and the checks that stop a fit which the record cannot support."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from friction_ros.core.identification.data.data_scale import velocity_scale
from friction_ros.core.identification.data.plateau_detection import Plateau
from friction_ros.core.identification.data.records import ExcitationError, JointData
from friction_ros.core.identification.data.velocity_regimes import motion_floor, moving_mask


@dataclass
class Excitation:
    """Summary of what a record excites."""

    max_speed_pos: float
    max_speed_neg: float
    reversals: int
    motion_range: float
    low_speed_fraction: float
    n_plateaus_pos: int
    n_plateaus_neg: int
    plateau_decades: float
    motion_floor: float = 1e-3


def excitation(data: JointData, plateaus: list[Plateau]) -> Excitation:
    v = data.velocity
    floor = motion_floor(v, data.resolution)
    moving = np.abs(v) > floor
    sv = np.sign(v[moving])
    rev = int(np.sum(sv[1:] != sv[:-1])) if sv.size > 1 else 0
    pv = [abs(p.velocity) for p in plateaus if abs(p.velocity) > 0]
    dec = math.log10(max(pv) / min(pv)) if len(pv) >= 2 else 0.0
    return Excitation(
        float(max(v.max(), 0.0)),
        float(max(-v.min(), 0.0)),
        rev,
        float(np.ptp(data.position)),
        float(np.mean(np.abs(v[moving]) < 0.05 * velocity_scale(data))) if moving.any() else 0.0,
        sum(p.velocity > 0 for p in plateaus),
        sum(p.velocity < 0 for p in plateaus),
        dec,
        floor,
    )


def check_motion(data: JointData, label: str) -> None:
    """Raise ExcitationError if the joint never moved."""
    q = data.resolution if data.resolution > 0 else 1e-6 * velocity_scale(data)
    if np.ptp(data.position) < 3 * q or not np.any(moving_mask(data.velocity, data.resolution, data.dt)):
        raise ExcitationError(
            f"{label}: no motion (position range {np.ptp(data.position):.3g} rad, max |v| "
            f"{np.max(np.abs(data.velocity)):.3g} rad/s); the joint must move: record the 'plateaus' "
            "experiment (constant-velocity plateaus in both directions) or ABB M19-S paper's 'random' "
            "excitation (band-limited random velocity under a 10 s envelope)"
        )


def one_direction_note(ex: Excitation) -> str:
    """A warning when the joint moved in one direction only (a conveyor, a wheel): the fit then
    gives that direction's friction, and Coulomb friction cannot be told from a constant load."""
    floor = 2.0 * ex.motion_floor  # above what the encoder resolves, in the record's own units
    if ex.max_speed_pos >= floor and ex.max_speed_neg >= floor:
        return ""
    d, other = ("positive", "negative") if ex.max_speed_pos >= floor else ("negative", "positive")
    return (
        f"the joint moved in the {d} direction only: the fitted friction is that direction's (the {other} "
        "direction is assumed the same) and a constant load adds to its Coulomb level; record motion in both "
        "directions ('plateaus' in both directions) to measure them apart"
    )


def check_excitation(ex: Excitation, *, dynamic: bool, static_from_plateaus: bool, label: str) -> None:
    """Raise ExcitationError naming what is missing and the experiment that provides it."""
    missing = []
    floor = 2.0 * ex.motion_floor  # above what the encoder resolves, in the record's own units
    if ex.max_speed_pos < floor or ex.max_speed_neg < floor:
        d = "positive" if ex.max_speed_pos < floor else "negative"
        missing.append(f"motion in the {d} direction (run 'plateaus' in both directions)")
    if static_from_plateaus and (ex.n_plateaus_pos + ex.n_plateaus_neg) < 3:
        missing.append(
            f"constant-velocity plateaus (found {ex.n_plateaus_pos}+/{ex.n_plateaus_neg}-, need >= 3; "
            "run the 'plateaus' experiment over a log-spaced speed range)"
        )
    if dynamic and ex.reversals < 4:
        missing.append(
            f"velocity reversals for presliding dynamics (found {ex.reversals}, need >= 4; run ABB M19-S paper's "
            "'random' excitation or the 'presliding' cycles)"
        )
    if missing:
        raise ExcitationError(f"{label}: too little excitation: missing " + "; ".join(missing))
