"""`python -m asibot.kinematics --robot asibot-sim [--rate 100]`: the Cartesian control server."""

from asibot import runtime
from asibot.kinematics import service

if __name__ == "__main__":
    raise SystemExit(runtime.run(service))
