"""`python -m asibot.asterics_bridge --robot pioneer-sim`: AsTeRICS, text and HTTP clients drive the robots."""

from asibot import runtime
from asibot.asterics_bridge import service

if __name__ == "__main__":
    raise SystemExit(runtime.run(service))
