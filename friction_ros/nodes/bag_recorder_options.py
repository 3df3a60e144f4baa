"""The bag_recorder's options: its ROS parameters (:data:`SCHEMA`) and its command line, which
sets the same parameters (``bag_recorder -o bags/run_1 /joint_states ...``)."""

from __future__ import annotations

import argparse

from friction_ros.core.bag.writer import COMPRESSIONS
from friction_ros.core.config import Field, Schema

SCHEMA = Schema(
    "bag_recorder",
    [
        Field(
            "topics",
            [],
            "topics to record (absolute names); empty with all_topics=false records nothing",
            kind=str,
            read_only=True,
        ),
        Field(
            "all_topics",
            False,
            "record every topic that appears (except /rosout and /parameter_events)",
            read_only=True,
        ),
        Field(
            "output",
            "",
            "bag directory to create; default run_<YYYYmmdd_HHMMSS> in the working directory",
            read_only=True,
        ),
        Field(
            "overwrite",
            False,
            "allow an existing non-empty output directory (its bag files are replaced)",
            read_only=True,
        ),
        Field("compression", "zstd", "MCAP chunk compression", choices=tuple(COMPRESSIONS), read_only=True),
        Field(
            "chunk_size",
            1048576,
            "uncompressed bytes per chunk before it is written",
            lo=1024,
            hi=1 << 30,
            unit="B",
            read_only=True,
        ),
        Field(
            "flush_interval",
            1.0,
            "longest time a message waits in the open chunk (SIGKILL loss bound)",
            lo=0.0,
            hi=3600.0,
            unit="s",
            read_only=True,
        ),
        Field(
            "qos_depth",
            0,
            "depth of the recording subscriptions: 0 keeps all (a burst waits in the publisher, never "
            "dropped here); > 0 keep-last of that depth",
            lo=0,
            hi=1000000,
            read_only=True,
        ),
        Field(
            "discovery_period",
            0.2,
            "period of the search for publishers of the wanted topics",
            lo=0.01,
            hi=60.0,
            unit="s",
            read_only=True,
        ),
        Field(
            "max_duration",
            0.0,
            "stop after this time, 0 = until SIGINT/SIGTERM",
            lo=0.0,
            hi=1e9,
            unit="s",
            read_only=True,
        ),
        Field(
            "diagnostics_period",
            1.0,
            "period of the diagnostics status (messages and drops per topic) and of drop log lines",
            lo=0.05,
            hi=3600.0,
            unit="s",
            read_only=True,
        ),
        Field("preset", "", "run metadata: plant/joint preset name", read_only=True),
        Field("program", "", "run metadata: excitation program", read_only=True),
        Field(
            "parameter_files",
            [],
            "run metadata: parameter files embedded by content",
            kind=str,
            read_only=True,
        ),
    ],
)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        allow_abbrev=False,
        prog="bag_recorder",
        description="Record topics to a rosbag2 MCAP bag (ROS parameters via --ros-args).",
    )
    ap.add_argument("topics", nargs="*", help="topics to record")
    ap.add_argument(
        "-a", "--all", dest="all_topics", action="store_true", default=None, help="record all topics"
    )
    ap.add_argument("-o", "--output", help="bag directory")
    ap.add_argument("--overwrite", action="store_true", default=None)
    ap.add_argument("--compression", choices=list(COMPRESSIONS))
    ap.add_argument("--chunk-size", dest="chunk_size", type=int, help="bytes")
    ap.add_argument("--flush-interval", dest="flush_interval", type=float, help="s (SIGKILL loss bound)")
    ap.add_argument("--qos-depth", dest="qos_depth", type=int)
    ap.add_argument("--max-duration", dest="max_duration", type=float, help="s")
    ap.add_argument("--preset")
    ap.add_argument("--program")
    ap.add_argument(
        "--param-file", dest="parameter_files", action="append", help="embed this file (repeatable)"
    )
    return ap


def parse_cli(argv: list[str]) -> dict:
    """The ROS parameters given on the command line (``argv`` without ROS arguments)."""
    ns = build_parser().parse_args(argv)
    out = {k: v for k, v in vars(ns).items() if v is not None}
    if not out.get("topics"):
        out.pop("topics", None)
    return out
