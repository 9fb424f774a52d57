"""`python -m asibot.sim --robot asibot-sim` (kitchen) or `--robot pioneer-sim` (apartment)."""

from asibot import runtime
from asibot.sim import service

if __name__ == "__main__":
    raise SystemExit(runtime.run(service))
