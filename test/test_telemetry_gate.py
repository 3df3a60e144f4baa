"""Plausibility gate of drive telemetry: the pure gate, its bounds from the axis limits, and
DriveAxis with spoofed frames in lock step (fake clock, no bus)."""

from __future__ import annotations

import dataclasses
import math
import struct

import pytest

from friction_ros.core.can import faults
from friction_ros.core.can import mit as mitc
from friction_ros.core.can import odrive as od
from friction_ros.core.can.axis import DriveAxis
from friction_ros.core.can.axis_config import AxisConfig
from friction_ros.core.can.joint import JointConversion
from friction_ros.core.can.telemetry_gate import FLOAT32_STEPS, TelemetryGate, TelemetryLimits

LIMITS = TelemetryLimits(max_position=100.0, max_velocity=20.0, max_effort=50.0, period=0.001, reject_run=3)


def test_gate_rejects_non_finite_out_of_range_and_jumps_and_keeps_the_reference():
    g = TelemetryGate(LIMITS)
    assert g.motion(1.0, 0.5, 0.0)
    assert not g.motion(math.nan, 0.0, 0.001) and g.log.last_reason == "not_finite"
    assert not g.motion(1.0, math.inf, 0.001) and g.log.last_reason == "not_finite"
    assert not g.motion(3.2e33, 0.0, 0.001) and g.log.last_reason == "out_of_range"
    assert not g.motion(1.0, 20.5, 0.001) and g.log.last_reason == "out_of_range"
    assert g.implausible  # 4 in a row >= reject_run 3
    # jump bound from the last accepted position (1.0 at t = 0): vmax * (max(dt, T) + T) + float32 steps
    dt = 0.01
    allowed = 20.0 * (dt + 0.001) + FLOAT32_STEPS * 1.2
    assert not g.motion(1.0 + 1.01 * allowed, 0.0, dt) and g.log.last_reason == "jump"
    assert g.motion(1.0 + 0.99 * allowed, 0.0, dt) and not g.implausible
    # a burst (frames received together): the bound takes one period, not the receive interval
    assert g.motion(1.0 + 0.99 * allowed + 0.039, 0.0, dt)
    assert g.log.counts == {"not_finite": 2, "out_of_range": 2, "jump": 1, "undecodable": 0}
    assert g.total == 5


def test_gate_channels_runs_reset_and_resolution():
    g = TelemetryGate(LIMITS._replace(resolution=0.5))
    assert g.motion(0.0, 0.0, 0.0)
    assert g.motion(0.5 + 20.0 * 0.002 - 1e-9, 0.0, 0.0)  # the resolution widens the jump bound
    for k in range(3):
        assert not g.effort(0.001 * k, 1.0, 51.0)  # |effort| above max_effort on the effort channel
        assert g.motion(0.54, 0.0, 0.001 * k)  # motion accepted: does not break the effort run
    assert g.runs == [0, 3] and g.implausible and "3 telemetry reports in a row" in g.reason()
    assert g.effort(0.004, -50.0) and not g.implausible
    g.undecodable(0, "node 1 encoder estimate is not finite", 0.005)
    assert g.runs == [1, 0] and g.log.counts["undecodable"] == 1
    assert not g.motion(90.0, 0.0, 0.006)  # a re-homed joint is a jump ...
    g.reset()
    assert g.motion(90.0, 0.0, 0.007) and g.runs == [0, 0]  # ... until reset adopts it
    assert not g.reading(90.0, 0.0, math.nan, 0.008)  # one report with both: rejected whole
    assert g.runs == [1, 1]


def test_bounds_follow_the_configured_limits_revolute_and_prismatic():
    rev = AxisConfig(velocity_limit=3.0, current_limit=8.0, conversion=JointConversion(50.0, 0.2))
    lim = rev.plausibility()
    assert lim.max_velocity == pytest.approx(10 * 3.0)
    assert lim.max_effort == pytest.approx(10 * 8.0 * 0.2 * 50.0)  # N*m at the joint
    assert lim.max_position == pytest.approx(2.0**24 * 2 * math.pi / 50.0)
    lead = 0.005  # m per motor turn
    pri = AxisConfig(velocity_limit=0.2, current_limit=8.0, conversion=JointConversion(1.0, 0.2, lead=lead))
    lim = pri.plausibility()
    assert lim.max_velocity == pytest.approx(10 * 0.2)  # m/s
    assert lim.max_effort == pytest.approx(10 * 8.0 * 0.2 * 2 * math.pi / lead)  # N
    mit = AxisConfig(protocol="mit", node_id=1, mit_master_id=0, limit_factor=4.0, velocity_limit=2.0)
    lim = mit.plausibility()
    assert lim.max_velocity == 8.0 and lim.resolution == pytest.approx(25.0 / 65535)
    with pytest.raises(Exception, match="telemetry_gate.reject_run"):
        AxisConfig(reject_run=0)


def feed_real(axis, t, pos=0.0, vel=0.0, iq=0.0):
    for f in (
        od.encode_encoder_estimates(1, pos, vel),
        od.encode_iq(1, iq, iq),
        od.encode_heartbeat(1, 0, 8),
    ):
        axis.on_frame(f.arbitration_id, f.data, False, False, False, t)


SPOOF = [
    od.Frame((1 << 5) | od.Cmd.GET_ENCODER_ESTIMATES, struct.pack("<ff", math.nan, 0.0)),
    od.encode_encoder_estimates(1, 3.2e33, 0.0),  # rad
    od.encode_encoder_estimates(1, 30.0, 0.0),  # 30 rad away: a jump
    od.encode_iq(1, 0.0, 1e6),  # an absurd current
]


@pytest.mark.parametrize("fast", [True, False])
def test_axis_drops_spoofed_frames_and_latches_after_a_run(fast):
    cfg = AxisConfig(node_id=1, telemetry_timeout=0.05, command_timeout=1.0, velocity_limit=5.0, reject_run=4)
    a = DriveAxis(cfg)
    if not fast:
        a._fast = {}  # the general decoder path
    a.request_enable()
    events, samples = [], []
    t = 0.0

    def period(spoof=(), real=True):
        nonlocal t
        if real:
            feed_real(a, t, pos=0.01)
        for f in spoof:
            a.on_frame(f.arbitration_id, f.data, False, False, False, t)
        a.set_command(0.1, t)
        res = a.cycle(t)
        events.extend(res.events)
        samples.append(res.sample)
        t += 0.001
        return res

    for _ in range(20):
        period()
    assert a.enabled
    for k in range(40):  # one spoofed frame now and then among the drive's frames: dropped, no fault
        period(spoof=[SPOOF[k % 4]] if k % 2 else [])
    good = [s for s in samples if s is not None]
    assert len(good) == 60 and all(s.position == pytest.approx(0.01) for s in good)
    assert all(abs(s.effort) < 1.0 for s in good)
    assert a.gate.total == 20 and a.enabled and not a.latched
    assert {e.kind for e in events} == {"telemetry_rejected", "command_watchdog"}
    events.clear()
    res = period(spoof=SPOOF * 2, real=False)  # the drive is drowned out: 4 in a row on a channel
    assert res.flags & faults.FAULT_TELEMETRY_IMPLAUSIBLE and not a.enabled
    assert od.AxisState.IDLE in [
        m.state for m in map(od.OdriveDecoder([1], "drive").decode_frame, res.frames) if hasattr(m, "state")
    ]
    start = [e for e in events if e.kind == "telemetry_implausible"]
    assert [e.level for e in start] == ["error"] and "drive disabled" in start[0].text
    assert "6 telemetry reports in a row" in start[0].text  # the 6 position reports
    events.clear()
    for _ in range(5):
        period()  # sane frames return: the condition clears, the fault stays latched
    texts = [e.text for e in events if e.kind == "telemetry_implausible"]
    assert len(texts) == 1 and texts[0].startswith("telemetry_implausible cleared after")
    assert texts[0].endswith("drive stays disabled until ~/enable") and not a.enabled
    events.clear()
    a.request_enable()
    for _ in range(3):
        period()
    assert a.enabled and "telemetry_implausible fault reset by ~/enable" in [e.text for e in events]
    assert all(s is None or abs(s.position) < 1.0 for s in samples)


def test_mit_reply_jump_is_rejected_and_run_time_limits_move_the_bounds():
    cfg = AxisConfig(protocol="mit", node_id=1, mit_master_id=0, velocity_limit=2.0, telemetry_timeout=0.05)
    a = DriveAxis(cfg)
    codec = mitc.MitCodec(1)

    def reply(pos, t):
        f = codec.encode_reply(pos, 0.0, 0.0)
        a.on_frame(f.arbitration_id, f.data, False, False, False, t)

    reply(0.0, 0.0)
    reply(1.0, 0.001)  # 1 rad in 1 ms: 20 rad/s x 2 ms = 0.04 rad allowed
    assert a.telemetry.motor_position == pytest.approx(0.0, abs=1e-3) and a.gate.log.counts["jump"] == 1
    a.cfg = dataclasses.replace(cfg, velocity_limit=100.0)  # a run-time change of velocity_limit
    assert a.gate.limits.max_velocity == 1000.0
    reply(1.0, 0.002)
    assert a.telemetry.motor_position == pytest.approx(1.0, abs=1e-3)
