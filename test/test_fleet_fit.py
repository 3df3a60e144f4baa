"""friction-fleet fit: discovery, the table's rows and units, idempotence, 1 vs 2 Dask workers, a
failed run, a killed worker, bad input. Tiny synthetic runs (2 s) and two static models keep it short."""

from __future__ import annotations

import datetime as dt
import hashlib
import math
import shutil
from pathlib import Path

import dask
import numpy as np
import pyarrow as pa
import pytest

from friction_ros.cli.fleet import main
from friction_ros.core.fleet import table as ft
from friction_ros.core.fleet.discovery import discover
from friction_ros.core.fleet.driver import KILLED
from friction_ros.core.fleet.run_fit import CRASH_MARK_ENV, run_rows
from friction_ros.core.synthetic.logs import make_log

FAST = ["--models", "coulomb", "stribeck", "--maxiter", "3", "--train-seconds", "1", "--quiet"]
PATTERN = "{robot}/{date:%Y-%m-%d}/{joint}.csv"
DAY = dt.datetime(2026, 3, 1, tzinfo=dt.UTC)


def _csv(path: Path, name: str, seed: int, temperature=None) -> Path:
    g = make_log(name, seed=seed, seconds=2.0)
    if temperature is not None:
        g.columns["drive_temperature"] = temperature(g.samples)
    path.parent.mkdir(parents=True, exist_ok=True)
    return g.write_csv(path)


def _temps(n: int) -> np.ndarray:
    return 40.0 + 5.0 * np.linspace(0.0, 1.0, n)


def _digest(root: Path) -> dict[str, str]:
    return {
        str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*")) if p.is_file()
    }


@pytest.fixture(scope="module")
def fleet(tmp_path_factory) -> Path:
    """r1: a revolute joint with a drive temperature column, a prismatic one (sidecar says so);
    r2: a revolute joint and a log without a time column (fails)."""
    root = tmp_path_factory.mktemp("fleet")
    day = root / "r1" / "2026-03-01"
    _csv(day / "j1.csv", "coarse_encoder", 1, temperature=_temps)
    _csv(day / "slide.csv", "prismatic_ballscrew", 2)
    (day / "slide.yaml").write_text("joint_type: prismatic\n")
    _csv(root / "r2" / "2026-03-01" / "j1.csv", "coarse_encoder", 3)
    (root / "r2" / "2026-03-01" / "j2.csv").write_text("a,b\n1,2\n3,4\n")
    return root


def _fit(root, table, *extra) -> int:
    return main(["fit", str(root), "--table", str(table), "--pattern", PATTERN, *FAST, *extra])


@pytest.fixture(scope="module")
def one_worker(fleet, tmp_path_factory):
    before = _digest(fleet)
    table = tmp_path_factory.mktemp("t1") / "fleet.parquet"
    rc = _fit(fleet, table, "--workers", "1")
    assert _digest(fleet) == before  # inputs untouched
    return rc, table


def test_pattern_sidecar_discovery(fleet, tmp_path):
    tasks, notes = discover([fleet], PATTERN)
    got = sorted((t.robot, t.joint, t.run_time, t.joint_type) for t in tasks)
    assert got == [
        ("r1", "j1", DAY, "auto"),
        ("r1", "slide", DAY, "prismatic"),
        ("r2", "j1", DAY, "auto"),
        ("r2", "j2", DAY, "auto"),
    ]
    assert notes == [] and all(len(t.source_sha256) == 64 and not t.problem for t in tasks)
    # a sidecar's robot/joint/time win over the pattern; a file outside the pattern is skipped
    other = tmp_path / "r5" / "2026-03-02"
    _csv(other / "x.csv", "coarse_encoder", 4)
    (other / "x.yaml").write_text("robot: arm7\njoint: wrist\ntime: 2026-03-02T08:30:00+01:00\n")
    _csv(tmp_path / "stray.csv", "coarse_encoder", 5)
    tasks, notes = discover([tmp_path], PATTERN)
    assert [(t.robot, t.joint, t.run_time) for t in tasks] == [
        ("arm7", "wrist", dt.datetime(2026, 3, 2, 7, 30, tzinfo=dt.UTC))
    ]
    assert len(notes) == 1 and "stray.csv" in notes[0]
    # without a pattern, a run nothing names is a problem row, not an exception
    tasks, _ = discover([tmp_path / "stray.csv"])
    assert tasks[0].problem.endswith("give a sidecar stray.yaml or --pattern")


def _bag(path: Path, temps) -> Path:
    from friction_ros.core.bag import BagWriter, encode, load_installed, make_qos

    js = load_installed("sensor_msgs/msg/JointState")
    tm = load_installed("sensor_msgs/msg/Temperature")
    g = make_log("coarse_encoder", seed=6, seconds=2.0)
    t0 = 1_772_352_000.0  # 2026-03-01T08:00:00Z
    meta = {"robot": "r9", "run_time": "2026-03-01T08:00:00Z"}
    with BagWriter(path, metadata=meta) as w:
        w.add_topic("/joint_states", "sensor_msgs/msg/JointState", qos_profiles=[make_qos()])
        w.add_topic("/drive/temperature", "sensor_msgs/msg/Temperature", qos_profiles=[make_qos()])
        for k in range(g.samples):
            ts = t0 + float(g.columns["time"][k])
            stamp = {"sec": int(ts), "nanosec": int(round((ts % 1) * 1e9)) % 1_000_000_000}
            vals = [float(g.columns[c][k]) for c in ("position", "velocity", "effort")]
            msg = {"header": {"stamp": stamp}, "name": ["a1", "a2"], "position": [vals[0]] * 2}
            msg.update(velocity=[vals[1]] * 2, effort=[vals[2]] * 2)
            w.write("/joint_states", encode(js, "sensor_msgs/msg/JointState", msg), int(ts * 1e9))
            if k % 500 == 0:
                t = {"header": {"stamp": stamp}, "temperature": temps[k // 500], "variance": 0.0}
                w.write("/drive/temperature", encode(tm, "sensor_msgs/msg/Temperature", t), int(ts * 1e9))
    return path


def test_bag_metadata_and_temperature_topic(tmp_path):
    from friction_ros.core.fleet.temperature import bag_temperature

    temps = [30.0, 31.0, 35.0, 32.0]
    bag = _bag(tmp_path / "robots" / "run1", temps)
    tasks, _ = discover([tmp_path / "robots"])
    assert [(t.robot, t.joint, t.run_time, t.path) for t in tasks] == [
        ("r9", j, dt.datetime(2026, 3, 1, 8, tzinfo=dt.UTC), str(bag)) for j in ("a1", "a2")
    ]
    assert bag_temperature(bag) == pytest.approx((np.mean(temps), 30.0, 35.0))
    # one joint of the bag fitted in this process: its rows carry the topic's temperature
    rows = run_rows(tasks[1], {"models": ("coulomb",), "maxiter": 3, "train_seconds": 1.0})
    assert [r["model"] for r in rows] == ["baseline", "coulomb"] and all(r["error"] == "" for r in rows)
    assert rows[0]["joint"] == "a2" and rows[0]["robot"] == "r9" and rows[0]["effort_unit"] == "N*m"
    assert (rows[0]["temperature_mean"], rows[0]["temperature_max"]) == pytest.approx((np.mean(temps), 35.0))


def test_rows_units_temperature_and_failed_run(one_worker, fleet):
    rc, table = one_worker
    assert rc == 1  # one run failed: said by the exit code, the others fitted
    t = ft.read_table(table)
    assert t.schema.equals(ft.FLEET_SCHEMA)
    rows = t.to_pylist()
    by = {}
    for r in rows:
        by.setdefault((r["robot"], r["joint"]), []).append(r)
    assert sorted(by) == [("r1", "j1"), ("r1", "slide"), ("r2", "j1"), ("r2", "j2")]
    failed = by[("r2", "j2")]
    assert len(failed) == 1 and "no time column" in failed[0]["error"] and failed[0]["compensate"] is False
    for key in [("r1", "j1"), ("r1", "slide"), ("r2", "j1")]:
        rs = by[key]
        assert sorted(r["model"] for r in rs) == ["baseline", "coulomb", "stribeck"]
        assert sum(r["recommended"] for r in rs) == 1
        assert all(r["error"] == "" and len(r["coef_names"]) == len(r["coef_values"]) for r in rs)
        assert all(r["run_time"] == DAY and r["samples"] > 1000 for r in rs)
    slide = by[("r1", "slide")]
    assert {(r["joint_type"], r["effort_unit"]) for r in slide} == {("prismatic", "N")}
    assert {(r["joint_type"], r["effort_unit"]) for r in by[("r1", "j1")]} == {("revolute", "N*m")}
    # load_rms from the file's effort column; temperature from the drive_temperature column
    data = np.genfromtxt(fleet / "r1" / "2026-03-01" / "slide.csv", delimiter=",", names=True, skip_header=2)
    assert slide[0]["load_rms"] == pytest.approx(np.sqrt(np.mean(data["force"] ** 2)), rel=1e-9)
    assert math.isnan(slide[0]["temperature_mean"])
    j1 = by[("r1", "j1")][0]
    temps = _temps(j1["samples"])
    assert (j1["temperature_mean"], j1["temperature_min"], j1["temperature_max"]) == pytest.approx(
        (temps.mean(), 40.0, 45.0)
    )
    # the stribeck fit of the prismatic axis finds its Coulomb force (truth 20 N) in N
    stri = next(r for r in slide if r["model"] == "stribeck")
    fc = dict(zip(stri["coef_names"], stri["coef_values"], strict=True))["fc"]
    assert 10.0 < fc < 30.0


def test_rerun_adds_nothing(one_worker, fleet, capsys):
    _, table = one_worker
    before = _digest(table)
    assert _fit(fleet, table, "--workers", "1") == 0
    assert _digest(table) == before  # nothing rewritten, nothing added
    assert "0 fitted, 0 failed, 4 already in the table" in capsys.readouterr().out


def test_two_workers_same_table_after_a_killed_worker(one_worker, fleet, tmp_path, monkeypatch, capsys):
    _, table1 = one_worker
    table2 = tmp_path / "fleet2.parquet"
    monkeypatch.setenv(CRASH_MARK_ENV, str(Path("r1") / "2026-03-01" / "j1.csv"))
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):  # not tried on a 2nd worker
        assert _fit(fleet, table2, "--workers", "2") == 1
    rows = ft.read_table(table2).to_pylist()
    killed = [r for r in rows if r["error"] == KILLED]
    assert [(r["robot"], r["joint"]) for r in killed] == [("r1", "j1")]
    assert {(r["robot"], r["joint"]) for r in rows if r["model"]} == {("r1", "slide"), ("r2", "j1")}
    monkeypatch.delenv(CRASH_MARK_ENV)
    capsys.readouterr()
    assert _fit(fleet, table2, "--workers", "2") == 0  # only the killed run is fitted again
    assert "1 fitted, 0 failed, 3 already in the table" in capsys.readouterr().out
    a, b = ft.read_table(table1), ft.read_table(table2)
    assert a.num_rows == 10 and ft.same_rows(a, b)
    assert a["fitted_at"] != b["fitted_at"]  # the one wall-clock column differs
    b = b.set_column(0, "robot", pa.array(["r0"] * b.num_rows))
    assert not ft.same_rows(a, b)


@pytest.mark.parametrize(
    "extra, says",
    [
        (["--pattern", "{robot}/{day}.csv"], "unknown field {day}"),
        (["--pattern", "{robot}/{date:%Y-%q}.csv"], "format %q is not supported"),
        (["--pattern", "{robot/x.csv"], "unbalanced brace"),
        (["--workers", "0"], "--workers 0: must be >= 1"),
        (["--models", "nosuch"], "nosuch"),
    ],
)
def test_bad_input_one_line_exit_2(fleet, tmp_path, capsys, extra, says):
    rc = main(["fit", str(fleet), "--table", str(tmp_path / "t.parquet"), *extra])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and says in err[0] and err[0].startswith("friction-fleet: error:")
    assert not (tmp_path / "t.parquet").exists()


def test_table_never_a_users_folder(fleet, tmp_path, capsys):
    data = tmp_path / "data"
    shutil.copytree(fleet / "r1", data)
    assert main(["fit", str(fleet), "--table", str(data), "--pattern", PATTERN]) == 2
    assert "holds other files" in capsys.readouterr().err
    log = data / "2026-03-01" / "j1.csv"
    assert main(["fit", str(fleet), "--table", str(log)]) == 2
    assert "is a file" in capsys.readouterr().err
