"""The page's live feed (asibot.web.live): a robot's view is pushed when it changed, not again
while it stays the same (a still arm's driver says the same 100 times a second), and a page that
attaches gets the next view even if it is the one pushed before."""

from __future__ import annotations

import asyncio
import json
import time

from asibot.web.live import PUSH_HZ, Live

ROBOT = "asibot-sim"


def test_a_still_robot_is_pushed_once_a_move_is_pushed_and_a_new_page_gets_the_next():
    view = {"id": ROBOT, "deg": 20.0}
    live = Live(lambda robot: dict(view), lambda: [dict(view)])

    async def pushed(page, deg: float) -> None:
        """The driver says the state until the page has it (a deadline of 5 s)."""
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            live.changed(ROBOT)
            await asyncio.sleep(1 / PUSH_HZ)
            if any(json.loads(t).get("robot", {}).get("deg") == deg for t in page.outbox._queue):
                return
        raise AssertionError(f"{deg} was never pushed")

    def robots(page) -> list:
        sent = [json.loads(t) for t in page.outbox._queue]
        return [m["robot"]["deg"] if m["type"] == "robot" else m["type"] for m in sent]

    async def scenario() -> tuple[list, list]:
        pusher = asyncio.ensure_future(live.pusher())
        first = await live.attach(object())       # the outbox is read here, not sent
        await pushed(first, 20.0)
        for _ in range(6):                        # the same state, six ticks of the pusher
            live.changed(ROBOT)
            await asyncio.sleep(1 / PUSH_HZ)
        view["deg"] = 21.0                        # the arm moved
        await pushed(first, 21.0)
        view["deg"] = 20.0
        second = await live.attach(object())      # its snapshot: 20; then back at 21 before a push
        view["deg"] = 21.0
        await pushed(second, 21.0)
        pusher.cancel()
        return robots(first), robots(second)

    first, second = asyncio.run(scenario())
    assert first[:4] == ["hello", "robots", 20.0, 21.0], first
    assert second[:3] == ["hello", "robots", 21.0], second
