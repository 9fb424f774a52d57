"""The CiA 402 state machine, from both sides."""

from __future__ import annotations

import pytest

from asibot.arm_driver import cia402
from asibot.arm_driver.cia402 import State


@pytest.mark.parametrize("statusword, state", [
    (0x0000, State.NOT_READY_TO_SWITCH_ON), (0x0250, State.SWITCH_ON_DISABLED),
    (0x0231, State.READY_TO_SWITCH_ON), (0x0233, State.SWITCHED_ON), (0x1637, State.OPERATION_ENABLED),
    (0x0217, State.QUICK_STOP_ACTIVE), (0x021F, State.FAULT_REACTION_ACTIVE), (0x0218, State.FAULT),
])
def test_statusword_patterns(statusword, state):
    assert cia402.state_of(statusword) is state


def test_master_steps_lead_to_operation_enabled_from_every_state():
    for start in State:
        state, steps, previous = start, 0, 0
        while state is not State.OPERATION_ENABLED and steps < 6:
            cw = cia402.next_command(state)
            if cw is None:                     # the drive must move on its own
                assert state in (State.NOT_READY_TO_SWITCH_ON, State.FAULT_REACTION_ACTIVE)
                break
            state, previous = cia402.transition(state, cw, previous), cw
            steps += 1
        else:
            assert state is State.OPERATION_ENABLED


def test_fault_reset_needs_a_rising_edge():
    assert cia402.transition(State.FAULT, 0x80, 0x00) is State.SWITCH_ON_DISABLED
    assert cia402.transition(State.FAULT, 0x80, 0x80) is State.FAULT
    assert cia402.transition(State.FAULT, 0x0F, 0x00) is State.FAULT


def test_quick_stop_and_disable():
    assert cia402.transition(State.OPERATION_ENABLED, cia402.QUICK_STOP, 0x0F) is State.QUICK_STOP_ACTIVE
    assert cia402.transition(State.QUICK_STOP_ACTIVE, cia402.DISABLE_VOLTAGE, 0x02) is State.SWITCH_ON_DISABLED
    assert cia402.transition(State.OPERATION_ENABLED, cia402.DISABLE_OPERATION, 0x0F) is State.SWITCHED_ON
    assert cia402.transition(State.SWITCH_ON_DISABLED, cia402.ENABLE_OPERATION, 0) is State.SWITCH_ON_DISABLED
