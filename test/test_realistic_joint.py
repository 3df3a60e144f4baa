"""Realistic synthetic joint logs (friction_ros.core.synthetic.realistic_joint): truth, sampling, bags."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from friction_ros.core.bag import read_bag
from friction_ros.core.friction.joint_load import JointLoad
from friction_ros.core.friction.static import StribeckEps
from friction_ros.core.identification.fit.metrics import nmse_percent
from friction_ros.core.synthetic.realistic_joint import (
    JointTruth,
    main,
    make_run,
    noise_floor_nmse_percent,
    pooled_measured_input_nmse_percent,
    pooled_noise_floor_nmse_percent,
    realistic_runs,
    trajectory,
    write_bag,
    write_csv,
)

ARRAYS = (
    "stamp_ns",
    "t",
    "position",
    "velocity",
    "effort",
    "true_position",
    "true_velocity",
    "true_acceleration",
    "true_torque",
    "true_friction",
    "true_load",
    "torque_noise",
)


@pytest.fixture(scope="module")
def runs():
    return realistic_runs()


@pytest.fixture(scope="module")
def short_runs():
    return realistic_runs(duration=3.0, seed=7)


def test_same_seed_identical_arrays_other_seed_differs(runs):
    again = realistic_runs()
    other = realistic_runs(seed=1)
    for a, b, c in zip(runs, again, other):
        assert a.name == b.name
        for key in ARRAYS:
            assert np.array_equal(getattr(a, key), getattr(b, key)), key
        assert not np.array_equal(a.effort[:100], c.effort[:100])
    assert [r.name for r in runs] == ["run0_speed0.1", "run1_speed0.25", "run2_speed0.4"]


def test_stamps_non_uniform_increasing_2ms(runs):
    for r in runs:
        d = np.diff(r.stamp_ns)
        assert np.all(d > 0)
        assert r.stamp_ns.dtype == np.int64
        assert abs(np.median(d) - 2_000_000) < 20_000
        assert 1.5e5 < np.std(d) < 5e5  # jitter ~ 0.15 ms per stamp, plus the rare dropped sample
        assert d.max() >= 3_000_000  # at least one dropped sample over 40 s (drop rate 0.1 %)
        assert np.array_equal(r.t, (r.stamp_ns - r.start_ns) * 1e-9)
        assert r.t[0] == 0.0 and r.t[-1] > 39.99
    # runs follow each other and never overlap
    assert all(a.stamp_ns[-1] < b.stamp_ns[0] for a, b in zip(runs, runs[1:]))


def test_position_quantised_velocity_noisy(runs):
    truth = JointTruth()
    res = truth.encoder_resolution
    for r in runs:
        counts = r.position / res
        assert np.max(np.abs(counts - np.round(counts))) < 1e-6
        assert np.max(np.abs(r.position - r.true_position)) <= 0.5 * res * (1 + 1e-9)
        assert np.unique(r.position).size < r.position.size  # quantised: repeated values at slow speed
        dv = r.velocity - r.true_velocity
        assert np.std(dv) == pytest.approx(truth.velocity_noise_std, rel=0.05)


def test_differentiated_velocity_estimate():
    truth = JointTruth(velocity_estimate="differentiated")
    r = make_run(truth, 0.3, 2.0, 5)
    assert np.array_equal(r.velocity[1:], np.diff(r.position) / np.diff(r.t))
    # link encoder steps over 2 ms (0.024 rad/s) are far coarser than the drive's estimate
    assert np.std(r.velocity - r.true_velocity) > 5 * truth.velocity_noise_std


def test_truth_composition(runs):
    truth = JointTruth()
    for r in runs:
        q, v, a = r.true_position, r.true_velocity, r.true_acceleration
        rebuilt = r.effort - r.torque_noise - r.sensor_offset
        assert np.allclose(rebuilt, truth.J * a + r.true_load + r.true_friction, rtol=0, atol=1e-12)
        assert np.array_equal(r.true_torque, truth.torque(q, v, a))
        assert np.array_equal(r.true_load, truth.load_torque(q))
        assert np.array_equal(r.true_friction, truth.friction(v, q, a))
        assert np.std(r.torque_noise) == pytest.approx(truth.torque_noise_std, rel=0.05)
        assert abs(np.mean(r.torque_noise)) < 5 * truth.torque_noise_std / math.sqrt(r.t.size)
    assert runs[0].sensor_offset == truth.sensor_offset


def test_truth_agrees_with_joint_load_and_stribeck_eps(runs):
    """The independent truth formulas against the package's JointLoad and StribeckEps (1e-12)."""
    truth = JointTruth()
    jl = JointLoad.from_config(truth.load_config())
    stribeck = StribeckEps(
        fc=truth.fc, fs=truth.fs, vs=truth.vs, delta=truth.delta, fv=truth.fv, eps=truth.eps
    )
    for r in runs:
        q, v, a = r.true_position, r.true_velocity, r.true_acceleration
        assert np.allclose(jl.load_torque(q), truth.load_torque(q), rtol=0, atol=1e-12)
        assert np.allclose(jl.ripple(q), truth.ripple(q), rtol=0, atol=1e-12)
        assert np.allclose(
            jl.friction(v, q, jl.load_torque(q) + truth.J * a),
            truth.friction(v, q, a) - truth.friction_map(v),
            rtol=0,
            atol=1e-12,
        )
        full = truth.J * a + jl.torque(q, v, a, inertia=truth.J) + stribeck.torque(v)
        assert np.allclose(full, r.true_torque, rtol=0, atol=1e-12)
    vv = np.array([-1.0, -0.03, -2e-3, -5e-4, 0.0, 5e-4, 2e-3, 0.03, 1.0])
    assert np.allclose(stribeck.torque(vv), truth.friction_map(vv), rtol=0, atol=1e-12)
    # hand values: F(vs) = fc + (fs - fc)/e + fv vs; F(eps/2) = (fc + (fs - fc) exp(-(eps/2/vs)^2))/2 + fv eps/2
    assert truth.friction_map(0.03) == pytest.approx(2.0 + 0.6 / math.e + 0.09, abs=1e-12)
    h = 5e-4
    assert truth.friction_map(h) == pytest.approx(
        0.5 * (2.0 + 0.6 * math.exp(-((h / 0.03) ** 2))) + 3.0 * h, abs=1e-12
    )


def test_defaults_are_a_harmonic_drive_joint_with_active_terms(runs):
    t = JointTruth()
    amp1 = math.hypot(t.ripple_cos[0], t.ripple_sin[0])
    assert 0.05 <= amp1 / t.fc <= 0.10
    assert 0.02 <= t.torque_noise_std / t.fc <= 0.05
    assert t.fs > t.fc and 0.02 <= t.vs <= 0.05 and 0.02 <= t.load_friction <= 0.05
    assert 0.1 <= t.sensor_offset <= 0.3 and t.sample_period == 0.002
    d = t.to_dict()
    assert d["J"] == t.J and d["ripple_cos"] == t.ripple_cos and "AI friction chapter eq. 5" in d["equations"]
    yaml.safe_dump(d)  # plain types only
    fast = runs[-1]
    load_fric = fast.true_friction - t.friction_map(fast.true_velocity)
    assert np.ptp(load_fric) > 0.5  # load-dependent and ripple terms visibly present
    with pytest.raises(ValueError, match="ripple"):
        JointTruth(ripple_cos=[0.1], ripple_sin=[])


def test_trajectories_ordinary_motion(runs):
    truth = JointTruth()
    for r, speed in zip(runs, (0.1, 0.25, 0.4)):
        v = r.true_velocity
        assert np.max(np.abs(v)) == pytest.approx(speed, rel=2e-3)
        assert np.max(np.abs(r.true_position)) <= 1.5 + 1e-9
        assert np.count_nonzero(np.diff(np.sign(v))) >= 6  # velocity reversals
        # no plateaus: the velocity never stays within 1 % of max speed for a whole second
        win = int(1.0 / truth.sample_period)
        sw = np.lib.stride_tricks.sliding_window_view(v, win)
        assert np.min(np.ptp(sw, axis=1)) > 0.01 * speed
    fast = runs[-1].true_position
    assert np.ptp(fast) > 2.0  # wide angle range at 0.4 rad/s
    g = np.sin(fast + truth.gravity_phase)
    assert g.min() < -0.5 and g.max() > 0.5  # both directions of gravity
    assert np.ptp(fast) / truth.ripple_period > 20  # many ripple periods


@pytest.mark.parametrize("kind", ["multisine", "bandlimited"])
def test_trajectory_derivatives_are_exact(kind):
    tr = trajectory(kind, 20.0, 0.3, seed=2)
    t = np.linspace(0.0, 20.0, 200_001)
    q, v, a = tr(t)
    dt = t[1] - t[0]
    assert np.max(np.abs(np.gradient(q, dt) - v)[1:-1]) < 1e-6
    assert np.max(np.abs(np.gradient(v, dt) - a)[1:-1]) < 1e-5
    assert np.max(np.abs(v)) == pytest.approx(0.3, rel=2e-3)
    assert np.array_equal(tr.q(t[:10]), trajectory(kind, 20.0, 0.3, seed=2).q(t[:10]))
    with pytest.raises(ValueError):
        trajectory("plateaus", 20.0, 0.3)


def test_noise_floor(runs):
    for r in runs:
        want = 100.0 * np.var(r.torque_noise) / np.var(r.effort)
        assert r.noise_floor_nmse_percent == pytest.approx(want, rel=1e-12)
        # what a perfect model (true torque + sensor offset) scores
        assert nmse_percent(r.true_torque + r.sensor_offset, r.effort) == pytest.approx(want, rel=1e-2)
        assert r.friction_noise_floor_nmse_percent == pytest.approx(
            100.0 * np.var(r.torque_noise) / np.var(r.true_friction + r.torque_noise), rel=1e-12
        )
        assert r.friction_noise_floor_nmse_percent > r.noise_floor_nmse_percent
        # the true model on the logged (noisy, quantised) inputs: worse than the floor, still small
        y_in = r.truth.torque(r.position, r.velocity, r.true_acceleration) + r.truth.sensor_offset
        assert np.array_equal(r.measured_input_torque(), y_in)
        assert r.measured_input_nmse_percent == pytest.approx(nmse_percent(y_in, r.effort), rel=1e-12)
        assert r.noise_floor_nmse_percent < r.measured_input_nmse_percent < 2.0
    pooled_in = pooled_measured_input_nmse_percent(runs)
    assert min(r.measured_input_nmse_percent for r in runs) < pooled_in
    assert pooled_in < max(r.measured_input_nmse_percent for r in runs)
    pooled = pooled_noise_floor_nmse_percent(runs)
    noise = np.concatenate([r.torque_noise for r in runs])
    eff = np.concatenate([r.effort for r in runs])
    assert pooled == pytest.approx(noise_floor_nmse_percent(noise, eff), rel=1e-12)
    assert pooled == pytest.approx(100.0 * np.var(noise) / np.var(eff), rel=1e-12)
    assert 0.0 < pooled < 1.0


def _read_rosbags(path):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    log, stamp, pos, vel, eff, names = [], [], [], [], [], set()
    with Reader(path) as rd:
        for conn, t, raw in rd.messages():
            assert conn.topic == "/joint_states" and conn.msgtype == "sensor_msgs/msg/JointState"
            m = ts.deserialize_cdr(raw, conn.msgtype)
            log.append(t)
            stamp.append(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)
            names.add(tuple(m.name))
            pos.append(m.position[0])
            vel.append(m.velocity[0])
            eff.append(m.effort[0])
    return names, np.array(log), np.array(stamp), np.array(pos), np.array(vel), np.array(eff)


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_bags_read_back_with_rosbags_and_package_reader(short_runs, tmp_path, storage):
    paths = write_bag(short_runs, tmp_path / "bags", storage=storage)
    assert [p.name for p in paths] == [r.name for r in short_runs]
    ext = ".mcap" if storage == "mcap" else ".db3"
    for r, p in zip(short_runs, paths):
        assert (p / "metadata.yaml").is_file() and list(p.glob(f"*{ext}"))
        names, log, stamp, pos, vel, eff = _read_rosbags(p)
        assert names == {("joint1",)}
        assert np.array_equal(log, r.stamp_ns) and np.array_equal(stamp, r.stamp_ns)
        assert np.array_equal(pos, r.position)
        assert np.array_equal(vel, r.velocity)
        assert np.array_equal(eff, r.effort)
        td = read_bag(p)["/joint_states"]
        j = td.joint("joint1")
        assert np.array_equal(td.log_time, r.stamp_ns)
        assert np.allclose(j.stamp, r.stamp_ns * 1e-9, rtol=0, atol=1e-6)
        assert np.array_equal(j.position, pos) and np.array_equal(j.position, r.position)
        assert np.array_equal(j.velocity, vel) and np.array_equal(j.velocity, r.velocity)
        assert np.array_equal(j.effort, eff) and np.array_equal(j.effort, r.effort)
    with pytest.raises(FileExistsError):
        write_bag(short_runs, tmp_path / "bags", storage=storage)


def test_bag_bytes_deterministic_and_explicit_paths(short_runs, tmp_path):
    a = write_bag(short_runs[:1], [tmp_path / "a" / "bag"])
    b = write_bag(realistic_runs(duration=3.0, seed=7)[:1], [tmp_path / "b" / "bag"])
    fa, fb = sorted(a[0].iterdir()), sorted(b[0].iterdir())
    assert [f.name for f in fa] == [f.name for f in fb] == ["bag.mcap", "metadata.yaml"]
    for x, y in zip(fa, fb):
        assert x.read_bytes() == y.read_bytes()
    (b[0] / "bag.mcap").write_bytes(b"stale")
    write_bag(short_runs[:1], [tmp_path / "b" / "bag"], overwrite=True)
    assert (b[0] / "bag.mcap").read_bytes() == (a[0] / "bag.mcap").read_bytes()
    with pytest.raises(ValueError, match="paths"):
        write_bag(short_runs, [tmp_path / "c"])
    with pytest.raises(ValueError, match="storage"):
        write_bag(short_runs, tmp_path / "d", storage="bag")


def test_csv_round_trip(short_runs, tmp_path):
    r = short_runs[1]
    p = write_csv(r, tmp_path / "run.csv")
    lines = p.read_text().splitlines()
    assert lines[0] == "time,position,velocity,effort"
    cols = np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]]).T
    for col, want in zip(cols, (r.t, r.position, r.velocity, r.effort)):
        assert np.array_equal(col, want)


def test_main_writes_bags_csv_and_truth(tmp_path, capsys):
    out = tmp_path / "out"
    assert main([str(out), "--duration", "2", "--speeds", "0.2", "--seed", "4"]) == 0
    doc = yaml.safe_load((out / "truth.yaml").read_text())
    assert doc["truth"] == JointTruth().to_dict()
    assert doc["runs"][0]["name"] == "run0_speed0.2"
    assert doc["pooled_noise_floor_nmse_percent"] == pytest.approx(doc["runs"][0]["noise_floor_nmse_percent"])
    j = read_bag(out / "run0_speed0.2")["/joint_states"].joint("joint1")
    assert j.position.size == doc["runs"][0]["samples"]
    assert (out / "run0_speed0.2.csv").is_file()
    assert "noise floor" in capsys.readouterr().out
