"""drive_emulator: run the frame-level servo-drive emulator as its own process.

The emulated drive (ODrive CANSimple or MIT) answers on a python-can bus with a project plant
preset behind it, so ``drive_interface`` can be exercised without hardware, e.g. on a Linux PC with
a virtual SocketCAN interface::

    sudo ip link add dev vcan0 type vcan && sudo ip link set vcan0 up
    drive_emulator --interface socketcan --channel vcan0 --preset abb_m19s
    drive_interface --ros-args -p channel:=vcan0 -p enable_on_start:=true ...

It is not a ROS node (a drive does not speak DDS); it prints a status line every few seconds and
stops cleanly on Ctrl-C. Fault injection: ``--silent-after``, ``--error-after``, ``--loss``, ``--latency``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import signal
import sys
import threading
import time

from friction_ros.core.can.emulator import DriveEmulator, EmulatorConfig, plant_from_preset
from friction_ros.core.can.protocol import PROTOCOLS
from friction_ros.core.validation import ParameterError


def emulated_drive(preset: str, direction: int = 1, zero_offset: float = 0.0, **config):
    """``(plant, EmulatorConfig)`` of one emulated drive: the preset's plant behind a drive whose
    joint conversion is the preset's (gear ratio, torque constant) with ``direction`` and
    ``zero_offset``; ``config`` holds the other EmulatorConfig fields (protocol, ids, rates, faults)."""
    plant, conv = plant_from_preset(preset)
    conv = dataclasses.replace(conv, direction=direction, zero_offset=zero_offset)
    return plant, EmulatorConfig(conversion=conv, **config)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="drive_emulator", description=__doc__.split("\n\n")[0], allow_abbrev=False
    )
    ap.add_argument("--interface", default="socketcan", help="python-can interface (default socketcan)")
    ap.add_argument("--channel", default="vcan0", help="CAN channel (default vcan0)")
    ap.add_argument("--bitrate", type=int, default=1_000_000)
    ap.add_argument(
        "--protocol", default="odrive_cansimple", choices=PROTOCOLS, help="drive protocol: %(choices)s"
    )
    ap.add_argument(
        "--node-id",
        type=int,
        nargs="+",
        default=[0],
        help="ODrive node id / MIT motor id; several ids emulate several drives on the bus, each "
        "with its own plant (e.g. --node-id 1 2 3 for a drive_interface with three joints)",
    )
    ap.add_argument("--mit-master-id", type=int, default=0)
    ap.add_argument("--preset", default="abb_m19s", help="plant preset name or YAML path")
    ap.add_argument("--direction", type=int, default=1, choices=(1, -1))
    ap.add_argument("--zero-offset", type=float, default=0.0, help="joint rad at motor zero")
    ap.add_argument("--physics-rate", type=float, default=1000.0, help="plant steps per second")
    ap.add_argument(
        "--encoder-rate", type=float, default=1000.0, help="cyclic encoder frames/s (0: RTR only)"
    )
    ap.add_argument("--iq-rate", type=float, default=1000.0)
    ap.add_argument("--torques-rate", type=float, default=0.0)
    ap.add_argument("--heartbeat-rate", type=float, default=10.0)
    ap.add_argument("--bus-voltage-rate", type=float, default=0.0)
    ap.add_argument("--latency", type=float, default=0.0, help="added to every transmitted frame [s]")
    ap.add_argument("--loss", type=float, default=0.0, help="probability a transmitted frame is lost")
    ap.add_argument("--silent-after", type=float, default=None, help="stop transmitting after S seconds")
    ap.add_argument("--error-after", type=float, default=None, help="raise an axis error after S seconds")
    ap.add_argument("--duration", type=float, default=None, help="exit after S seconds")
    ap.add_argument("--status-period", type=float, default=5.0)
    return ap


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    ids = list(a.node_id)
    try:
        import can

        if len(set(ids)) != len(ids):
            raise ParameterError(f"--node-id {' '.join(map(str, ids))}: ids must differ")
        drives = []
        for node_id in ids:
            plant, cfg = emulated_drive(
                a.preset,
                a.direction,
                a.zero_offset,
                protocol=a.protocol,
                node_id=node_id,
                mit_master_id=a.mit_master_id,
                physics_rate_hz=a.physics_rate,
                encoder_rate_hz=a.encoder_rate,
                iq_rate_hz=a.iq_rate,
                torques_rate_hz=a.torques_rate,
                heartbeat_rate_hz=a.heartbeat_rate,
                bus_voltage_rate_hz=a.bus_voltage_rate,
                latency=a.latency,
                loss_probability=a.loss,
            )
            try:  # one bus handle per drive: each is its own node on the bus
                bus = can.Bus(interface=a.interface, channel=a.channel, bitrate=a.bitrate)
            except Exception as exc:
                raise ParameterError(
                    f"cannot open CAN bus interface={a.interface} channel={a.channel}: {exc}"
                ) from None
            drives.append((DriveEmulator(bus, plant, cfg), bus))
    except (ParameterError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    for emu, _bus in drives:
        for after, action in ((a.silent_after, emu.set_silent), (a.error_after, emu.inject_axis_error)):
            if after is not None:
                t = threading.Timer(after, action)
                t.daemon = True
                t.start()
    print(
        f"drive_emulator: {a.protocol} node{'s' if len(ids) > 1 else ''} {', '.join(map(str, ids))} on "
        f"{a.interface}:{a.channel}, plant preset {a.preset} "
        f"(gear_ratio {cfg.conversion.gear_ratio:g}, torque_constant {cfg.conversion.torque_constant:g})",
        flush=True,
    )
    for emu, _bus in drives:
        emu.start()
    t0 = time.monotonic()
    end = t0 + a.duration if a.duration is not None else math.inf
    next_status = t0 + a.status_period
    try:
        while not stop.wait(max(0.0, min(next_status, end) - time.monotonic())):
            now = time.monotonic()
            if now >= end:
                break
            if now < next_status:
                continue
            next_status += a.status_period
            for node_id, (emu, _bus) in zip(ids, drives):
                s = emu.stats
                print(
                    f"t={now - t0:.0f}s node {node_id} armed={emu.armed} q={emu.meas.position:+.4f} rad "
                    f"rx={s.frames_rx} tx={s.frames_tx} lost={s.frames_lost} cmds={s.commands}",
                    flush=True,
                )
    finally:
        for node_id, (emu, bus) in zip(ids, drives):
            emu.stop()
            bus.shutdown()
            state = "ENABLED (torque on)" if emu.armed else "disabled"
            print(f"drive_emulator: node {node_id} stopped, drive {state}", flush=True)
    return 0


if __name__ == "__main__":
    from friction_ros.nodes.process_exit import exit_now

    exit_now(main())  # everything is closed: no interpreter teardown (see process_exit)
