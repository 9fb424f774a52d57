""""Give me the red can": pick the red can off the kitchen counter and hold it up.

Run it against the kitchen simulation (`asibot up`), or any ASIBOT whose red can stands at
CAN below, in the arm's base frame. Robot: argv[1], ASIBOT_ROBOT, or asibot-sim.
Points are the seed's [x, y, z, rot(y'), rot(z'')] in m and deg: rot(y') = 180 points the
gripper straight down.
"""

import os
import sys

from asibot.client import CartesianClient

robot_name = sys.argv[1] if len(sys.argv) > 1 else os.environ.get("ASIBOT_ROBOT", "asibot-sim")

CAN = [0.0, 0.5, 0.02]      # the can's centre, m, in the arm's base frame
FINGERS = 0.04              # the fingertips' centre is this far beyond the tool point, m
GRIP_HEIGHT = 0.03          # grip the upper half of the can, m above its centre
DOWN = [180, 0]             # gripper pointing down


def point_over_can(height: float) -> list:
    """The tool point that puts the fingertips `height` m above the grip height."""
    x, y, z = CAN
    return [x, y, z + GRIP_HEIGHT + FINGERS + height] + DOWN


robot = CartesianClient()
robot.open(robot_name)
print("opening the gripper")
robot.grip(close=False)
print("moving above the can")
robot.movj(point_over_can(0.12))
robot.wait()
print("reaching down")
robot.movl(point_over_can(0.0), speed=0.05)
robot.wait()
if not robot.grip():
    robot.grip(close=False)
    robot.movl(point_over_can(0.12))
    robot.wait()
    robot.close()
    sys.exit("the gripper closed on nothing: is the can where CAN says?")
print("got it; lifting")
robot.movl(point_over_can(0.10), speed=0.05)
robot.wait()
print("here is your red can:", [round(v, 3) for v in robot.stat()])
robot.close()
