"""`python -m asibot.voice --robot asibot-sim`: the robot listens for the user's words and answers."""

from asibot import runtime
from asibot.voice import service

if __name__ == "__main__":
    raise SystemExit(runtime.run(service))
