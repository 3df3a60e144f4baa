"""friction-fit: identify friction models from bags or CSV logs; write a report, a JSON summary and ROS parameters.

Example::

    friction-fit bags/run_1 --joint joint1 --models coulomb stribeck lugre gms4 --out fit_run_1
    friction-fit log.csv --columns time=t,position=q,velocity=dq,effort=tau --time-scale 1e-9
    friction-fit bags/arm_run --joint all --jobs 2 --out fit_arm

Inputs: rosbag2 directories (MCAP or SQLite3), ``.mcap``/``.db3`` files, or ``.csv`` logs with a
header line (time, position/velocity, effort or current columns: see
:mod:`friction_ros.core.identification.data.csv_loading` for the names found automatically).

Writes ``<out>/report.md``, ``<out>/summary.json``, ``<out>/plots/*.png`` and the parameter file
(``<out>/friction_params.yaml`` or ``--params-out``) for compensating_controller,
friction_estimator and plant_simulator. ``--joint all`` (or ``--joint j1,j3``) fits every joint as
``--joint <joint>`` would into ``<out>/<joint>/``, writes ``<out>/index.md`` (model, validation NMSE,
verdict per joint) and one parameter file in the per-joint layout of the multi-joint nodes
(:mod:`friction_ros.core.identification.report.multi_joint`). Inputs are never changed: an output that is one of the
bags, or a parameter file this command did not write, is refused (``--force`` replaces a file that
exists). Exit codes: 0 ok, 2 bad input (missing topic/joint, no motion, too little excitation, bad
option, output collision), 1 unexpected error.
"""

from __future__ import annotations

import argparse
import math
import sys

from friction_ros.cli.fit_args import fit_options, gate_options, log_options  # noqa: F401 (gate_options: re-exported)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(allow_abbrev=False, prog="friction-fit", description=__doc__.splitlines()[0])
    p.add_argument(
        "bags",
        nargs="+",
        help="rosbag2 directories (MCAP or SQLite3), .mcap/.db3 files or .csv logs",
    )
    p.add_argument(
        "--columns",
        default=None,
        metavar="ROLE=NAME,...",
        help=(
            "CSV column of each role, e.g. time=t,position=q,velocity=dq,effort=tau (roles: "
            f"{', '.join(CSV_ROLES)}; default: found by header name)"
        ),
    )
    p.add_argument(
        "--time-scale",
        type=float,
        default=1.0,
        help="CSV time column unit in seconds, e.g. 1e-9 for nanoseconds, 1e-3 for ms (default 1)",
    )
    p.add_argument(
        "--topic", default="/joint_states", help="sensor_msgs/JointState topic (default /joint_states)"
    )
    p.add_argument(
        "--joint",
        default=None,
        help="joint name (required when the topic carries several joints); 'all' or a list j1,j3 fits each "
        "joint and writes one parameter file for the multi-joint nodes (per-joint reports in <out>/<joint>/)",
    )
    p.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="with --joint all or a list: joints fitted in parallel processes (default 1; same output for any N)",
    )
    p.add_argument(
        "--models",
        "--model",
        dest="models",
        nargs="+",
        default=["coulomb", "stribeck", "lugre", "gms4"],
        help=(
            "models (--model is the same option): coulomb coulomb_viscous stribeck dahl lugre gms<N> gms<N>d (GMS with presliding "
            "damping sigma1) anfis nusvr, or a model added as a plugin (docs/architecture.md) "
            "(default: coulomb stribeck lugre gms4)"
        ),
    )
    p.add_argument("--out", default="friction_fit", help="output directory (default friction_fit)")
    p.add_argument(
        "--params-out",
        default=None,
        help="where to write the parameter YAML (default <out>/friction_params.yaml)",
    )
    p.add_argument(
        "--params",
        default=None,
        help=argparse.SUPPRESS,  # an input in every other command: refused here with a hint
    )
    p.add_argument(
        "--force", action="store_true", help="replace a parameter file that friction-fit did not write"
    )
    p.add_argument(
        "--events-topic",
        default="/experiment_events",
        help="ExperimentEvent topic (plateau/breakaway markers)",
    )
    p.add_argument(
        "--current-topic",
        default=None,
        help="topic carrying the motor current (default: the joint-state topic)",
    )
    p.add_argument(
        "--current-field",
        default=None,
        help="current field [A]; torque = current x torque constant x gear ratio",
    )
    p.add_argument("--torque-constant", type=float, default=None, help="motor torque constant [N*m/A]")
    p.add_argument(
        "--gear-ratio", type=float, default=1.0, help="gear ratio (joint torque / motor torque), default 1"
    )
    p.add_argument(
        "--torque-delay",
        type=float,
        default=0.0,
        help="shift the torque earlier by this lag behind the motion [s] (default 0)",
    )
    p.add_argument(
        "--plant-preset",
        default=None,
        help="preset whose plant parameters the plant_simulator section starts from (e.g. abb_m19s)",
    )
    p.add_argument(
        "--train-seconds",
        type=float,
        default=10.0,
        help="training window per record [s] (10, as in the friction-characterization paper: docs/sources.md)",
    )
    p.add_argument(
        "--max-samples",
        type=int,
        default=300_000,
        help="a longer log is cut down to this many samples chosen by content (reversals, speeds, "
        "accelerations, positions, plateaus); the report says what was used (default 300000: 5 min at 1 kHz; 0: all)",
    )
    p.add_argument(
        "--train-window",
        choices=["content", "window", "first"],
        default="content",
        help="training data: chunks chosen by content so training and validation both hold reversals, high "
        "and low speeds (content, default), the single most exciting --train-seconds window (window), or "
        "the first --train-seconds (first, as in the friction-characterization paper)",
    )
    p.add_argument(
        "--current-lag",
        type=float,
        default=None,
        help="drive current-loop time constant [s] for the compensation safety gate (default: the "
        "--plant-preset's, else 0 with a warning)",
    )
    p.add_argument(
        "--delay",
        type=float,
        default=None,
        help="pure measurement + actuation delay [s] for the safety gate (default: the --plant-preset's, "
        "else 0 with a warning)",
    )
    p.add_argument(
        "--no-gate",
        action="store_true",
        help="write the parameter file without checking the compensation modes in closed loop",
    )
    p.add_argument(
        "--optimizer",
        choices=["de", "ga"],
        default="de",
        help="global optimiser: differential evolution or the genetic algorithm of the GA friction-modelling "
        "thesis (docs/sources.md)",
    )
    p.add_argument(
        "--maxiter", type=int, default=None, help="global-search generations (default 40 + 15 x dimension)"
    )
    p.add_argument("--seed", type=int, default=3, help="random seed (default 3)")
    p.add_argument(
        "--eps",
        type=float,
        default=None,
        help="linear-zone width of sgn(v) for static models [velocity unit] (default 1e-3 times the log's "
        "speed scale: the decade of its 95th percentile speed)",
    )
    p.add_argument(
        "--high-threshold",
        type=float,
        default=None,
        help="high/low velocity split [rad/s] (default automatic)",
    )
    p.add_argument(
        "--load",
        default="auto",
        help="load, gravity and position terms fitted with every model: auto (chosen by validation when the "
        "log has no plateaus), none, or a list of gravity,offset,spring,load_friction,ripple=<harmonics>",
    )
    p.add_argument(
        "--ripple-period",
        type=float,
        default=2.0 * math.pi,
        help="period of the position-dependent friction [rad] (2*pi/N for the motor angle of an N:1 gear; "
        "default 2*pi)",
    )
    p.add_argument(
        "--residual",
        choices=["auto", "none", "mlp", "rff"],
        default="auto",
        help="learned residual on top of the best physics model (auto: for logs without plateaus)",
    )
    p.add_argument(
        "--cross-validate",
        action="store_true",
        help="with several runs: also train on all but one run and validate on it, for each run",
    )
    p.add_argument(
        "--validate-on",
        nargs="+",
        default=None,
        metavar="LOG",
        help="validate on these logs (bags or CSV, read like the inputs) and train on the whole of the inputs, "
        "as published benchmarks split estimation and validation runs",
    )
    p.add_argument(
        "--joint-type",
        choices=["auto", "revolute", "prismatic"],
        default="auto",
        help="revolute (rad, N*m) or prismatic (m, N); auto: from the log's metadata or column names, else revolute",
    )
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    return p


FITTED_HEADER = "# friction-fit:"
CSV_ROLES = ("time", "position", "velocity", "effort", "current", "load")


def parse_columns(text: str | None) -> dict[str, str] | None:
    """``time=t,position=q`` -> {"time": "t", "position": "q"}; ParameterError on bad syntax or role."""
    from friction_ros.core.validation import ParameterError

    if text is None:
        return None
    out: dict[str, str] = {}
    for item in text.split(","):
        role, sep, name = item.partition("=")
        role, name = role.strip(), name.strip()
        if not sep or not role or not name:
            raise ParameterError(
                f"--columns {text!r}: {item.strip()!r} is not ROLE=NAME: write e.g. time=t,position=q,effort=tau"
            )
        if role not in CSV_ROLES:
            raise ParameterError(
                f"--columns {text!r}: unknown role {role!r}: roles are {', '.join(CSV_ROLES)}"
            )
        if role in out:
            raise ParameterError(f"--columns {text!r}: role {role!r} is given twice")
        out[role] = name
    return out


def check_outputs(args) -> None:
    """Refuse outputs that would overwrite an input or a file this command did not write."""
    from pathlib import Path

    from friction_ros.core.validation import ParameterError

    if args.params is not None:
        raise ParameterError(
            "--params is an input (a parameter file to read) in friction-experiment and friction-bringup: "
            "write the fitted parameters with --params-out PATH"
        )
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ParameterError(f"--out {args.out} is a file: must be a directory (created if missing)")
    bags = [Path(b).resolve() for b in [*args.bags, *(getattr(args, "validate_on", None) or [])]]
    pf = Path(args.params_out) if args.params_out else out / "friction_params.yaml"
    for target, name in ((out.resolve(), "--out"), (pf.resolve(), "--params-out")):
        for b in bags:  # a bag directory, a .mcap/.db3 file or a .csv log: all inputs
            if target == b or b in target.parents or (name == "--out" and target in b.parents):
                kind = "log" if b.suffix.lower() == ".csv" else "bag"
                raise ParameterError(f"{name} {target} overlaps the input {kind} {b}: choose another path")
    if pf.is_dir():
        raise ParameterError(f"--params-out {pf} is a directory: must be a file path")
    if pf.exists() and not args.force:
        try:
            first = pf.read_text(errors="replace").splitlines()[:1]
        except OSError as exc:
            raise ParameterError(f"--params-out {pf}: cannot read it ({exc.strerror})") from None
        if not first or not first[0].startswith(FITTED_HEADER):
            raise ParameterError(
                f"--params-out {pf} exists and was not written by friction-fit: choose another path or pass --force"
            )


def main_joints(args, columns) -> int:
    """--joint all / j1,j3: every joint fitted as --joint <joint>, one multi-joint parameter file."""
    from pathlib import Path

    from friction_ros.core.identification.fit.models import check_model_names
    from friction_ros.core.identification.report import multi_joint
    from friction_ros.core.validation import ParameterError

    try:
        models = check_model_names(args.models)
        available = multi_joint.bag_joint_names(args.bags, args.topic)
        joints = multi_joint.requested_joints(args.joint, available)
        for j in joints:  # each joint's own outputs: refused like --params-out
            check_outputs(
                argparse.Namespace(**{**vars(args), "out": str(Path(args.out) / j), "params_out": None})
            )
    except ParameterError as exc:
        print(f"friction-fit: error: {exc}", file=sys.stderr)
        return 2

    def on_joint(f) -> None:
        if not args.quiet:
            print(f"friction-fit: {f.joint}: {f.verdict} ({f.seconds:.1f} s)", file=sys.stderr)

    try:
        res = multi_joint.fit_joints(
            args.bags,
            joints,
            models,
            args.out,
            params_file=args.params_out,
            jobs=args.jobs,
            on_joint=on_joint,
            topic=args.topic,
            options=fit_options(args),
            **log_options(args, columns),
        )
    except ParameterError as exc:
        print(f"friction-fit: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("friction-fit: interrupted", file=sys.stderr)
        return 130
    header = multi_joint.INDEX_HEADER
    rows = multi_joint.index_rows(res)
    width = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    for r in [header, *rows]:
        print("  ".join(c.ljust(w) for c, w in zip(r, width)).rstrip())
    for w in res.warnings:
        print(f"warning: {w}")
    for f in res.joints:
        if f.files.get("report"):
            print(f"wrote report {f.joint}: {f.files['report']}")
    for kind in ("params", "index"):
        print(f"wrote {kind}: {res.files[kind]}")
    if not any(f.compensated for f in res.joints):
        print("friction-fit: error: no joint could be fitted: see the warnings above", file=sys.stderr)
        return 2
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from friction_ros.core.validation import ParameterError

    try:
        check_outputs(args)
        columns = parse_columns(args.columns)
        if args.jobs < 1:
            raise ParameterError(f"--jobs {args.jobs}: must be >= 1")
    except ParameterError as exc:
        print(f"friction-fit: error: {exc}", file=sys.stderr)
        return 2
    from friction_ros.core.identification.report.multi_joint import is_joint_list

    if is_joint_list(args.joint):
        return main_joints(args, columns)

    try:
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        console = Console(stderr=True)
    except ImportError:  # pragma: no cover
        Progress = None
        console = None
    from friction_ros.core.identification import fit_bag
    from friction_ros.core.identification.fit.models import check_model_names

    try:
        models = check_model_names(args.models)
        progress = None
        if Progress is not None and not args.quiet:
            progress = Progress(
                TextColumn("[bold]{task.description:<8}"),
                BarColumn(),
                TextColumn("{task.percentage:>3.0f}%"),
                TimeElapsedColumn(),
                console=console,
                transient=False,
            )
        tasks: dict[str, int] = {}

        def on_progress(name: str, frac: float) -> None:
            if progress is None:
                return
            if name not in tasks:
                tasks[name] = progress.add_task(name, total=1.0)
            progress.update(tasks[name], completed=frac)

        if progress is not None:
            progress.start()
        try:
            res = fit_bag(
                args.bags,
                args.topic,
                args.joint,
                models,
                args.out,
                params_file=args.params_out,
                progress=on_progress,
                options=fit_options(args),
                **log_options(args, columns),
            )
        finally:
            if progress is not None:
                progress.stop()
    except (ParameterError, ValueError) as exc:
        print(f"friction-fit: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("friction-fit: interrupted", file=sys.stderr)
        return 130

    from friction_ros.cli.fit_summary import print_summary

    print_summary(res)
    return 0


if __name__ == "__main__":
    sys.exit(main())
