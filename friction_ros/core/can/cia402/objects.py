"""CiA 301 / CiA 402 constants: COB-IDs, NMT commands, object indices, EMCY error code texts.

Sources: CiA 301 v4.2 (predefined connection set: COB-ID = function code + node id; NMT, SYNC,
EMCY, heartbeat, SDO) and CiA 402-2 v4.1 (drive objects 0x6040..0x6502, error codes Table 41).
"""

from __future__ import annotations

# ---- predefined connection set (CiA 301 7.3.3): COB-ID = base + node id ---------------------------
COB_NMT = 0x000
COB_SYNC = 0x080
COB_EMCY = 0x080
COB_TPDO1 = 0x180
COB_RPDO1 = 0x200
COB_TPDO2 = 0x280
COB_SDO_TX = 0x580  # drive -> master (SDO server response)
COB_SDO_RX = 0x600  # master -> drive (SDO client request)
COB_HEARTBEAT = 0x700
NODE_ID_MIN, NODE_ID_MAX = 1, 127

# ---- NMT (CiA 301 7.2.8.3.1) ------------------------------------------------------------------------
NMT_START = 0x01
NMT_STOP = 0x02
NMT_PRE_OPERATIONAL = 0x80
NMT_RESET_NODE = 0x81
NMT_RESET_COMMUNICATION = 0x82
# NMT states as reported in the heartbeat (CiA 301 7.2.8.3.2.1)
NMT_BOOT_UP, NMT_STOPPED, NMT_OPERATIONAL, NMT_PRE_OP = 0x00, 0x04, 0x05, 0x7F
NMT_STATE_NAMES = {
    NMT_BOOT_UP: "BOOT-UP",
    NMT_STOPPED: "STOPPED",
    NMT_OPERATIONAL: "OPERATIONAL",
    NMT_PRE_OP: "PRE-OPERATIONAL",
}

# ---- object dictionary indices ---------------------------------------------------------------------
OD_ERROR_REGISTER = 0x1001
OD_HEARTBEAT_PRODUCER = 0x1017
OD_RPDO1_COMM, OD_RPDO1_MAP = 0x1400, 0x1600
OD_TPDO1_COMM, OD_TPDO1_MAP = 0x1800, 0x1A00
OD_TPDO2_COMM, OD_TPDO2_MAP = 0x1801, 0x1A01
OD_ERROR_CODE = 0x603F
OD_CONTROLWORD = 0x6040
OD_STATUSWORD = 0x6041
OD_MODES_OF_OPERATION = 0x6060
OD_MODES_DISPLAY = 0x6061
OD_POSITION_ACTUAL = 0x6064
OD_VELOCITY_ACTUAL = 0x606C
OD_TARGET_TORQUE = 0x6071
OD_MAX_TORQUE = 0x6072
OD_RATED_CURRENT = 0x6075  # [mA]
OD_RATED_TORQUE = 0x6076  # [mN*m]
OD_TORQUE_ACTUAL = 0x6077
OD_CURRENT_ACTUAL = 0x6078
OD_ENCODER_RESOLUTION = 0x608F  # sub 1 increments, sub 2 motor revolutions
OD_GEAR_RATIO = 0x6091  # sub 1 motor revolutions, sub 2 shaft revolutions
OD_SUPPORTED_MODES = 0x6502

MODE_CYCLIC_SYNC_TORQUE = 10  # 0x6060 value (CiA 402-2 Table 63)
PDO_COB_INVALID = 0x80000000  # bit 31 of a PDO COB-ID: PDO does not exist / is disabled
SYNC_TRANSMISSION = 1  # PDO transmission type: synchronous, every SYNC


def map_entry(index: int, subindex: int, bits: int) -> int:
    """PDO mapping entry (CiA 301 7.5.2.36): ``index << 16 | subindex << 8 | length in bits``."""
    return (index << 16) | (subindex << 8) | bits


# ---- EMCY error codes (CiA 301 Table 21, CiA 402-2 Table 41) -----------------------------------------
EMCY_TEXTS = {
    0x0000: "error reset or no error",
    0x1000: "generic error",
    0x2220: "continuous over current (device inside)",
    0x2310: "continuous over current (device output side)",
    0x2320: "short circuit / earth leakage (device output side)",
    0x3210: "DC link over-voltage",
    0x3220: "DC link under-voltage",
    0x4210: "excess temperature device",
    0x4310: "excess temperature drive",
    0x5530: "data storage (non-volatile memory)",
    0x6010: "software reset (watchdog)",
    0x7121: "motor blocked",
    0x7305: "incremental sensor 1 fault",
    0x8100: "communication",
    0x8110: "CAN overrun (objects lost)",
    0x8120: "CAN in error passive mode",
    0x8130: "life guard error or heartbeat error",
    0x8140: "recovered from bus off",
    0x8210: "PDO not processed due to length error",
    0x8250: "RPDO timeout",
    0x8311: "excess torque",
    0x8611: "following error",
    0xFF00: "device specific",
}
ERROR_GENERIC, ERROR_COMMUNICATION, ERROR_HEARTBEAT = 0x1000, 0x8100, 0x8130
_EMCY_CLASSES = {
    0x1: "generic",
    0x2: "current",
    0x3: "voltage",
    0x4: "temperature",
    0x5: "device hardware",
    0x6: "device software",
    0x7: "additional modules",
    0x8: "monitoring",
    0x9: "external error",
    0xF: "additional functions",
}


def emcy_text(code: int) -> str:
    """Human-readable text of an EMCY error code: the exact entry, else its class (high nibble)."""
    if code in EMCY_TEXTS:
        return EMCY_TEXTS[code]
    if code >= 0xFF00:
        return "device specific"
    return _EMCY_CLASSES.get(code >> 12, "unknown") + " error"


# ---- SDO abort codes (CiA 301 Table 22, the common ones) -----------------------------------------------
SDO_ABORT_TEXTS = {
    0x05040000: "SDO protocol timed out",
    0x05040001: "command specifier not valid or unknown",
    0x06010000: "unsupported access to an object",
    0x06010001: "attempt to read a write only object",
    0x06010002: "attempt to write a read only object",
    0x06020000: "object does not exist in the object dictionary",
    0x06040041: "object cannot be mapped to the PDO",
    0x06040042: "the number and length of the objects to be mapped would exceed PDO length",
    0x06070010: "data type does not match, length of service parameter does not match",
    0x06090011: "sub-index does not exist",
    0x06090030: "invalid value for parameter (download only)",
    0x06090031: "value of parameter written too high",
    0x08000000: "general error",
    0x08000020: "data cannot be transferred or stored to the application",
    0x08000022: "data cannot be transferred because of the present device state",
}


def sdo_abort_text(code: int) -> str:
    return SDO_ABORT_TEXTS.get(code, "unknown abort code")
