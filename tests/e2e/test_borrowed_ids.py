"""Issue 25: on the open router (the sim profile), another local process reads the holders'
ids from their liveliness tokens and commands both robots as them, plays recorded commands
again, and releases the estop in someone else's name. Nothing of it moves a robot."""

import textwrap
import time

import pytest

from asibot.safety import identity
from asibot import keys
from asibot.client import CartesianClient
from asibot.messages import ArmState, Event, Odometry
from asibot.testing import Inbox, wait_until

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

ARM, BASE = "asibot-sim", "pioneer-sim"

#: The attacker: a separate process on the same router, with only what the bus shows it.
ATTACKER = textwrap.dedent("""
    import sys, time
    from asibot import keys, messages
    from asibot.bus import Bus
    from asibot.messages import ArmCommand, EStop, Twist

    bus = Bus("attacker", wait=10)
    arm_holder = keys.controller_of(bus.alive(keys.controllers_alive("asibot-sim"))[0])
    base_holder = keys.controller_of(bus.alive(keys.base_controllers_alive("pioneer-sim"))[0])
    recorded = [messages.decode(ArmCommand, bytes.fromhex(h)) for h in sys.argv[2:]]
    print("holders", arm_holder, base_holder, flush=True)
    for i in range(50 if sys.argv[1] == "drive" else 0):   # 1 s of commands in the holders' names
        bus.put_raw(keys.arm_command("asibot-sim"), messages.encode(ArmCommand(
            mode="position", values=[0.6, 0.3, 0.3, 0.3, 0.0], controller=arm_holder)))
        bus.put_raw(keys.base_cmd_vel("pioneer-sim"), messages.encode(Twist(vx=0.3, wz=1.0, controller=base_holder)))
        for cmd in recorded:   # the holder's own commands, signed, as they went by earlier
            bus.put_raw(keys.arm_command("asibot-sim"), messages.encode(cmd))
        time.sleep(0.02)
    if sys.argv[1] == "release":
        bus.latch(keys.estop("asibot-sim"), EStop(engaged=False, reason="released", by="the nurse"))
    print("done", flush=True)
    time.sleep(0.5)
    bus.close()
""")


def test_another_process_cannot_command_as_the_holders_or_release_their_estop(up):
    stack = up("sim", "kinematics-asibot-sim", "nav-pioneer-sim")
    stack.wait_alive("sim/asibot-sim", "kinematics/asibot-sim", "nav/pioneer-sim", timeout=90)
    bus = stack.bus
    wait_until(lambda: bus.alive(keys.base_controllers_alive(BASE)), 30)
    arm, odom, events = Inbox(), Inbox(), Inbox()
    bus.subscribe(keys.arm_state(ARM), ArmState, arm)
    bus.subscribe(keys.base_odom(BASE), Odometry, odom)
    bus.subscribe(keys.events(ARM), Event, events)
    bus.subscribe(keys.events(BASE), Event, events)
    # A real motion of the arm, recorded as it goes by: the attacker plays it again later.
    recorded = Inbox()
    bus.subscribe_raw(keys.arm_command(ARM), lambda key, data, t: recorded(bytes(data)))
    with CartesianClient(ARM) as robot:
        robot.movj(joints=[5, 5, 5, 5, 0], duration=1.0)
        robot.wait(timeout=20)
    wait_until(lambda: len(recorded) > 10, 10)
    wait_until(lambda: len(arm) and len(odom), 20)
    time.sleep(0.5)
    q0, x0 = list(arm.last().positions), odom.last()
    script = stack.folder / "attacker.py"
    script.write_text(ATTACKER)

    out = stack.run("-u", str(script), "drive", *[data.hex() for data in recorded.all()[-5:]], timeout=60)
    assert out.returncode == 0 and "done" in out.stdout, out.stdout + out.stderr
    for code in ("not_signed", "replayed"):
        wait_until(lambda: any(e.code == code for e in events.all()), 10, message=f"no {code} event")
    time.sleep(0.5)
    assert arm.last().positions == pytest.approx(q0, abs=1e-3), "the arm moved"
    assert (odom.last().x, odom.last().y, odom.last().theta) == pytest.approx((x0.x, x0.y, x0.theta), abs=2e-3)

    with CartesianClient(ARM) as robot:
        robot.estop("a test")
    wait_until(lambda: bus.call(keys.driver_rpc(ARM, "status"))["estop"] is True, 10)
    out = stack.run("-u", str(script), "release", timeout=60)
    assert out.returncode == 0 and "done" in out.stdout, out.stdout + out.stderr
    refused = wait_until(lambda: [e for e in events.all() if e.code == "release_refused"], 10)[0]
    assert "the nurse, unsigned" in refused.text
    time.sleep(0.3)
    assert bus.call(keys.driver_rpc(ARM, "status"))["estop"] is True, "a stranger released the estop"

    # The estop holds until a release that is signed; its event names the key that signed it.
    with CartesianClient(ARM) as robot:
        robot.release("the test is over")
        wait_until(lambda: bus.call(keys.driver_rpc(ARM, "status"))["estop"] is False, 10)
        released = next(e for e in wait_until(lambda: [e for e in events.all() if e.code == "estop_released"], 10))
        assert f"key {identity.short(robot._me.id)}" in released.text, released.text
    assert stack.stop() == 130   # stopped by Ctrl-C: the shell's 128 + SIGINT

