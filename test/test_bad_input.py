"""Bad input to the command-line tools: exit code 2, exactly one line on stderr naming the problem,
and every input file byte-identical afterwards (table-driven: tool x bad-input class)."""

from __future__ import annotations

import hashlib
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _digest(paths: list[Path]) -> dict[str, str]:
    out = {}
    for p in paths:
        files = [p] if p.is_file() else sorted(f for f in p.rglob("*") if f.is_file())
        for f in files:
            out[str(f)] = hashlib.sha256(f.read_bytes()).hexdigest()
    return out


@pytest.fixture(scope="module")
def small_bag(tmp_path_factory) -> Path:
    """A short recorded-style bag (written by the package's writer from a simulated joint)."""
    from friction_ros.core.identification import synthetic

    rec = synthetic.seed003_experiment(12.0, low=0.05)
    return synthetic.write_bag(tmp_path_factory.mktemp("bags") / "small", rec)


def _files(tmp: Path, bag: Path) -> dict[str, Path]:
    """Input files of every kind the table uses, created fresh per case."""
    d = tmp / "inputs"
    d.mkdir()
    f = {
        "bag": d / "bag",
        "empty": d / "empty.mcap",
        "random": d / "random.mcap",
        "truncated": d / "truncated.mcap",
        "not_yaml": d / "not_yaml.yaml",
        "preset_copy": d / "preset.yaml",
        "dir": d / "a_dir",
    }
    shutil.copytree(bag, f["bag"])
    f["empty"].write_bytes(b"")
    f["random"].write_bytes(bytes(range(256)) * 40)
    mcap = sorted(f["bag"].glob("*.mcap"))[0].read_bytes()
    f["truncated"].write_bytes(mcap[: len(mcap) // 3])
    f["not_yaml"].write_text("plant_simulator: [unclosed\n  : : :\n")
    shutil.copy(ROOT / "params" / "abb_m19s.yaml", f["preset_copy"])
    f["dir"].mkdir()
    return f


# (tool module, argv template, words the error line must contain); {name} -> a file of _files
CASES = {
    "fit-missing-bag": ("fit", ["{tmp}/no_such_bag"], ["no such"]),
    "fit-empty-bag": ("fit", ["{empty}"], ["empty"]),
    "fit-random-bytes": ("fit", ["{random}"], ["mcap"]),
    "fit-wrong-topic": ("fit", ["{bag}", "--topic", "/nope"], ["/nope"]),
    "fit-wrong-joint": ("fit", ["{bag}", "--joint", "nope"], ["nope"]),
    "fit-unknown-model": ("fit", ["{bag}", "--models", "magic"], ["magic"]),
    "fit-out-is-a-file": ("fit", ["{bag}", "--out", "{preset_copy}"], ["--out"]),
    "fit-params-out-is-a-preset": ("fit", ["{bag}", "--params-out", "{preset_copy}"], ["not written by"]),
    "fit-params-out-is-a-dir": ("fit", ["{bag}", "--params-out", "{dir}"], ["directory"]),
    "fit-params-is-an-input-name": ("fit", ["{bag}", "--params", "{preset_copy}"], ["--params-out"]),
    "fit-out-inside-the-bag": ("fit", ["{bag}", "--out", "{bag}/fit"], ["overlaps"]),
    "bag-info-missing": ("bag", ["info", "{tmp}/no_such_bag"], ["no such"]),
    "bag-info-random-bytes": ("bag", ["info", "{random}"], ["mcap"]),
    "bag-recover-in-place": ("bag", ["recover", "{bag}", "{bag}", "--overwrite"], ["overlaps"]),
    "bag-recover-into-the-bag": ("bag", ["recover", "{bag}", "{bag}/out", "--overwrite"], ["overlaps"]),
    "bag-recover-existing-output": ("bag", ["recover", "{bag}", "{dir}"], ["exists"]),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_gives_one_line_exit_2_and_leaves_inputs_alone(case, small_bag, tmp_path):
    tool, argv, words = CASES[case]
    f = _files(tmp_path, small_bag)
    subs = {k: str(v) for k, v in f.items()} | {"tmp": str(tmp_path)}
    args = [a.format(**subs) for a in argv]
    before = _digest(list(f.values()))
    proc = subprocess.run(
        [sys.executable, "-m", f"friction_ros.cli.{tool}", *args, *(["--quiet"] if tool == "fit" else [])],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    err = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, (proc.returncode, proc.stdout[-2000:], proc.stderr[-2000:])
    assert len(err) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    for w in words:
        assert w.lower() in err[0].lower(), err[0]
    assert _digest(list(f.values())) == before
