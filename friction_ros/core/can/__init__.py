"""CAN drive protocols (registry, pure codecs), joint conversion, axis safety logic and the drive emulator.

Nothing here imports rclpy; :mod:`friction_ros.core.can.emulator` touches a python-can bus (the
``friction_local`` socket bus lives outside the core, in :mod:`friction_ros.can_bus.local_bus`).
"""

from friction_ros.core.can.axis import CycleResult, DriveAxis, JointSample
from friction_ros.core.can.axis_config import AxisConfig
from friction_ros.core.can.frame import DecodeStats, Frame
from friction_ros.core.can.joint import JointConversion
from friction_ros.core.can.mit import MitCodec, MitDecoder, MitRanges
from friction_ros.core.can.odrive import OdriveDecoder
from friction_ros.core.can.protocol import (
    DriveProtocol,
    DriveTelemetry,
    EmulatedDriveProtocol,
    drive_protocol,
    protocol_names,
    register_drive_protocol,
)

__all__ = [
    "AxisConfig",
    "CycleResult",
    "DecodeStats",
    "DriveAxis",
    "DriveProtocol",
    "DriveTelemetry",
    "EmulatedDriveProtocol",
    "Frame",
    "JointConversion",
    "JointSample",
    "MitCodec",
    "MitDecoder",
    "MitRanges",
    "OdriveDecoder",
    "drive_protocol",
    "protocol_names",
    "register_drive_protocol",
]
