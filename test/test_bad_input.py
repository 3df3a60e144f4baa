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
    from friction_ros.core.synthetic import plant_runs

    rec = plant_runs.abb_m19s_excitation_experiment(12.0, low=0.05)
    return plant_runs.write_bag(tmp_path_factory.mktemp("bags") / "small", rec)


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
        "random_yaml": d / "random.yaml",
        "list_yaml": d / "list.yaml",
        "rcl_bad": d / "mixed_list.yaml",
        "bomb": d / "bomb.yaml",
        "deep": d / "deep.yaml",
        "huge": d / "huge.yaml",
    }
    shutil.copytree(bag, f["bag"])
    f["empty"].write_bytes(b"")
    f["random"].write_bytes(bytes(range(256)) * 40)
    mcap = sorted(f["bag"].glob("*.mcap"))[0].read_bytes()
    f["truncated"].write_bytes(mcap[: len(mcap) // 3])
    f["not_yaml"].write_text("plant_simulator: [unclosed\n  : : :\n")
    shutil.copy(ROOT / "params" / "abb_m19s.yaml", f["preset_copy"])
    f["dir"].mkdir()
    (d / "a_dir.yaml").mkdir()
    f["random_yaml"].write_bytes(bytes(range(256)) * 4)
    f["list_yaml"].write_text("- plant_simulator\n- mode: lockstep\n")
    f["rcl_bad"].write_text("plant_simulator:\n  ros__parameters:\n    x: [1, 'a', 2.0]\n")  # YAML, not ROS
    # ~1 kB of nested aliases: 4^30 nodes once expanded, each level a valid "namespace: node" mapping
    bomb = ["n0: &n0 {plant_simulator: {ros__parameters: {x: 1}}}"]
    bomb += [f"n{i}: &n{i} {{a: *n{i - 1}, b: *n{i - 1}, c: *n{i - 1}, d: *n{i - 1}}}" for i in range(1, 30)]
    f["bomb"].write_text("\n".join(bomb) + "\n")
    f["deep"].write_text("plant_simulator:\n  ros__parameters:\n    x: " + "[" * 5000 + "]" * 5000 + "\n")
    f["huge"].write_text("plant_simulator:\n  ros__parameters:\n    x: '" + "x" * (1 << 20) + "'\n")
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
    # a --preset that is not a preset YAML, before anything starts
    "experiment-preset-not-yaml": ("experiment", ["--preset", "{not_yaml}", "-o", "{tmp}/o"], ["not valid yaml"]),
    "experiment-preset-random-bytes": ("experiment", ["--preset", "{random_yaml}", "-o", "{tmp}/o"], ["not a yaml"]),
    "experiment-params-not-yaml": ("experiment", ["--params", "{not_yaml}", "-o", "{tmp}/o"], ["not valid yaml"]),
    "experiment-set-beyond-the-limits": (
        "experiment",
        ["--no-sim", "--program", "plateaus", "--set", "plateaus.v_max=10", "--set", "limits.max_travel=3.0",
         "-o", "{tmp}/o"],
        ["plateaus.v_max", "limits.max_travel", "at most"],
    ),
    "bringup-preset-not-yaml": ("bringup", ["--preset", "{not_yaml}", "--duration", "1"], ["not valid yaml"]),
    "bringup-preset-is-a-dir": ("bringup", ["--preset", "{dir}.yaml", "--duration", "1"], ["directory"]),
    "bringup-params-not-yaml": ("bringup", ["--params", "{not_yaml}", "--duration", "1"], ["not valid yaml"]),
    "bringup-params-not-a-mapping": ("bringup", ["--params", "{list_yaml}", "--duration", "1"], ["ros__parameters"]),
    "drive-emulator-preset-not-yaml": (
        "nodes.drive_emulator", ["--interface", "virtual", "--preset", "{not_yaml}", "--duration", "1"],
        ["not valid yaml"],
    ),
    # every node given a parameter file that is not YAML (rcl would print a traceback, exit 1)
    **{
        f"{node}-params-file-not-yaml": (
            f"nodes.{node}", ["--ros-args", "--params-file", "{not_yaml}"], ["parameter file", "not valid yaml"]
        )
        for node in (
            "plant_simulator", "compensating_controller", "friction_estimator", "drive_interface",
            "simulated_drive", "identification_experiment", "bag_recorder", "bag_player",
        )
    },
    # parameter files that would take unbounded time or memory: refused by the limit, never a hang
    **{
        f"{tool}-params-file-alias-bomb": (tool, [*pre, "--params-file", "{bomb}"], ["{bomb}", "aliases", "limit"])
        for tool, pre in (
            ("nodes.plant_simulator", ["--ros-args"]), ("nodes.compensating_controller", ["--ros-args"]),
            ("nodes.friction_estimator", ["--ros-args"]), ("nodes.simulated_drive", ["--ros-args"]),
            ("nodes.identification_experiment", ["--ros-args"]), ("nodes.bag_recorder", ["--ros-args"]),
            ("nodes.bag_player", ["--ros-args"]),
            ("nodes.composition", ["--node", "plant_simulator", "--ros-args"]),
        )
    },
    "bringup-params-alias-bomb": ("bringup", ["--params", "{bomb}", "--duration", "1"], ["{bomb}", "aliases", "limit"]),
    "experiment-params-alias-bomb": ("experiment", ["--params", "{bomb}", "-o", "{tmp}/o"], ["{bomb}", "aliases"]),
    "experiment-preset-alias-bomb": ("experiment", ["--preset", "{bomb}", "-o", "{tmp}/o"], ["{bomb}", "aliases"]),
    "plant_simulator-params-file-too-deep": (
        "nodes.plant_simulator", ["--ros-args", "--params-file", "{deep}"], ["{deep}", "nested", "limit of 64"]
    ),
    "plant_simulator-params-file-too-large": (
        "nodes.plant_simulator", ["--ros-args", "--params-file", "{huge}"], ["{huge}", "bytes", "limit of 1048576"]
    ),
    "plant_simulator-params-file-rcl-refuses": (
        "nodes.plant_simulator", ["--ros-args", "--params-file", "{rcl_bad}"], ["params file", "same type"]
    ),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_gives_one_line_exit_2_and_leaves_inputs_alone(case, small_bag, tmp_path):
    tool, argv, words = CASES[case]
    f = _files(tmp_path, small_bag)
    subs = {k: str(v) for k, v in f.items()} | {"tmp": str(tmp_path), "dir": str(f["dir"])}
    args = [a.format(**subs) for a in argv]
    before = _digest(list(f.values()))
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            f"friction_ros.{tool}" if "." in tool else f"friction_ros.cli.{tool}",
            *args,
            *(["--quiet"] if tool == "fit" else []),
        ],
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
        assert w.format(**subs).lower() in err[0].lower(), err[0]
    assert _digest(list(f.values())) == before
    assert not (tmp_path / "o").exists()  # nothing started, nothing created
