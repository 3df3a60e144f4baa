"""simulated_drive: the real ``drive_interface`` node talking CAN frames to an emulated drive.

The CAN path without hardware: a :class:`friction_ros.core.can.emulator.DriveEmulator` (the plant
preset behind a frame-level ODrive CANSimple or MIT drive) and the unmodified drive_interface node
share one python-can ``virtual`` bus in this process (python-can's virtual bus does not cross
processes, and kernel vcan is not available everywhere). Everything the node does on a robot —
encoding, decoding, watchdog, limits, IDLE on exit — happens on real frames; the topics are the
same as drive_interface's and plant_simulator's, so controllers cannot tell the difference.

    simulated_drive --preset abb_m19s --protocol odrive_cansimple -- \\
        --ros-args -p joint_name:=joint1 -p torque_limit:=3.0

Options before ``--`` configure the emulator; ROS arguments after it go to drive_interface (its
``interface``/``channel``/conversion parameters are set here to match the emulated drive).
"""

from __future__ import annotations

import argparse
import sys
import uuid

import can

from friction_ros.core.can.emulator import DriveEmulator
from friction_ros.core.can.protocol import PROTOCOLS
from friction_ros.core.validation import ParameterError
from friction_ros.nodes.drive_emulator import emulated_drive
from friction_ros.nodes.node_help import help_requested, parameter_lines


def _drive_interface_parameters() -> str:
    """The drive_interface parameters (ROS arguments after ``--``), for ``--help``."""
    from friction_ros.nodes import drive_interface

    lines = parameter_lines(drive_interface.parameter_schema())
    return (
        "drive_interface parameters after -- (interface, channel, protocol, node_id, gear_ratio,\n"
        "torque_constant and control_period are set to match the emulated drive):\n" + "\n".join(lines)
    )


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    sep = "--" if "--" in argv else "--ros-args" if "--ros-args" in argv else None
    ros = argv[argv.index(sep) + (1 if sep == "--" else 0) :] if sep else []
    own = argv[: argv.index(sep)] if sep else argv
    ap = argparse.ArgumentParser(
        prog="simulated_drive",
        description=__doc__.split("\n\n")[0],
        allow_abbrev=False,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=_drive_interface_parameters() if help_requested(["simulated_drive", *own]) else None,
    )
    ap.add_argument("--preset", default="abb_m19s", help="plant preset behind the emulated drive")
    ap.add_argument(
        "--protocol", default="odrive_cansimple", choices=PROTOCOLS, help="drive protocol: %(choices)s"
    )
    ap.add_argument("--node-id", type=int, default=0, help="drive node id (default 0)")
    ap.add_argument("--rate", type=float, default=1000.0, help="telemetry and physics rate [Hz]")
    ap.add_argument("--latency", type=float, default=0.0, help="frame latency of the drive [s]")
    ap.add_argument("--loss", type=float, default=0.0, help="frame loss probability")
    a = ap.parse_args(own)
    try:
        rates = {f"{k}_rate_hz": a.rate for k in ("physics", "encoder", "iq")}  # telemetry = physics rate
        plant, cfg = emulated_drive(
            a.preset,
            protocol=a.protocol,
            node_id=a.node_id,
            latency=a.latency,
            loss_probability=a.loss,
            **rates,
        )
        conv = cfg.conversion
    except (ParameterError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    channel = f"simulated_drive_{uuid.uuid4().hex[:8]}"
    bus = can.Bus(interface="virtual", channel=channel)
    emulator = DriveEmulator(bus, plant, cfg)
    emulator.start()
    from friction_ros.nodes import drive_interface

    fixed = [
        "-p", "interface:=virtual",
        "-p", f"channel:={channel}",
        "-p", f"protocol:={a.protocol}",
        "-p", f"node_id:={a.node_id}",
        "-p", f"gear_ratio:={conv.gear_ratio}",
        "-p", f"torque_constant:={conv.torque_constant}",
        "-p", f"control_period:={1.0 / a.rate!r}",
    ]  # fmt: skip
    ros_args = ros[1:] if ros[:1] == ["--ros-args"] else ros
    try:
        return drive_interface.main(["simulated_drive", "--ros-args", *fixed, *ros_args])
    finally:
        emulator.stop()
        bus.shutdown()


if __name__ == "__main__":
    raise SystemExit(main())
