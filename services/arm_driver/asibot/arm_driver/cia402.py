"""The CiA 402 drive state machine: statusword -> state, and the controlword that moves a
drive one step towards "operation enabled" (docs/canopen.md, "CiA 402 states")."""

from __future__ import annotations

from enum import Enum


class State(str, Enum):
    NOT_READY_TO_SWITCH_ON = "not ready to switch on"
    SWITCH_ON_DISABLED = "switch on disabled"
    READY_TO_SWITCH_ON = "ready to switch on"
    SWITCHED_ON = "switched on"
    OPERATION_ENABLED = "operation enabled"
    QUICK_STOP_ACTIVE = "quick stop active"
    FAULT_REACTION_ACTIVE = "fault reaction active"
    FAULT = "fault"


# (mask, value) pairs of the statusword, checked in this order.
_PATTERNS = (
    (0x4F, 0x00, State.NOT_READY_TO_SWITCH_ON),
    (0x4F, 0x40, State.SWITCH_ON_DISABLED),
    (0x6F, 0x21, State.READY_TO_SWITCH_ON),
    (0x6F, 0x23, State.SWITCHED_ON),
    (0x6F, 0x27, State.OPERATION_ENABLED),
    (0x6F, 0x07, State.QUICK_STOP_ACTIVE),
    (0x4F, 0x0F, State.FAULT_REACTION_ACTIVE),
    (0x4F, 0x08, State.FAULT),
)

STATUSWORD = {
    State.NOT_READY_TO_SWITCH_ON: 0x0000,
    State.SWITCH_ON_DISABLED: 0x0040,
    State.READY_TO_SWITCH_ON: 0x0021,
    State.SWITCHED_ON: 0x0023,
    State.OPERATION_ENABLED: 0x0027,
    State.QUICK_STOP_ACTIVE: 0x0007,
    State.FAULT_REACTION_ACTIVE: 0x000F,
    State.FAULT: 0x0008,
}

# Statusword bits beyond the state.
SW_VOLTAGE_ENABLED = 1 << 4
SW_REMOTE = 1 << 9
SW_TARGET_REACHED = 1 << 10
SW_INTERNAL_LIMIT = 1 << 11
SW_SETPOINT_ACK = 1 << 12      # profile position: new set-point acknowledged
SW_FOLLOWING = 1 << 12         # cyclic synchronous position: drive follows the target

# Controlword commands (CiA 402 table 4).
SHUTDOWN = 0x0006
SWITCH_ON = 0x0007
ENABLE_OPERATION = 0x000F
DISABLE_VOLTAGE = 0x0000
QUICK_STOP = 0x0002
DISABLE_OPERATION = 0x0007
FAULT_RESET = 0x0080
CW_NEW_SETPOINT = 1 << 4
CW_CHANGE_IMMEDIATELY = 1 << 5
CW_RELATIVE = 1 << 6
CW_HALT = 1 << 8


def state_of(statusword: int) -> State:
    for mask, value, state in _PATTERNS:
        if statusword & mask == value:
            return state
    return State.NOT_READY_TO_SWITCH_ON


def next_command(state: State) -> int | None:
    """The controlword that takes a drive one step towards operation enabled.

    None means "nothing to send": already enabled, or the drive must finish on its own
    (not ready to switch on, fault reaction active).
    """
    return {
        State.FAULT: FAULT_RESET,
        State.SWITCH_ON_DISABLED: SHUTDOWN,
        State.READY_TO_SWITCH_ON: SWITCH_ON,
        State.SWITCHED_ON: ENABLE_OPERATION,
        State.QUICK_STOP_ACTIVE: DISABLE_VOLTAGE,
    }.get(state)


def transition(state: State, controlword: int, previous_controlword: int) -> State:
    """Where a drive in `state` goes on `controlword` (the emulator's state machine).

    Fault reset acts on the rising edge of bit 7 only, as CiA 402 requires.
    """
    cw = controlword
    if state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
        if state is State.FAULT and cw & FAULT_RESET and not previous_controlword & FAULT_RESET:
            return State.SWITCH_ON_DISABLED
        return state
    if cw & FAULT_RESET:
        return state
    if cw & 0x02 == 0:                                   # disable voltage (transitions 7, 9, 10, 12)
        return State.SWITCH_ON_DISABLED if state is not State.NOT_READY_TO_SWITCH_ON else state
    if cw & 0x06 == 0x02:                                # quick stop (7, 10, 11)
        if state is State.OPERATION_ENABLED:
            return State.QUICK_STOP_ACTIVE
        if state in (State.READY_TO_SWITCH_ON, State.SWITCHED_ON):
            return State.SWITCH_ON_DISABLED
        return state
    if cw & 0x0F == 0x06:                                # shutdown (2, 6, 8)
        if state in (State.SWITCH_ON_DISABLED, State.SWITCHED_ON, State.OPERATION_ENABLED):
            return State.READY_TO_SWITCH_ON
        return state
    if cw & 0x0F == 0x07:                                # switch on / disable operation (3, 5)
        if state in (State.READY_TO_SWITCH_ON, State.OPERATION_ENABLED):
            return State.SWITCHED_ON
        return state
    if cw & 0x0F == 0x0F:                                # enable operation (4, 16; 3+4)
        if state in (State.SWITCHED_ON, State.QUICK_STOP_ACTIVE, State.READY_TO_SWITCH_ON):
            return State.OPERATION_ENABLED
        return state
    return state
