"""`python -m asibot.perception --robot pioneer-sim`: depth -> scan, obstacle warnings, object finder."""

from asibot import runtime
from asibot.perception import service

if __name__ == "__main__":
    raise SystemExit(runtime.run(service))
