"""friction-experiment: record a whole identification experiment into a rosbag2 (MCAP) directory.

Examples::

    # simulated ABB M19-S joint, deterministic and faster than real time, ~30 s program
    friction-experiment --profile quick --mode lockstep

    # the full default program (~2 min of joint time) on another preset, in real time
    friction-experiment --preset seed004_dc_motor --mode realtime -o bags/dc_motor_run1

    # a real joint: start drive_interface yourself (same namespace/joint name), then
    friction-experiment --no-sim --program plateaus --set plateaus.v_max=2.0 --set limits.max_travel=3.0

Sizing: with a simulated joint (``--preset``) the program is sized to the joint by default
(``--sizing joint``): plateau speeds from below the Stribeck velocity down to what the encoder
resolves up to a fraction of the speed limit, ramp torques and amplitudes from the breakaway
torque, travel and loop gains from the inertia, current lag and delays
(``friction_ros.core.experiment.experiment_sizing``). On a real joint (``--no-sim``) give what a short probe
measured (``--breakaway``, ``--inertia``, ``--torque-limit``, ``--speed-limit``, ``--travel``,
``--resolution``) to size it the same way; without them the ``--profile`` values are used as they
are (``--sizing profile``, scaled for the ABB M19-S). ``--set`` overrides any key afterwards.

An arm: ``--joints j1,j2,j3 --presets abb_m19s,seed004_dc_motor,seed000_gearhead`` (or a
multi-joint parameter file such as ``--params params/arm7_plant.yaml``, whose ``joints``,
``presets`` and ``plant.<joint>.*`` are used) runs each joint's program, sized to its own plant,
one joint after another (``--joint-sequence one_at_a_time``, the others held by a PD hold) or all
at once (``together``); ``--set limits.j2.max_travel=0.5`` sets one joint's value
(:mod:`friction_ros.cli.experiment_arm`). The bag has every joint on ``joint_states`` and each
event names its joint, so ``friction-fit BAG --joint j2`` fits j2 from j2's segments. A joint
leaving its limits stops the whole arm (zero torque on every joint, exit 3); the summary is
printed for every joint.

Starts (friction-bringup machinery) ``bag_recorder`` (joint_states, experiment_events, optionally
diagnostics) and ``identification_experiment``, which waits for the recorder before it begins; a
simulated joint's ``plant_simulator`` runs in the experiment's process (one executor,
:mod:`friction_ros.nodes.composition`: about half the CPU of two processes, the same bag), a real
joint's drive (``--no-sim``) is yours. Output lines are labelled with the node they are about.
When the program is over the experiment node ends its process by itself (zero torque), then the
recorder gets SIGINT so the bag is finished properly. Ctrl-C stops the experiment first (zero torque). Prints the
bag location and a summary: segments, aborts, breakaway torques and the plateau map (mean and
spread of velocity and torque per plateau; with the simulated plant also the preset's true
steady-state friction). Exit code: 0 completed, 3 stopped by a safety limit, 2 bad arguments or
a node refused its parameters, 1 a process failed, timed out or the joint was not excited (the
program's motion check: no motion, no reversals, plateaus that do not reach their speed; the
experiment node stops the program with an ABORT event naming the reason). A failed run ends with
one line ``error: <reason>`` on stderr, with or without ``--quiet``; a run that recorded nothing
removes the bag folder it created when the program never started (no experiment event: a node
refused to start, no joint states), so the same ``-o`` works again.
"""

from __future__ import annotations

import argparse
import math
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import yaml

from friction_ros.cli.bringup import Bringup, NodeSpec, composed_spec, members
from friction_ros.cli.experiment_arm import arm_setup
from friction_ros.cli.experiment_config import (
    nest,
    node_values,
    parse_sets,
    sized_config,
    typed_like_defaults,
)
from friction_ros.cli.experiment_summary import summarize
from friction_ros.cli.state_watch import FirstStateWatch, no_state_reason
from friction_ros.core.config import flatten
from friction_ros.core.experiment.arm import SEQUENCES
from friction_ros.core.experiment.excitation import EXIT_ABORTED, EXIT_NOT_EXCITED, ExcitationProgram
from friction_ros.core.experiment.excitation_config import PROFILES, PROGRAM_NAMES, resolve_config
from friction_ros.core.experiment.experiment_sizing import fit_to_limits
from friction_ros.core.validation import ParameterError


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        allow_abbrev=False,
        prog="friction-experiment",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawTextHelpFormatter,
    )
    p.add_argument(
        "--profile", choices=tuple(PROFILES), default="default", help="program defaults (%(default)s)"
    )
    p.add_argument(
        "--program", choices=PROGRAM_NAMES, default="sequence", help="excitation program (%(default)s)"
    )
    p.add_argument("--preset", default="abb_m19s", help="plant preset of the simulated joint (%(default)s)")
    p.add_argument(
        "--mode", choices=("lockstep", "realtime"), default="lockstep", help="plant mode (%(default)s)"
    )
    p.add_argument(
        "--no-sim", action="store_true", help="real joint: do not start the plant (run drive_interface)"
    )
    p.add_argument(
        "--drive-preset",
        metavar="PRESET",
        help="with --no-sim: the joint behind drive_interface is this plant preset in an emulated drive "
        "(drive_emulator): the program is sized to it and the summary shows its true friction",
    )
    p.add_argument("-o", "--output", help="bag directory (default bags/experiment_<preset>_<date>)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing bag directory")
    p.add_argument("--joint", default="joint1", help="joint name (%(default)s)")
    arm = p.add_argument_group("an arm (several joints; see 'Experiments on an arm' in docs/workflows.md)")
    arm.add_argument(
        "--joints",
        metavar="J1,J2,...",
        help="the arm's joints (default: the joints of the --params file, e.g. params/arm7_plant.yaml)",
    )
    arm.add_argument(
        "--presets",
        metavar="P1,P2,...",
        help="one plant preset per joint (default: the --params file's presets, else --preset for every joint)",
    )
    arm.add_argument(
        "--joint-sequence",
        choices=SEQUENCES,
        default=SEQUENCES[0],
        help="one_at_a_time: each joint's program in turn, the others held; together: all at once (%(default)s)",
    )
    arm.add_argument(
        "--joint-gap", type=float, default=0.5, help="time between two joints' programs [s] (%(default)s)"
    )
    p.add_argument("--namespace", default="", help="namespace of the joint's topics")
    p.add_argument(
        "--params", action="append", default=[], help="parameter YAML for the plant and the experiment"
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="experiment parameter, e.g. plateaus.repeats=5, limits.max_velocity=20",
    )
    p.add_argument(
        "--sizing",
        choices=("joint", "profile"),
        help="joint: size the program to the joint (default with --preset or probe values); "
        "profile: the profile's values as they are (ABB M19-S scale)",
    )
    probe = p.add_argument_group("real joint probe (size the program to a joint you measured)")
    probe.add_argument("--breakaway", type=float, help="breakaway torque [N*m] (N for a linear axis)")
    probe.add_argument("--inertia", type=float, help="joint-side inertia [kg*m^2] (kg for a linear axis)")
    probe.add_argument("--torque-limit", type=float, help="largest torque the program may command [N*m]")
    probe.add_argument("--speed-limit", type=float, help="largest speed [rad/s] (m/s)")
    probe.add_argument("--travel", type=float, help="allowed travel from the start position [rad] (m)")
    probe.add_argument("--resolution", type=float, help="encoder resolution at the joint [rad] (m) per count")
    p.add_argument("--diagnostics", action="store_true", help="also record /diagnostics")
    p.add_argument("--timeout", type=float, help="give up after this wall time (default 60 s + 10 x planned)")
    p.add_argument(
        "--state-timeout",
        type=float,
        help="give up when no joint state came this long after the nodes were started "
        "(default 10 s on a real joint, 30 s simulated)",
    )
    p.add_argument("--quiet", action="store_true", help="do not forward node output")
    return p


def _topic(ns: str, name: str) -> str:
    ns = ns.strip("/")
    return f"/{ns}/{name}" if ns else f"/{name}"


def _stop_proc(proc: subprocess.Popen, grace: float = 5.0) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    params_tmp = None
    try:
        sets = parse_sets(args.set)
        preset = None if args.no_sim else args.preset
        if args.drive_preset and not args.no_sim:
            raise ParameterError("--drive-preset names the plant behind an emulated drive: it needs --no-sim")
        if args.state_timeout is not None and not (
            args.state_timeout > 0 and math.isfinite(args.state_timeout)
        ):
            raise ParameterError(f"--state-timeout {args.state_timeout:g}: must be > 0 s")
        if args.joint_gap < 0 or not math.isfinite(args.joint_gap):
            raise ParameterError(f"--joint-gap {args.joint_gap:g}: must be >= 0 s")
        arm = arm_setup(args, sets)
        if arm is None:
            preset_obj = None
            if preset or args.drive_preset:
                from friction_ros.core.presets import load_preset

                preset_obj = load_preset(preset or args.drive_preset)
            sized = sized_config(args, preset_obj, sets)
            sized_flat = typed_like_defaults(flatten(sized, keep_none=True), args.profile)
            sized_flat = {
                k: v for k, v in sized_flat.items() if k not in ("program", "profile", "control_period")
            }
            core = {"program": args.program, "profile": args.profile, **nest({**sized_flat, **sets})}
            # speeds re-derived within the limits (what the user set is kept, or refused if it cannot fit)
            program = ExcitationProgram(fit_to_limits(resolve_config(core), keep=set(sets)))
            sized_flat = node_values(program.config, args.profile, sized_flat)
            plan = (program.name, program.marked_count, program.total_duration)
            summary_joints = [(args.joint, preset or args.drive_preset)]
        else:
            sized_flat = arm.node_params
            plan = (arm.name, arm.marked_count, arm.total_duration(args.joint_sequence, args.joint_gap))
            summary_joints = list(zip(arm.joints, arm.plants))
        if sized_flat:
            import tempfile

            fd, params_tmp = tempfile.mkstemp(prefix="friction_experiment_", suffix=".yaml")
            with open(fd, "w") as fh:
                yaml.safe_dump({"identification_experiment": {"ros__parameters": sized_flat}}, fh)
        stamp = time.strftime("%Y%m%d_%H%M%S")
        kind = (preset or "joint") if arm is None else "arm"
        out = Path(args.output or Path("bags") / f"experiment_{kind}_{stamp}")
        # what a failed run that recorded nothing may remove: the folder it creates, or only its own
        # files in an empty folder that was there
        created = (
            "folder" if not out.exists() else ("files" if out.is_dir() and not any(out.iterdir()) else "")
        )
        if out.exists() and any(out.iterdir()) and not args.overwrite:
            raise ParameterError(
                f"output {out} exists and is not empty: choose another -o or pass --overwrite"
            )
        out.parent.mkdir(parents=True, exist_ok=True)
        states, events = _topic(args.namespace, "joint_states"), _topic(args.namespace, "experiment_events")
        topics = [states, events] + ([_topic(args.namespace, "diagnostics")] if args.diagnostics else [])
        joints_over = (
            {"joint_name": args.joint}
            if arm is None
            else {
                "joints": arm.joints,
                "joint_sequence": args.joint_sequence,
                "joint_gap": float(args.joint_gap),
            }
        )
        exp_over = {
            "profile": args.profile,
            "program": args.program,
            **joints_over,
            "wait_for_subscribers": 1,
            **sets,
        }
        specs = [
            NodeSpec(
                "bag_recorder",
                "",
                [],
                {
                    "topics": topics,
                    "output": str(out),
                    "overwrite": bool(args.overwrite),
                    "preset": preset or args.drive_preset or "real joint",
                    "program": f"{args.program} ({args.profile})",
                },
            )
        ]
        if preset:
            plant_joints = (
                {"joint_name": args.joint}
                if arm is None
                else {"joints": arm.joints, **({"presets": arm.presets} if arm.presets else {})}
            )
            specs.append(
                NodeSpec(
                    "plant_simulator",
                    args.namespace,
                    list(args.params),
                    # a recorder that fell behind the lockstep run gets its last states before the exit
                    {"preset": preset, "mode": args.mode, "exit_wait_for_readers": 15.0, **plant_joints},
                )
            )
        exp_params = ([params_tmp] if params_tmp else []) + list(args.params)
        specs.append(NodeSpec("identification_experiment", args.namespace, exp_params, exp_over))
        if preset:  # simulated: plant and experiment in one process (module docstring)
            specs[1:] = [composed_spec(specs[1:])]
        for s in specs:
            s.command()
    except (ParameterError, ValueError, OSError) as exc:
        if params_tmp:
            Path(params_tmp).unlink(missing_ok=True)
        print(f"error: {exc}", file=sys.stderr)
        return 2

    name, marked, total = plan
    timeout = args.timeout if args.timeout else 60.0 + 10.0 * total
    if arm is None:
        where = f"simulated {preset} ({args.mode})" if preset else "real joint (drive_interface must run)"
        if args.drive_preset:
            where = f"{args.drive_preset} in an emulated drive, real time (drive_interface must run)"
    else:
        plants = ", ".join(arm.presets) if arm.presets else preset
        where = f"joints {', '.join(arm.joints)} ({args.joint_sequence}); " + (
            f"simulated {plants} ({args.mode})" if preset else "real arm (drive_interface must run)"
        )
    print(
        f"[experiment] {name} ({args.profile}): {marked} segments, {total:.1f} s planned; {where}"
        f"; recording {', '.join(topics)} to {out}",
        flush=True,
    )
    try:
        return _run(args, specs, out, created, timeout, summary_joints, events, states)
    finally:
        if params_tmp:
            Path(params_tmp).unlink(missing_ok=True)


def _run(args, specs, out: Path, created: str, timeout: float, joints, events: str, states: str) -> int:
    """Run the graph; print the bag, the summary and, for a failed run, one ``error:`` line.
    ``joints``: ``(joint, preset)`` of each joint summarised (the preset gives the true friction)."""
    bring = Bringup(specs, quiet=args.quiet)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    t0 = time.monotonic()
    nodes = {m.node: m for s in specs for m in members(s)}
    simulated = "plant_simulator" in nodes
    state_timeout = args.state_timeout or (30.0 if simulated else 10.0)
    watch = FirstStateWatch(states)
    bring.start()
    t_started = time.monotonic()
    # the process of each node (simulated: plant and experiment share one)
    procs = {m.node: p for s, p in bring.procs for m in members(s)}
    exp = procs["identification_experiment"]
    exp_label = nodes["identification_experiment"].label
    # the labels whose exit is the experiment's own (its node, the nodes composed with it)
    exp_labels = {
        lbl for s, p in bring.procs if p is exp for lbl in (s.label, *(m.label for m in members(s)))
    }
    status = "ok"
    while exp.poll() is None:
        if stop.is_set():
            status = "interrupted"
            break
        if any(p.poll() is not None for p in procs.values() if p is not exp):
            status = "failed"
            break
        if time.monotonic() - t0 > timeout:
            status = "timeout"
            break
        if watch.seen:  # poll returns at once from now on: wait here, not in a busy loop
            watch.close()  # once: the node is not needed any more
            stop.wait(0.05)
        elif not watch.poll(0.05) and time.monotonic() - t_started > state_timeout:
            status = "no_states"
            break
    watch.close()
    _stop_proc(exp)  # no-op when it exited by itself; else zero torque first
    time.sleep(0.5)  # last events/states reach the recorder
    first = bring.first_failure()
    bring.stop()
    wall = time.monotonic() - t0
    rc_exp = exp.returncode
    if first is not None and first[0] in exp_labels and first[1] in (EXIT_ABORTED, EXIT_NOT_EXCITED):
        first = None  # the run's own result, reported below with the summary
    error = None
    if first is not None:
        label, code, reason = first
        error = f"{label}: {reason}"
        if code == 2:  # a node refused its input: nothing was run
            _remove_if_empty(out, created, events)
            print(f"error: {error}", file=sys.stderr)
            return 2
    elif status == "timeout":
        error = f"timed out after {wall:.1f} s wall (--timeout {timeout:g} s)" + _waiting_reason(
            bring, exp_label
        )
    elif status == "no_states":
        error = no_state_reason(states, state_timeout, simulated)
    elif status == "interrupted":
        error = f"interrupted after {wall:.1f} s wall"
    elif status == "failed":  # another node ended by itself (exit 0) before the program did
        gone = [
            s.label
            for s, p in bring.procs
            if p is not exp and bring.ended.get(s.label, math.inf) < bring.stopping
        ]
        error = f"{', '.join(gone) or 'a node'} exited before the program ended (after {wall:.1f} s wall)"
    elif rc_exp == EXIT_NOT_EXCITED:
        error = _last_line_with(bring.output.get(exp_label, []), "joint not excited:") or "joint not excited"
    if _remove_if_empty(out, created, events):
        print(f"[experiment] the program never started: removed {out}", flush=True)
        print(
            f"error: {error or 'the program never started (no experiment event recorded)'}", file=sys.stderr
        )
        return 1
    print(f"[experiment] bag: {out.resolve()} ({wall:.1f} s wall)", flush=True)
    try:
        print("\n".join(summarize(out, j, p, events, states) for j, p in joints), flush=True)
    except (ParameterError, ValueError, OSError) as exc:
        error = error or f"summary not available: {exc}"
    if error is not None:
        print(f"error: {error}", file=sys.stderr)
        return 1
    return EXIT_ABORTED if rc_exp == EXIT_ABORTED else 0


def _last_line_with(lines: list[str], marker: str) -> str | None:
    """The text from ``marker`` on of the last line that contains it."""
    for ln in reversed(lines):
        if marker in ln:
            return ln[ln.index(marker) :].strip()
    return None


def _waiting_reason(bring: Bringup, exp_label: str) -> str:
    """Why the program did not run: the experiment's line about joint_states without its joint."""
    text = _last_line_with(bring.output.get(exp_label, []), "joint_states carry no joint")
    if text:
        arm = "; set joints" in text
        return ": " + text.split("; set joint")[0] + (" (set --joints)" if arm else " (set --joint)")
    return ""


def _remove_if_empty(out: Path, created: str, events_topic: str) -> bool:
    """After a run whose program never started (no experiment event recorded: a node refused to
    start, the joint states never came), remove what it created: the bag folder (``created`` =
    "folder") or only its files in a folder that was empty before ("files"); True if removed."""
    if not created or not out.is_dir():
        return False
    from friction_ros.core.bag import bag_info
    from friction_ros.core.bag.writer import RESERVE_NAME

    try:
        info = bag_info(out).info
        if events_topic in info and info[events_topic].count > 0:
            return False
    except (ValueError, OSError):  # a bag the recorder could not even start: its own files only
        pass
    ours = {f"{out.name}_0.mcap", "metadata.yaml", "metadata.yaml.tmp", RESERVE_NAME}
    files = list(out.iterdir())
    if not {f.name for f in files} <= ours or any(not f.is_file() for f in files):
        return False
    for f in files:
        f.unlink()
    if created == "folder":
        out.rmdir()
    return True


if __name__ == "__main__":
    sys.exit(main())
