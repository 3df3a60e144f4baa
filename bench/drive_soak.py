"""Drive soak: no false stale-telemetry fault over a long healthy run under CPU load; a killed drive.

    .venv/bin/python bench/drive_soak.py [--duration 300] [--load 2] [--configs single,arm]

Set-up as on a robot, at the README's settings: the ``drive_emulator`` program (abb_m19s preset) in a
process of its own and ``drive_interface`` in another, on the ``friction_local`` bus (the README's
"CAN without SocketCAN" commands: automatic telemetry timeout, 1 kHz); this process is the
controller (PD hold over DDS, one joint_commands message per joint_states message) and reads the
node's ``diagnostics`` once a second. ``--load`` busy-loop processes keep the cores busy. Configs:
``single`` (one drive) and ``arm`` (the README's whole-arm example: joints shoulder, elbow, wrist on
ids 1, 2, 3 in one node, one emulator process with ``--node-id 1 2 3``).

Figures per config: stale-telemetry faults (diagnostics ``stale_faults`` and fault lines in the
node's log, must be 0), the timeout, the largest telemetry age the node saw (the drive's longest
silence as seen at a control period) and the 99th percentile of the per-second maxima, late
periods (telemetry older than 3 periods: no sample and zero torque for that period; % of the 1 kHz
periods), watchdog trips (a controller late by more than ``command_timeout``: not a drive fault),
joint_states rate.
At the end the emulator is killed (SIGKILL): time from the kill to the node's logged
``telemetry_stale`` line (the bound is the timeout plus one control period after the drive's last
frame, plus however late the node itself runs), and whether the drive was disabled.
"""

from __future__ import annotations

import importlib.util
import math
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path

_BENCH = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("_bench_common", _BENCH / "_common.py")
_common = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_common)

KT = 0.49  # abb_m19s torque constant (gear ratio 1): what the emulated drive needs
ARM = {"shoulder": 1, "elbow": 2, "wrist": 3}
LOG_LINE = re.compile(r"\[(\w+)\] \[(\d+\.\d+)\] \[drive_interface\]: (.*)")


def node_command(channel: str, joints: dict[str, int] | None, extra: list[str] = ()) -> list[str]:
    ros = ["-p", "interface:=friction_local", "-p", f"channel:={channel}", "-p", "enable_on_start:=true",
           "-p", f"torque_constant:={KT}"]  # fmt: skip
    if joints:
        ros += ["-p", f"joints:=[{', '.join(joints)}]"]
        for j, nid in joints.items():
            ros += ["-p", f"{j}.node_id:={nid}"]
    for p in extra:
        ros += ["-p", p]
    return [sys.executable, "-m", "friction_ros.nodes.drive_interface", "--ros-args", *ros]


def emulator_command(channel: str, ids: list[int]) -> list[str]:
    return [sys.executable, "-m", "friction_ros.nodes.drive_emulator", "--interface", "friction_local",
            "--channel", channel, "--node-id", *map(str, ids), "--preset", "abb_m19s",
            "--status-period", "3600"]  # fmt: skip


def log_lines(text: str) -> list[tuple[str, float, str]]:
    """(level, wall time, message) of every drive_interface log line."""
    return [(m[1], float(m[2]), m[3]) for m in map(LOG_LINE.search, text.splitlines()) if m]


class Drain:
    """Collect a child's combined output on a thread (a full pipe would block it)."""

    def __init__(self, proc: subprocess.Popen):
        self.text: list[str] = []
        self._t = threading.Thread(target=lambda: self.text.extend(proc.stdout), daemon=True)
        self._t.start()

    def join(self) -> str:
        self._t.join(5)
        return "".join(self.text)


def soak(duration: float, load: int = 2, joints: dict[str, int] | None = None, kill: bool = True,
         node_params: list[str] = ()) -> dict:  # fmt: skip
    """Run one soak; return its figures (see the module docstring)."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState

    from friction_ros.nodes.qos import COMMAND_QOS, STATE_QOS

    names = list(joints) if joints else ["joint"]
    ids = list(joints.values()) if joints else [0]
    channel = f"soak{uuid.uuid4().hex[:6]}"
    tmp = tempfile.TemporaryDirectory(prefix="drive_soak_")
    env = {**os.environ, "FRICTION_CAN_DIR": tmp.name}
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(load)]
    emu = subprocess.Popen(emulator_command(channel, ids), env=env, stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True)  # fmt: skip
    out_emu = Drain(emu)
    deadline = time.time() + 60
    while not out_emu.text and emu.poll() is None and time.time() < deadline:
        time.sleep(0.05)  # the drive is up (first status line) before the node starts
    node = subprocess.Popen(node_command(channel, joints, node_params), env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)  # fmt: skip
    out_node = Drain(node)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    ros = rclpy.create_node(f"drive_soak_{os.getpid()}", context=ctx)
    pub = ros.create_publisher(JointState, "joint_commands", COMMAND_QOS)
    n_states = [0]
    diags: list[tuple[float, dict[str, str]]] = []
    target = 0.2

    def on_state(msg: JointState):
        n_states[0] += 1
        u = [30.0 * (target - q) - 0.3 * v for q, v in zip(msg.position, msg.velocity)]
        pub.publish(JointState(name=list(msg.name), effort=u))

    def on_diag(msg: DiagnosticArray):
        for st in msg.status:
            if st.name.endswith("drive_interface"):
                diags.append((time.time(), {kv.key: kv.value for kv in st.values}))

    ros.create_subscription(JointState, "joint_states", on_state, STATE_QOS)
    ros.create_subscription(DiagnosticArray, "diagnostics", on_diag, STATE_QOS)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(ros)
    res: dict = {"config": "arm" if joints else "single", "drives": len(names), "load_processes": load}
    try:
        deadline = time.time() + 60
        while n_states[0] < 100 and time.time() < deadline and node.poll() is None:
            ex.spin_once(timeout_sec=0.05)
        if n_states[0] < 100:
            raise RuntimeError(f"no joint_states from drive_interface:\n{out_node.join()}")
        end = time.time() + 1.5  # past the first diagnostics period
        while time.time() < end:
            ex.spin_once(timeout_sec=0.05)
        t_start, n0, d0 = time.time(), n_states[0], len(diags)
        first = diags[-1][1] if diags else {}
        while time.time() < t_start + duration and node.poll() is None:
            ex.spin_once(timeout_sec=0.05)
        t_end, n_end = time.time(), n_states[0]
        soak_diags = diags[d0:]
        t_kill = math.nan
        if kill:
            t_kill = time.time()
            emu.send_signal(signal.SIGKILL)
            end = time.time() + 3.0
            while time.time() < end:
                ex.spin_once(timeout_sec=0.05)
    finally:
        ros.destroy_node()
        rclpy.shutdown(context=ctx)
        for b in busy:
            b.kill()
        for p in (node, emu):
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
                try:
                    p.wait(15)
                except subprocess.TimeoutExpired:
                    p.kill()
        text = out_node.join()
        out_emu.join()
        tmp.cleanup()
    lines = log_lines(text)
    res["node_exit"] = node.returncode
    res["node_log"] = text
    prefix = (lambda j: f"{j}.") if joints else (lambda j: "")
    last = soak_diags[-1][1] if soak_diags else {}
    per_drive = []
    for j in names:
        k = prefix(j)
        ages = sorted(float(d[k + "telemetry_age_max_ms"]) for _, d in soak_diags)
        stale_lines = [
            (t, m)
            for lvl, t, m in lines
            if f"drive '{j}'" in m and "telemetry_stale:" in m and t_start <= t <= t_end
        ]
        per_drive.append({
            "joint": j,
            "stale_faults": int(last.get(k + "stale_faults", -1)) - int(first.get(k + "stale_faults", 0)),
            "stale_log_lines": len(stale_lines),
            "timeout_ms": float(last.get(k + "telemetry_timeout_ms", math.nan)),
            "telemetry_age_max_ms": float(last.get(k + "telemetry_age_max_total_ms", math.nan)),
            "telemetry_age_p99_of_1s_max_ms": ages[int(0.99 * (len(ages) - 1))] if ages else math.nan,
            "watchdog_trips": int(last.get(k + "watchdog_trips", -1)),
            "late_periods": int(last.get(k + "telemetry_late_periods", -1))
            - int(first.get(k + "telemetry_late_periods", 0)),
            "enabled_at_end_of_soak": last.get(k + "enabled") == "True",
        })  # fmt: skip
    res["per_drive"] = per_drive
    res["duration_s"] = t_end - t_start
    res["joint_states_hz"] = (n_end - n0) / (t_end - t_start)
    res["loop_overruns"] = int(last.get("loop_overruns", -1))
    if kill:
        after = [(t, m) for lvl, t, m in lines if t >= t_kill and "telemetry_stale:" in m]
        res["kill_fault_lines"] = len(after)
        res["kill_to_fault_log_ms"] = (min(t for t, _ in after) - t_kill) * 1e3 if after else math.nan
        res["kill_disabled"] = len(after) == len(names) and all("drive disabled" in m for _, m in after)
    return res


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=300.0, help="soak length per config [s]")
    ap.add_argument("--load", type=int, default=2, help="busy-loop processes")
    ap.add_argument("--configs", default="single,arm", help="single, arm or both (comma separated)")
    a = ap.parse_args()
    runs = []
    for cfg in a.configs.split(","):
        r = soak(a.duration, a.load, ARM if cfg == "arm" else None)
        r.pop("node_log")
        runs.append(r)
    rows = [
        [r["config"], d["joint"], f"{r['duration_s']:.0f}", r["load_processes"], d["stale_faults"],
         d["stale_log_lines"], d["timeout_ms"], d["telemetry_age_max_ms"], d["telemetry_age_p99_of_1s_max_ms"],
         d["watchdog_trips"], d["late_periods"], f"{100 * d['late_periods'] / (1000 * r['duration_s']):.2f}",
         f"{r['joint_states_hz']:.0f}"]
        for r in runs for d in r["per_drive"]
    ]  # fmt: skip
    _common.print_table(
        "Healthy drive_emulator process, drive_interface at the README settings, busy loops on both cores",
        ["config", "joint", "s", "busy", "stale faults", "stale log lines", "timeout ms", "max age ms",
         "p99 of 1 s max ms", "watchdog trips", "late periods", "late %", "joint_states Hz"],
        rows,
    )  # fmt: skip
    _common.print_table(
        "Emulator killed (SIGKILL) at the end of the soak",
        ["config", "fault lines", "kill -> logged fault ms", "drives disabled"],
        [[r["config"], r["kill_fault_lines"], r["kill_to_fault_log_ms"], r["kill_disabled"]] for r in runs],
    )
    _common.write_results("drive_soak", {"runs": runs})


if __name__ == "__main__":
    main()
