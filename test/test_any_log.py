"""Identification from any log: MCAP and SQLite3 rosbag2 bags (written by rosbags) and CSV files.

The same simulated run stored three ways must give the same record and the same fit; CSV logs with
several joints, motor current, jittered stamps or bad content; the real DFKI pendulum excerpt.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from friction_ros.cli.fit import main
from friction_ros.core.bag import bag_files, bag_info, iter_messages, read_bag
from friction_ros.core.bag.msgdef import load_installed, parse_schema
from friction_ros.core.bag.rosbags_reader import typestore
from friction_ros.core.identification.data.bag_loading import load_bag
from friction_ros.core.identification.data.csv_loading import load_csv
from friction_ros.core.identification.data.log_loading import load_log
from friction_ros.core.identification.data.records import ExcitationError
from friction_ros.core.identification.fit.pipeline import fit_records
from friction_ros.core.synthetic import plant_runs

PENDULUM = Path(__file__).parent / "data" / "dfki_pendulum" / "control_method_pd_system_identification.csv"
EPOCH_NS = 1_700_000_000_000_000_000
MODELS = ["coulomb_viscous", "stribeck"]
#: physics models only: the learned residual (fit_records residual="auto") is another test's subject
NO_RESIDUAL = ["--residual", "none"]


# ------------------------------------------------------------------------------------------ writers
def _stamps(t: np.ndarray, epoch_ns: int = EPOCH_NS) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(ns, sec, nanosec, float s) of ``t``; the float is what the bag loader computes from the header."""
    ns = epoch_ns + np.round(np.asarray(t) * 1e9).astype(np.int64)
    sec, nsec = ns // 1_000_000_000, ns % 1_000_000_000
    return ns, sec, nsec, sec.astype(np.float64) + nsec * 1e-9


def _write_rosbags(path: Path, plugin, t, joints: dict, events=()) -> Path:
    """A rosbag2 bag by the rosbags writer: JointState of ``joints`` {name: (pos, vel, eff)} + events."""
    from rosbags.rosbag2 import Writer

    ts = typestore()
    js_t = ts.types["sensor_msgs/msg/JointState"]
    hdr = ts.types["std_msgs/msg/Header"]
    tm = ts.types["builtin_interfaces/msg/Time"]
    ev_t = ts.types["friction_msgs/msg/ExperimentEvent"]
    ns, sec, nsec, _ = _stamps(t)
    names = list(joints)
    cols = [np.stack([joints[n][i] for n in names], axis=1) for i in range(3)]
    with Writer(path, version=9, storage_plugin=plugin) as w:
        cj = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        ce = w.add_connection("/experiment_events", "friction_msgs/msg/ExperimentEvent", typestore=ts)
        for e in events:
            ens, es, en, _ = _stamps(np.array([e.time]))
            msg = ev_t(
                hdr(tm(sec=int(es[0]), nanosec=int(en[0])), ""),
                e.program,
                e.segment,
                e.index,
                e.event,
                e.target,
                e.note,
            )
            w.write(ce, int(ens[0]), ts.serialize_cdr(msg, ce.msgtype))
        for k in range(len(ns)):
            msg = js_t(
                hdr(tm(sec=int(sec[k]), nanosec=int(nsec[k])), ""),
                names,
                cols[0][k].copy(),
                cols[1][k].copy(),
                cols[2][k].copy(),
            )
            w.write(cj, int(ns[k]), ts.serialize_cdr(msg, cj.msgtype))
    return path


def _write_csv(path: Path, columns: dict[str, np.ndarray], sep: str = ",") -> Path:
    """CSV with a header and every float written with repr (round-trips exactly)."""
    names = list(columns)
    arrays = [np.asarray(columns[n]) for n in names]
    lines = [sep.join(names)]
    for k in range(len(arrays[0])):
        lines.append(sep.join(repr(a[k].item()) for a in arrays))
    path.write_text("\n".join(lines) + "\n")
    return path


def _coefficients(res) -> dict[str, dict[str, float]]:
    return {m: {k: float(v) for k, v in r.coefficients.items()} for m, r in res.models.items()}


def _same_fit(a, b) -> None:
    assert a.recommended == b.recommended
    ca, cb = _coefficients(a), _coefficients(b)
    assert ca.keys() == cb.keys()
    for m in ca:
        assert ca[m].keys() == cb[m].keys(), m
        for k in ca[m]:
            np.testing.assert_allclose(cb[m][k], ca[m][k], rtol=1e-9, atol=0, err_msg=f"{m}.{k}")


def _expect_error(argv, capsys, *words) -> str:
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.startswith("friction-fit: error:") and err.count("\n") == 1, err  # one line
    for w in words:
        assert w in err, err
    return err


# ------------------------------------------------------------------------------------------ fixtures
@pytest.fixture(scope="module")
def run():
    """20 s of ABB M19-S paper's excitation on the simulated ABB joint (deterministic)."""
    return plant_runs.abb_m19s_excitation_experiment(20.0, low=0.05)


@pytest.fixture(scope="module")
def logs(run, tmp_path_factory):
    """The same run as an MCAP bag and a SQLite3 bag (rosbags) and a CSV log."""
    from rosbags.rosbag2 import StoragePlugin

    d = tmp_path_factory.mktemp("anylog")
    joints = {"joint1": (run.position, run.velocity, run.effort)}
    mcap = _write_rosbags(d / "run_mcap", StoragePlugin.MCAP, run.t, joints, run.events)
    db3 = _write_rosbags(d / "run_db3", StoragePlugin.SQLITE3, run.t, joints, run.events)
    _, _, _, stamp = _stamps(run.t)
    csv = _write_csv(
        d / "run.csv",
        {"time": stamp, "position": run.position, "velocity": run.velocity, "effort": run.effort},
    )
    return {"mcap": mcap, "db3": db3, "csv": csv}


# ------------------------------------------------------------------------------------------ (a) same data
def test_storage_dispatch(logs):
    assert sorted(p.suffix for p in bag_files(logs["mcap"])[1]) == [".mcap"]
    assert [p.suffix for p in bag_files(logs["db3"])[1]] == [".db3"]
    info = bag_info(logs["db3"]).info
    assert (
        info["/joint_states"].count == 20000 and info["/joint_states"].msgtype == "sensor_msgs/msg/JointState"
    )
    assert info["/experiment_events"].msgtype == "friction_msgs/msg/ExperimentEvent"
    assert sum(1 for m in iter_messages(logs["db3"], ["/experiment_events"])) == 2


def test_bags_and_csv_load_the_same_record(logs, run):
    recs = {k: load_log(p, events_topic=None) for k, p in logs.items()}
    ref = recs["mcap"]
    assert ref.n >= run.t.size and abs(ref.dt - 1e-3) < 1e-6
    for k, r in recs.items():
        assert r.n == ref.n and r.dt == ref.dt and r.t0 == ref.t0, k
        for f in ("t", "position", "velocity", "acceleration", "torque"):
            assert np.array_equal(getattr(r, f), getattr(ref, f)), (k, f)
    # the bag columns themselves: the db3 through rosbags equals the MCAP through the fast reader
    a, b = read_bag(logs["mcap"])["/joint_states"], read_bag(logs["db3"])["/joint_states"]
    assert np.array_equal(a.log_time, b.log_time) and list(a.fields) == list(b.fields)
    for key in ("position", "velocity", "effort", "header.stamp.sec", "header.stamp.nanosec"):
        assert a[key].dtype == b[key].dtype and np.array_equal(a[key], b[key]), key
    assert list(a["name"]) == list(b["name"])


def test_db3_events_match_mcap(logs):
    ev = {k: load_bag(logs[k]).events for k in ("mcap", "db3")}
    assert len(ev["db3"]) == 2 and [e.event for e in ev["db3"]] == [0, 1]
    for x, y in zip(ev["mcap"], ev["db3"], strict=True):
        assert x._replace(target=0.0) == y._replace(target=0.0) and math.isnan(x.target) == math.isnan(
            y.target
        )


def test_same_fit_from_every_storage(logs):
    res = {k: fit_records(load_log(p, events_topic=None), MODELS, residual="none") for k, p in logs.items()}
    assert set(res["mcap"].models) == {*MODELS, "baseline"}
    for m in MODELS:  # a real fit, not two empty results compared
        assert any(v != 0 for v in _coefficients(res["mcap"])[m].values()), m
    _same_fit(res["mcap"], res["db3"])
    _same_fit(res["mcap"], res["csv"])


def test_single_db3_file_and_db3_directory_without_metadata(logs, tmp_path):
    db3_file = next(logs["db3"].glob("*.db3"))
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(db3_file, bare / "part_0.db3")
    ref = load_log(logs["db3"], events_topic=None)
    for p in (db3_file, bare):
        r = load_log(p, events_topic=None)
        assert np.array_equal(r.torque, ref.torque) and np.array_equal(r.position, ref.position), p


def test_custom_type_definition_from_the_type_store():
    """A db3 without stored definitions: ExperimentEvent comes from msg_defs via the rosbags store."""
    name = "friction_msgs/msg/ExperimentEvent"
    text, _ = typestore().generate_msgdef(name, ros_version=2)
    got = parse_schema(text, name)[name]
    want = load_installed(name)[name]
    assert [(f.name, f.type, f.array) for f in got.fields] == [(f.name, f.type, f.array) for f in want.fields]


def test_bad_db3_is_one_line(tmp_path):
    bad = tmp_path / "broken.db3"
    bad.write_bytes(b"not a database" * 10)
    with pytest.raises(ExcitationError) as exc:
        load_log(bad)
    msg = str(exc.value)
    assert "\n" not in msg and str(bad) in msg and "sqlite3" in msg


def test_bag_ignores_csv_options_with_a_warning(logs):
    r = load_log(logs["db3"], columns={"time": "t"}, time_scale=1e-3, events_topic=None)
    assert any("apply to .csv logs only" in w for w in r.meta["warnings"])


# ------------------------------------------------------------------------------------------ (b) CLI
def test_cli_fits_a_db3_bag(logs, tmp_path, capsys):
    out = tmp_path / "fit_db3"
    argv = [str(logs["db3"]), "--models", "coulomb_viscous", "--out", str(out), "--no-gate", "--no-plots"]
    rc = main([*argv, "--quiet", *NO_RESIDUAL])
    text = capsys.readouterr()
    assert rc == 0, text.err
    params = out / "friction_params.yaml"
    assert params.read_text().startswith("# friction-fit:")


def test_cli_fits_a_csv_with_named_columns_and_time_scale(run, tmp_path, capsys):
    ns = np.round(run.t * 1e9).astype(np.int64)
    csv = _write_csv(
        tmp_path / "log.csv",
        {"clock_ns": ns, "angle": run.position, "rate": run.velocity, "drive_torque": run.effort},
    )
    before = csv.read_bytes()
    out = tmp_path / "fit_csv"
    argv = [str(csv), "--columns", "time=clock_ns,position=angle,velocity=rate,effort=drive_torque"]
    argv += ["--time-scale", "1e-9", "--models", "coulomb_viscous", "--out", str(out)]
    rc = main([*argv, "--no-gate", "--no-plots", "--quiet", *NO_RESIDUAL])
    text = capsys.readouterr()
    assert rc == 0, text.err
    assert (out / "friction_params.yaml").read_text().startswith("# friction-fit:")
    assert csv.read_bytes() == before
    # forgetting the time scale of a column named in ns is refused, not read as seconds
    _expect_error(
        argv[:3] + ["--out", str(tmp_path / "x"), "--quiet"], capsys, str(csv), "ns", "--time-scale 1e-09"
    )


# ------------------------------------------------------------------------------------------ (c) CSV cases
@pytest.fixture(scope="module")
def two_joints(run, tmp_path_factory):
    d = tmp_path_factory.mktemp("two")
    t = run.t
    cols = {
        "time": t,
        "position_j1": 0.5 * run.position,
        "velocity_j1": 0.5 * run.velocity,
        "effort_j1": 2.0 * run.effort,
        "j2_position": run.position,
        "j2_velocity": run.velocity,
        "j2_effort": run.effort,
    }
    single = {"time": t, "position": run.position, "velocity": run.velocity, "effort": run.effort}
    return _write_csv(d / "two.csv", cols), _write_csv(d / "single.csv", single)


def test_csv_two_joints_choose_one(two_joints):
    two, single = two_joints
    j2, ref = load_csv(two, "j2"), load_csv(single)
    assert j2.meta["joint"] == "j2" and j2.meta["columns"]["position"] == "j2_position"
    assert np.array_equal(j2.position, ref.position) and np.array_equal(j2.torque, ref.torque)
    j1 = load_csv(two, joint="j1")
    assert np.array_equal(j1.torque, 2.0 * ref.torque)
    with pytest.raises(ExcitationError, match="joints j1, j2"):
        load_csv(two)
    with pytest.raises(ExcitationError, match="no columns of joint 'elbow': joints are j1, j2"):
        load_csv(two, "elbow")


def test_cli_two_joints(two_joints, tmp_path, capsys):
    two, _ = two_joints
    before = two.read_bytes()
    _expect_error([str(two), "--out", str(tmp_path / "a"), "--quiet"], capsys, str(two), "j1, j2", "--joint")
    rc = main(
        [str(two), "--joint", "j2", "--models", "coulomb_viscous", "--out", str(tmp_path / "b")]
        + ["--no-gate", "--no-plots", "--quiet", *NO_RESIDUAL]
    )
    assert rc == 0, capsys.readouterr().err
    assert (tmp_path / "b" / "friction_params.yaml").exists() and two.read_bytes() == before


def test_csv_motor_current_gives_the_same_fit(run, tmp_path, capsys):
    kt, ratio = 0.5, 4.0  # powers of two: current x kt x ratio is the effort bit for bit
    eff = _write_csv(
        tmp_path / "eff.csv",
        {"t": run.t, "q": run.position, "dq": run.velocity, "tau": run.effort},
    )
    cur = _write_csv(
        tmp_path / "cur.csv",
        {"t": run.t, "q": run.position, "dq": run.velocity, "iq": run.effort / (kt * ratio)},
        sep=";",
    )
    a = load_csv(eff)
    b = load_csv(cur, torque_constant=kt, gear_ratio=ratio)
    assert b.meta["columns"] == {"time": "t", "position": "q", "velocity": "dq", "current": "iq"}
    assert np.array_equal(a.torque, b.torque)
    _same_fit(
        fit_records(a, ["coulomb_viscous"], residual="none"),
        fit_records(b, ["coulomb_viscous"], residual="none"),
    )
    with pytest.raises(ExcitationError, match="--torque-constant"):
        load_csv(cur)
    rc = main(
        [str(cur), "--torque-constant", "0.5", "--gear-ratio", "4", "--models", "coulomb_viscous"]
        + ["--out", str(tmp_path / "fit"), "--no-gate", "--no-plots", "--quiet", *NO_RESIDUAL]
    )
    assert rc == 0, capsys.readouterr().err


def test_csv_jittered_stamps_recover_known_friction(tmp_path):
    """2 ms +- 0.4 ms stamps, torque = Fc sgn(v) + Fv v: resampled to 2 ms and the fit finds Fc, Fv."""
    rng = np.random.default_rng(17)
    n = 10000
    t = np.arange(n) * 2e-3 + rng.uniform(-4e-4, 4e-4, n)
    w1, w2 = 2 * np.pi * 0.3, 2 * np.pi * 1.1
    pos = 0.8 * np.sin(w1 * t) + 0.15 * np.sin(w2 * t)
    vel = 0.8 * w1 * np.cos(w1 * t) + 0.15 * w2 * np.cos(w2 * t)
    fc, fv = 0.3, 0.12
    tau = fc * np.sign(vel) + fv * vel
    csv = _write_csv(tmp_path / "jitter.csv", {"timestamp": t, "pos": pos, "vel": vel, "torque": tau})
    d = load_csv(csv)
    assert abs(d.dt - 2e-3) < 2e-5 and np.allclose(np.diff(d.t), d.dt)
    assert d.meta["columns"]["time"] == "timestamp"
    c = fit_records(d, ["coulomb_viscous"], residual="none").models["coulomb_viscous"].coefficients
    assert abs(c["fc"] - fc) < 0.03 * fc and abs(c["fv"] - fv) < 0.05 * fv, c


BAD_CSVS = {
    "no_header.csv": ("0.0,0.1,0.2,0.3\n0.1,0.1,0.2,0.3\n0.2,0.1,0.2,0.3\n", "is numbers, not column names"),
    "no_effort.csv": ("time,position,velocity\n0,0,0\n1,1,1\n2,2,2\n", "no effort column"),
    "no_time.csv": ("clock,position,effort\n0,0,0\n1,1,1\n2,2,2\n", "no time column"),
    "text.csv": ("time,position,effort\n0,0,0\n1,abc,1\n2,2,2\n", "'abc' is not a number"),
    "short.csv": ("time,position,effort\n0,0,0\n1,1,1\n", "2 data rows: need at least 3"),
    "empty.csv": ("", "file is empty"),
    "ragged.csv": ("time,position,effort\n0,0,0\n1,1\n2,2,2\n3,3,3\n", "has 2 values, the header 3"),
    "two_pos.csv": ("time,pos,position,effort\n0,0,0,0\n1,1,1,1\n2,2,2,2\n", "all look like position"),
}


@pytest.mark.parametrize("name", sorted(BAD_CSVS))
def test_bad_csv_is_one_line_and_left_unchanged(name, tmp_path, capsys):
    text, words = BAD_CSVS[name]
    csv = tmp_path / name
    csv.write_text(text)
    before = csv.read_bytes()
    _expect_error([str(csv), "--out", str(tmp_path / "out"), "--quiet"], capsys, str(csv), words)
    assert csv.read_bytes() == before


def test_bad_columns_and_outputs(two_joints, tmp_path, capsys):
    _, csv = two_joints
    before = csv.read_bytes()
    base = [str(csv), "--out", str(tmp_path / "o"), "--quiet"]
    _expect_error([*base, "--columns", "time:t"], capsys, "not ROLE=NAME")
    _expect_error([*base, "--columns", "angle=q"], capsys, "unknown role 'angle'", "time, position")
    _expect_error([*base, "--columns", "time=clock"], capsys, "no column 'clock'", "time, position")
    _expect_error([*base, "--time-scale", "0"], capsys, "time_scale")
    _expect_error([str(csv), "--params-out", str(csv), "--quiet"], capsys, "overlaps the input log")
    _expect_error(
        [str(tmp_path / "missing.csv"), "--out", str(tmp_path / "o"), "--quiet"], capsys, "no such file"
    )
    assert csv.read_bytes() == before


# ------------------------------------------------------------------------------------------ (d) real data
def test_pendulum_excerpt_loads_with_detected_columns():
    d = load_log(PENDULUM)
    assert d.meta["columns"] == {
        "time": "time",
        "position": "position",
        "velocity": "velocity",
        "effort": "torque",
    }
    assert 1165 <= d.n <= 1175 and abs(d.dt - 3.334e-3) < 2e-5
    assert 3.8 < d.t[-1] < 4.0
    assert -17.6 < d.torque.min() < -17.0 and 16.5 < d.torque.max() < 17.1
    assert np.ptp(d.position) > 1.0  # the swing-up moves the joint
