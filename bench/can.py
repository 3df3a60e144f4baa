"""CAN drive interface benchmark: codec cost per frame, node CPU at 1 kHz, highest sustainable rate.

    .venv/bin/python bench/can.py [--duration 8] [--rates 1000,2000,2500,2600,3000]

Set-up: a child process runs drive_interface (the real ``main()``) and the drive emulator (own
thread) on a python-can ``virtual`` bus; the parent is the controller (one joint_commands message
per received joint_states, over DDS). 3 frames per cycle per axis = Set_Input_Torque out +
Get_Encoder_Estimates + Get_Iq in (+ a 10 Hz heartbeat). A 1 Mbit/s bus carries about 8,000 8-byte
standard frames/s (~125 bit each with stuffing), i.e. at most ~2,660 such cycles/s.

Node CPU = CPU time (user + system, from /proc/self/task/*/stat) of every thread of the child
process except the emulator's thread, over the measurement window (it starts ``WARM_UP_S`` after
every drive is enabled and the loop runs, so no start-up work is in it), divided by wall time. So
it includes the executor/control thread, the middleware's (Fast DDS) threads and any python-can
thread, and also the node's side of the virtual bus: its ``send`` (python-can deep-copies
every frame into each receiver's queue, in the sender's thread; SocketCAN would spend a syscall there
instead) and its ``recv`` calls. The emulator's own sends are charged to the emulator thread. Not
counted: the parent (controller) process. The emulator shares the GIL with the node, which can only
delay the node (timing), not add to its CPU time. A run whose drive faulted (disabled) during the
window is marked, because a disabled drive sends fewer frames and would understate the cost.

Two more rows at 1 kHz put the emulator where a drive is on a robot, outside the node's process:
the ``drive_emulator`` program in a process of its own, on the ``friction_local`` bus (Unix datagram
sockets carrying SocketCAN's ``struct can_frame``: one syscall per frame, as on SocketCAN); node
CPU is then every thread of the node's process. Once with default scheduling, once with the node
on CPU 1 (its ``cpu_affinity`` parameter) and the emulator and the controller on CPU 0.

A platform probe first measures what a wake-up costs on this machine without ROS or CAN (pipe round
trip between two processes, idle 1 kHz Python loop): every 1 kHz node pays it several times a
period (timer, DDS notifications, frames), and under nested virtualisation it is many times the
bare-metal figure.

Sustained rate: cycles/s >= 98 % of the requested rate, overruns <= 1 % of the cycles, the drive
enabled without a fault trip for the whole window, and 3 frames x rate within the 1 Mbit/s bus.
The first row runs ``loop_spin`` = 200 us (busy-wait before each deadline, on a loop thread of its
own) for comparison, with the emulator in its own process (an emulator thread in the node's
process starves behind the spinning thread's GIL and its telemetry goes stale); the other rows use
the node's default (no spin, control period in the executor thread). The last two rows run 2 and 3
drives in one node (``joints``; one emulator process with ``--node-id 1 2 3``), CPU per axis =
node CPU / drives. Shared machine: other processes' load shows up as overruns, rerun when it matters.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import threading
import time
import timeit
import uuid
from pathlib import Path

# This file is named like python-can's package: take the bench folder off sys.path before any
# "import can", and load the shared helpers by path.
_BENCH = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _BENCH]
_spec = importlib.util.spec_from_file_location("_bench_common", _BENCH / "_common.py")
_common = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_common)
print_table, write_results = _common.print_table, _common.write_results

BUS_LIMIT_FPS = 8000.0


def codec_costs() -> list[list]:
    from friction_ros.core.can import mit as mitc
    from friction_ros.core.can import odrive as od

    enc = od.encode_encoder_estimates(1, 1.0, 2.0)
    iq = od.encode_iq(1, 1.0, 2.0)
    dec = od.OdriveDecoder([1])
    codec = mitc.MitCodec(1)
    mdec = mitc.MitDecoder(codec)
    reply = codec.encode_reply(0.1, 0.2, 0.3)
    import can

    cases = {
        "odrive encode Set_Input_Torque": lambda: od.encode_set_input_torque(1, 0.5),
        "odrive encode Get_Encoder_Estimates": lambda: od.encode_encoder_estimates(1, 1.0, 2.0),
        "odrive decode Get_Encoder_Estimates": lambda: dec.decode(enc.arbitration_id, enc.data),
        "odrive decode Get_Iq": lambda: dec.decode(iq.arbitration_id, iq.data),
        "odrive decode foreign id (ignored)": lambda: dec.decode(0x049, enc.data),
        "mit encode command": lambda: codec.encode_command(0.1, 0.2, 10.0, 1.0, 0.5),
        "mit decode reply": lambda: mdec.decode(0, reply.data),
        "python-can Message() (for reference)": lambda: can.Message(arbitration_id=0x2E, data=enc.data),
    }
    rows = []
    for name, fn in cases.items():
        n = 50_000
        t = min(timeit.repeat(fn, number=n, repeat=3)) / n
        rows.append([name, t * 1e6])
    return rows


# ---- child: the node (+ the emulator, on the virtual bus) --------------------------------------------
PROTOCOL = os.environ.get("FRICTION_BENCH_PROTOCOL", "odrive_cansimple")  # bench/can_protocols.py sets it
#: seconds of running drives before the measurement window (after they are enabled and cycling)
WARM_UP_S = float(os.environ.get("FRICTION_BENCH_WARM_UP", "1.0"))


def child(
    rate: float,
    duration: float,
    out: str,
    spin: float,
    bus: str = "virtual",
    pin: bool = False,
    axes: int = 1,
) -> None:
    """Run drive_interface's real ``main()`` in this process and measure it.

    ``bus = "virtual"``: the emulator runs on a thread of this process (python-can's virtual bus
    does not cross processes). ``bus = "friction_local"``: the emulator is the ``drive_emulator``
    program in a process of its own, on the Unix-socket bus (friction_ros.can_bus.local_bus), as a
    drive is on a robot; nothing but the node runs in this process. ``pin``: the node on CPU 1
    (its ``cpu_affinity`` parameter), the emulator process (and the parent controller) on CPU 0.
    """
    import signal

    from friction_ros.nodes import drive_interface

    channel = f"b{uuid.uuid4().hex[:6]}"
    emu = emu_proc = None
    if bus == "virtual":
        import can

        from friction_ros.core.can.emulator import DriveEmulator, EmulatorConfig, plant_from_preset

        plant, conv = plant_from_preset("abb_m19s")
        emu = DriveEmulator(
            can.Bus(interface="virtual", channel=channel),
            plant,
            EmulatorConfig(
                node_id=1, conversion=conv, encoder_rate_hz=rate, iq_rate_hz=rate, physics_rate_hz=rate
            ),
        )
        emu.start()
    else:
        emu_proc = subprocess.Popen(
            (["taskset", "-c", "0"] if pin else []) + [sys.executable, "-m", "friction_ros.nodes.drive_emulator", "--interface", bus, "--channel", channel, "--protocol", PROTOCOL,
             "--node-id", *[str(i + 1) for i in range(axes)], "--preset", "abb_m19s", "--physics-rate", str(rate), "--encoder-rate", str(rate),
             "--iq-rate", str(rate), "--status-period", "60"],
            stdout=subprocess.DEVNULL,
        )  # fmt: skip
        time.sleep(1.0)  # the emulator's socket exists before the node's first request
    holder: dict = {}
    orig = drive_interface.DriveInterface.__init__

    def init(self, **kw):
        orig(self, **kw)
        holder["node"] = self

    drive_interface.DriveInterface.__init__ = init

    def task_cpu() -> dict[int, float]:
        tick = os.sysconf("SC_CLK_TCK")
        res = {}
        for tid in os.listdir("/proc/self/task"):
            with open(f"/proc/self/task/{tid}/stat") as fh:
                f = fh.read().rsplit(")", 1)[1].split()
            res[int(tid)] = (int(f[11]) + int(f[12])) / tick
        return res

    def proc_cpu(pid: int) -> float:
        with open(f"/proc/{pid}/stat") as fh:
            f = fh.read().rsplit(")", 1)[1].split()
        return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")

    def measure():
        # warm-up: until every drive is enabled and the loop runs (imports, discovery, the drive's
        # start-up: CiA 402's SDO configuration and state machine), then WARM_UP_S more
        end = time.monotonic() + 60.0
        while time.monotonic() < end:
            node = holder.get("node")
            loop = getattr(node, "loop", None)
            if loop is not None and loop.stats.cycles > 0 and all(a.enabled for a in node.axes):
                break
            time.sleep(0.05)
        time.sleep(WARM_UP_S)
        node = holder["node"]
        c0, t0 = task_cpu(), time.monotonic()
        e0 = proc_cpu(emu_proc.pid) if emu_proc else 0.0

        def total(attr: str) -> int:
            return sum(getattr(a.counters, attr) for a in node.axes)

        cyc0, rx0, tx0 = node.loop.stats.cycles, total("frames_rx"), total("frames_tx")
        ov0, cmd0 = node.loop.stats.overruns, total("commands")
        trips0, en0 = total("fault_trips"), all(a.enabled for a in node.axes)
        time.sleep(duration)
        c1, t1 = task_cpu(), time.monotonic()
        dt = t1 - t0
        emu_tid = emu._thread.native_id if emu else None
        cpu = {tid: (c1.get(tid, 0) - c0.get(tid, 0)) / dt for tid in c1}
        names = {t.native_id: t.name for t in threading.enumerate()}
        proc_total = sum(cpu.values())
        emu_cpu = cpu.get(emu_tid, 0.0) if emu else (proc_cpu(emu_proc.pid) - e0) / dt
        result = {
            "rate_hz": rate,
            "bus": bus,
            "pinned": pin,
            "window_s": dt,
            "axes": len(node.axes),
            "process_cpu": proc_total,
            "emulator_cpu": emu_cpu,
            "node_cpu": proc_total - (cpu.get(emu_tid, 0.0) if emu else 0.0),
            "threads": {names.get(t, str(t)): v for t, v in cpu.items() if v > 0.005},
            "cycle_rate_hz": (node.loop.stats.cycles - cyc0) / dt,
            "overruns": node.loop.stats.overruns - ov0,
            "rx_fps": (total("frames_rx") - rx0) / dt,
            "tx_fps": (total("frames_tx") - tx0) / dt,
            "command_rate_hz": (total("commands") - cmd0) / dt / len(node.axes),
            "enabled": all(a.enabled for a in node.axes),
            "enabled_throughout": en0
            and all(a.enabled for a in node.axes)
            and total("fault_trips") == trips0,
            "fault_reason": "; ".join(a.fault_reason for a in node.axes if a.fault_reason),
            "max_lateness_ms": node.loop.stats.max_lateness * 1e3,
            "loop_spin_s": node.v["loop_spin"],
        }
        Path(out).write_text(json.dumps(result))
        os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=measure, daemon=True).start()
    joints = ["-p", "node_id:=1", "-p", "joint_name:=j1"]
    if axes > 1:
        joints = ["-p", f"joints:=[{', '.join(f'j{i + 1}' for i in range(axes))}]"]
        joints += [x for i in range(axes) for x in ("-p", f"j{i + 1}.node_id:={i + 1}")]
    ros = ["-p", f"interface:={bus}", "-p", f"channel:={channel}", "-p", f"protocol:={PROTOCOL}", *joints,
           "-p", "enable_on_start:=true", "-p", f"control_period:={1.0 / rate!r}", "-p", "torque_constant:=0.49",
           "-p", "telemetry_timeout:=0.05", "-p", "command_timeout:=0.2", "-p", f"loop_spin:={spin}",
           "-p", f"cpu_affinity:={1 if pin else -1}"]  # fmt: skip
    try:
        drive_interface.main(["drive_interface", "--ros-args", *ros])
    finally:
        if emu:
            emu.stop()
        if emu_proc:
            emu_proc.send_signal(signal.SIGINT)
            emu_proc.wait(10)


def run_rate(
    rate: float, duration: float, spin: float, bus: str = "virtual", pin: bool = False, axes: int = 1
) -> dict:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState

    from friction_ros.nodes.qos import COMMAND_QOS, STATE_QOS

    out = f"/tmp/can_bench_{uuid.uuid4().hex[:6]}.json"
    args = [
        sys.executable,
        __file__,
        "--child",
        str(rate),
        str(duration),
        out,
        str(spin),
        bus,
        str(int(pin)),
        str(axes),
    ]
    if pin:
        os.sched_setaffinity(0, {0})  # this controller on CPU 0 with the emulator, the node on CPU 1
    proc = subprocess.Popen(args)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("can_bench_controller", context=ctx)
    pub = node.create_publisher(JointState, "joint_commands", COMMAND_QOS)

    def on_state(msg):  # a PD holding 0 rad: one command (all joints) per received joint state
        pub.publish(
            JointState(
                name=msg.name, effort=[-5.0 * q - 0.1 * dq for q, dq in zip(msg.position, msg.velocity)]
            )
        )

    node.create_subscription(JointState, "joint_states", on_state, STATE_QOS)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    while proc.poll() is None:
        ex.spin_once(timeout_sec=0.05)
    node.destroy_node()
    rclpy.shutdown(context=ctx)
    os.sched_setaffinity(0, range(os.cpu_count() or 1))
    res = json.loads(Path(out).read_text())
    os.unlink(out)
    return res


def sustained(r: dict) -> bool:
    """The node kept the requested rate (see the module docstring for the criteria)."""
    return (
        r["cycle_rate_hz"] >= 0.98 * r["rate_hz"]
        and r["overruns"] <= 0.01 * r["cycle_rate_hz"] * max(r.get("window_s", 1.0), 1.0)
        and r["enabled_throughout"]
        and 3 * r.get("axes", 1) * r["rate_hz"] <= BUS_LIMIT_FPS
    )


def node_work_per_cycle(n: int = 20_000) -> float:
    """The node's own computation in one 1 kHz cycle, hot, no I/O [us]: two telemetry frames
    decoded into the axis, one raw joint_commands message decoded and applied, the axis cycle
    (safety checks, torque command frame), the python-can Message built, JointState serialised."""
    import can
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from friction_ros.core.can import odrive as od
    from friction_ros.core.can.axis import DriveAxis
    from friction_ros.core.can.axis_config import axis_config
    from friction_ros.core.config import flatten
    from friction_ros.core.wire import JointStateDecoder
    from friction_ros.nodes.drive_interface import parameter_schema
    from friction_ros.nodes.drive_state_publishers import StatePackets

    v = flatten(parameter_schema().defaults())
    v.update(node_id=1, enable_on_start=True, torque_constant=0.49)
    axis = DriveAxis(axis_config(v, 1.0 / v["control_period"]))
    axis.request_enable()
    packets, decoder = StatePackets("j1", "odrive_cansimple"), JointStateDecoder()
    raw = serialize_message(JointState(name=["j1"], effort=[0.1]))
    enc, iq = od.encode_encoder_estimates(1, 1.0, 2.0), od.encode_iq(1, 1.0, 2.0)
    clock = [time.monotonic()]
    frames_out = [0]

    def one():
        clock[0] += 0.001
        now = clock[0]
        axis.on_frame(enc.arbitration_id, enc.data, False, False, False, now)
        axis.on_frame(iq.arbitration_id, iq.data, False, False, False, now)
        axis.set_command(decoder.decode(raw).effort[0], now)
        r = axis.cycle(now)
        for f in r.frames:
            can.Message(
                arbitration_id=f.arbitration_id, data=f.data, is_extended_id=f.is_extended,
                is_remote_frame=f.is_remote, dlc=f.length,
            )  # fmt: skip
            frames_out[0] += 1
        if r.sample is not None:
            packets.set_joint(1, 2, r.sample.position, r.sample.velocity, r.sample.effort)

    one()
    assert axis.enabled and frames_out[0] >= 1, "axis not running: the measurement would be empty"
    return min(timeit.repeat(one, number=n, repeat=3)) / n * 1e6


def platform_probe(n: int = 5000) -> dict:
    """What a wake-up costs on this machine, without ROS or CAN.

    * ``pipe_round_trip_us``: two processes on different CPUs bounce one byte through two pipes
      (each side sleeps in ``read`` until the other writes): wall time per round trip, and CPU time
      of one side per round trip (2 syscalls + 1 sleep/wake-up). Bare-metal Linux takes a few
      microseconds for this; nested virtualisation makes every wake-up and context switch trap.
    * ``idle_loop_1khz_cpu_percent``: CPU use of a Python thread that only sleeps to 1 kHz
      deadlines (the floor under any 1 kHz loop node).
    """
    r1, w1 = os.pipe()
    r2, w2 = os.pipe()
    ncpu = os.cpu_count() or 1
    pid = os.fork()
    if pid == 0:  # pragma: no cover - child
        os.sched_setaffinity(0, {ncpu - 1})
        for _ in range(n):
            os.read(r1, 1)
            os.write(w2, b"x")
        os._exit(0)
    old = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {0})
    t, c = time.perf_counter(), time.process_time()
    for _ in range(n):
        os.write(w1, b"x")
        os.read(r2, 1)
    wall, cpu = (time.perf_counter() - t) / n, (time.process_time() - c) / n
    os.waitpid(pid, 0)
    for fd in (r1, w1, r2, w2):
        os.close(fd)
    nxt = time.monotonic()
    c0, end = time.thread_time(), nxt + 3.0
    while nxt < end:
        nxt += 0.001
        d = nxt - time.monotonic()
        if d > 0:
            time.sleep(d)
    idle = (time.thread_time() - c0) / 3.0
    os.sched_setaffinity(0, old)
    return {
        "pipe_round_trip_us": wall * 1e6,
        "pipe_round_trip_cpu_us": cpu * 1e6,
        "idle_loop_1khz_cpu_percent": idle * 100,
    }


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(
            float(sys.argv[2]),
            float(sys.argv[3]),
            sys.argv[4],
            float(sys.argv[5]),
            sys.argv[6],
            sys.argv[7] == "1",
            int(sys.argv[8]),
        )
        return
    import argparse

    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=8.0)
    ap.add_argument("--rates", default="1000,2000,2500,2600,3000")
    a = ap.parse_args()
    os.environ.setdefault("ROS_DOMAIN_ID", str(os.getpid() % 100 + 1))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

    codec = codec_costs()
    print_table("codec cost per frame", ["operation", "us/frame"], codec)
    platform = platform_probe()
    platform["node_python_work_us_per_cycle"] = node_work_per_cycle()
    print_table(
        "this machine: cost of a wake-up (no ROS, no CAN), and the node's own work per cycle",
        ["probe", "value"],
        [[k.replace("_", " "), v] for k, v in platform.items()],
    )
    runs = [run_rate(1000.0, a.duration, 0.0002, "friction_local")]  # busy-wait spin, for comparison
    runs += [run_rate(float(r), a.duration, 0.0) for r in a.rates.split(",")]
    runs += [run_rate(1000.0, a.duration, 0.0, "friction_local", pin) for pin in (False, True)]
    runs += [run_rate(1000.0, a.duration, 0.0, "friction_local", False, n) for n in (2, 3)]
    rows = []
    for r in runs:
        fps = r["rx_fps"] + r["tx_fps"]
        r["sustained"] = sustained(r)
        where = "thread" if r["bus"] == "virtual" else "process"
        n = r.get("axes", 1)
        rows.append([
            r["bus"], "yes" if r["pinned"] else "no", where, n, f"{r['rate_hz']:.0f}", f"{r['loop_spin_s'] * 1e6:.0f}",
            r["cycle_rate_hz"], r["overruns"], r["command_rate_hz"], fps, 100 * fps / BUS_LIMIT_FPS,
            100 * r["node_cpu"], 100 * r["node_cpu"] / n, 100 * r["emulator_cpu"],
            "yes" if r["enabled_throughout"] else "FAULT", "yes" if r["sustained"] else "no",
        ])  # fmt: skip
    print_table(
        "drive_interface at 1 kHz..3 kHz, 3 frames/cycle per axis (cmds/s: per axis)",
        ["bus", "pinned", "emulator in", "axes", "rate Hz", "spin us", "cycles/s", "overruns", "cmds/s", "frames/s",
         "% of 1 Mbit/s", "node CPU %", "node CPU % per axis", "emulator CPU %", "enabled", "sustained"],
        rows,
    )  # fmt: skip
    for r in runs:
        print(
            f"threads at {r['rate_hz']:.0f} Hz ({r['bus']}{', pinned' if r['pinned'] else ''}, {r.get('axes', 1)} axes): "
            + ", ".join(f"{k} {100 * v:.1f}%" for k, v in r["threads"].items())
            + ("" if r["enabled_throughout"] else f" (drive faulted: {r['fault_reason']})")
        )

    def cpu_at_1k(bus: str, pin: bool, axes: int = 1):
        ok = [
            r["node_cpu"] / axes
            for r in runs
            if r["bus"] == bus and r["pinned"] == pin and r["loop_spin_s"] == 0
            and r["rate_hz"] == 1000.0 and r["enabled_throughout"] and r.get("axes", 1) == axes
        ]  # fmt: skip
        return ok[0] if ok else None

    default = [r for r in runs if r["loop_spin_s"] == 0 and r.get("axes", 1) == 1]
    ok = [r["rate_hz"] for r in default if r["sustained"]]
    summary = {
        "node_cpu_1khz": cpu_at_1k("virtual", False),
        "node_cpu_1khz_separate_process": cpu_at_1k("friction_local", False),
        "node_cpu_1khz_separate_process_pinned": cpu_at_1k("friction_local", True),
        "node_cpu_per_axis_1khz_2_axes": cpu_at_1k("friction_local", False, 2),
        "node_cpu_per_axis_1khz_3_axes": cpu_at_1k("friction_local", False, 3),
        "max_sustained_rate_hz": max(ok) if ok else None,
        "bus_limit_rate_hz": BUS_LIMIT_FPS / 3,
        **{f"platform_{k}": v for k, v in platform.items()},
    }
    for label, key in (
        ("emulator thread, virtual bus", "node_cpu_1khz"),
        ("emulator process, friction_local bus", "node_cpu_1khz_separate_process"),
        ("emulator process, node pinned to CPU 1", "node_cpu_1khz_separate_process_pinned"),
        ("per axis, 2 drives in one node", "node_cpu_per_axis_1khz_2_axes"),
        ("per axis, 3 drives in one node", "node_cpu_per_axis_1khz_3_axes"),
    ):
        v = summary[key]
        print(
            f"node CPU at 1 kHz, {label}: "
            + (f"{100 * v:.1f} % of a core (goal < 25 %)" if v else "no valid run")
        )
    print(
        f"highest sustained rate tested: {summary['max_sustained_rate_hz'] or 0:.0f} Hz "
        f"(1 Mbit/s bus limit ~{summary['bus_limit_rate_hz']:.0f} Hz at 3 frames/cycle)"
    )
    write_results(
        "can",
        {
            "codec_us_per_frame": {n: v for n, v in codec},
            "summary": summary,
            "runs": runs,
            "bus_limit_fps": BUS_LIMIT_FPS,
        },
        command=".venv/bin/python bench/can.py " + " ".join(sys.argv[1:]),
    )


if __name__ == "__main__":
    main()
