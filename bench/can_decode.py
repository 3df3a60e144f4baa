"""drive_interface's per-period CAN work per protocol, in CPU microseconds, independent of machine load.

    .venv/bin/python bench/can_decode.py [--periods 20000] [--protocols odrive_cansimple,mit,cia402]

What one control period of ``drive_interface`` does for its drives, without the bus, ROS or a
clock: every received telemetry frame through ``DriveAxis.on_frame`` (routing, decode, telemetry
gate), ``DriveAxis.set_command`` and ``DriveAxis.cycle`` (supervision, limits, command frames,
CiA 402 SYNC) and the python-can ``Message`` of every frame to send (``CanBusLink``'s, without the
send call itself). The frames come from the frame-level drive emulator (abb_m19s plant, PD tracking
a 0.5 Hz sine) run in lock step once and recorded; an identical second set-up replays them with the
timer running (``time.thread_time``: CPU time of this thread; per chunk of 250 periods the least of
5 replays, as other processes' load only adds to it). The replayed node must send exactly the frames of the recording (checked).

A second replay goes through the node's bus link as well (column "through the bus link"):
``CanBusLink.receive`` (``recv`` of every frame, the receive filters, routing) and
``CanBusLink.send`` (Message, pack, one ``sendto`` per frame) on a ``friction_local`` bus whose other
member puts the recorded frames on the bus and takes the node's outside the timing. The frames per
period on the bus, by kind, are printed too (CiA 402 sends one SYNC per bus and period more).

Not included: ROS publishing and the executor's wake-up. ``bench/can_protocols.py`` measures the
whole node in real time.
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
import time
from pathlib import Path

_BENCH = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _BENCH]  # python-can is "can"
_spec = importlib.util.spec_from_file_location("_bench_common", _BENCH / "_common.py")
_common = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_common)

DT = 1e-3
CHUNK = 250  # periods timed together
REPEAT = 5
KP, KD = 40.0, 1.5


def _setup(protocol: str, n_axes: int):
    """(axes, router, emulators) with every axis enabled, in lock step (no clock)."""
    from friction_ros.core.can.axis import DriveAxis
    from friction_ros.core.can.axis_config import AxisConfig
    from friction_ros.core.can.drive_set import frame_router
    from friction_ros.core.can.emulator import DriveEmulator, EmulatorConfig, plant_from_preset

    axes, emus = [], []
    for node_id in range(1, n_axes + 1):
        plant, conv = plant_from_preset("abb_m19s")
        emus.append(
            DriveEmulator(None, plant, EmulatorConfig(protocol=protocol, node_id=node_id, conversion=conv))
        )
        axes.append(
            DriveAxis(
                AxisConfig(
                    protocol=protocol, node_id=node_id, conversion=conv, telemetry_period=DT,
                    telemetry_timeout=0.05, command_timeout=0.2, torque_limit=4.0, current_limit=20.0,
                    velocity_limit=50.0,
                )
            )
        )  # fmt: skip
    return axes, frame_router(axes), emus


def _exchange(emus, frames, t):
    """The drives take the node's frames at ``t``; returns what the node receives next period."""
    for e in emus:
        for f in frames:
            e.handle(f, t)
    t2 = t + DT
    rx = []
    for e in emus:
        e.advance(t2 + 1e-12)
        rx += e.pop_due(t2 + 1e-12)
    return rx


def _command(k: int, sample) -> float:
    if sample is None:
        return 0.0
    w = 2 * math.pi * 0.5
    return KP * (0.3 * math.sin(w * k * DT) - sample.position) + KD * (
        0.3 * w * math.cos(w * k * DT) - sample.velocity
    )


def _warm_up(axes, route, emus) -> tuple[float, list]:
    """Start-up and enable, in lock step until every axis is enabled and stays so for 0.3 s."""
    t = 0.0
    rx = _exchange(emus, [f for a in axes for f in a.startup_frames()], t)
    for a in axes:
        a.request_enable()
    steady = 0
    for _ in range(20_000):
        t += DT
        for f in rx:
            route(f.arbitration_id, f.data).on_frame(
                f.arbitration_id, f.data, f.is_remote, f.is_extended, False, t
            )
        out = []
        for a in axes:
            out += a.cycle(t).frames
        rx = _exchange(emus, out, t)
        steady = steady + 1 if all(a.enabled and not a.latched for a in axes) else 0
        if steady >= 300:
            return t, rx
    raise RuntimeError(f"{axes[0].cfg.protocol}: the axes did not enable: {[a.fault_reason for a in axes]}")


def record(protocol: str, n_axes: int, periods: int):
    """Lock-step run: per period the frames the node receives, its commands and the frames it sends."""
    axes, route, emus = _setup(protocol, n_axes)
    t, rx = _warm_up(axes, route, emus)
    t0, script = t, []
    samples = [None] * n_axes
    for k in range(periods):
        t += DT
        for f in rx:
            route(f.arbitration_id, f.data).on_frame(
                f.arbitration_id, f.data, f.is_remote, f.is_extended, False, t
            )
        cmds = [_command(k, s) for s in samples]
        out = []
        for i, a in enumerate(axes):
            a.set_command(cmds[i], t)
            r = a.cycle(t)
            samples[i] = r.sample
            out += r.frames
        script.append((rx, cmds, out))
        rx = _exchange(emus, out, t)
    faults = [a.fault_reason for a in axes if a.latched or not a.enabled]
    return t0, script, faults


def replay(protocol: str, n_axes: int, t0: float, script) -> tuple[list[float], bool]:
    """Replay ``script`` into a fresh, identically warmed-up node; (CPU s of each chunk of
    ``CHUNK`` periods, sent the recorded frames)."""
    from friction_ros.nodes.can_bus import FrameMessages

    axes, route, emus = _setup(protocol, n_axes)
    t, _ = _warm_up(axes, route, emus)
    assert t == t0
    message = FrameMessages(reuse=True).message  # CanBusLink.send's (SocketCAN, friction_local)
    sent, chunks = [], []
    clock = time.thread_time
    c0 = clock()
    for k, (rx, cmds, _) in enumerate(script, 1):
        t += DT
        for f in rx:
            arb, data = f.arbitration_id, f.data
            route(arb, data).on_frame(arb, data, f.is_remote, f.is_extended, False, t)
        out = []
        for a, u in zip(axes, cmds):
            a.set_command(u, t)
            out += a.cycle(t).frames
        for f in out:
            message(f)
        sent.append(out)
        if k % CHUNK == 0:
            c1 = clock()
            chunks.append(c1 - c0)
            c0 = c1
    same = all(list(o) == list(s[2]) for o, s in zip(sent, script))
    return chunks, same


class _ReplayLink:
    """The node's ``CanBusLink`` on a ``friction_local`` bus of its own, with a second member (the
    drives' side) that puts the recorded frames on the bus and takes the node's, untimed."""

    def __init__(self, axes, route, directory: str):
        import can

        from friction_ros.can_bus.local_bus import LocalBus
        from friction_ros.nodes.can_bus import CanBusLink

        class Link(CanBusLink):
            def startup_frames(self):  # the axes are started already
                return []

        self.drives = LocalBus("replay", directory=Path(directory) / "replay")  # the link's folder
        self.link = Link("friction_local", "replay", 1_000_000, axes, route, 3, 1.0, None)
        assert isinstance(self.link.bus, LocalBus), type(self.link.bus)
        self.drives._refresh(-1.0)
        self.link.bus._refresh(time.monotonic())
        self._msg = {}  # Frame -> Message of the drives' side (built once)
        self._can = can

    def put(self, frames) -> None:
        for f in frames:
            m = self._msg.get(f)
            if m is None:
                m = self._msg[f] = self._can.Message(
                    arbitration_id=f.arbitration_id, data=f.data, is_extended_id=f.is_extended,
                    is_remote_frame=f.is_remote,
                )  # fmt: skip
            self.drives.send(m, timeout=0.01)

    def take(self) -> list[tuple[int, bytes]]:
        out = []
        while (m := self.drives.recv(0.0)) is not None:
            out.append((m.arbitration_id, bytes(m.data)))
        return out

    def close(self) -> None:
        self.link.bus.shutdown()
        self.drives.shutdown()


def replay_bus(protocol: str, n_axes: int, t0: float, script) -> tuple[list[float], bool]:
    """:func:`replay` through the node's bus link (``CanBusLink.receive``: ``recv`` of every frame,
    python-can's filters, routing; ``CanBusLink.send``: Message, pack, one ``sendto`` per frame) on
    a ``friction_local`` bus; the drives' side puts each period's frames on the bus and takes the
    node's outside the timing (the clock pair's own cost is subtracted)."""
    import os
    import tempfile

    axes, route, emus = _setup(protocol, n_axes)
    t, _ = _warm_up(axes, route, emus)
    assert t == t0
    clock = time.thread_time
    c0 = clock()
    for _ in range(1000):
        clock()
    pair = (clock() - c0) / 1000
    with tempfile.TemporaryDirectory() as d:
        os.environ["FRICTION_CAN_DIR"] = d
        bus = _ReplayLink(axes, route, d)
        link = bus.link
        mono = time.monotonic() - t  # the link's clock: receive times are clamped to [previous, now]
        same, chunks, acc = True, [], 0.0
        try:
            for k, (rx, cmds, sent) in enumerate(script, 1):
                t += DT
                bus.put(rx)
                c0 = clock()
                link.receive(t + mono)
                out = []
                for a, u in zip(axes, cmds):
                    a.set_command(u, t)
                    out += a.cycle(t).frames
                link.send(out)
                acc += clock() - c0 - pair
                same = same and bus.take() == [(f.arbitration_id, bytes(f.data)) for f in sent]
                if k % CHUNK == 0:
                    chunks.append(acc)
                    acc = 0.0
        finally:
            bus.close()
    return chunks, same


def frame_kinds(protocol: str, script) -> dict[str, float]:
    """Frames per period on the bus by kind (CiA 402 COB function, ODrive command, MIT: all one)."""
    from friction_ros.core.can.odrive import Cmd

    cia = {0x000: "NMT", 0x080: "SYNC/EMCY", 0x180: "TPDO1", 0x200: "RPDO1", 0x280: "TPDO2",
           0x580: "SDO tx", 0x600: "SDO rx", 0x700: "heartbeat"}  # fmt: skip

    def kind(arb: int) -> str:
        if protocol == "cia402":
            return cia.get(arb & 0x780, hex(arb & 0x780))
        if protocol == "odrive_cansimple":
            try:
                return Cmd(arb & 0x1F).name.lower()
            except ValueError:
                return hex(arb & 0x1F)
        return protocol

    counts: dict[str, float] = {}
    for rx, _, out in script:
        for d, frames in (("in", rx), ("out", out)):
            for f in frames:
                k = f"{d} {kind(f.arbitration_id)}"
                counts[k] = counts.get(k, 0) + 1
    return {k: v / len(script) for k, v in sorted(counts.items())}


def measure(protocol: str, n_axes: int, periods: int, repeat: int = REPEAT) -> dict:
    """Per chunk of periods the least CPU time of ``repeat`` replays (the same work each time: other
    processes only ever add to it), summed over the chunks."""
    periods -= periods % CHUNK
    t0, script, faults = record(protocol, n_axes, periods)
    rx = sum(len(s[0]) for s in script) / periods
    tx = sum(len(s[2]) for s in script) / periods
    runs = [replay(protocol, n_axes, t0, script) for _ in range(repeat)]
    us = sum(map(min, zip(*(c for c, _ in runs)))) / periods * 1e6
    bus_runs = [replay_bus(protocol, n_axes, t0, script) for _ in range(repeat)]
    bus_us = sum(map(min, zip(*(c for c, _ in bus_runs)))) / periods * 1e6
    return {
        "us_per_period": us,
        "bus_us_per_period": bus_us,
        "bus_us_per_axis": bus_us / n_axes,
        "bus_replay_identical": all(ok for _, ok in bus_runs),
        "frame_kinds_per_period": frame_kinds(protocol, script),
        "us_per_axis": us / n_axes,
        "frames_in_per_period": rx,
        "frames_out_per_period": tx,
        "replay_identical": all(ok for _, ok in runs),
        "faults": faults,
    }


def send_cost(n: int = 20_000) -> float:
    """CPU us of one ``friction_local`` send (8-byte frame, one other member: pack + one ``sendto``),
    the receiving member drained between batches of 8 (its queue holds 10) outside the timing."""
    import tempfile

    import can

    from friction_ros.can_bus.local_bus import LocalBus

    with tempfile.TemporaryDirectory() as d:
        tx, rx = LocalBus("c", directory=d), LocalBus("c", directory=d)
        msg = can.Message(arbitration_id=0x201, data=bytes(8), is_extended_id=False)
        best, clock = [], time.thread_time
        try:
            for _ in range(n // 8):
                c0 = clock()
                for _ in range(8):
                    tx.send(msg, timeout=0.001)
                best.append(clock() - c0)
                while rx.recv(0.0) is not None:
                    pass
        finally:
            tx.shutdown()
            rx.shutdown()
    best.sort()
    return sum(best[: len(best) // 2]) / (8 * (len(best) // 2)) * 1e6  # the faster half: load only adds


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("--periods", type=int, default=20_000, help="control periods per row (>= 100)")
    ap.add_argument("--protocols", default="odrive_cansimple,mit,cia402", help="comma-separated")
    ap.add_argument("--axes", default="1,3", help="axes on one bus per row, comma-separated")
    a = ap.parse_args()
    if a.periods < 100:
        print(f"error: --periods {a.periods}: must be >= 100", file=sys.stderr)
        return 2
    rows, kinds, figures = [], [], {}
    send_us = send_cost()
    figures["friction_local_send_us"] = send_us
    for protocol in a.protocols.split(","):
        for n in map(int, a.axes.split(",")):
            r = measure(protocol, n, a.periods)
            r["us_per_axis_with_sends"] = (r["us_per_period"] + r["frames_out_per_period"] * send_us) / n
            figures[f"{protocol}_{n}_axes"] = r
            rows.append([
                protocol, n, r["frames_in_per_period"], r["frames_out_per_period"], r["us_per_period"],
                r["us_per_axis"], r["us_per_axis_with_sends"], r["bus_us_per_axis"],
                "yes" if r["replay_identical"] and r["bus_replay_identical"] and not r["faults"] else f"NO {r['faults']}",
            ])  # fmt: skip
            kinds.append(
                [protocol, n, ", ".join(f"{k} {v:.3g}" for k, v in r["frame_kinds_per_period"].items())]
            )
    _common.print_table(
        f"drive_interface CAN work per 1 kHz period, CPU us (no bus, no ROS; {a.periods} periods, least of {REPEAT} per {CHUNK} periods)",
        [
            "protocol",
            "axes",
            "frames in",
            "frames out",
            "us / period",
            "us / period / axis",
            f"+ sends ({send_us:.1f} us each) / axis",
            "through the bus link / axis",
            "replay ok",
        ],
        rows,
    )
    _common.print_table(
        "frames per period on the bus (node's view)", ["protocol", "axes", "kind: count"], kinds
    )
    _common.write_results("can_decode", figures)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
