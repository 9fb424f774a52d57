"""asibot.safety.estop: the latched estop outlives whoever engaged it, since every process that obeys
it keeps serving it; a restarted driver learns it from the controller. No stamp decides: the
attacks of issue 51 (a release from the future, a clock 30 s off either way, an engage from
the future, a release played again) each fail."""

import dataclasses
import time

import pytest

from asibot.safety import estop, identity
from asibot import keys
from asibot.bus import Bus
from asibot.safety.estop import EStopState, who
from asibot.safety.identity import Identity
from asibot.messages import EStop
from asibot.testing import Inbox, wait_until
from asibot.web.fleet import Fleet

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


def test_a_release_clears_only_the_engages_received_before_it(memory_bus):
    """Arrival order decides, not stamps: an engage after a release stops again whatever its
    stamp says, and the same message twice (the latched answer and its sample) counts once."""
    with Bus("driver") as driver_bus, Bus("ui") as ui:
        seen = Inbox()
        state = EStopState(driver_bus, R, seen)
        page = Identity("web")
        first = estop.latch(ui, R, page, True, "first", "ana")
        wait_until(lambda: state.engaged, 2)
        estop.latch(ui, R, page, False, "released", "ana")
        wait_until(lambda: not state.engaged, 2)
        late = page.sign(EStop(engaged=True, reason="stamped before the release", by="ana",
                               stamp=first.stamp - 1), estop.context(R))
        ui.latch(keys.estop(R), late)
        wait_until(lambda: state.engaged, 2, message="an engage stamped before the release was ignored")
        ui.latch(keys.estop(R), late)
        wait_until(lambda: len(seen) == 3, 2)
        assert [m.reason for m in seen.all()] == ["first", "released", "stamped before the release"]


YEARS_10 = 10 * 365 * 86_400 * 10**9
SECONDS_30 = 30 * 10**9


def _signed(sender: Identity, engaged: bool, by: str, skew_ns: int, reason: str = "") -> EStop:
    return sender.sign(EStop(engaged=engaged, reason=reason, by=by, stamp=time.time_ns() + skew_ns),
                       estop.context(R))


def test_a_release_stamped_ten_years_ahead_never_switches_the_estop_off(memory_bus):
    """The attack of issue 51: a local process latched a release signed with its own key and
    stamped ten years ahead; two presses of the page's estop then counted for nothing."""
    with Bus("driver") as driver_bus, Bus("web") as web, Bus("mallory") as mallory:
        refused = Inbox()
        state = EStopState(driver_bus, R, lambda msg: None, lambda msg, why: refused(why))
        mallory.latch(keys.estop(R), _signed(Identity("mallory"), False, "mallory", YEARS_10))
        wait_until(lambda: len(refused) == 1, 2)
        assert "ahead of this robot's clock" in refused.last() and "days" in refused.last()
        estop.latch(web, R, Identity("web"), True, "emergency stop from the page", "ana")
        wait_until(lambda: state.engaged, 2, message="the page's estop did not count after a future release")
        # And while engaged, the future release is refused again: the robot stays stopped.
        mallory.latch(keys.estop(R), _signed(Identity("mallory"), False, "mallory", YEARS_10))
        wait_until(lambda: len(refused) == 2, 2)
        assert state.engaged


@pytest.mark.parametrize("skew_ns", [SECONDS_30, -SECONDS_30], ids=["ahead", "behind"])
def test_a_clock_30_s_off_neither_releases_nor_escapes_a_stop(memory_bus, skew_ns):
    """A sender whose clock is 30 s off: its release is refused and said; its engage stops (and
    is said, so someone sets the clock), and a release at the right time clears it."""
    with Bus("driver") as driver_bus, Bus("web") as web, Bus("laptop") as laptop:
        refused, skewed = Inbox(), Inbox()
        state = EStopState(driver_bus, R, lambda msg: None, lambda msg, why: refused(why),
                           lambda msg, text: skewed(text))
        page, off = Identity("web"), Identity("laptop")
        estop.latch(web, R, page, True, "stop", "ana")
        wait_until(lambda: state.engaged, 2)
        laptop.latch(keys.estop(R), _signed(off, False, "bob@laptop", skew_ns))
        wait_until(lambda: len(refused) == 1, 2)
        assert ("ahead of" if skew_ns > 0 else "in the past") in refused.last()
        assert "30 s" in refused.last() and state.engaged
        estop.latch(web, R, page, False, "released", "ana")
        wait_until(lambda: not state.engaged, 2)
        laptop.latch(keys.estop(R), _signed(off, True, "bob@laptop", skew_ns, "skewed stop"))
        wait_until(lambda: state.engaged, 2, message="an engage from a clock 30 s off did not stop")
        wait_until(lambda: len(skewed) == 1, 2)
        assert "30 s" in skewed.last() and "It counts" in skewed.last()
        estop.latch(web, R, page, False, "released", "ana")
        wait_until(lambda: not state.engaged, 2, message="a stop from a skewed clock could not be released")


def test_an_engage_stamped_ten_years_ahead_stops_and_can_be_released(memory_bus):
    """It could never be released, while the page showed "released" and nav refused to drive."""
    with Bus("driver") as driver_bus, Bus("web") as web:
        fleet = Fleet(web)
        state = EStopState(driver_bus, R, lambda msg: None)
        with Bus("mallory") as mallory:              # engages from the future, then exits
            mallory.latch(keys.estop(R), _signed(Identity("mallory"), True, "mallory", YEARS_10))
            wait_until(lambda: state.engaged and fleet.estops.engaged(R), 2)
            wait_until(lambda: state.state.stamp > time.time_ns() + YEARS_10 // 2, 2)
        estop.latch(web, R, Identity("web"), False, "released from the page", "ana")
        wait_until(lambda: not state.engaged, 2, message="an engage from the future could not be released")
        # The page shows what the driver holds, also to a page started now.
        wait_until(lambda: not fleet.estops.engaged(R), 2)
        with Bus("web-restarted") as again:
            assert not Fleet(again).estops.engaged(R)


def test_a_recorded_release_played_again_is_refused(memory_bus):
    with Bus("driver") as driver_bus, Bus("web") as web, Bus("replay") as replay:
        refused = Inbox()
        state = EStopState(driver_bus, R, lambda msg: None, lambda msg, why: refused(why))
        page = Identity("web")
        estop.latch(web, R, page, True, "stop", "ana")
        wait_until(lambda: state.engaged, 2)
        release = estop.latch(web, R, page, False, "released", "ana")
        wait_until(lambda: not state.engaged, 2)
        estop.latch(web, R, page, True, "stop again", "ana")
        wait_until(lambda: state.engaged, 2)
        replay.latch(keys.estop(R), release)            # within the clock's tolerance: by its number
        wait_until(lambda: len(refused) == 1, 2)
        assert "played again" in refused.last() and state.engaged
        old = dataclasses.replace(release, stamp=release.stamp - 60 * 10**9)
        replay.latch(keys.estop(R), old)                 # a minute old: by its stamp, even unsigned
        wait_until(lambda: len(refused) == 2, 2)
        assert state.engaged


def test_a_release_that_names_nobody_is_refused(memory_bus):
    with Bus("driver") as driver_bus, Bus("web") as web:
        refused = Inbox()
        state = EStopState(driver_bus, R, lambda msg: None, lambda msg, why: refused(why))
        estop.latch(web, R, Identity("web"), True, "stop", "ana")
        wait_until(lambda: state.engaged, 2)
        estop.latch(web, R, Identity("web"), False, "released", " ")
        wait_until(lambda: len(refused) == 1, 2)
        assert refused.last() == "it does not say who released it" and state.engaged


def test_a_follower_started_later_starts_stopped_when_one_keeper_holds_an_engage(memory_bus):
    """A keeper that holds an engage (one that missed the release, or a stranger's) is enough:
    the newcomer starts stopped, whatever the stamps, and the next release clears it."""
    with Bus("kinematics") as keeper, Bus("mallory") as mallory, Bus("web") as web:
        EStopState(keeper, R, lambda msg: None)
        page = Identity("web")
        estop.latch(web, R, page, True, "stop", "ana")
        estop.latch(web, R, page, False, "released", "ana")
        mallory.latch(keys.estop(R), EStop(engaged=True, reason="stale", stamp=1))
        mallory.latch(keys.estop(R), _signed(Identity("m"), False, "mallory", YEARS_10))  # refused by all
        with Bus("driver-restarted") as restarted:
            state = EStopState(restarted, R, lambda msg: None)
            wait_until(lambda: state.state is not None, 2)
            assert state.engaged
            estop.latch(web, R, page, False, "released again", "ana")
            wait_until(lambda: not state.engaged, 2)


def test_a_follower_started_later_ignores_a_release_latched_from_the_future(memory_bus):
    with Bus("mallory") as mallory, Bus("driver") as driver_bus:
        mallory.latch(keys.estop(R), _signed(Identity("m"), False, "mallory", YEARS_10))
        refused = Inbox()
        state = EStopState(driver_bus, R, lambda msg: None, lambda msg, why: refused(why))
        wait_until(lambda: len(refused) == 1, 2)
        assert state.state is None


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
