"""Small things a new user meets in the CLIs: no option abbreviations, readable gains and reasons in
console tables, friction-bag info's duration and truncation status, the default fit folder ignored."""

from __future__ import annotations

import struct
import subprocess

import numpy as np
import pytest
from conftest import ROOT
from test_bag_core import T0, write_sample

from friction_ros.cli import bag as bag_cli
from friction_ros.cli.demo_report import print_table
from friction_ros.cli.demo_results import DemoResult, TrackingRun, refusal_warning
from friction_ros.cli.fit_summary import print_summary
from friction_ros.cli.reasons import footnotes, format_values, grouped
from friction_ros.core.compensation_gate import Verdict
from friction_ros.core.identification.fit.fit_results import FitResult, ModelResult

LONG = (
    "refused: limit cycle (37 Hz, not in the reference) with plant friction +20 % coefficients "
    "(+2 more cases); the bound assumes the current-loop lag and delays measured on this joint"
)


# ------------------------------------------------------------------------------ abbreviations
def _parsers():
    from friction_ros.cli import bringup, demo, experiment, fit
    from friction_ros.nodes import bag_player, bag_recorder, drive_emulator

    return {
        "friction-fit": fit.build_parser(),
        "friction-demo": demo.build_parser(),
        "friction-experiment": experiment.build_parser(),
        "friction-bringup": bringup.build_parser(),
        "drive_emulator": drive_emulator.build_parser(),
        "bag_recorder": bag_recorder.build_parser(),
        "bag_player": bag_player.build_parser(),
    }


def test_every_parser_refuses_abbreviations():
    for name, parser in _parsers().items():
        assert parser.allow_abbrev is False, name
    with pytest.raises(SystemExit) as exc:
        _parsers()["friction-fit"].parse_args(["log.csv", "--mod", "lugre"])
    assert exc.value.code == 2


def test_fit_model_is_a_documented_alias_of_models(capsys):
    parser = _parsers()["friction-fit"]
    assert parser.parse_args(["log.csv", "--model", "lugre", "gms4"]).models == ["lugre", "gms4"]
    assert parser.parse_args(["log.csv", "--models", "lugre"]).models == ["lugre"]
    assert "--models MODELS [MODELS ...], --model MODELS [MODELS ...]" in parser.format_help()
    with pytest.raises(SystemExit):  # a prefix of another option stays refused
        parser.parse_args(["log.csv", "--train-sec", "5"])
    assert "unrecognized arguments: --train-sec" in capsys.readouterr().err


def test_bag_subcommands_refuse_abbreviations(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        bag_cli.main(["recover", str(tmp_path / "a"), str(tmp_path / "b"), "--over"])
    assert exc.value.code == 2
    assert "--over" in capsys.readouterr().err


# ------------------------------------------------------------------------------ gains and reasons
def test_format_values():
    assert format_values({"p": 200.0, "i": 0, "d": 0.15}) == "p 200, i 0, d 0.15"
    assert (
        format_values({"type": "pid", "ok": True, "lim": np.float64(2.5e-4)})
        == "type pid, ok True, lim 0.00025"
    )
    assert format_values({"pos": {"p": 3.0}}) == "pos (p 3)"


def test_footnotes_share_one_line_per_reason():
    markers, lines = footnotes({"a": LONG, "b": "refused: other", "c": LONG, "d": ""}, strip="refused: ")
    assert markers == {"a": "[1]", "b": "[2]", "c": "[1]"}
    assert lines == [f"[1] a, c: {LONG.removeprefix('refused: ')}", "[2] b: other"]
    assert grouped({"x": "r1", "y": "r2", "z": "r1"}) == [("x, z", "r1"), ("y", "r2")]


def _run(label, rms, enabled=True, reason=""):
    t = np.arange(0.0, 1.0, 0.001)
    err = np.full_like(t, rms)
    z = np.zeros_like(t)
    return TrackingRun(label, t, z, z, err, z, err, z, z, 1.0, enabled, reason)


def test_demo_table_prints_gains_plainly_and_each_reason_once(capsys):
    res = DemoResult(preset="abb_m19s", model="lugre", gains={"p": 200.0, "i": 5.0, "d": 0.15})
    res.reference = {"type": "sine"}
    res.runs = {
        "none": _run("none", 1e-3),
        "feedforward": _run("feedforward", 0.5e-3),
        "feedback": _run("feedback", 2e-3, False, LONG),
        "blended": _run("blended", 3e-3, False, LONG),
    }
    res.warnings = [refusal_warning(m, LONG) for m in ("feedback", "blended")] + ["something else"]
    print_table(res)
    out = capsys.readouterr().out
    assert "tracking gains p 200, i 5, d 0.15; reference sine" in out
    assert "{" not in out
    detail = LONG.removeprefix("refused: ")
    assert out.count(detail) == 1
    assert "| feedback | refused [1] |" in out and "| blended | refused [1] |" in out
    assert f"[1] feedback, blended: {detail}" in out
    assert "| feedforward | enabled | 0.5000 |" in out
    assert "WARNING: something else" in out
    assert "best enabled mode: feedforward (50.0 % lower RMS error)" in out


def _model(name, status="fitted", reason="", nmse=1.0):
    metrics = {"nmse_percent": nmse, "n_params": 2, "bic": -100.0} if status == "fitted" else {}
    return ModelResult(name, "plateaus", {}, None, metrics, {}, 0.1, None, None, status=status, reason=reason)


def test_fit_summary_prints_a_failure_reason_once_under_the_table(capsys):
    why = "the optimiser diverged: the state z left its bound in every start (" + "x" * 60 + ")"
    models = {
        "coulomb": _model("coulomb", nmse=3.25),
        "lugre": _model("lugre", "diverged", why),
        "gms4": _model("gms4", "diverged", why),
    }
    gate = {m: Verdict(m, False, LONG) for m in ("feedforward", "feedback", "blended")}
    res = FitResult(models, "coulomb", [], [], [], [], None, 1.0, {}, gate=gate)
    print_summary(res)
    out = capsys.readouterr().out.splitlines()
    assert sum(why in line for line in out) == 1
    assert "lugre            diverged [1]" in out and "gms4             diverged [1]" in out
    assert f"  [1] lugre, gms4: {why}" in out
    assert sum(LONG in line for line in out) == 1
    assert f"compensation feedforward, feedback, blended: {LONG}" in out
    assert any(line.startswith("coulomb") and "3.25" in line and "<- recommended" in line for line in out)


# ------------------------------------------------------------------------------ friction-bag info
def _data_end(data: bytes) -> int:
    """Offset of the MCAP data-end record (opcode 0x0F): the data section ends there."""
    pos = 8
    while data[pos] != 0x0F:
        pos += 9 + struct.unpack_from("<Q", data, pos + 1)[0]
    return pos


def _info(capsys, path) -> str:
    assert bag_cli.main(["info", str(path)]) == 0
    return capsys.readouterr().out


def test_bag_info_duration_and_status(tmp_path, capsys):
    n = 500
    write_sample(tmp_path / "g", n=n)
    out = _info(capsys, tmp_path / "g")
    last = T0 + (n - 1) * 1_000_000 + 10  # the last /command message (log time + 10 ns)
    assert f"duration: {(last - T0) * 1e-9:.3f} s" in out
    assert "status:   complete" in out and "truncat" not in out.lower()

    data = (tmp_path / "g" / "g_0.mcap").read_bytes()
    end = _data_end(data)
    unclosed = tmp_path / "unclosed"
    unclosed.mkdir()
    (unclosed / "u_0.mcap").write_bytes(data[:end])  # every record complete, no summary/footer
    out = _info(capsys, unclosed)
    assert "status:   NOT CLOSED" in out
    assert "truncated at byte" not in out and "TRUNCATED" not in out
    assert "every message in it was read" in out
    assert f"{n:9d} msgs" in out

    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / "c_0.mcap").write_bytes(data[: end - 7])  # inside the last record
    out = _info(capsys, cut)
    assert "status:   TRUNCATED" in out and "truncated at byte" in out
    assert f"of {end - 7} " in out


# ------------------------------------------------------------------------------ .gitignore
def test_default_fit_output_is_ignored_by_git(tmp_path):
    from friction_ros.cli.fit import build_parser

    default = build_parser().get_default("out")
    r = subprocess.run(
        ["git", "check-ignore", "-q", f"{default}/report.md"], cwd=ROOT, capture_output=True, text=True
    )
    assert r.returncode == 0, f"{default}/ is not in .gitignore"
