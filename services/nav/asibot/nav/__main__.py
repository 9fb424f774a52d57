"""`python -m asibot.nav --robot pioneer-sim`: localisation, goals, places and driving primitives."""

from asibot import runtime
from asibot.nav import service

if __name__ == "__main__":
    raise SystemExit(runtime.run(service))
