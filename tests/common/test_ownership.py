"""asibot.ownership: which controller holds a part of a robot, from the liveliness tokens."""

import time

import pytest

from asibot import keys, ownership
from asibot.bus import Bus
from asibot.testing import wait_until


def test_controller_keys_name_the_controller_and_parse_back():
    assert keys.controller_alive("asibot", "kinematics-1a2b") == "rb/asibot/controller/alive/kinematics-1a2b"
    assert keys.base_controller_alive("pioneer", "nav-9") == "rb/pioneer/base/controller/alive/nav-9"
    assert keys.controller_of(keys.controller_alive("asibot", "k-1")) == "k-1"
    assert keys.controller_of(keys.base_controller_alive("pioneer", "nav-9")) == "nav-9"
    for other in (keys.driver_alive("asibot"), keys.controllers_alive("asibot"), "rb/asibot/controller/alive",
                  "svc/kinematics/asibot"):
        assert keys.controller_of(other) is None, other
    assert keys.ALL_CONTROLLERS == keys.every_robot(keys.controllers_alive)
    with pytest.raises(ValueError, match="not a valid name"):
        keys.controller_alive("asibot", "a/b")


def test_ids_are_new_at_every_start_and_valid_key_chunks():
    a, b = ownership.new_id("kinematics"), ownership.new_id("kinematics")
    assert a != b and a.startswith("kinematics-")
    keys.controller_alive("r", a)


def test_the_first_controller_alive_holds_until_it_vanishes_then_the_next_oldest():
    changes = []
    h = ownership.Holder("asibot", "arm", on_change=changes.append)
    key = lambda c: keys.controller_alive("asibot", c)  # noqa: E731
    assert h.current is None and h.refusal("a") is not None
    h.update(key("a"), True)
    h.update(key("b"), True)
    h.update(key("a"), True)                   # a token seen twice (alive() then watch())
    assert h.current == "a" and h.alive == ["a", "b"] and h.refusal("a") is None
    refused = h.refusal("b")
    assert refused.reason == "not_holder" and refused.code == "not_holder"
    assert "came from controller 'b', and controller 'a' holds the arm of asibot" in str(refused)
    assert "without a controller identity" in str(h.refusal(""))
    h.update(key("b"), False)                  # not the holder: nothing changes
    h.update(key("c"), True)
    h.update(key("a"), False)
    assert h.current == "c" and changes == ["a", "c"]
    h.update(key("c"), False)
    assert h.current is None and changes == ["a", "c", None]
    assert "no controller holds the arm of asibot" in str(h.refusal("c"))
    h.update(keys.base_controller_alive("asibot", "x") + "/extra", True)   # not a controller token
    assert h.current is None


def test_holders_follow_the_bus_and_arm_and_base_are_held_apart(memory_bus):
    arm, base = ownership.Holder("r", "arm"), ownership.Holder("r", "base")
    with Bus("watcher") as watcher, Bus("kinematics") as kin, Bus("nav") as nav:
        k = ownership.announce(kin, "r", "arm", "kinematics")
        arm.follow(watcher)                     # one alive before following, one after
        base.follow(watcher)
        n = ownership.announce(nav, "r", "base", "nav")
        wait_until(lambda: arm.current == k and base.current == n, 2)
        kin.close()
        wait_until(lambda: arm.current is None, 2)
        assert base.current == n
    with pytest.raises(ValueError, match="part must be one of arm, base"):
        ownership.Holder("r", "gripper")


def test_hold_wait_asks_the_driver_until_it_names_us_and_not_after(memory_bus):
    robot = "hold-wait"
    bus = Bus("kinematics", memory_bus)
    try:
        hold = ownership.HoldWait(bus, robot, "arm", "k-1", poll=0.005)
        assert not hold.wait(time.monotonic() + 0.2)                  # no driver answers: not held
        said: list = [{"holders": {"arm": "k-0"}}]
        asked: list = []
        driver = Bus("arm_driver", memory_bus)
        driver.serve(keys.driver_rpc(robot, "status"), lambda req: asked.append(1) or said[-1])
        assert not hold.wait(time.monotonic() + 0.1) and asked       # another holds it
        said.append({"holders": {"arm": "k-1"}})
        assert hold.wait(time.monotonic() + 2) and hold.held
        n = len(asked)
        assert hold.wait(time.monotonic() + 2) and len(asked) == n   # asked once per driver
        hold.forget()
        said.append({"robot": robot})                                   # a driver that does not say
        assert hold.wait(time.monotonic() + 2)
        base = ownership.HoldWait(bus, robot, "base", "nav-1")         # says nothing of the base
        assert base.wait(time.monotonic() + 2)
        with pytest.raises(ValueError, match="part must be one of arm, base"):
            ownership.HoldWait(bus, robot, "wheel", "x")
        driver.close()
    finally:
        bus.close()
