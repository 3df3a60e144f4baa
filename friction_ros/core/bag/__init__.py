"""MCAP bag I/O (rosbag2-compatible; SQLite3 bags are read through rosbags), CDR and message definitions. Pure Python + numpy: no rclpy.

Reading (offline fitting)::

    from friction_ros.core.bag import read_bag
    bag = read_bag("bags/run_1")                    # directory, .mcap or .db3 file (sqlite3 via rosbags)
    js = bag.topic("/joint_states", "sensor_msgs/msg/JointState")
    j = js.joint("joint1")                          # JointSeries: time, stamp, position, velocity, effort
    u = bag["/controller_state"]["command"]         # numpy column per field ("header.stamp.sec" ...)

Writing::

    with BagWriter("bags/run_1", metadata=run_metadata(preset="abb_m19s")) as w:
        w.add_topic("/joint_states", "sensor_msgs/msg/JointState", qos_profiles=[make_qos()])
        w.write("/joint_states", cdr_bytes, log_time_ns)
"""

from .cdr import decode, decode_batch, encode
from .contents import Bag, JointSeries, RawMessage, TopicData, TopicInfo
from .digest import content_digest
from .errors import (
    BagError,
    CdrError,
    DiskFullError,
    NotMcapError,
    SchemaError,
    TopicNotFoundError,
    TruncatedBagError,
    UnsupportedBagError,
)
from .msgdef import MsgDef, find_msg_file, load_installed, parse_msg, parse_schema, schema_text, type_hash
from .qos import dump_qos, make_qos, parse_qos
from .reader import bag_files, bag_info, iter_messages, read_bag, read_joint_states, storage_of
from .writer import RUN_METADATA_NAME, BagWriter, package_version, run_metadata

__all__ = [
    "Bag",
    "BagError",
    "BagWriter",
    "CdrError",
    "DiskFullError",
    "JointSeries",
    "MsgDef",
    "NotMcapError",
    "RUN_METADATA_NAME",
    "RawMessage",
    "SchemaError",
    "TopicData",
    "TopicInfo",
    "TopicNotFoundError",
    "TruncatedBagError",
    "UnsupportedBagError",
    "bag_files",
    "bag_info",
    "content_digest",
    "decode",
    "decode_batch",
    "dump_qos",
    "encode",
    "find_msg_file",
    "iter_messages",
    "load_installed",
    "make_qos",
    "package_version",
    "parse_msg",
    "parse_qos",
    "parse_schema",
    "read_bag",
    "read_joint_states",
    "run_metadata",
    "schema_text",
    "storage_of",
    "type_hash",
]
