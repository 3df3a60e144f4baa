"""friction-bag: inspect, check and repair MCAP bags without ROS tools.

    friction-bag info bags/run_1            topics, types, counts, duration, run metadata, problems;
                                            status complete, NOT CLOSED, TRUNCATED or DAMAGED
    friction-bag recover bags/run_1 out/    rewrite the readable messages of a killed recording (or of
                                            a damaged bag) as a finished bag (summary, statistics,
                                            metadata.yaml)

Unreadable input prints one line ``error: ...`` and exits with code 2 (no traceback); a full output
disk prints one line naming it and exits with code 1 (nothing is written: the output is built in a
temporary folder next to it).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from friction_ros.core.bag import BagWriter, DiskFullError, bag_files, bag_info, iter_messages


def _info(path: str) -> int:
    bag = bag_info(path)
    counts = {t: i.count for t, i in bag.info.items()}
    print(f"bag:      {bag.path}")
    print(f"files:    {', '.join(str(f.name) for f in bag.files)}")
    print(f"messages: {sum(counts.values())}")
    if bag.duration is not None:
        print(f"duration: {bag.duration:.3f} s")
    width = max((len(t) for t in counts), default=5)
    for t, i in sorted(bag.info.items()):
        print(
            f"  {t.ljust(width)}  {i.msgtype:40s} {i.count:9d} msgs  {i.message_encoding}/{i.schema_encoding}"
        )
    for name, md in bag.metadata.items():
        if name == "rosbag2":
            continue
        keys = {k: v for k, v in md.items() if not k.startswith("parameter_file:")}
        print(f"metadata {name}: " + ", ".join(f"{k}={v}" for k, v in keys.items()))
    for w in bag.warnings:
        print(f"warning: {w}")
    print(f"status:   {_status(bag)}")
    return 0


def _status(bag) -> str:
    """``complete``, ``TRUNCATED ...`` (cut inside a record), ``NOT CLOSED ...`` (ends after a complete
    record without its summary) and/or ``DAMAGED: <messages lost per topic>``."""
    from friction_ros.core.bag.damage import describe_loss

    parts = []
    if bag.damaged:
        parts.append(f"DAMAGED: {describe_loss(bag.lost)}")
    if bag.cut:
        parts.append("TRUNCATED (recovered complete chunks; the last, incomplete chunk is lost)")
    elif bag.truncated:
        parts.append("NOT CLOSED (no summary/footer; every message was read; recover writes a closed copy)")
    return "; ".join(parts) or "complete"


def _recover(path: str, out: str, overwrite: bool) -> int:
    """Rewrite into a temporary folder next to ``out``, rename it into place on success.

    The input is never touched: an output that is the input, lies inside it or contains one of its
    files is refused before anything is written.
    """
    import shutil
    import tempfile

    src = Path(path).resolve()
    dst = Path(out).resolve()
    _, files = bag_files(src)
    inputs = {src, *(f.resolve() for f in files)}
    for f in inputs:
        if dst == f or dst in f.parents or f in dst.parents:
            raise ValueError(
                f"output {out} overlaps the input bag {path}: recover into a new folder "
                "(the input is left as it is)"
            )
    if dst.exists() and not overwrite:
        raise ValueError(f"output {out} exists: choose another folder or pass --overwrite")
    dst.parent.mkdir(parents=True, exist_ok=True)
    bag = bag_info(src)
    tmp = Path(tempfile.mkdtemp(prefix=".friction-bag-recover-", dir=dst.parent))
    work = tmp / dst.name  # the bag's files are named after its folder
    try:
        with BagWriter(work, metadata=bag.run_metadata or None, overwrite=True) as w:
            for t, i in bag.info.items():
                if i.message_encoding == "cdr" and i.schema:
                    w.add_topic(
                        t,
                        i.msgtype,
                        qos_profiles=i.qos_profiles,
                        msgdef=i.schema,
                        type_description_hash=i.type_hash,
                    )
            n = 0
            for m in iter_messages(src, list(w.topics)):
                w.write(m.topic, m.data, m.log_time, m.publish_time)
                n += 1
        if dst.exists():
            shutil.rmtree(dst) if dst.is_dir() else dst.unlink()
        work.rename(dst)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    notes = ["input was truncated" if bag.cut else "input was not closed"] if bag.truncated else []
    if bag.damaged:
        from friction_ros.core.bag.damage import describe_loss

        notes.append(f"input was damaged: {describe_loss(bag.lost)}")
    print(f"wrote {n} messages to {out}" + (f" ({'; '.join(notes)})" if notes else ""))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, prog="friction-bag", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("info", allow_abbrev=False, help="describe a bag")
    p.add_argument("bag")
    p = sub.add_parser("recover", allow_abbrev=False, help="rewrite a truncated bag as a finished one")
    p.add_argument("bag")
    p.add_argument("output")
    p.add_argument("--overwrite", action="store_true")
    ns = ap.parse_args(argv)
    try:
        if ns.cmd == "info":
            return _info(ns.bag)
        return _recover(ns.bag, ns.output, ns.overwrite)
    except DiskFullError as exc:  # not bad input: the output disk filled
        print(
            f"error: disk full: {exc.where} while writing {ns.output}: nothing written (the input is "
            f"unchanged); {exc.advice}",
            file=sys.stderr,
        )
        return 1
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
