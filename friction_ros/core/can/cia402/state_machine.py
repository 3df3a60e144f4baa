"""The CiA 402 drive state machine (CiA 402-2 v4.1, 6.3: Figure 8, Tables 26-30), both sides.

Statusword 0x6041 -> state (Table 30; bits 0-3, 5, 6):

    xxxx xxxx x0xx 0000  NOT READY TO SWITCH ON     xxxx xxxx x01x 0111  OPERATION ENABLED
    xxxx xxxx x1xx 0000  SWITCH ON DISABLED         xxxx xxxx x00x 0111  QUICK STOP ACTIVE
    xxxx xxxx x01x 0001  READY TO SWITCH ON         xxxx xxxx x0xx 1111  FAULT REACTION ACTIVE
    xxxx xxxx x01x 0011  SWITCHED ON                xxxx xxxx x0xx 1000  FAULT

Controlword 0x6040 commands (Table 28; bit 7 fault reset acts on its rising edge):
shutdown ``0b0xxx x110``, switch on ``0b0xxx 0111``, enable operation ``0b0xxx 1111``,
disable voltage ``0b0xxx xx0x``, quick stop ``0b0xxx x01x``, disable operation = switch on.

:func:`master_controlword` is the master's walk towards a target state (one command per period,
like ros2_canopen's ``canopen_402_driver`` state handler); :class:`DriveStateMachine` is what a
drive does with the commands it receives (used by the emulator).
"""

from __future__ import annotations

from enum import IntEnum


class State(IntEnum):
    NOT_READY_TO_SWITCH_ON = 0
    SWITCH_ON_DISABLED = 1
    READY_TO_SWITCH_ON = 2
    SWITCHED_ON = 3
    OPERATION_ENABLED = 4
    QUICK_STOP_ACTIVE = 5
    FAULT_REACTION_ACTIVE = 6
    FAULT = 7
    UNKNOWN = 8


STATE_NAMES = {s: s.name.replace("_", " ") for s in State}

# (mask, value) of the statusword per state, checked in this order (Table 30)
_SW_PATTERNS = (
    (0x4F, 0x00, State.NOT_READY_TO_SWITCH_ON),
    (0x4F, 0x40, State.SWITCH_ON_DISABLED),
    (0x6F, 0x21, State.READY_TO_SWITCH_ON),
    (0x6F, 0x23, State.SWITCHED_ON),
    (0x6F, 0x27, State.OPERATION_ENABLED),
    (0x6F, 0x07, State.QUICK_STOP_ACTIVE),
    (0x4F, 0x0F, State.FAULT_REACTION_ACTIVE),
    (0x4F, 0x08, State.FAULT),
)
# statusword bits a drive reports for each state (voltage enabled 0x10 and remote 0x200 added by the drive)
STATE_STATUSWORD = {
    State.NOT_READY_TO_SWITCH_ON: 0x00,
    State.SWITCH_ON_DISABLED: 0x40,
    State.READY_TO_SWITCH_ON: 0x21,
    State.SWITCHED_ON: 0x23,
    State.OPERATION_ENABLED: 0x27,
    State.QUICK_STOP_ACTIVE: 0x07,
    State.FAULT_REACTION_ACTIVE: 0x0F,
    State.FAULT: 0x08,
}
SW_FAULT = 0x0008
SW_VOLTAGE_ENABLED = 0x0010
SW_WARNING = 0x0080
SW_REMOTE = 0x0200

CW_DISABLE_VOLTAGE = 0x00
CW_QUICK_STOP = 0x02
CW_SHUTDOWN = 0x06
CW_SWITCH_ON = 0x07
CW_ENABLE_OPERATION = 0x0F
CW_FAULT_RESET = 0x80


def state_from_statusword(sw: int) -> State:
    for mask, value, state in _SW_PATTERNS:
        if sw & mask == value:
            return state
    return State.UNKNOWN


def master_controlword(state: State, target: State, last_cw: int = 0) -> int:
    """The controlword that moves a drive in ``state`` one transition towards ``target``.

    ``target`` is OPERATION ENABLED (enable), SWITCH ON DISABLED (disable) or QUICK STOP ACTIVE.
    In FAULT the fault-reset bit alternates with 0 so that every second period is a rising edge
    (transition 15); states the drive leaves on its own get ``last_cw`` without the reset bit.
    """
    if state == target == State.OPERATION_ENABLED:
        return CW_ENABLE_OPERATION  # the every-period case first
    if state == State.FAULT:
        if target == State.OPERATION_ENABLED:
            return CW_DISABLE_VOLTAGE if last_cw & CW_FAULT_RESET else CW_FAULT_RESET
        return CW_DISABLE_VOLTAGE
    if state in (State.NOT_READY_TO_SWITCH_ON, State.FAULT_REACTION_ACTIVE, State.UNKNOWN):
        return CW_DISABLE_VOLTAGE
    if target == State.SWITCH_ON_DISABLED:
        return CW_DISABLE_VOLTAGE
    if target == State.QUICK_STOP_ACTIVE:
        if state in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE):
            return CW_QUICK_STOP
        return CW_DISABLE_VOLTAGE
    return _UP[state]  # target OPERATION ENABLED


_UP = {  # controlword towards OPERATION ENABLED, per state
    State.SWITCH_ON_DISABLED: CW_SHUTDOWN,  # transition 2
    State.READY_TO_SWITCH_ON: CW_SWITCH_ON,  # 3
    State.SWITCHED_ON: CW_ENABLE_OPERATION,  # 4
    State.OPERATION_ENABLED: CW_ENABLE_OPERATION,  # hold
    State.QUICK_STOP_ACTIVE: CW_DISABLE_VOLTAGE,  # 12, then up again from SWITCH ON DISABLED
}


class DriveStateMachine:
    """Drive side: ``apply(controlword)`` once per received controlword; ``fault()`` on a drive error.

    Quick stop option code 6 behaviour (CiA 402-2 6.5.1): QUICK STOP ACTIVE is held (zero torque)
    until disable voltage or enable operation (transition 16).
    """

    def __init__(self) -> None:
        self.state = State.SWITCH_ON_DISABLED  # transitions 0 and 1 happen at power-up
        self._last_cw = 0
        self.fault_active = False  # the fault condition itself (cleared by clear_fault())

    @property
    def statusword(self) -> int:
        sw = STATE_STATUSWORD.get(self.state, 0) | SW_REMOTE
        if self.state not in (State.NOT_READY_TO_SWITCH_ON, State.SWITCH_ON_DISABLED, State.FAULT):
            sw |= SW_VOLTAGE_ENABLED
        return sw

    def fault(self) -> None:
        """A drive error: FAULT REACTION ACTIVE, then FAULT at the next :meth:`apply` (transitions 13, 14)."""
        self.fault_active = True
        self.state = State.FAULT_REACTION_ACTIVE

    def clear_fault(self) -> None:
        self.fault_active = False

    def apply(self, cw: int) -> State:
        rising_reset = bool(cw & CW_FAULT_RESET) and not self._last_cw & CW_FAULT_RESET
        self._last_cw = cw
        s = self.state
        if s == State.FAULT_REACTION_ACTIVE:
            self.state = State.FAULT  # 14: the reaction (torque off) is immediate here
        elif s == State.FAULT:
            if rising_reset and not self.fault_active:
                self.state = State.SWITCH_ON_DISABLED  # 15
        elif cw & CW_FAULT_RESET:
            pass  # bit 7 set: no other command is executed
        elif cw & 0x02 == 0:  # disable voltage: 7, 9, 10, 12
            if s != State.NOT_READY_TO_SWITCH_ON:
                self.state = State.SWITCH_ON_DISABLED
        elif cw & 0x06 == 0x02:  # quick stop
            if s == State.OPERATION_ENABLED:
                self.state = State.QUICK_STOP_ACTIVE  # 11
            elif s in (State.READY_TO_SWITCH_ON, State.SWITCHED_ON):
                self.state = State.SWITCH_ON_DISABLED  # 7, 10
        elif cw & 0x07 == 0x06:  # shutdown: 2, 6, 8
            if s in (State.SWITCH_ON_DISABLED, State.SWITCHED_ON, State.OPERATION_ENABLED):
                self.state = State.READY_TO_SWITCH_ON
        elif cw & 0x0F == 0x07:  # switch on (3) / disable operation (5)
            if s in (State.READY_TO_SWITCH_ON, State.OPERATION_ENABLED):
                self.state = State.SWITCHED_ON
        elif cw & 0x0F == 0x0F:  # enable operation: 4, 16 (and 3 + 4 from READY)
            if s in (State.SWITCHED_ON, State.QUICK_STOP_ACTIVE, State.READY_TO_SWITCH_ON):
                self.state = State.OPERATION_ENABLED
        return self.state
