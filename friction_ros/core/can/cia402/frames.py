"""CiA 301 frame codecs with pre-built ``struct`` formats (little-endian, CiA 301 7.1.2).

The per-period PDOs of the fixed mapping this package configures (see :data:`RPDO1_MAP` ...):

    RPDO1 (0x200 + id, 4 bytes): controlword u16 | target torque i16 [per mille of 0x6076]
    TPDO1 (0x180 + id, 8 bytes): statusword u16 | torque actual i16 [per mille] | position actual i32 [counts]
    TPDO2 (0x280 + id, 6 bytes): velocity actual i32 [counts/s] | current actual i16 [per mille of 0x6075]

plus NMT (0x000: command u8, node u8), SYNC (0x080, empty), EMCY (0x080 + id: error code u16,
error register u8, 5 vendor bytes), heartbeat (0x700 + id: NMT state u8) and expedited SDO
(CiA 301 7.2.4.3: command specifier u8, index u16, sub-index u8, 4 data bytes).
"""

from __future__ import annotations

import struct
from typing import NamedTuple

from friction_ros.core.can.cia402 import objects as ob
from friction_ros.core.can.frame import Frame

RPDO1 = struct.Struct("<Hh")
TPDO1 = struct.Struct("<Hhi")
TPDO2 = struct.Struct("<ih")
EMCY = struct.Struct("<HB5s")
SDO = struct.Struct("<BHB4s")
I16_MIN, I16_MAX = -32768, 32767

RPDO1_MAP = (
    ob.map_entry(ob.OD_CONTROLWORD, 0, 16),
    ob.map_entry(ob.OD_TARGET_TORQUE, 0, 16),
)
TPDO1_MAP = (
    ob.map_entry(ob.OD_STATUSWORD, 0, 16),
    ob.map_entry(ob.OD_TORQUE_ACTUAL, 0, 16),
    ob.map_entry(ob.OD_POSITION_ACTUAL, 0, 32),
)
TPDO2_MAP = (
    ob.map_entry(ob.OD_VELOCITY_ACTUAL, 0, 32),
    ob.map_entry(ob.OD_CURRENT_ACTUAL, 0, 16),
)

SYNC_FRAME = Frame(ob.COB_SYNC, b"")


def nmt(command: int, node_id: int) -> Frame:
    """NMT command to one node (``node_id`` 0: all nodes)."""
    return Frame(ob.COB_NMT, bytes((command, node_id)))


def heartbeat(node_id: int, nmt_state: int) -> Frame:
    return Frame(ob.COB_HEARTBEAT + node_id, bytes((nmt_state,)))


def emcy(node_id: int, code: int, register: int = 0, vendor: bytes = b"") -> Frame:
    return Frame(ob.COB_EMCY + node_id, EMCY.pack(code, register, vendor))


class EmcyMessage(NamedTuple):
    code: int
    register: int
    vendor: bytes

    @property
    def text(self) -> str:
        return f"EMCY 0x{self.code:04X} {ob.emcy_text(self.code)} (error register 0x{self.register:02X})"


def decode_emcy(data: bytes) -> EmcyMessage:
    return EmcyMessage(*EMCY.unpack(bytes(data[:8]).ljust(8, b"\0")))


# ---- expedited SDO ---------------------------------------------------------------------------------------
_SIZE_BITS = {1: 0x0C, 2: 0x08, 3: 0x04, 4: 0x00}  # n = 4 - size in bits 2-3, e=1, s=1


def sdo_download(
    node_id: int, index: int, subindex: int, value: int, size: int, signed: bool = False
) -> Frame:
    """Expedited SDO download request (initiate download, ccs = 1) writing ``size`` bytes."""
    data = int(value).to_bytes(size, "little", signed=signed).ljust(4, b"\0")
    return Frame(ob.COB_SDO_RX + node_id, SDO.pack(0x23 | _SIZE_BITS[size], index, subindex, data))


def sdo_upload(node_id: int, index: int, subindex: int) -> Frame:
    """SDO upload request (initiate upload, ccs = 2)."""
    return Frame(ob.COB_SDO_RX + node_id, SDO.pack(0x40, index, subindex, b"\0\0\0\0"))


class SdoResponse(NamedTuple):
    kind: str  # "download" (write confirmed), "upload" (value read), "abort", "other"
    index: int
    subindex: int
    value: int  # uploaded value (unsigned) or abort code
    size: int


def decode_sdo_response(data: bytes) -> SdoResponse:
    cmd, index, sub, payload = SDO.unpack(bytes(data[:8]).ljust(8, b"\0"))
    scs = cmd & 0xE0
    if scs == 0x60:
        return SdoResponse("download", index, sub, 0, 0)
    if scs == 0x40 and cmd & 0x02:  # expedited upload
        size = 4 - ((cmd >> 2) & 0x03) if cmd & 0x01 else 4
        return SdoResponse("upload", index, sub, int.from_bytes(payload[:size], "little"), size)
    if scs == 0x80:
        return SdoResponse("abort", index, sub, int.from_bytes(payload, "little"), 4)
    return SdoResponse("other", index, sub, cmd, 0)
