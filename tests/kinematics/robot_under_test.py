"""The real ASIBOT model from the robot catalog, under a test robot id, so these tests drive
the controller and server with exactly what the service runs."""

from __future__ import annotations

import dataclasses

from asibot import robots
from asibot.kinematics.model import solver_for

ROBOT = "asibot-test"


def asibot_spec(robot_id: str = ROBOT) -> robots.RobotSpec:
    return dataclasses.replace(robots.get("asibot-sim"), robot_id=robot_id)


def asibot_model():
    return solver_for(asibot_spec())
