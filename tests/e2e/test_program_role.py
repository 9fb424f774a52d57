"""Issue 51: on the default sim profile (an open router) a sandboxed program took the base from
nav as a "teleop" controller and drove it 3.57 m, and released an estop the page had engaged.
A program now reaches the bus only through the router's programs socket, with the program
role's rights on every profile: it calls the verbs asibot.client uses, and nothing else."""

import textwrap

import pytest

from asibot import keys
from asibot.messages import Odometry
from asibot.testing import Inbox, wait_until

# Alone (tests/run's third pass): a stack of its own beside the robots' moving in real time
# loaded the machine enough for their heartbeats to come late (CI).
pytestmark = [pytest.mark.slow, pytest.mark.alone, pytest.mark.timeout(300)]

ARM, BASE = "asibot-sim", "pioneer-sim"

ATTACK = textwrap.dedent(f"""
    import time
    from asibot import keys
    from asibot.bus import Bus
    from asibot.messages import Twist
    from asibot.safety import estop, ownership
    from asibot.safety.identity import Identity

    with Bus("client", wait=10.0) as bus:
        print("bus", bus.endpoint, flush=True)
        print("stat", len(bus.call(keys.cart_rpc({ARM!r}, "stat"), {{}}, timeout=10.0)["point"]), flush=True)
        print("places", "fridge" in str(bus.call(keys.nav_rpc({BASE!r}, "places"), {{}}, timeout=10.0)), flush=True)
        teleop = ownership.announce(bus, {BASE!r}, "base", "teleop")
        drive = bus.publisher(keys.base_cmd_vel({BASE!r}), Twist, express=True)
        time.sleep(1.0)                            # the driver sees the new controller
        teleop.put(drive, Twist(vx=0.0, wz=0.0))   # takes the base from nav, then pauses: armed
        time.sleep(0.5)
        for _ in range(100):                       # 2 s at 1.2 m/s, as the attack did
            teleop.put(drive, Twist(vx=1.2, wz=0.0))
            time.sleep(0.02)
        estop.latch(bus, {ARM!r}, Identity("web"), False, "released by a program", "the web page")
        try:
            bus.call(keys.nav_rpc({BASE!r}, "localize"), {{}}, timeout=3.0)
            print("localize answered")
        except Exception as exc:
            print("localize refused:", type(exc).__name__)
        print("done", flush=True)
""")


def test_a_program_on_the_open_router_keeps_to_its_role(up):
    stack = up("sim", "kinematics-asibot-sim", "nav-pioneer-sim", "web")
    stack.wait_alive("sim/asibot-sim", "sim/pioneer-sim", "kinematics/asibot-sim", "nav/pioneer-sim",
                     "web/main", timeout=120)
    bus = stack.bus
    odom = Inbox()
    bus.subscribe(keys.base_odom(BASE), Odometry, odom)
    wait_until(lambda: len(odom), 30)
    start = odom.last()
    assert stack.web("POST", f"/api/robots/{ARM}/estop")[0] == 200     # the arm's: the base may move
    wait_until(lambda: bus.call(keys.driver_rpc(ARM, "status"))["estop"] is True, 10)

    assert stack.web("POST", "/api/programs", {"name": "attack"})[0] == 200
    assert stack.web("PUT", "/api/programs/attack", {"text": ATTACK})[0] == 200
    status, run = stack.web("POST", "/api/programs/attack/run", {"robot": ARM})
    assert status == 200, run

    def finished() -> dict | None:
        run = stack.web("GET", "/api/run")[1]
        return None if run["running"] or run["last"] is None else run
    run = wait_until(finished, 90, interval=0.5, message="the program did not end")
    out = [line for stream, line in run["output"] if stream == "out"]
    assert "done" in out, run["output"]
    # The base stayed where nav keeps it, and the page's estop stayed engaged ...
    wait_until(lambda: odom.last().stamp > start.stamp, 10)
    moved = ((odom.last().x - start.x) ** 2 + (odom.last().y - start.y) ** 2) ** 0.5
    assert moved < 0.02, f"a program drove the base {moved:.2f} m"
    assert bus.call(keys.driver_rpc(ARM, "status"))["estop"] is True, "a program released the page's estop"
    # ... while it had a program's rights, through the programs socket: the verbs asibot.client
    # calls, and not nav's localize.
    assert out[0].startswith("bus unixsock-stream/"), run["output"]
    assert "stat 5" in out and "places True" in out, run["output"]
    assert "localize refused: Unavailable" in out, run["output"]
    assert stack.web("POST", f"/api/robots/{ARM}/release")[0] == 200
    assert stack.stop() == 130
