"""The wire format of the package: CDR (ROS 2 serialisation) in one place. Pure Python, no rclpy.

* :mod:`.cdr`: primitives shared by every codec: encapsulation header, alignment, strings,
  sequences of float64, builtin_interfaces/Time, std_msgs/Header, the template :class:`Writer`
  and :func:`compile_template` (a template with variable slots -> one ``struct.Struct``).
* :mod:`.messages`: fast encoders/decoders of the messages the nodes publish and take every period
  (sensor_msgs/JointState, friction_msgs/ControllerState, DriveState, FrictionEstimate) or second
  (diagnostic_msgs/DiagnosticArray), byte-for-byte what rclpy's serialiser writes.

The schema-driven codec of the bag reader/writer (:mod:`friction_ros.core.bag.cdr`, any message
type from its ``.msg`` definition) is built on the same primitives.
"""

from .cdr import (
    CDR_LE,
    ENCAPSULATIONS,
    ORIGIN,
    TIME,
    U32,
    WireDecodeError,
    Writer,
    compile_template,
    encapsulation,
    padding,
    string_bytes,
)
from .messages import (
    CONTROLLER_STATE_FLOATS,
    DRIVE_STATE_FLOATS,
    DRIVE_STATE_UINTS,
    ControllerStateEncoder,
    DecodedJointState,
    DriveStateEncoder,
    FrictionEstimateEncoder,
    JointStateDecoder,
    JointStateEncoder,
    encode_diagnostic_array,
)

__all__ = [
    "WireDecodeError",
    "CDR_LE",
    "CONTROLLER_STATE_FLOATS",
    "DRIVE_STATE_FLOATS",
    "DRIVE_STATE_UINTS",
    "ENCAPSULATIONS",
    "ORIGIN",
    "TIME",
    "U32",
    "ControllerStateEncoder",
    "DriveStateEncoder",
    "FrictionEstimateEncoder",
    "DecodedJointState",
    "JointStateDecoder",
    "JointStateEncoder",
    "encode_diagnostic_array",
    "Writer",
    "compile_template",
    "encapsulation",
    "padding",
    "string_bytes",
]
