"""asibot.safety.driver_contract: the bus side every driver shares, with a driver that only records."""

import pytest

from asibot import keys, messages
from asibot.safety import ownership
from asibot.bus import Bus
from asibot.safety.driver_contract import DriverContract, command
from asibot.safety.arming import NotReady
from asibot.safety.events import CommandRefused
from asibot.errors import RpcError
from asibot.messages import ArmCommand, EStop, Event, Twist
from asibot.testing import Inbox, release, wait_until
from asibot.verbs import Field, OneOf, Verb

R = "contract-robot"


class Recorder:
    """What a driver behind the contract was told to do."""

    def __init__(self) -> None:
        self.obeyed, self.heard, self.holders, self.estops = Inbox(), Inbox(), Inbox(), Inbox()

    def arm(self, cmd: ArmCommand) -> None:
        if cmd.values[0] == 2.5:
            raise ValueError("the emergency stop is engaged")
        if cmd.values[0] > 3.0:
            raise CommandRefused("position_limit", "joint q1 position 4 rad is beyond its upper limit 3 rad")
        if cmd.values[0] < -3.0:
            raise NotReady("not_ready", "the arm was re-armed after a test")
        self.obeyed(cmd)


@pytest.fixture
def driver(memory_bus):
    rec = Recorder()
    with Bus("driver") as bus, Bus("user") as user:
        contract = DriverContract(bus, R)
        contract.serve(
            [command("arm", rec.arm, rec.heard), command("cmd_vel", rec.obeyed)],
            on_holder=lambda part, holder: rec.holders((part, holder)),
            on_estop=lambda engaged, reason, by: rec.estops((engaged, reason, by)),
            status=lambda: {"mode": "idle"}, reset_fault=lambda: {"reset": True},
            verbs={"inject_fault": Verb({"fault": Field(OneOf(("silent", "clear")), required=True)})},
            handlers={"inject_fault": lambda args: {"injected": args.fault}})
        events = Inbox()
        user.subscribe(keys.events(R), Event, events)
        arm = ownership.announce(user, R, "arm", "kinematics")
        base = ownership.announce(user, R, "base", "nav")
        wait_until(lambda: contract.holders["arm"].current == arm.id and contract.holders["base"].current == base.id, 5)
        yield contract, rec, user, events, arm, base
        contract.close()


def codes(events) -> list[str]:
    return [e.code for e in events.all()]


def test_the_holders_signed_commands_are_obeyed_and_the_rest_refused_with_a_sentence(driver):
    contract, rec, user, events, arm, base = driver
    pub = user.publisher(keys.arm_command(R), ArmCommand)
    arm.put(pub, ArmCommand(mode="position", values=[0.1] * 5))
    user.publisher(keys.base_cmd_vel(R), Twist).put(base.sign(Twist(vx=0.1, wz=0.0)))
    wait_until(lambda: len(rec.obeyed) == 2, 5)
    assert ("arm", arm.id) in rec.holders.all() and ("base", base.id) in rec.holders.all()

    base.put(pub, ArmCommand(mode="position", values=[0.2] * 5))          # the base's controller
    pub.put(ArmCommand(mode="position", values=[0.2] * 5, controller=arm.id))   # the id, unsigned
    arm.put(pub, ArmCommand(mode="position", values=[4.0] * 5))           # beyond a limit
    arm.put(pub, ArmCommand(mode="position", values=[-4.0] * 5))          # refused by the state
    user.put_raw(keys.arm_command(R), messages.pack({"mode": "sideways", "values": [0.0]}))
    wait_until(lambda: {"not_holder", "not_signed", "bad_command", "not_ready"} <= set(codes(events)), 5, message=lambda: str(codes(events)))
    texts = [e.text for e in events.all()]
    assert all(t.startswith("Arm command refused, the arm keeps its previous motion: ") for t in texts)
    assert any("joint q1 position 4 rad is beyond its upper limit 3 rad." in t for t in texts)
    assert any("must be 'position' or 'velocity'" in t for t in texts)
    assert rec.heard.all() == [base.id]            # another controller's stream, noted; the forged one not
    assert len(rec.obeyed) == 2
    assert contract.not_holder == 2 and contract.rejected == 5      # the malformed one too
    assert contract.health() == {"holder_arm": arm.id, "holder_base": base.id, "not_holder": 2,
                                 "commands_rejected": 5}


def test_during_an_estop_a_refusal_of_the_stop_is_counted_not_shouted(driver):
    contract, rec, user, events, arm, base = driver
    pub = user.publisher(keys.arm_command(R), ArmCommand)
    user.latch(keys.estop(R), EStop(engaged=True, reason="test"))
    wait_until(lambda: contract.estop.engaged, 5)
    arm.put(pub, ArmCommand(mode="position", values=[2.5] * 5))   # refused by the stop
    wait_until(lambda: contract.rejected == 1, 5)
    arm.put(pub, ArmCommand(mode="position", values=[4.0] * 5))   # beyond a limit: said even now
    wait_until(lambda: "bad_command" in codes(events), 5)
    assert codes(events) == ["bad_command"] and contract.rejected == 2
    release(user, R)
    wait_until(lambda: not contract.estop.engaged, 5)
    arm.put(pub, ArmCommand(mode="position", values=[2.5] * 5))   # no stop: said
    wait_until(lambda: codes(events).count("bad_command") == 2, 5)


def test_status_verbs_estop_and_liveliness(driver):
    contract, rec, user, events, arm, base = driver
    assert user.alive(keys.driver_alive(R)) == [keys.driver_alive(R)]
    status = user.call(keys.driver_rpc(R, "status"))
    assert status == {"ok": True, "robot": R, "mode": "idle", "holders": {"arm": arm.id, "base": base.id},
                      "controllers": {"arm": [arm.id], "base": [base.id]}}
    assert user.call(keys.driver_rpc(R, "reset_fault")) == {"ok": True, "reset": True}
    assert user.call(keys.driver_rpc(R, "inject_fault"), {"fault": "silent"}) == {"ok": True, "injected": "silent"}
    with pytest.raises(RpcError, match="'fault' must be silent or clear; got 'meteor'"):
        user.call(keys.driver_rpc(R, "inject_fault"), {"fault": "meteor"})
    with pytest.raises(RpcError, match="status takes no arguments"):
        user.call(keys.driver_rpc(R, "status"), {"verbose": True})
    user.latch(keys.estop(R), EStop(engaged=True, reason="test", by="ana"))
    wait_until(lambda: len(rec.estops) == 1, 5)
    assert rec.estops.last() == (True, "test", "ana, unsigned")
    user.latch(keys.estop(R), EStop(engaged=False, reason="stranger", by="ana"))
    wait_until(lambda: "release_refused" in codes(events), 5)
    release(user, R, by="bob")
    wait_until(lambda: len(rec.estops) == 2, 5)
    engaged, reason, by = rec.estops.last()
    assert not engaged and by.startswith("bob, key test-")


def test_a_kind_of_command_it_does_not_know_is_refused():
    with pytest.raises(ValueError, match="a driver obeys arm, gripper, cmd_vel commands, not 'wheel'"):
        command("wheel", print)
