"""Input plausibility gate (pure core): stamps, jumps, magnitudes, selection, re-synchronisation,
rate-limited logging; bounded controller defaults; plant command range."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from friction_ros.core.control import CompensatingController, Pid
from friction_ros.core.input_gate import (
    ACCEPTED,
    DUPLICATE,
    GATE_DEFAULTS,
    REJECTED,
    RESYNC,
    JointInputGate,
    RejectionLog,
    select_command,
    select_sample,
)
from friction_ros.core.plant.servo import MAX_COMMAND
from friction_ros.core.presets import resolve_preset
from friction_ros.core.validation import ParameterError

MS = 1_000_000
T0 = 1_700_000_000 * 1_000_000_000  # a wall-clock time in ns


def js(stamp_ns, pos, vel=0.0, eff=0.0, name=("joint1",)):
    def seq(x):
        return () if x is None else (x,) if not isinstance(x, tuple) else x

    return SimpleNamespace(
        stamp_ns=stamp_ns, name=tuple(name), position=seq(pos), velocity=seq(vel), effort=seq(eff)
    )


def feed(gate, samples, now_ns=None):
    """Admit (stamp, pos) samples; the node clock follows the stamps unless ``now_ns`` is given."""
    return [gate.admit(js(s, p), s if now_ns is None else now_ns, now_wall=s * 1e-9) for s, p in samples]


def test_normal_stream_is_accepted_and_duplicates_are_not_rejections():
    g = JointInputGate("joint1")
    out = feed(g, [(T0 + k * MS, 0.001 * k) for k in range(100)])
    assert out == [ACCEPTED] * 100
    assert g.admit(js(T0 + 99 * MS, 0.099), T0 + 99 * MS) == DUPLICATE  # lockstep re-send
    assert g.log.total == 0 and g.counts["duplicates"] == 1
    assert g.stamp_ns == T0 + 99 * MS and g.position == pytest.approx(0.099)


def test_one_future_stamp_is_rejected_and_does_not_poison_the_time_base():
    g = JointInputGate("joint1")
    feed(g, [(T0 + k * MS, 0.0) for k in range(10)])
    now = T0 + 10 * MS
    assert g.admit(js(now + 3600 * 10**9, 0.0), now) == REJECTED
    assert "[future_stamp]" in g.log_line and "3600 s ahead" in g.log_line
    # the following good samples are accepted (before the fix they were all "older" for ever)
    assert feed(g, [(T0 + k * MS, 0.0) for k in range(11, 500)]) == [ACCEPTED] * 489
    assert g.log.counts["future_stamp"] == 1 and g.counts["resyncs"] == 0


def test_first_sample_far_ahead_of_the_node_clock_is_rejected():
    g = JointInputGate("joint1")
    assert g.admit(js(T0 + 10 * 10**9, 0.0), T0) == REJECTED
    assert g.log.counts["future_stamp"] == 1
    assert g.admit(js(T0, 0.0), T0) == ACCEPTED
    # unknown node clock (use_sim_time before /clock): no clock check
    g2 = JointInputGate("joint1")
    assert g2.admit(js(T0, 0.0), 0) == ACCEPTED


def test_unstamped_samples_use_the_receive_time_and_keep_being_controlled():
    g = JointInputGate("joint1")
    out = [g.admit(js(0, 0.001 * k), T0 + k * MS) for k in range(50)]
    assert out == [ACCEPTED] * 50  # before: only the first, then "duplicates" for ever
    assert g.stamp_ns == T0 + 49 * MS and g.counts["unstamped"] == 50
    # lockstep start: stamp 0 with the simulated clock at 0 is time 0, its re-send a duplicate
    lock = JointInputGate("joint1")
    assert lock.admit(js(0, 0.0), 0) == ACCEPTED and lock.stamp_ns == 0
    assert lock.admit(js(0, 0.0), 0) == DUPLICATE
    assert lock.admit(js(MS, 0.0), 0) == ACCEPTED


def test_old_stamps_are_rejected_and_a_genuine_clock_jump_is_adopted_after_n_samples():
    g = JointInputGate("joint1", {"resync_samples": 10})
    feed(g, [(T0 + k * MS, 0.0) for k in range(10)])
    assert g.admit(js(T0 + 5 * MS, 0.0), T0 + 10 * MS) == REJECTED
    assert g.log.counts["old_stamp"] == 1
    # the source's clock jumps back by 1 h and stays there (a bag loop, a restarted simulator)
    back = T0 - 3600 * 10**9
    out = feed(g, [(back + k * MS, 0.0) for k in range(10)], now_ns=T0 + 20 * MS)
    assert out == [REJECTED] * 9 + [RESYNC]
    assert "re-synchronised on 10 consistent samples after old_stamp rejections" in g.log_line
    out = feed(g, [(back + k * MS, 0.0) for k in range(10, 20)], now_ns=T0 + 20 * MS)
    assert out == [ACCEPTED] * 10
    assert g.counts["resyncs"] == 1 and g.resync_reason == "old_stamp"
    # a clock jump forward: the same
    g2 = JointInputGate("joint1", {"resync_samples": 3})
    feed(g2, [(T0 + k * MS, 0.0) for k in range(5)])
    fwd = T0 + 7200 * 10**9
    out = [g2.admit(js(fwd + k * MS, 0.0), T0 + (5 + k) * MS) for k in range(5)]
    assert out == [REJECTED, REJECTED, RESYNC, ACCEPTED, ACCEPTED]


def test_interleaved_bad_stream_never_resynchronises():
    g = JointInputGate("joint1", {"resync_samples": 3})
    for k in range(200):
        assert g.admit(js(T0 + k * MS, 0.0), T0 + k * MS) == ACCEPTED
        assert g.admit(js(T0 + 10**12 + k * MS, 0.0), T0 + k * MS) == REJECTED
    assert g.counts["resyncs"] == 0 and g.log.counts["future_stamp"] == 200


@pytest.mark.parametrize(
    "pos, vel, eff, reason",
    [
        (1e300, 0.0, 0.0, "out_of_range"),
        (0.0, 5e3, 0.0, "out_of_range"),
        (0.0, 0.0, 1e7, "out_of_range"),
        (math.nan, 0.0, 0.0, "not_finite"),
        (math.inf, 0.0, 0.0, "not_finite"),
        (0.0, -math.inf, 0.0, "not_finite"),
        (0.0, 0.0, math.nan, "not_finite"),
    ],
)
def test_absurd_and_non_finite_values_are_rejected(pos, vel, eff, reason):
    g = JointInputGate("joint1")
    assert g.admit(js(T0, 0.0), T0) == ACCEPTED
    assert g.admit(js(T0 + MS, pos, vel, eff), T0 + MS) == REJECTED
    assert g.log.counts[reason] == 1 and f"[{reason}]" in g.log_line
    assert g.admit(js(T0 + 2 * MS, 0.001), T0 + 2 * MS) == ACCEPTED  # the next good one


def test_position_jump_limit_from_max_velocity_and_the_stamp_step():
    g = JointInputGate("joint1", {"max_velocity": 100.0}, period=1e-3)
    feed(g, [(T0, 0.0)])
    assert g.admit(js(T0 + MS, 0.2), T0 + MS) == REJECTED  # 0.2 rad in 1 ms > 100 rad/s x 1 ms
    assert "allowed 0.1 rad" in g.log_line
    assert g.admit(js(T0 + 2 * MS, 0.15), T0 + 2 * MS) == ACCEPTED  # 0.15 rad in 2 ms: plausible
    # a lasting offset (re-homed encoder) is adopted after resync_samples consistent samples
    out = feed(g, [(T0 + (3 + k) * MS, 6.4 + 0.01 * k) for k in range(10)])
    assert out == [REJECTED] * 9 + [RESYNC] and g.resync_reason == "jump"


def test_selection_reasons_wrong_joint_and_wrong_lengths():
    assert select_sample(js(1, 0.5), "joint1")[0] == (0.5, 0.0, 0.0)
    unnamed = SimpleNamespace(name=(), position=(0.5,), velocity=(), effort=())
    assert select_sample(unnamed, "joint1")[0] == (0.5, None, None)
    two = SimpleNamespace(name=("a", "joint1"), position=(1.0, 2.0), velocity=(3.0, 4.0), effort=())
    assert select_sample(two, "joint1")[0] == (2.0, 4.0, None)
    cases = [
        (js(1, 0.5, name=("other",)), "wrong_joint", "is not in name ['other']"),
        (js(1, None, name=("joint1",)), "wrong_length", "position has 0 values for 1 names"),
        (
            SimpleNamespace(name=("joint1",), position=(1.0, 2.0), velocity=(), effort=()),
            "wrong_length",
            "2 values",
        ),
        (
            SimpleNamespace(name=("a", "joint1"), position=(1.0, 2.0), velocity=(1.0,), effort=()),
            "wrong_length",
            "velocity",
        ),
        (SimpleNamespace(name=(), position=(1.0, 2.0), velocity=(), effort=()), "wrong_joint", "unnamed"),
    ]
    for msg, reason, text in cases:
        sel, r, detail = select_sample(msg, "joint1")
        assert sel is None and r == reason and text in detail
        g = JointInputGate("joint1")
        msg.stamp_ns = T0
        assert g.admit(msg, T0) == REJECTED and g.log.counts[reason] == 1
    need = JointInputGate("joint1", need_velocity=True, need_effort=True)
    assert need.admit(js(T0, 0.5, eff=None), T0) == REJECTED and "no effort value" in need.log_line


def test_select_command():
    cmd = SimpleNamespace(name=("joint1",), effort=(0.5,))
    assert select_command(cmd, "joint1", 1e6) == (0.5, "", "")
    assert select_command(SimpleNamespace(name=(), effort=(0.5,)), "joint1", 1e6)[0] == 0.5
    for msg, reason in [
        (SimpleNamespace(name=("x",), effort=(0.5,)), "wrong_joint"),
        (SimpleNamespace(name=("joint1",), effort=()), "wrong_length"),
        (SimpleNamespace(name=("joint1", "b"), effort=(0.5,)), "wrong_length"),
        (SimpleNamespace(name=(), effort=(0.5, 1.0)), "wrong_length"),
        (SimpleNamespace(name=("joint1",), effort=(math.nan,)), "not_finite"),
        (SimpleNamespace(name=("joint1",), effort=(1e308,)), "out_of_range"),
    ]:
        e, r, detail = select_command(msg, "joint1", 1e6)
        assert e is None and r == reason and detail


def test_rejection_log_is_rate_limited_per_reason_and_reports_recovery():
    log = RejectionLog("joint state of j", period=1.0)
    lines = [log.reject("jump", "x", 0.001 * k) for k in range(10_000)]  # 10 s of 1 kHz rejections
    printed = [ln for ln in lines if ln]
    assert len(printed) == 10 and log.counts["jump"] == 10_000
    assert "(999 more jump rejections since the last line)" in printed[1]
    assert log.reject("not_finite", "y", 9.9999) is not None  # another reason has its own limit
    assert log.recovered() == "joint state of j: accepted again after 10001 rejected"
    assert log.recovered() is None


def test_gate_configuration_is_validated():
    assert set(GATE_DEFAULTS) >= {"max_position", "max_velocity", "max_effort", "max_stamp_lead"}
    with pytest.raises(ParameterError, match="input_gate.max_velocity = 0 is out of range"):
        JointInputGate("j", {"max_velocity": 0.0})
    with pytest.raises(ParameterError, match="input_gate.max_jump is not a parameter"):
        JointInputGate("j", {"max_jump": 1.0})
    with pytest.raises(ParameterError, match="resync_samples"):
        JointInputGate("j", {"resync_samples": 0})


CTRL = {"mode": "pid", "pid": {"p": 200.0, "i": 50.0, "d": 0.15}}


def test_controller_defaults_bound_the_command_and_the_integrator():
    """The issue's case without any gate: one finite absurd position gave 1e301 N*m, then ~5e297 N*m
    on every later valid state. Defaults now: |command| <= 1e6 N*m, integrator not wound up."""
    c = CompensatingController(CTRL)
    ref = (0.1, 0.0, 0.0)
    clean = CompensatingController(CTRL)
    bad = c.compute(0.0, ref, (1e300, 0.0), 1e-3)
    assert bad.saturated and bad.command == -1e6
    for k in range(1, 200):
        m = (0.05 + 1e-4 * k, 0.0)
        a = c.compute(k * 1e-3, ref, m, 1e-3).command
        b = clean.compute(k * 1e-3, ref, m, 1e-3).command
        assert a == b and abs(a) < 20.0  # the absurd sample left no trace
    assert c.pid.integral == clean.pid.integral > 0.0


def test_pid_integral_bounds_and_default_antiwindup():
    pid = Pid(p=1.0, i=100.0)
    assert pid.antiwindup_strategy == "conditional_integration"
    for _ in range(100):
        pid.update(1e9, 1e-3, error_dot=0.0, integral_lower=-5.0, integral_upper=5.0)
    assert pid.integral == 5.0


def test_gate_in_front_of_the_controller_gives_the_clean_run():
    """Bad samples never enter the controller: the commands on the good samples are bit-identical
    to a run that never saw the bad ones."""
    g = JointInputGate("joint1")
    c, clean = CompensatingController(CTRL), CompensatingController(CTRL)
    bad = {20: (1e300, 0.0), 40: (math.nan, 0.0), 60: (0.0, math.inf), 80: (50.0, 0.0)}
    for k in range(100):
        pos, vel = bad.get(k, (0.01 * math.sin(0.1 * k), 0.0))
        stamp = T0 + k * MS
        if g.admit(js(stamp, pos, vel), stamp) in (ACCEPTED, RESYNC):
            a = c.compute(k * 1e-3, (0.1, 0.0, 0.0), (g.position, g.velocity), 1e-3).command
            b = clean.compute(k * 1e-3, (0.1, 0.0, 0.0), (pos, vel), 1e-3).command
            assert a == b
        else:
            assert k in bad
    assert g.log.total == 4 and g.log.counts["jump"] == 1


def test_plant_refuses_an_absurd_command_and_stays_finite_at_the_limit():
    plant = resolve_preset("seed001_harmonic_drive", {}).make_plant()  # no current/voltage limit
    before = plant.state
    for c in (1e308, -1e308, math.nan, math.inf, 2 * MAX_COMMAND):
        with pytest.raises(ParameterError, match="plant command = .* is out of range"):
            plant.step(c, 1e-3)
    assert plant.state["position"] == before["position"] and plant.time == 0.0
    for k in range(2000):  # 2 s of bang-bang at the largest accepted command
        m = plant.step(MAX_COMMAND if k % 200 < 100 else -MAX_COMMAND, 1e-3)
    assert all(math.isfinite(x) for x in (m.position, m.velocity, m.effort))
    with pytest.raises(ParameterError):
        plant.run_open_loop([0.0, 1e308], 1e-3)
