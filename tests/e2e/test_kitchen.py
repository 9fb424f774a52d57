""""Give me the red can" in the simulated kitchen, from `asibot up` to the can in the gripper."""

import pytest

from asibot import keys
from asibot.recorder.reader import summarize

from .conftest import EXAMPLES

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]


def test_a_client_script_picks_up_the_red_can(up):
    stack = up("sim", "recorder", "kinematics-asibot-sim")
    stack.wait_alive("sim/asibot-sim", "kinematics/asibot-sim", "recorder/main")
    can = stack.bus.call(keys.driver_rpc("asibot-sim", "object_pose"), {"name": "red_can"})["pos"]

    out = stack.run("-u", str(EXAMPLES / "give_me_the_red_can.py"), "asibot-sim", timeout=90)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "here is your red can" in out.stdout

    lifted = stack.bus.call(keys.driver_rpc("asibot-sim", "object_pose"), {"name": "red_can"})["pos"]
    assert lifted[2] - can[2] == pytest.approx(0.10, abs=0.02)   # lifted 10 cm, still in the gripper
    assert abs(lifted[0] - can[0]) < 0.02 and abs(lifted[1] - can[1]) < 0.02

    # The seed's template program, unchanged apart from the robot name, takes it home.
    out = stack.run(str(EXAMPLES / "template.py"), "asibot-sim")
    assert out.returncode == 0, out.stdout + out.stderr
    assert "hello, robot!" in out.stdout and "done!" in out.stdout

    assert stack.stop() == 130   # stopped by Ctrl-C: the shell's 128 + SIGINT
    files = sorted((stack.folder / "recordings").glob("*.mcap"))
    assert len(files) == 1
    summary = summarize(files[0])
    assert summary.complete
    topics = summary.counts
    assert topics[keys.arm_state("asibot-sim")] > 100
    assert keys.gripper_command("asibot-sim") in topics
