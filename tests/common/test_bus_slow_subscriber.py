"""A slow subscriber holds up only itself: the other subscriptions and the calls of its bus go on.

In CI the AsTeRICS bridge's subscriptions once all went quiet while nav ran. The cause: on Zenoh,
a subscription's full FIFO channel blocked the session's receive path, so every subscription of
that bus and every reply to its calls waited for one slow callback. Both backends are held to
the same rule here: a full subscription drops its oldest waiting message, and nothing waits.
"""

import threading

from asibot import keys, messages as m
from asibot.bus import Bus
from asibot.testing import wait_until


def test_a_stuck_callback_does_not_silence_the_other_subscriptions_or_the_calls(endpoint):
    with Bus("talker", endpoint) as talker, Bus("listener", endpoint) as listener:
        stuck = threading.Event()
        unstick = threading.Event()
        events, statuses = [], []

        def slow(msg):
            stuck.set()
            unstick.wait(30)
            events.append(msg.text)
        listener.subscribe(keys.events("r1"), m.Event, slow, maxsize=5)
        listener.subscribe(keys.nav_status("r1"), m.NavStatus, statuses.append)
        talker.serve("test/rpc/echo", lambda req: {"n": req.get("n")})
        flood = talker.publisher(keys.events("r1"), m.Event, block=True)
        status = talker.publisher(keys.nav_status("r1"), m.NavStatus)
        assert flood.wait_for_subscribers(5) and status.wait_for_subscribers(5)
        try:
            for i in range(200):       # far more than the stuck subscription keeps
                flood.put(m.Event(level="info", code="tick", text=str(i)))
            assert stuck.wait(5)
            for i in range(5):
                status.put(m.NavStatus(goal_id=i, state="active", text=f"driving {i}"))
            wait_until(lambda: len(statuses) == 5, 5,
                       message="another subscription of the same bus goes quiet behind a stuck one")
            assert listener.call("test/rpc/echo", {"n": 7}, timeout=5)["n"] == 7
        finally:
            unstick.set()
        # once the callback is free again it gets the newest; the oldest waiting ones were dropped
        wait_until(lambda: events and events[-1] == "199", 10)
        assert len(events) <= 1 + 5 and events == sorted(events, key=int), events
