"""asibot.safety.estop: the latched estop outlives whoever engaged it, since every process that obeys
it keeps serving it; a restarted driver learns it from the controller."""

import dataclasses

from asibot.safety import estop, identity
from asibot import keys
from asibot.bus import Bus
from asibot.safety.estop import EStopState, who
from asibot.safety.identity import Identity
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


def test_a_release_counts_only_signed_and_names_the_key_that_signed_it(memory_bus):
    with Bus("driver") as driver_bus, Bus("ui") as ui, Bus("stranger") as stranger:
        seen, refused = Inbox(), Inbox()
        state = EStopState(driver_bus, R, seen, on_refused=lambda msg, why: refused((msg, why)))
        engage = estop.latch(ui, R, Identity("web"), True, "test", "ana@home (web, pid 1)")
        wait_until(lambda: state.engaged, 2)
        # Unsigned, or signed in another's name by a key that is not its: ignored, and said.
        stranger.latch(keys.estop(R), EStop(engaged=False, reason="anonymous", by="ana@home (web, pid 1)"))
        wait_until(lambda: len(refused) == 1, 2)
        nurse = Identity("web")
        borrowed = dataclasses.replace(estop.latch(stranger, "elsewhere", Identity("x"), False, "x", "bob"),
                                       signer=nurse.id)
        stranger.latch(keys.estop(R), borrowed)
        wait_until(lambda: len(refused) == 2, 2)
        # Signed for another robot: not a release of this one.
        stranger.latch(keys.estop(R), estop.latch(stranger, "elsewhere", nurse, False, "x", "bob"))
        wait_until(lambda: len(refused) == 3, 2)
        assert state.engaged and [m.stamp for m in seen.all()] == [engage.stamp]
        msg, why = refused.all()[0]
        assert why == "it is not signed"
        assert "ana@home (web, pid 1), unsigned" in estop.refused_text(msg, why)
        assert "is not" in refused.all()[1][1] and "elsewhere" not in refused.all()[1][1]
        release = estop.latch(ui, R, nurse, False, "released", "bob@home (asibot release, pid 2)")
        wait_until(lambda: not state.engaged, 2)
        assert estop.named(release) == f"bob@home (asibot release, pid 2), key {identity.short(nurse.id)}"
        assert estop.named(EStop(engaged=True)) == ""


def test_an_unsigned_engage_still_stops(memory_bus):
    with Bus("driver") as driver_bus, Bus("button") as button:
        state = EStopState(driver_bus, R, lambda msg: None)
        button.latch(keys.estop(R), EStop(engaged=True, reason="a panel that cannot sign"))
        wait_until(lambda: state.engaged, 2)
