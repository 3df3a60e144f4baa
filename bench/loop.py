"""Benchmark `loop` (issue 5): the closed loop across separate processes over real DDS.

1. Real time: plant_simulator (1 kHz wall-clock loop) + compensating_controller + friction_estimator
   for ``--realtime-seconds`` (default 60): achieved rate, state-to-command latency p50/p99 (measured
   by the plant: command arrival minus the stamp of the state it answers), missed cycles (periods in
   which the answer to the previous state had not arrived), loop overruns, CPU per node process.
   The plant's statistics start 2 s after the first command (``stats_delay``: start-up, discovery and
   the seconds before the controller answers are not loop behaviour).
2. Lockstep: the three-node graph at a 1 kHz control period: simulated seconds per wall second over
   the same window (and including start-up).
3. Soak: ``--soak-seconds`` (default 600) at 1 kHz real time; resident memory growth per node
   between the end of warm-up and the end, overruns in the worst 10 s window.

Both 1 and 2 run in three scheduling configurations: ``default`` (no pinning, normal scheduler),
``pinned`` (plant and controller on core 0, estimator on core 1: ``friction-bringup --pin``) and
``pinned_fifo`` (plant and controller share core 0 with SCHED_FIFO 80 via their ``realtime_priority``
and ``cpu_affinity`` parameters, the estimator runs on core 1 with normal scheduling).

    .venv/bin/python bench/loop.py                       # full (about 17 minutes)
    .venv/bin/python bench/loop.py --quick               # iterate: 15 s + 10 s per configuration, no soak

Measured floor on the 2-core development VM (rclpy 7.1.5 / Jazzy, Fast DDS shared memory,
EventsExecutor; measured while other jobs kept the load average at 3-5, so +-30 %):

* JointState ping-pong between two rclpy processes, CPU of the pinging process per round trip:
  message objects 130-160 us (round trip p50 ~200 us); raw CDR bytes (``raw=True`` subscription,
  ``publish(bytes)``) 64-99 us (p50 100-130 us) across cores, 34-41 us (p50 55-67 us) with both
  processes on one core: a wake-up across cores costs an IPI and VM exits here. A
  builtin_interfaces/Time message (no sequences or strings) costs 63 us as objects.
* An idle 1 kHz timed wait costs 28 us CPU per cycle with time.sleep, 44 us with
  EventsExecutor.spin_once(timeout) (timer programming and HLT wake-ups are VM exits).
* Python work per message before -> after the hot-path changes: JointState build + serialise
  ~10 us -> 0.3 us (``JointStateEncoder``); deserialise into a message 17 us -> 1.6 us
  (``JointStateDecoder``); ControllerState build + publish 17 us -> ~2 us (and nothing without a
  subscriber); Reference.sample 9-15 us -> 0.3 us; estimator update 34 us -> 11 us.

So per 1 kHz cycle the plant needs one timed wake-up, one take and one publish to two readers, the
controller one take and one or two publishes: ~150-300 us of CPU per process in real time mode, of
which the Python node code is now < 30 us; the rest is rclpy/Fast DDS and wake-up cost. On two cores
shared with other work, p99 < 1 ms needs the latency chain on one core with SCHED_FIFO; without it
the scheduler (other processes) dominates the tail.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import yaml

sys.path.append(str(Path(__file__).resolve().parent))  # bench/can.py must not shadow python-can
from _common import print_table, write_results  # noqa: E402

from friction_ros.cli.bringup import Bringup, NodeSpec  # noqa: E402

# a graph of its own: other ROS processes on this machine (tests, other benchmarks) must not share
# the topics or the discovery traffic
os.environ.setdefault("ROS_DOMAIN_ID", str(180 + os.getpid() % 50))
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

CONTROLLER = {
    "mode": "pid",
    "effort_limit": 4.9,
    "pid": {"p": 30.0, "i": 60.0, "d": 0.3},
    "compensation": {"source": "feedforward"},
    "friction": {"model": "coulomb_viscous", "fc": 0.8, "fv": 0.01},
    "reference": {"type": "sinusoid", "amplitude": 0.2, "frequency": 0.5},
}
ESTIMATOR = {"model": "coulomb_viscous", "inertia": 0.0012}


def rss_kb(pid: int) -> int:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        return 0
    return 0


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process (all threads) from /proc/<pid>/stat."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


#: Scheduling configurations of the benchmark. "pinned_fifo": plant and controller (the latency
#: chain) share core 0 with SCHED_FIFO 80, the estimator runs on core 1 with normal scheduling.
SCHEDULING = {
    "default": ({}, {}, {}),
    # friction-bringup --mode lockstep's default (--pin auto): no root needed
    "pinned": ({"cpu_affinity": 0}, {"cpu_affinity": 0}, {"cpu_affinity": 1}),
    "pinned_fifo": (
        {"realtime_priority": 80, "cpu_affinity": 0},
        {"realtime_priority": 80, "cpu_affinity": 0},
        {"cpu_affinity": 1},
    ),
}


def run_graph(
    tmp: Path,
    mode: str,
    seconds: float,
    warmup: float = 5.0,
    sample_every: float = 0.0,
    scheduling: str = "default",
) -> dict:
    params = tmp / "params.yaml"
    params.write_text(
        yaml.safe_dump(
            {
                "compensating_controller": {"ros__parameters": CONTROLLER},
                "friction_estimator": {"ros__parameters": ESTIMATOR},
            }
        )
    )
    stats = tmp / f"stats_{mode}.json"
    plant_s, ctrl_s, est_s = SCHEDULING[scheduling]
    sim = {"use_sim_time": True} if mode == "lockstep" else {}
    # statistics start 2 s after the first command (the graph is connected and warm by then)
    plant = {"preset": "abb_m19s", "mode": mode, "stats_file": str(stats), "stats_delay": 2.0, **plant_s}
    specs = [
        NodeSpec("plant_simulator", "", [], plant),
        NodeSpec("compensating_controller", "", [str(params)], {**sim, **ctrl_s}),
        NodeSpec("friction_estimator", "", [str(params)], {**sim, **est_s}),
    ]
    bring = Bringup(specs, quiet=True)
    bring.start()
    time.sleep(warmup)
    rss0 = {s.node: rss_kb(p.pid) for s, p in bring.procs}
    cpu0 = {s.node: cpu_s(p.pid) for s, p in bring.procs}
    wall0 = time.monotonic()
    samples = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        time.sleep(min(sample_every or 1.0, max(0.0, end - time.monotonic())))
        if sample_every:
            samples.append({s.node: rss_kb(p.pid) for s, p in bring.procs})
        if bring.failed():
            break
    rss1 = {s.node: rss_kb(p.pid) for s, p in bring.procs}
    cpu1 = {s.node: cpu_s(p.pid) for s, p in bring.procs}
    wall = time.monotonic() - wall0
    failed = bring.failed()
    bring.stop()
    if failed:
        raise SystemExit(f"nodes failed: {failed}\n" + "\n".join(sum(bring.output.values(), [])[-40:]))
    out = json.loads(stats.read_text())
    out["rss_start_kb"] = rss0
    out["rss_end_kb"] = rss1
    out["rss_growth_kb"] = {k: rss1[k] - rss0[k] for k in rss0}
    out["cpu_percent"] = {k: 100.0 * (cpu1[k] - cpu0[k]) / wall for k in cpu0}
    if samples:
        out["rss_samples_kb"] = samples
    return out


TIMER_FLOOR_PROBE = """
import os, sys, time
fifo, seconds = sys.argv[1] == "1", float(sys.argv[2])
os.sched_setaffinity(0, {0})
if fifo:
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(80))
nxt = time.monotonic()
end, n, late1, late5, worst = nxt + seconds, 0, 0, 0, 0.0
while nxt < end:
    nxt += 0.001
    d = nxt - time.monotonic()
    if d > 0:
        time.sleep(d)
    lateness = time.monotonic() - nxt
    n += 1
    late1 += lateness > 0.001
    late5 += lateness > 0.005
    worst = max(worst, lateness)
print(n, late1, late5, worst)
"""


def timer_floor(seconds: float) -> dict:
    """The machine's own floor: a bare Python loop that sleeps to 1 kHz deadlines (no ROS, no work),
    pinned to core 0, with and without SCHED_FIFO 80. Cycles woken more than 1 ms late are cycles
    the closed loop cannot make whatever the nodes do."""
    import subprocess

    out = {}
    for name, fifo in (("default", "0"), ("pinned_fifo", "1")):
        res = subprocess.run(
            [sys.executable, "-c", TIMER_FLOOR_PROBE, fifo, str(seconds)], capture_output=True, text=True
        )
        if res.returncode != 0:
            out[name] = {"error": res.stderr.strip().splitlines()[-1] if res.stderr.strip() else "failed"}
            continue
        n, late1, late5, worst = res.stdout.split()
        out[name] = {
            "cycles": int(n),
            "late_1ms_percent": 100.0 * int(late1) / int(n),
            "late_5ms": int(late5),
            "max_late_ms": 1e3 * float(worst),
        }
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--realtime-seconds", type=float, default=60.0)
    parser.add_argument("--lockstep-seconds", type=float, default=20.0)
    parser.add_argument("--soak-seconds", type=float, default=600.0)
    parser.add_argument(
        "--quick",
        action="store_true",
        help="iterate: 15 s real time, 10 s lockstep, no soak (not for README)",
    )
    args = parser.parse_args()
    if args.quick:
        args.realtime_seconds, args.lockstep_seconds, args.soak_seconds = 15.0, 10.0, 0.0
    figures: dict = {"realtime": {}, "lockstep": {}}
    figures["timer_floor"] = timer_floor(args.realtime_seconds / 2)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for sched in SCHEDULING:
            rt = run_graph(tmp, "realtime", args.realtime_seconds, scheduling=sched)
            cycles = max(rt["cycles"], 1)
            figures["realtime"][sched] = {
                "seconds": args.realtime_seconds,
                "window_seconds": rt["window_wall_time"],
                "rate_hz": rt["rate_hz"],
                "latency_p50_ms": rt["latency_p50_s"] * 1e3,
                "latency_p99_ms": rt["latency_p99_s"] * 1e3,
                "latency_max_ms": rt["latency_max_s"] * 1e3,
                "missed_cycles": rt["missed_commands"],
                "missed_percent": 100.0 * rt["missed_commands"] / cycles,
                "overruns": rt["overruns"],
                "cycles": rt["cycles"],
                "cpu_percent": rt["cpu_percent"],
            }
            ls = run_graph(tmp, "lockstep", args.lockstep_seconds, warmup=3.0, scheduling=sched)
            figures["lockstep"][sched] = {
                "wall_seconds": args.lockstep_seconds,
                "sim_seconds_per_wall_second": ls["sim_seconds_per_wall_second"],
                "sim_seconds_per_wall_second_total": ls["sim_seconds_per_wall_second_total"],
                "steps": ls["steps"],
                "cpu_percent": ls["cpu_percent"],
            }
        if args.soak_seconds > 0:
            soak = run_graph(tmp, "realtime", args.soak_seconds, warmup=30.0, sample_every=10.0)
            figures["soak"] = {
                "seconds": args.soak_seconds,
                "rss_growth_kb": soak["rss_growth_kb"],
                "rss_end_kb": soak["rss_end_kb"],
                "overruns": soak["overruns"],
                "missed_percent": 100.0 * soak["missed_commands"] / max(soak["cycles"], 1),
                "latency_p99_ms": soak["latency_p99_s"] * 1e3,
                "rate_hz": soak["rate_hz"],
            }
    rts, lks = figures["realtime"], figures["lockstep"]
    print_table(
        f"Real-time closed loop, 1 kHz, {args.realtime_seconds:g} s, 3 processes (goal: p99 < 1 ms, missed < 0.1 %)",
        [
            "scheduling",
            "rate Hz",
            "latency p50 ms",
            "latency p99 ms",
            "max ms",
            "missed cycles",
            "missed %",
            "overruns",
        ],
        [
            [
                k,
                r["rate_hz"],
                r["latency_p50_ms"],
                r["latency_p99_ms"],
                r["latency_max_ms"],
                r["missed_cycles"],
                r["missed_percent"],
                r["overruns"],
            ]
            for k, r in rts.items()
        ],
    )
    print_table(
        "Timer floor of this machine: bare 1 kHz sleep loop on core 0, no ROS "
        f"({args.realtime_seconds / 2:g} s)",
        ["scheduling", "cycles", "woken > 1 ms late %", "> 5 ms late", "max late ms"],
        [
            [
                k,
                f.get("cycles", "-"),
                f.get("late_1ms_percent", "-"),
                f.get("late_5ms", "-"),
                f.get("max_late_ms", f.get("error")),
            ]
            for k, f in figures["timer_floor"].items()
        ],
    )
    print_table(
        "Lockstep, 3-node graph, 1 kHz control period (goal: >= 3x real time)",
        ["scheduling", "sim s / wall s", "incl. start-up", "steps"],
        [
            [k, lk["sim_seconds_per_wall_second"], lk["sim_seconds_per_wall_second_total"], lk["steps"]]
            for k, lk in lks.items()
        ],
    )
    rows = []
    for k in rts:
        r, lk = rts[k], lks[k]
        steps_per_s = 1000.0 * lk["sim_seconds_per_wall_second"]
        for node in r["cpu_percent"]:
            rows.append(
                [
                    k,
                    node,
                    r["cpu_percent"][node],
                    1e4 * r["cpu_percent"][node] / max(r["rate_hz"], 1.0),
                    lk["cpu_percent"][node],
                    1e4 * lk["cpu_percent"][node] / max(steps_per_s, 1.0),
                ]
            )
    print_table(
        "CPU per node process (% of one core; us per cycle = CPU time / control cycles)",
        ["scheduling", "node", "real time %", "real time us/cycle", "lockstep %", "lockstep us/step"],
        rows,
    )
    if "soak" in figures:
        s = figures["soak"]
        print_table(
            f"Soak, {args.soak_seconds:g} s at 1 kHz (goal: RSS growth < 5 MB per node)",
            ["node", "RSS end MB", "growth MB"],
            [[k, s["rss_end_kb"][k] / 1024, s["rss_growth_kb"][k] / 1024] for k in s["rss_growth_kb"]],
        )
        print(
            f"soak: overruns {s['overruns']}, missed {s['missed_percent']:.3f} %, p99 {s['latency_p99_ms']:.3f} ms"
        )
    write_results("loop", figures)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
