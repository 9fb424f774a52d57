""""Pick it up" made from steps (issue 27, point 3), run as a user's program against the
kitchen simulation: the generated Python lifts the red can from the one point at it, and with
that point 3 cm off it either still lifts the can or ends with the sentence that says why."""

import pytest

from asibot.client import SimClient
from asibot.web import steps

pytestmark = [pytest.mark.slow, pytest.mark.timeout(400)]

ROBOT = "asibot-sim"
#: The grip pose at the red can (its centre [0, 0.5, 0.02], gripped 3 cm below its top).
AT_THE_CAN = [0.0, 0.5, 0.09, 180.0, 0.0]


def run_pick(stack, tmp_path, point: list[float]):
    text = steps.generate("pick", steps.pick_it_up("grasp-can"), {"grasp-can": point})
    program = tmp_path / "pick.py"
    program.write_text(text)
    return stack.run("-u", str(program), ROBOT, timeout=150)


def test_a_generated_pick_it_up_lifts_the_red_can(up, tmp_path):
    stack = up("sim", "kinematics-asibot-sim")
    stack.wait_alive("sim/asibot-sim", "kinematics/asibot-sim")
    sim = SimClient.on(stack.bus, ROBOT)
    can = sim.object_pose("red_can")

    out = run_pick(stack, tmp_path, AT_THE_CAN)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "Close the gripper and check it holds something" in out.stdout and "done!" in out.stdout
    assert "Notice:" not in out.stdout              # every straight move was made straight
    lifted = sim.object_pose("red_can")
    assert lifted[2] - can[2] == pytest.approx(steps.ABOVE_HEIGHT, abs=0.02)   # lifted, in the gripper
    assert abs(lifted[0] - can[0]) < 0.02 and abs(lifted[1] - can[1]) < 0.02

    # The same point 3 cm off: the fingers close on the can's side, or on nothing; either way
    # the program says what happened.
    sim.reset_world()
    can = sim.object_pose("red_can")
    out = run_pick(stack, tmp_path, [0.03, 0.5, 0.09, 180.0, 0.0])
    lifted = sim.object_pose("red_can")
    if out.returncode == 0:
        assert "done!" in out.stdout
        # Off the counter, in the gripper (gripped off its axis, it may hang lower or tilted).
        assert lifted[2] - can[2] > 0.03, "the program finished but the can stayed down"
    else:
        assert out.returncode == 1, out.stdout + out.stderr
        assert out.stderr.strip().splitlines()[-1] == "nothing in the gripper after closing at grasp-can"
        assert "Move above grasp-can" not in out.stdout.split("Close the gripper")[-1]   # no lift after it
        assert lifted[2] - can[2] < 0.02
