"""The seed's Task Creator template program, in Python 3. Robot: argv[1], ASIBOT_ROBOT, or asibot-sim."""

import os
import sys

from asibot.client import CartesianClient

robot_name = sys.argv[1] if len(sys.argv) > 1 else os.environ.get("ASIBOT_ROBOT", "asibot-sim")

home = [0, 0, 1.4, 0, 0]
simCart = CartesianClient()
simCart.open(robot_name)  # "asibot" for the real arm
print("hello, robot!")
simCart.movl(home)
simCart.wait()
print("done!")
simCart.close()
