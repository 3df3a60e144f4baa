"""Reference trajectories from waypoints (trajectory_msgs input of the controller)."""

import math

import numpy as np
import pytest

from friction_ros.core.experiment.trajectory import TrajectoryReference
from friction_ros.core.validation import ParameterError


def test_hermite_passes_through_waypoints_with_their_velocities():
    tr = TrajectoryReference([0.0, 1.0, 2.0], [0.0, 1.0, 0.0], [0.0, 0.5, 0.0], start_time=10.0)
    for t, q, v in [(10.0, 0.0, 0.0), (11.0, 1.0, 0.5), (12.0, 0.0, 0.0)]:
        p, pv, _ = tr.sample(t + 1e-12 if t < 12 else t - 1e-12)
        assert p == pytest.approx(q, abs=1e-9)
        assert pv == pytest.approx(v, abs=1e-6)
    # velocity is the derivative of position, acceleration the derivative of velocity
    ts = np.linspace(10.1, 11.9, 50)
    h = 1e-6
    for t in ts:
        p0, v0, a0 = tr.sample(t)
        p1, v1, _ = tr.sample(t + h)
        assert (p1 - p0) / h == pytest.approx(v0, abs=1e-4)
        assert (v1 - v0) / h == pytest.approx(a0, abs=1e-2)


def test_holds_before_and_after_and_linear_without_velocities():
    tr = TrajectoryReference([1.0, 3.0], [0.2, 1.2])
    assert tr.sample(0.0) == (0.2, 0.0, 0.0)
    assert tr.sample(5.0) == (1.2, 0.0, 0.0)
    p, v, a = tr.sample(2.0)
    assert (p, v, a) == (pytest.approx(0.7), pytest.approx(0.5), 0.0)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(times=[0.0, 1.0], positions=[0.0, math.nan]), "positions contains NaN"),
        (dict(times=[0.0, 0.0], positions=[0.0, 1.0]), "strictly increasing"),
        (dict(times=[0.0, 1.0], positions=[0.0]), "1 positions for 2 points"),
        (dict(times=[], positions=[]), "at least one point"),
    ],
)
def test_bad_trajectories_are_rejected_with_a_clear_reason(kwargs, message):
    with pytest.raises(ParameterError, match=message):
        TrajectoryReference(**kwargs)
