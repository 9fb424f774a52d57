"""`python -m asibot.camera --robot pioneer --name front --source realsense:`: a real depth camera;
`python -m asibot.camera --list`: the cameras plugged in, as --source names (no bus needed)."""

import sys

from asibot import runtime
from asibot.camera import service

if __name__ == "__main__":
    if "--list" in sys.argv[1:]:
        print("\n".join(service.list_cameras()) or "no camera found")
        raise SystemExit(0)
    raise SystemExit(runtime.run(service))
