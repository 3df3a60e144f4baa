"""friction-bag: inspect, check and repair MCAP bags without ROS tools.

    friction-bag info bags/run_1            topics, types, counts, duration, run metadata, problems
    friction-bag recover bags/run_1 out/    rewrite the readable messages of a killed recording as a
                                            finished bag (summary, statistics, metadata.yaml)

Unreadable input prints one line ``error: ...`` and exits with code 2 (no traceback).
"""

from __future__ import annotations

import argparse
import sys

from friction_ros.core.bag import BagWriter, bag_info, iter_messages


def _info(path: str) -> int:
    bag = bag_info(path)
    counts = {t: i.count for t, i in bag.info.items()}
    print(f"bag:      {bag.path}")
    print(f"files:    {', '.join(str(f.name) for f in bag.files)}")
    print(f"messages: {sum(counts.values())}")
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
    print("status:   " + ("TRUNCATED (recovered complete chunks)" if bag.truncated else "complete"))
    return 0


def _recover(path: str, out: str, overwrite: bool) -> int:
    bag = bag_info(path)
    with BagWriter(out, metadata=bag.run_metadata or None, overwrite=overwrite) as w:
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
        for m in iter_messages(path, list(w.topics)):
            w.write(m.topic, m.data, m.log_time, m.publish_time)
            n += 1
    print(f"wrote {n} messages to {out}" + (" (input was truncated)" if bag.truncated else ""))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="friction-bag", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("info", help="describe a bag")
    p.add_argument("bag")
    p = sub.add_parser("recover", help="rewrite a truncated bag as a finished one")
    p.add_argument("bag")
    p.add_argument("output")
    p.add_argument("--overwrite", action="store_true")
    ns = ap.parse_args(argv)
    try:
        if ns.cmd == "info":
            return _info(ns.bag)
        return _recover(ns.bag, ns.output, ns.overwrite)
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
