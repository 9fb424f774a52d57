"""The status board keeps following the robots: a subscription that went quiet while nav runs
is declared again (seen once in CI: status, pose and events stopped while calls still worked)."""

from __future__ import annotations

from asibot import keys
from asibot import messages as m
from asibot.bus import Bus
from asibot.testing import wait_until

from asibot.asterics_bridge.status import RESUBSCRIBE_EVERY_NS, STALE_NS, StatusBoard

ROBOT = "pioneer-sim"


class Clock:
    def __init__(self) -> None:
        self.t = 10 ** 12

    def __call__(self) -> int:
        return self.t


def status(text: str, state: str = "active") -> m.NavStatus:
    return m.NavStatus(goal_id=1, state=state, text=text, place="fridge")


def test_a_quiet_subscription_is_declared_again_while_nav_runs(memory_bus):
    nav_bus, bridge_bus = Bus("nav", memory_bus), Bus("asterics_bridge", memory_bus)
    clock = Clock()
    board = StatusBoard(bridge_bus, lambda notice: None, clock)
    pub = nav_bus.publisher(keys.nav_status(ROBOT), m.NavStatus)
    token = nav_bus.announce(keys.service("nav", ROBOT))
    pub.put(status("driving to fridge"))
    wait_until(lambda: board.json(ROBOT)["text"] == "driving to fridge", 5)

    for sub in board._subscriptions:    # what CI saw: nothing delivered any more
        sub.close()
    pub.put(status("arrived at fridge", "succeeded"))
    assert not board.check()                              # not quiet for long yet
    clock.t += STALE_NS + 1
    assert board.json(ROBOT)["state"] == "active"         # the board still believes it drives
    assert board.check() and board.resubscribed == 1
    pub.put(status("arrived at fridge", "succeeded"))
    wait_until(lambda: board.json(ROBOT)["state"] == "succeeded", 5, message="not following nav again")

    clock.t += STALE_NS + 1                               # quiet again at once: not again so soon
    assert not board.check()
    clock.t += RESUBSCRIBE_EVERY_NS
    token.close()                                         # nav stopped: its silence is no fault of ours
    wait_until(lambda: keys.service("nav", ROBOT) not in bridge_bus.alive(keys.ALL_SERVICES), 5)
    assert not board.check() and board.resubscribed == 1
    for bus in (nav_bus, bridge_bus):
        bus.close()
