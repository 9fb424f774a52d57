"""The sim's own verbs on the bus: `reset_world` answers once the reset world is published, so
whoever moves the arm next plans from home, not from where the arm was (a plan from before the
jump would yank the arm back there)."""

import pytest

from asibot import keys
from asibot import messages as m
from asibot.testing import wait_until

from .conftest import ROBOT


def test_reset_world_answers_after_the_arm_at_home_was_published(sim):
    home = list(sim.svc.sim.robot.home)
    away = [q + 0.3 for q in home[:3]] + home[3:]
    sim.arm_controller.put(sim.user.publisher(keys.arm_command(ROBOT), m.ArmCommand),
                           m.ArmCommand(mode="position", values=away))
    for _ in range(3):      # each time from away: the last state heard is away until the reset
        wait_until(lambda: sim.arm.last().positions[0] > home[0] + 0.25, timeout=10,
                   message=lambda: f"the arm did not go to {away}: {sim.arm.last().positions}")
        sim.user.call(keys.driver_rpc(ROBOT, "reset_world"), {}, timeout=5)
        # Published before the answer; our subscription's thread may still be handing it over
        # (seen under load: the answer first, the state a moment later): moments, not a tick.
        wait_until(lambda: sim.arm.last().positions == pytest.approx(home, abs=0.01), timeout=2,
                   message=lambda: f"not home after the answer: {sim.arm.last().positions}")
        sim.arm_controller.put(sim.user.publisher(keys.arm_command(ROBOT), m.ArmCommand),
                               m.ArmCommand(mode="position", values=away))
