"""Edges in the SIP flags become single events; the battery has hysteresis."""

from asibot.base_driver.notices import Notices
from asibot.base_driver.state import BaseState


def state(**kw) -> BaseState:
    base = dict(x=0.0, y=0.0, theta=0.0, vx=0.0, wz=0.0, volts=12.8, motors_enabled=True, estop_pressed=False,
                stall_left=False, stall_right=False, front_bumpers=[False] * 7, rear_bumpers=[False] * 7,
                sonar_ranges=[4.335] * 16, sonar_fresh=True, moving=False)
    base.update(kw)
    return BaseState(**base)


def run(states):
    events = []
    n = Notices(lambda level, code, text: events.append((level, code)))
    for s in states:
        n.update(s)
    return events


def test_a_held_bumper_is_one_event_and_a_new_hit_another():
    hit = state(front_bumpers=[False, True] + [False] * 5)
    assert run([state(), hit, hit, hit, state(), hit]) == [("warning", "bumper")] * 2


def test_stall_per_wheel_estop_button_and_motors():
    events = run([state(), state(stall_left=True, stall_right=True), state(estop_pressed=True),
                  state(motors_enabled=False), state(motors_enabled=False)])
    assert [c for _, c in events] == ["stall", "stall", "estop_button", "motors_disabled"]


def test_the_first_state_sets_the_baseline():
    assert run([state(rear_bumpers=[True] * 7)]) == []


def test_battery_low_critical_and_recovery_with_hysteresis():
    volts = [12.5, 11.7, 11.8, 11.7, 11.9, 11.7, 10.9, 11.1, 10.9, 12.1]
    assert run([state(volts=v) for v in volts]) == [
        ("warning", "battery_low"), ("error", "battery_critical"), ("info", "battery_ok")]


def test_no_battery_reading_is_not_an_alarm():
    assert run([state(volts=0.0)]) == []
