"""asibot.bus.OnDemand: a service subscribes to camera pictures only while it is asked for them
(the web while a page watches, perception when it finds an object). A camera's publisher sees a
subscriber from the first ask until the asks stop, then none, so the sim renders nothing."""

from __future__ import annotations

import threading
import time

from asibot import keys, messages as m
from asibot.bus import Bus, OnDemand
from asibot.testing import wait_until

KEY = keys.camera_rgb("asibot-sim", "kitchen")
EVERY = keys.every_robot(keys.camera_rgb, "*")


def test_subscribed_from_the_first_ask_until_the_asks_stop(memory_bus):
    web, camera = Bus("web"), Bus("camera")
    pub = camera.publisher(KEY, m.RgbImage)
    subscribed: list[str] = []

    def declare():
        subscribed.append(EVERY)
        return web.subscribe_raw(EVERY, lambda k, p, t: None)
    demand = OnDemand(web, declare, linger_s=1.0)
    try:
        assert not pub.matching(), "no page asked yet: nothing subscribed, the camera renders nothing"
        for _ in range(10):                     # a page polling ten times a second
            demand.want()
            assert pub.matching()
            time.sleep(0.1)
        assert len(subscribed) == 1, "asks closer together than the linger keep one subscription"
        wait_until(lambda: not pub.matching(), timeout=5, message="the asks stopped, the subscription stayed")
        demand.want()
        assert pub.matching() and len(subscribed) == 2, "a later ask subscribes again"
    finally:
        demand.close()
        web.close()
        camera.close()
    assert not pub.matching()


def test_the_first_ask_waits_for_the_first_picture(memory_bus):
    web, camera = Bus("web"), Bus("camera")
    pub = camera.publisher(KEY, m.RgbImage)
    got: list[str] = []
    demand = OnDemand(web, lambda: web.subscribe_raw(EVERY, lambda k, p, t: got.append(k)))
    sending = threading.Event()

    def camera_loop() -> None:              # a camera that sends once someone subscribes
        while not sending.wait(0.02):
            if pub.matching():
                pub.put(m.RgbImage(jpeg=b"\xff\xd8", width=1, height=1))
    thread = threading.Thread(target=camera_loop, daemon=True)
    thread.start()
    try:
        demand.want(lambda: bool(got))
        assert got, "want() came back before the first picture"
    finally:
        sending.set()
        thread.join()
        demand.close()
        web.close()
        camera.close()
