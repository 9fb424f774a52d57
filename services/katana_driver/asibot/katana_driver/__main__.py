"""`python -m asibot.katana_driver --robot pioneer --serial /dev/ttyUSB0` (or `--serial emulated`)."""

from asibot import runtime
from asibot.katana_driver import service

if __name__ == "__main__":
    raise SystemExit(runtime.run(service))
