"""`python -m asibot.arm_driver --robot asibot --can socketcan:can0` (or `--can emulated`)."""

from asibot import runtime
from asibot.arm_driver import service

if __name__ == "__main__":
    raise SystemExit(runtime.run(service))
