"""asibot.estop: the latched estop outlives whoever engaged it, since every process that obeys
it keeps serving it; a restarted driver learns it from the controller."""

from asibot import keys
from asibot.bus import Bus
from asibot.estop import EStopState, who
from asibot.messages import EStop
from asibot.testing import Inbox, wait_until

R = "arm-1"


def test_the_state_outlives_the_process_that_engaged_it(memory_bus):
    driver_bus, late = Bus("driver"), Bus("ui")
    try:
        seen = Inbox()
        driver = EStopState(driver_bus, R, seen)
        with Bus("asibot-estop") as button:            # engages, then exits
            button.latch(keys.estop(R), EStop(engaged=True, reason="test", by="ana"))
            wait_until(lambda: driver.engaged, 2)
        learnt = Inbox()
        late.subscribe(keys.estop(R), EStop, learnt, latest=True)
        wait_until(lambda: len(learnt), 2, message="a subscriber started later learnt nothing")
        assert learnt.last().engaged and learnt.last().by == "ana"
    finally:
        late.close()
        driver_bus.close()


def test_a_restarted_driver_learns_it_from_the_controller(memory_bus):
    controller_bus = Bus("kinematics")
    try:
        controller = EStopState(controller_bus, R, lambda msg: None)
        with Bus("asibot-estop") as button:
            button.latch(keys.estop(R), EStop(engaged=True, reason="test"))
            wait_until(lambda: controller.engaged, 2)
        with Bus("driver") as first:                     # a driver that then crashes
            crashed = EStopState(first, R, lambda msg: None)
            wait_until(lambda: crashed.engaged, 2)
        with Bus("driver-restarted") as restarted:
            again = Inbox()
            EStopState(restarted, R, again)
            wait_until(lambda: len(again), 2, message="the restarted driver learnt nothing")
            assert again.last().engaged
    finally:
        controller_bus.close()


def test_the_newest_state_wins_and_an_older_one_is_ignored(memory_bus):
    with Bus("driver") as driver_bus, Bus("ui") as ui:
        seen = Inbox()
        state = EStopState(driver_bus, R, seen)
        ui.latch(keys.estop(R), EStop(engaged=True, stamp=2_000))
        wait_until(lambda: state.engaged, 2)
        ui.latch(keys.estop(R), EStop(engaged=False, stamp=1_000))   # older: a late copy
        ui.latch(keys.estop(R), EStop(engaged=True, reason="newest", stamp=3_000))
        wait_until(lambda: state.state.reason == "newest", 2)
        assert [m.stamp for m in seen.all()] == [2_000, 3_000]


def test_who_names_the_user_the_program_and_the_process():
    text = who("asibot release")
    assert "@" in text and "(asibot release, pid " in text
