"""Excitation programs (pure core) driving the ABB M19-S plant directly with command_scale."""

from __future__ import annotations

import math

import numpy as np
import pytest

from friction_ros.core.experiment.events import ABORT, END, START
from friction_ros.core.experiment.excitation import ExcitationProgram, make_program
from friction_ros.core.experiment.velocity_programs import random_velocity
from friction_ros.core.presets import load_preset
from friction_ros.core.validation import ParameterError

FS = 0.95  # ABB M19-S paper static friction of the ABB M19-S [N*m]


def run(config, *, max_time=None, plant=None):
    """Step the preset plant with the program's torque; return arrays and events."""
    preset = load_preset("abb_m19s")
    plant = plant or preset.make_plant()
    scale = plant.command_scale
    prog = make_program(config)
    dt = prog.config["control_period"]
    t, pos, vel = 0.0, 0.0, 0.0
    rows, events, progress = [], [], []
    limit = (max_time or prog.total_duration) + 1.0
    while not prog.done and t < limit:
        tau, ev = prog.update(t, pos, vel)
        events += ev
        progress.append(prog.progress)
        m = plant.step(tau * scale, dt)
        rows.append((t, tau, m.position, m.velocity, m.effort))
        t += dt
        pos, vel = m.position, m.velocity
    a = np.array(rows)
    return (
        prog,
        {"t": a[:, 0], "tau": a[:, 1], "pos": a[:, 2], "vel": a[:, 3], "eff": a[:, 4]},
        events,
        progress,
    )


def pairs(events, program):
    starts = {e.index: e for e in events if e.program == program and e.event == START}
    return [(starts[e.index], e) for e in events if e.program == program and e.event == END]


def test_plateaus_reach_velocity_and_measure_steady_state_friction():
    preset = load_preset("abb_m19s")
    prog, d, events, _ = run({"program": "plateaus", "profile": "quick"})
    assert prog.done and not prog.aborted
    p = prog.config["plateaus"]
    speeds = np.geomspace(p["v_max"], p["v_min"], p["count"])
    expected = [s * sgn for s in speeds for sgn in (1, -1)]
    segs = pairs(events, "plateaus")
    assert [s.target for s, _ in segs] == pytest.approx(expected)
    assert [s.index for s, _ in segs] == list(range(len(expected)))
    assert all(s.note == "settle=0.2" for s, _ in segs)
    for s, e in segs:
        sel = (d["t"] >= s.time + p["settle"]) & (d["t"] < e.time)
        v, tau = d["vel"][sel].mean(), d["eff"][sel].mean()
        assert v == pytest.approx(s.target, rel=0.02, abs=0.005), s.segment
        truth = float(preset.friction.steady_state(np.array([v]))[0])
        assert tau == pytest.approx(truth, rel=0.02), s.segment
    assert d["tau"][-1] == 0.0


def test_breakaway_detected_at_static_friction_both_directions():
    prog, d, events, _ = run({"program": "breakaway", "breakaway": {"repeats": 2}})
    assert prog.done and not prog.aborted
    ends = [e for e in events if e.event == END]
    assert [e.segment for e in ends] == ["breakaway+", "breakaway-"] * 2
    for e in ends:
        assert abs(e.target) == pytest.approx(FS, rel=0.03)
        assert math.copysign(1, e.target) == (1 if e.segment.endswith("+") else -1)
    assert [b for _, b in prog.breakaways] == [e.target for e in ends]
    # released: zero torque at the end, joint at rest
    assert d["tau"][-1] == 0.0 and abs(d["vel"][-50:]).max() < 0.5


def test_breakaway_without_motion_aborts_at_max_torque():
    # max below the static friction: the ramp ends without motion -> ABORT, program goes on; no ramp
    # broke away, so the program ends with a program-level ABORT: the joint was not excited
    prog, d, events, _ = run({"program": "breakaway", "breakaway": {"repeats": 1, "max": 0.8}})
    aborts = [e for e in events if e.event == ABORT]
    assert len(aborts) == 3 and "no breakaway up to breakaway.max = 0.8" in aborts[0].note
    assert [a.segment for a in aborts] == ["breakaway+", "breakaway-", "program"]
    assert prog.not_excited == aborts[2].note and "none of the 2 segments" in prog.not_excited
    assert prog.done and abs(d["tau"]).max() <= 0.8 + 1e-12 and d["tau"][-1] == 0.0


def test_random_velocity_is_band_limited_under_the_rectangular_envelope():
    cfg = make_program({"program": "random"}).config
    v = random_velocity(cfg)
    dt = cfg["control_period"]
    assert v.size == 50000  # ABB M19-S paper: 50 s at 1 kHz
    spec = np.abs(np.fft.rfft(v)) ** 2
    f = np.fft.rfftfreq(v.size, dt)
    assert spec[f > 8.0].sum() < 0.01 * spec.sum()  # 4 Hz band limit
    t = np.arange(v.size) * dt
    phase = (t % 10.0) / 10.0
    hi = np.sqrt(np.mean(v[(phase > 0.1) & (phase < 0.4)] ** 2))
    lo = np.sqrt(np.mean(v[(phase > 0.6) & (phase < 0.9)] ** 2))
    assert hi > 4 * lo  # the envelope emphasises low velocity half of each 10 s period
    assert abs(v[0]) < 1e-9 and abs(v[-1]) < 1e-9


def test_random_program_tracks_reference_on_the_plant():
    prog, d, events, _ = run({"program": "random", "random": {"duration": 10.0}})
    assert [(e.segment, e.event) for e in events] == [("random", START), ("random", END)]
    ref = random_velocity(prog.config)
    n = min(ref.size, d["vel"].size)
    c = np.corrcoef(ref[: n - 5], d["vel"][5:n])[0, 1]
    assert c > 0.85  # PI only (no friction feed-forward): the joint sticks briefly at reversals


def test_chirp_decaying_amplitude_stops_motion_near_the_end():
    prog, d, events, _ = run({"program": "chirp", "chirp": {"duration": 6.0}})
    assert not prog.aborted
    first, last = d["t"] < 1.0, d["t"] > 5.4
    assert np.abs(d["tau"][first]).max() == pytest.approx(1.2, rel=0.05)
    assert np.abs(d["tau"][last]).max() < 0.6
    assert np.ptp(d["pos"][first]) > 0.05  # breaks away at the start
    assert np.abs(d["vel"][last]).max() < 0.5 * np.abs(d["vel"][first]).max()


def test_presliding_cycles_stay_in_presliding():
    prog, d, events, _ = run({"program": "presliding", "profile": "quick"})
    assert [e.segment for e in events if e.event == END] == ["presliding0.4", "presliding0.8"]
    assert np.ptp(d["pos"]) < 0.01  # Q_h ~ 0.004 rad: no gross sliding
    assert np.abs(d["tau"]).max() <= 0.8 + 1e-9


def test_quick_sequence_events_progress_and_duration():
    prog, d, events, progress = run({"profile": "quick"})
    assert prog.done and not prog.aborted
    assert list(dict.fromkeys(e.program for e in events)) == [
        "breakaway",
        "plateaus",
        "presliding",
        "random",
        "chirp",
    ]
    assert sum(e.event == START for e in events) == sum(e.event == END for e in events) == prog.marked_count
    assert 20.0 <= d["t"][-1] <= prog.total_duration <= 40.0
    assert np.all(np.diff(progress) >= -1e-12) and prog.progress == 1.0
    assert np.abs(d["tau"]).max() <= prog.max_torque
    default = make_program({})
    assert 60.0 <= default.total_duration <= 140.0


def test_position_limit_aborts_with_zero_torque():
    prog, d, events, _ = run({"program": "plateaus", "limits": {"max_travel": 0.5}})
    aborts = [e for e in events if e.event == ABORT]
    assert len(aborts) == 1 and "position limit" in aborts[0].note and "limits.max_travel" in aborts[0].note
    assert aborts[0].program == "plateaus"
    i = int(np.searchsorted(d["t"], aborts[0].time))
    assert np.all(d["tau"][i:] == 0.0) and prog.done and prog.aborted
    assert prog.update(d["t"][-1] + 1.0, 0.0, 0.0) == (0.0, [])


def test_velocity_and_nonfinite_limits_and_skip():
    prog = make_program({"program": "plateaus", "profile": "quick", "limits": {"on_limit": "skip"}})
    tau, ev = prog.update(0.0, 0.0, 0.0)
    assert [e.event for e in ev] == [START] and tau != 0.0
    tau, ev = prog.update(0.001, 0.0, 99.0)
    assert tau == 0.0 and ev[0].event == ABORT and "velocity limit" in ev[0].note
    assert not prog.done  # skip: zero torque for `gap`, then the next segment
    tau, ev = prog.update(0.002, 0.0, 0.0)
    assert tau == 0.0 and ev == []
    tau, ev = prog.update(1.0, 0.0, 0.0)
    assert ev[0].event == START and ev[0].index == 1
    tau, ev = prog.update(1.001, math.nan, 0.0)
    assert tau == 0.0 and "not finite" in ev[0].note


def test_torque_limit_aborts():
    prog = make_program({"program": "presliding"})
    prog.max_torque = 0.5  # below the 0.6 N*m cycle: the defence against a program bug trips
    taus = []
    events = []
    for k in range(6000):
        tau, ev = prog.update(k * 1e-3, 0.0, 0.0)
        taus.append(tau)
        events += ev
        if prog.done:
            break
    ab = [e for e in events if e.event == ABORT]
    assert ab and "torque limit" in ab[0].note and prog.done
    assert max(abs(x) for x in taus) <= 0.5


def test_duplicate_time_returns_cached_torque():
    prog = make_program({"program": "plateaus"})
    tau0, ev0 = prog.update(0.0, 0.0, 0.0)
    tau1, ev1 = prog.update(0.0, 0.0, 5.0)
    assert tau1 == tau0 and ev1 == [] and len(ev0) == 1


@pytest.mark.parametrize(
    "config, words",
    [
        ({"program": "sine"}, ["program", "plateaus"]),
        ({"profile": "slow"}, ["profile", "quick"]),
        ({"plateaus": {"v_min": -1.0}}, ["plateaus.v_min", "> 0"]),
        ({"plateaus": {"vmin": 1.0}}, ["plateaus", "'vmin'", "v_min"]),
        ({"plateaus": {"v_max": 50.0}}, ["plateaus.v_max", "limits.max_velocity"]),
        ({"breakaway": {"max": 3.0}}, ["breakaway.max", "<= 2.5"]),
        ({"breakaway": {"counts": 0}}, ["breakaway.counts", ">= 1"]),
        ({"sequence": ["plateaus", "sequence"]}, ["sequence[1]"]),
        ({"limits": {"on_limit": "ignore"}}, ["limits.on_limit", "stop"]),
        ({"presliding": {"amplitudes": []}}, ["presliding.amplitudes"]),
        ({"chirp": {"f1": 0.5}}, ["chirp.f1", ">= 2"]),
        ({"velocity_loop": {"p": "fast"}}, ["velocity_loop.p", "number"]),
        ({"control_period": 0.0}, ["control_period", ">= 1e-05"]),
    ],
)
def test_validation_errors_name_key_and_range(config, words):
    with pytest.raises(ParameterError) as exc:
        ExcitationProgram(config)
    for w in words:
        assert w in str(exc.value)
