"""asibot.safety.ownership: which controller holds a part of a robot, from the liveliness tokens."""

import dataclasses
import time

import pytest

from asibot.safety import identity, ownership
from asibot import keys
from asibot.bus import Bus
from asibot.safety.identity import Identity
from asibot.messages import ArmCommand, GripperCommand, Twist
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


def test_ids_are_new_at_every_start_carry_a_key_and_are_valid_key_chunks():
    a, b = ownership.Controller("r", "arm", "kinematics"), ownership.Controller("r", "arm", "kinematics")
    assert a.id != b.id and a.id.startswith("kinematics-")
    assert identity.public_key(a.id) is not None
    keys.controller_alive("r", a.id)
    with pytest.raises(ValueError, match="part must be one of arm, base"):
        ownership.Controller("r", "wheel")


def alive(*controllers) -> ownership.Holder:
    h = ownership.Holder("asibot", "arm")
    for c in controllers:
        h.update(keys.controller_alive("asibot", c.id), True)
    return h


def test_the_first_controller_alive_holds_until_it_vanishes_then_the_next_oldest():
    changes = []
    h = ownership.Holder("asibot", "arm", on_change=changes.append)
    a, b, c = (ownership.Controller("asibot", "arm", n) for n in "abc")
    key = lambda c: keys.controller_alive("asibot", c.id)  # noqa: E731
    assert h.current is None and h.refusal(a.sign(Twist(vx=0.0, wz=0.0))) is not None
    h.update(key(a), True)
    h.update(key(b), True)
    h.update(key(a), True)                   # a token seen twice (alive() then watch())
    assert h.current == a.id and h.alive == [a.id, b.id]
    assert h.refusal(a.sign(GripperCommand(opening=0.01))) is None
    refused = h.refusal(b.sign(GripperCommand(opening=0.01)))
    assert refused.reason == "not_holder" and refused.code == "not_holder"
    assert f"came from controller {b.id!r}, and controller {a.id!r} holds the arm of asibot" in str(refused)
    assert "without a controller identity" in str(h.refusal(GripperCommand(opening=0.01)))
    h.update(key(b), False)                  # not the holder: nothing changes
    h.update(key(c), True)
    h.update(key(a), False)
    assert h.current == c.id and changes == [a.id, c.id]
    h.update(key(c), False)
    assert h.current is None and changes == [a.id, c.id, None]
    assert "no controller holds the arm of asibot" in str(h.refusal(c.sign(GripperCommand(opening=0.01))))
    h.update(keys.base_controller_alive("asibot", "x") + "/extra", True)   # not a controller token
    assert h.current is None


def test_a_command_that_borrows_the_holders_id_is_refused():
    holder, stranger = ownership.Controller("asibot", "arm", "kinematics"), Identity("kinematics")
    h = alive(holder)
    cmd = ArmCommand(mode="position", values=[0.5] * 5, controller=holder.id)
    unsigned = h.refusal(cmd)
    assert unsigned.code == "not_signed" and "it is not signed" in str(unsigned)
    # Signed by another key, in the holder's name: what a process that read the token can do.
    forged = dataclasses.replace(stranger.sign(cmd, "asibot/arm"), controller=holder.id)
    assert h.refusal(forged).code == "not_signed"
    # The holder's own signature, with a field changed after it signed.
    signed = holder.sign(cmd)
    assert h.refusal(dataclasses.replace(signed, values=[1.5] * 5)).code == "not_signed"
    # Signed for another robot or part: not valid here.
    elsewhere = ownership.Controller("kitchen", "arm", "kinematics")
    moved = dataclasses.replace(elsewhere.sign(cmd), controller=holder.id)
    assert h.refusal(moved).code == "not_signed"
    assert h.refusal(signed) is None


def test_a_command_played_again_is_refused_and_each_type_counts_apart():
    holder = ownership.Controller("asibot", "arm", "kinematics")
    h = alive(holder)
    first, grip, second = (holder.sign(ArmCommand(mode="position", values=[0.1] * 5)),
                           holder.sign(GripperCommand(opening=0.02)),
                           holder.sign(ArmCommand(mode="position", values=[0.2] * 5)))
    assert h.refusal(second) is None
    assert h.refusal(grip) is None                       # older than `second`, but a gripper command
    again = h.refusal(second)
    assert again.code == "replayed" and "a copy played again" in str(again)
    assert h.refusal(first).code == "replayed"           # recorded earlier, played later
    # A controller that comes back is a new one: what it obeyed before is forgotten with it.
    h.update(keys.controller_alive("asibot", holder.id), False)
    assert not h._obeyed


def test_the_senders_id_must_carry_a_key():
    h = ownership.Holder("asibot", "arm")
    h.update(keys.controller_alive("asibot", "kinematics-1a2b3c4d"), True)   # an id from before keys
    refused = h.refusal(ArmCommand(mode="position", values=[0.0] * 5, controller="kinematics-1a2b3c4d"))
    assert refused.code == "not_signed" and "carries no key" in str(refused)


def test_holders_follow_the_bus_and_arm_and_base_are_held_apart(memory_bus):
    arm, base = ownership.Holder("r", "arm"), ownership.Holder("r", "base")
    with Bus("watcher") as watcher, Bus("kinematics") as kin, Bus("nav") as nav:
        k = ownership.announce(kin, "r", "arm", "kinematics")
        arm.follow(watcher)                     # one alive before following, one after
        base.follow(watcher)
        n = ownership.announce(nav, "r", "base", "nav")
        wait_until(lambda: arm.current == k.id and base.current == n.id, 2)
        kin.close()
        wait_until(lambda: arm.current is None, 2)
        assert base.current == n.id
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


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_priority_follows_the_controllers_name():
    nav, joystick = ownership.Controller("p", "base", "nav"), ownership.Controller("p", "base", "joystick")
    assert ownership.priority(nav.id) == ownership.AUTONOMOUS == ownership.priority("nav")
    assert ownership.priority(joystick.id) == ownership.TELEOP > ownership.AUTONOMOUS
    assert ownership.priority("navigator-abc") == ownership.TELEOP     # only the name itself counts


def test_a_person_takes_the_base_from_nav_at_once_and_gives_it_back_once_quiet():
    clock, changes = Clock(), []
    h = ownership.Holder("p", "base", on_change=changes.append, clock=clock)
    nav, joystick = ownership.Controller("p", "base", "nav"), ownership.Controller("p", "base", "joystick")
    for c in (nav, joystick):
        h.update(keys.base_controller_alive("p", c.id), True)
    assert h.current == nav.id and changes == [nav.id]
    assert h.refusal(nav.sign(Twist(vx=0.3, wz=0.0))) is None
    # the joystick's first command takes the base: obeyed, and nav's are refused from then on
    assert h.refusal(joystick.sign(Twist(vx=0.1, wz=0.2))) is None
    assert h.current == h.taker == joystick.id and changes == [nav.id, joystick.id]
    refused = h.refusal(nav.sign(Twist(vx=0.3, wz=0.0)))
    assert refused.code == "not_holder" and f"controller {joystick.id!r} holds the base of p" in str(refused)
    # it keeps the base while it commands at least every TAKEOVER_HOLD s
    for _ in range(5):
        clock.now += ownership.TAKEOVER_HOLD * 0.9
        h.tick()
        assert h.refusal(joystick.sign(Twist(vx=0.1, wz=0.0))) is None
    clock.now += ownership.TAKEOVER_HOLD * 0.9
    h.tick()
    assert h.current == joystick.id and changes == [nav.id, joystick.id]
    clock.now += ownership.TAKEOVER_HOLD * 0.2                     # quiet for longer than the hold
    h.tick()
    assert h.current == nav.id and h.taker is None and changes == [nav.id, joystick.id, nav.id]
    assert h.refusal(nav.sign(Twist(vx=0.3, wz=0.0))) is None
    # it takes it again with its next command; and gives it back at once when it ends
    assert h.refusal(joystick.sign(Twist(vx=0.0, wz=0.1))) is None and h.current == joystick.id
    h.update(keys.base_controller_alive("p", joystick.id), False)
    assert h.current == nav.id and changes == [nav.id, joystick.id, nav.id, joystick.id, nav.id]


def test_only_a_signed_new_command_of_a_higher_priority_takes_the_base():
    h = ownership.Holder("p", "base", clock=Clock())
    nav, joystick, other = (ownership.Controller("p", "base", n) for n in ("nav", "joystick", "teleop"))
    for c in (joystick, nav, other):
        h.update(keys.base_controller_alive("p", c.id), True)
    assert h.current == joystick.id and h.taker is None   # the oldest: a person's program, idle
    assert h.refusal(nav.sign(Twist(vx=0.3, wz=0.0))).code == "not_holder"     # nav waits its turn
    assert h.refusal(other.sign(Twist(vx=0.3, wz=0.0))).code == "not_holder"   # same priority: in line
    h.update(keys.base_controller_alive("p", joystick.id), False)
    assert h.current == nav.id
    unsigned = Twist(vx=0.2, wz=0.0, controller=other.id)
    assert h.refusal(unsigned).code == "not_signed" and h.current == nav.id
    forged = dataclasses.replace(Identity("teleop").sign(unsigned, "p/base"), controller=other.id)
    assert h.refusal(forged).code == "not_signed" and h.current == nav.id
    stranger = ownership.Controller("p", "base", "joystick")          # not alive: not in line at all
    assert h.refusal(stranger.sign(Twist(vx=0.2, wz=0.0))).code == "not_holder" and h.current == nav.id
    first = other.sign(Twist(vx=0.2, wz=0.0))
    assert h.refusal(first) is None and h.current == other.id
    assert h.refusal(first).code == "replayed"


def test_hold_wait_lets_a_person_command_once_the_driver_knows_it_is_alive(memory_bus):
    """A joystick while nav holds the base: its first command takes the base, so it waits only
    until the driver lists it among the base's controllers (else that command would be refused
    and its stream count as one from before the takeover)."""
    robot = "hold-wait-takeover"
    nav, joystick = ownership.Controller(robot, "base", "nav"), ownership.Controller(robot, "base", "joystick")
    said: list = [{"holders": {"base": nav.id}, "controllers": {"base": [nav.id]}}]
    with Bus("joystick", memory_bus) as bus, Bus("base_driver", memory_bus) as driver:
        driver.serve(keys.driver_rpc(robot, "status"), lambda req: said[-1])
        assert not ownership.HoldWait(bus, robot, "base", joystick.id, poll=0.005).wait(time.monotonic() + 0.1)
        said.append({"holders": {"base": nav.id}, "controllers": {"base": [nav.id, joystick.id]}})
        assert ownership.HoldWait(bus, robot, "base", joystick.id, poll=0.005).wait(time.monotonic() + 2)
        # nav, of lower priority than a joystick that holds the base, waits its turn
        said.append({"holders": {"base": joystick.id}, "controllers": {"base": [nav.id, joystick.id]}})
        assert not ownership.HoldWait(bus, robot, "base", nav.id, poll=0.005).wait(time.monotonic() + 0.1)
