"""The page's live feed (asibot.web.live): a robot's view is pushed when it changed, not again
while it stays the same (a still arm's driver says the same 100 times a second)."""

from __future__ import annotations

import asyncio
import json

from asibot.web.live import PUSH_HZ, Live


def test_a_still_robot_is_pushed_once_and_a_move_is_pushed():
    view = {"id": "asibot-sim", "joints": {"deg": [0.0, 20.0]}}
    live = Live(lambda robot: dict(view), lambda: [dict(view)])

    async def scenario() -> list[dict]:
        pusher = asyncio.ensure_future(live.pusher())
        page = await live.attach(object())       # the outbox is read here, not sent
        ticks = 2.0 / PUSH_HZ
        for _ in range(6):                        # the driver says the same state, tick after tick
            live.changed("asibot-sim")
            await asyncio.sleep(ticks)
        view["joints"] = {"deg": [0.0, 21.0]}     # the arm moved
        for _ in range(3):
            live.changed("asibot-sim")
            await asyncio.sleep(ticks)
        pusher.cancel()
        sent = []
        while not page.outbox.empty():
            sent.append(json.loads(page.outbox.get_nowait()))
        return sent

    sent = asyncio.run(scenario())
    assert [m["type"] for m in sent[:2]] == ["hello", "robots"]
    pushed = [m["robot"]["joints"]["deg"] for m in sent[2:]]
    assert pushed == [[0.0, 20.0], [0.0, 21.0]], pushed
