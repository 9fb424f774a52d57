"""Nav's first motion waits until the base driver names nav as the base's holder.

Nav's first Twist can reach the driver a few ms before nav's liveliness token does. Refused
then, it makes the whole primitive "a stream from before" the takeover (asibot.safety.arming), and a
primitive sent just after nav started would never move the base: the same race that made a
movj do nothing right after the kinematics service started (asibot.safety.ownership.HoldWait).
"""

from __future__ import annotations

import threading
import time

import pytest

from asibot.safety import identity, ownership
from asibot import keys
from asibot import messages as m
from asibot.bus import Bus
from asibot.client import NavClient
from asibot.errors import RpcError
from asibot.nav.geometry import Pose
from asibot.nav.service import NavService
from asibot.testing import wait_until

START = Pose(1.0, 1.5, 0.0)
ROBOT = "pioneer-hold"


def test_the_first_primitive_waits_until_the_driver_names_nav_holder(memory_bus, apartment, world_places):
    bus = Bus("nav", memory_bus)
    svc = NavService(bus, ROBOT, apartment, world_places, START, run_loop=False)
    driver = Bus("base_driver", memory_bus)
    knows: list[str] = []                     # whom the driver's status names as the base's holder
    asked: list[dict] = []

    def status(req: dict) -> dict:
        asked.append(req)
        return {"holders": {"base": "".join(knows[-1:])}}
    driver.serve(keys.driver_rpc(ROBOT, "status"), status)
    odom = driver.publisher(keys.base_odom(ROBOT), m.Odometry)
    quit_odom = threading.Event()

    def odometry() -> None:                   # a base standing at the start, at 20 Hz
        while not quit_odom.wait(0.05):
            odom.put(m.Odometry(x=START.x, y=START.y, theta=START.theta, stamp=time.time_ns()))
    sender = threading.Thread(target=odometry, daemon=True)
    sender.start()
    try:
        with NavClient(ROBOT, timeout=10) as nav:
            wait_until(lambda: svc.pilot._odom is not None, 5)
            nav.primitive("stop")
            assert asked == [], "a stop waited for the driver: a stop is never delayed"
            done: list = []
            t = threading.Thread(target=lambda: done.append(nav.primitive("forward")))
            t.start()
            time.sleep(0.3)
            assert done == [] and not svc.pilot._driving, "the primitive began before the driver named nav"
            knows.append(svc.controller)
            t.join(10)
            assert done and svc.pilot._driving
            svc.step()
            assert svc.commands >= 1
            # once named, never asked again: a second motion goes at once
            knows.append("someone-else")
            nav.primitive("stop")
            before = len(asked)
            nav.primitive("backward")
            assert svc.pilot._driving and len(asked) == before
            # a driver that comes back learns anew: nav asks again
            svc.hold.forget()
            assert not svc.hold.wait(time.monotonic() + 0.2)
            knows.append(svc.controller)
            assert svc.hold.wait(time.monotonic() + 2)
    finally:
        quit_odom.set()
        sender.join(2)
        svc.close()
        driver.close()
        bus.close()


def test_while_another_program_holds_the_base_nav_says_so_at_once(memory_bus, apartment, world_places):
    other = Bus("joystick", memory_bus)
    # Alive before nav, and first by id among those nav finds at its start ("joystick-" sorts
    # before "nav-"): it holds the base in nav's view as in the driver's.
    teleop = ownership.announce(other, ROBOT, "base", "joystick")
    bus = Bus("nav", memory_bus)
    svc = NavService(bus, ROBOT, apartment, world_places, START, run_loop=False)
    driver = Bus("base_driver", memory_bus)
    asked: list[dict] = []

    def status(req: dict) -> dict:
        asked.append(req)
        return {"holders": {"base": teleop.id}}
    driver.serve(keys.driver_rpc(ROBOT, "status"), status)
    try:
        wait_until(lambda: svc.holder.current == teleop.id, 5)
        with NavClient(ROBOT, timeout=10) as nav:
            for move in (lambda: nav.primitive("forward"), lambda: nav.goto("fridge"), lambda: nav.turn(90),
                         lambda: bus.call(keys.nav_rpc(ROBOT, "localize"), {}, timeout=5)):   # it turns in place
                with pytest.raises(RpcError, match=f"Another program drives the base of {ROBOT} \\({identity.short(teleop.id)}\\)") as err:
                    move()
                assert err.value.code == "busy"
            assert asked == [], "nav waited for the driver to name it, though another program held the base"
            assert not svc.pilot._driving
            nav.primitive("stop")                     # a stop is always taken
            nav.primitive(" Stop ")                   # in any case and spacing
    finally:
        svc.close()
        driver.close()
        bus.close()
        other.close()
