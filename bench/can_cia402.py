"""CiA 402 over CANopen benchmark: PDO codec cost (struct vs canopen's PDO machinery), driver CPU per
axis and missed SYNC periods at 1 kHz with 1 and 3 drives.

    .venv/bin/python bench/can_cia402.py [--duration 5]

Set-up: the driver (Cia402Network with one Cia402Master per drive: RPDO1 out per drive, one SYNC,
TPDO1 + TPDO2 in per drive, heartbeat consumer) runs in this process on the ``friction_local`` bus
(one syscall per frame, as on SocketCAN); the emulated drives (canopen LocalNode + the abb_m19s
plant each) run in a child process, where a drive is on a robot. The driver loop sleeps to 1 kHz
deadlines in one thread; a period whose deadline has already passed when the previous one ends is
skipped (no SYNC for it), like a late timer. ``missed SYNC`` = expected periods - SYNCs sent.

Driver CPU = CPU time of the driver thread (``time.thread_time``; the process has no other busy
thread) / wall time; per axis = / drives. The floor row is the same loop doing nothing: the cost of
waking up 1000 times a second on this machine, and the periods it misses by itself (timer floor).
``TPDO1 / SYNC`` = TPDO1 frames received per drive and SYNC (1.0: every period answered).
Shared 2-core machine: other processes' load shows up as missed periods, rerun when it matters.
"""

from __future__ import annotations

import argparse
import importlib.util
import multiprocessing as mp
import os
import sys
import tempfile
import time
import timeit
from pathlib import Path

_BENCH = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _BENCH]  # python-can is "can"
_spec = importlib.util.spec_from_file_location("_bench_common", _BENCH / "_common.py")
_common = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_common)
print_table, write_results = _common.print_table, _common.write_results

PERIOD = 1e-3


def codec_costs(n: int = 20_000) -> list[list]:
    """Per-call cost [us] of the per-period PDO work, struct vs canopen's PdoMap."""
    import canopen

    from friction_ros.core.can.cia402 import frames as fr
    from friction_ros.core.can.cia402.emulator import DEFAULT_EDS
    from friction_ros.core.can.cia402.units import Cia402Scaling

    node = canopen.Network().add_node(1, DEFAULT_EDS)
    rpdo, tpdo1, tpdo2 = node.rpdo[1], node.tpdo[1], node.tpdo[2]
    for p in (rpdo, tpdo1, tpdo2):
        p.read(from_od=True)
    cw, tq = rpdo["Controlword"], rpdo["Target torque"]
    d1, d2 = bytearray(fr.TPDO1.pack(0x237, -250, 123456)), bytearray(fr.TPDO2.pack(-4000, 99))
    sc = Cia402Scaling()
    pack, up1, up2 = fr.RPDO1.pack, fr.TPDO1.unpack_from, fr.TPDO2.unpack_from

    def canopen_encode():
        cw.raw = 0x0F
        tq.raw = -1234
        return bytes(rpdo.data)

    def canopen_decode():
        tpdo1.on_message(tpdo1.cob_id, d1, 0.0)
        tpdo2.on_message(tpdo2.cob_id, d2, 0.0)
        sw, t, p = (v.raw for v in tpdo1)
        v, c = (v.raw for v in tpdo2)
        return sw, sc.joint_torque(t), sc.joint_position(p), sc.joint_velocity(v), sc.current(c)

    def struct_decode():
        sw, t, p = up1(d1)
        v, c = up2(d2)
        return sw, sc.joint_torque(t), sc.joint_position(p), sc.joint_velocity(v), sc.current(c)

    cases = [
        ("RPDO1 encode (controlword + target torque)", lambda: pack(0x0F, -1234), canopen_encode),
        ("TPDO1 + TPDO2 decode to SI", struct_decode, canopen_decode),
    ]
    rows = []
    for name, fast, generic in cases:
        assert (fast() == generic()) if name.startswith("RPDO") else True
        a = min(timeit.repeat(fast, number=n, repeat=3)) / n * 1e6
        b = min(timeit.repeat(generic, number=n, repeat=3)) / n * 1e6
        rows.append([name, a, b, b / a])
    return rows


def master_period_cost(n: int = 20_000) -> float:
    """One axis's full per-period work without the bus [us]: frames() + handle(TPDO1) + handle(TPDO2)."""
    from friction_ros.core.can.cia402 import Cia402Config, Cia402Master
    from friction_ros.core.can.cia402 import frames as fr
    from friction_ros.core.can.cia402.state_machine import State

    m = Cia402Master(
        Cia402Config(node_id=1, counts_per_rev=4096, gear_ratio=50, rated_torque=1.0, rated_current=5.0)
    )
    m.start(0.0)
    m._resolve_units({})
    m.phase, m.target = "operational", State.OPERATION_ENABLED
    d1, d2 = fr.TPDO1.pack(0x237, 10, 1000), fr.TPDO2.pack(100, 5)
    t = [0.0]

    def period():
        t[0] += 1e-6
        m.set_torque(1.0)
        m.frames(t[0])
        m.handle(0x181, d1, t[0])
        m.handle(0x281, d2, t[0])
        m.handle(0x701, b"\x05", t[0])

    return min(timeit.repeat(period, number=n, repeat=3)) / n * 1e6


def _drives(channel, directory, node_ids, ready, stop):  # child process
    os.environ["FRICTION_CAN_DIR"] = directory
    from friction_ros.can_bus.local_bus import LocalBus
    from friction_ros.core.can.cia402.emulator import emulated_drives

    net, drives = emulated_drives(LocalBus(channel), node_ids)
    for d in drives:  # compile / load the plant kernels before the clock starts
        for _ in range(2000):
            d.plant.step(0.0, d.dt)
    ready.set()
    c0 = time.process_time()
    stop.wait()
    print(f"  (drives' process CPU {100 * (time.process_time() - c0) / max(stop_time(), 1e-9):.0f} %)")
    net.disconnect()


def stop_time() -> float:
    return float(os.environ.get("CIA402_BENCH_DURATION", "1"))


def loop(step, duration: float) -> tuple[int, float, float]:
    """Sleep to 1 kHz deadlines calling ``step``; returns (periods run, thread CPU, wall)."""
    nxt = t0 = time.monotonic()
    c0, end, ran = time.thread_time(), t0 + duration, 0
    while nxt < end:
        step()
        ran += 1
        nxt += PERIOD
        now = time.monotonic()
        if nxt > now:
            time.sleep(nxt - now)
        else:
            nxt += (now - nxt) // PERIOD * PERIOD  # skip the periods already over
    return ran, time.thread_time() - c0, time.monotonic() - t0


def run_drives(n_drives: int, duration: float) -> dict:
    from friction_ros.can_bus.local_bus import LocalBus
    from friction_ros.core.can.cia402 import Cia402Config, Cia402Master, Cia402Network

    directory = tempfile.mkdtemp(prefix="cia402_bench_")
    os.environ["FRICTION_CAN_DIR"] = directory
    os.environ["CIA402_BENCH_DURATION"] = str(duration)
    ctx = mp.get_context("spawn")
    ready, stop = ctx.Event(), ctx.Event()
    ids = list(range(1, n_drives + 1))
    child = ctx.Process(target=_drives, args=("cia402", directory, ids, ready, stop))
    child.start()
    ready.wait(60)
    masters = [Cia402Master(Cia402Config(node_id=k)) for k in ids]
    net = Cia402Network(LocalBus("cia402"), masters, PERIOD)
    net.start()
    ok = net.run_until(lambda: all(m.phase == "operational" for m in masters), 5.0)
    for m in masters:
        m.enable(time.monotonic())
    ok = ok and net.run_until(lambda: all(m.enabled for m in masters), 5.0)
    for k, m in enumerate(masters):
        m.set_torque(0.5 * (-1) ** k)
    net.run_until(lambda: False, 0.5)  # settle
    s0, r0 = net.sync.count, [m.tpdo1_count for m in masters]
    ran, cpu, wall = loop(net.step, duration)
    syncs = net.sync.count - s0
    tpdo = min(m.tpdo1_count - r for m, r in zip(masters, r0))
    faults = [m.fault for m in masters if m.fault]
    net.close()
    stop.set()
    child.join(10)
    net.bus.shutdown()
    return {
        "drives": n_drives,
        "enabled": ok and not faults,
        "faults": faults,
        "cpu_percent": 100 * cpu / wall,
        "cpu_per_axis_percent": 100 * cpu / wall / n_drives,
        "cpu_us_per_period": cpu / max(ran, 1) * 1e6,
        "expected_periods": round(wall / PERIOD),
        "syncs": syncs,
        "missed_sync": round(wall / PERIOD) - syncs,
        "tpdo1_per_sync": tpdo / max(syncs, 1),
        "frames_dropped_by_bus": net.bus.frames_dropped,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=5.0, help="seconds per row (> 0)")
    a = ap.parse_args()
    if not a.duration > 0:
        print(f"--duration = {a.duration:g} is out of range: must be > 0 [s]", file=sys.stderr)
        sys.exit(2)
    codec = codec_costs()
    print_table(
        "PDO work per call [us]: pre-built struct vs canopen's PdoMap",
        ["operation", "struct", "canopen PdoMap", "speed-up"],
        codec,
    )
    per_axis_us = master_period_cost()
    ran, cpu, wall = loop(lambda: None, a.duration)
    floor = {
        "cpu_percent": 100 * cpu / wall,
        "cpu_us_per_period": cpu / ran * 1e6,
        "missed": round(wall / PERIOD) - ran,
        "expected": round(wall / PERIOD),
    }
    runs = [run_drives(n, a.duration) for n in (1, 3)]
    rows = [
        [
            "timer floor (empty 1 kHz loop)",
            0,
            floor["cpu_percent"],
            floor["cpu_us_per_period"],
            "-",
            f"{floor['missed']} / {floor['expected']}",
            "-",
        ]
    ]
    rows += [
        [
            f"CiA 402, {r['drives']} drive(s)" + ("" if r["enabled"] else " (FAULT)"),
            r["drives"],
            r["cpu_percent"],
            r["cpu_us_per_period"],
            r["cpu_per_axis_percent"],
            f"{r['missed_sync']} / {r['expected_periods']}",
            r["tpdo1_per_sync"],
        ]
        for r in runs
    ]
    print_table(
        f"Driver at 1 kHz on friction_local, drives in another process ({a.duration:g} s per row; "
        f"master work per axis and period without the bus: {per_axis_us:.1f} us)",
        [
            "row",
            "drives",
            "driver CPU %",
            "CPU us / period",
            "CPU per axis %",
            "missed SYNC / periods",
            "TPDO1 / SYNC",
        ],
        rows,
    )
    write_results(
        "can_cia402",
        {
            "codec_us": {r[0]: {"struct": r[1], "canopen": r[2]} for r in codec},
            "master_period_us_per_axis": per_axis_us,
            "timer_floor": floor,
            "runs": runs,
            "load_average_1min_after": os.getloadavg()[0],
        },
        command=f".venv/bin/python bench/can_cia402.py --duration {a.duration:g}",
    )


if __name__ == "__main__":
    main()
