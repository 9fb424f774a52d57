"""The ARCOS emulator's command line: an emulated P3-AT on TCP and optionally a pty.

    python -m asibot.base_driver.emulator --listen 127.0.0.1:8101 [--map apartment.yaml]
        [--start X,Y,THETA] [--pty /tmp/pioneer] [--control 127.0.0.1:8102]

Line faults are injected over the control socket (`control.py`) as text lines, one JSON
reply each: `silent SECONDS`, `garbage COUNT`, `drop COUNT`, `unplug SECONDS`, `status`.
In-process users (tests, benchmarks) take `ArcosEmulator` directly.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading

from asibot.base_driver.emulator import gridmap
from asibot.base_driver.emulator.control import ControlServer
from asibot.base_driver.emulator.robot import EmulatedP3at, Pose
from asibot.base_driver.emulator.server import ArcosEmulator
from asibot.base_driver.params import KNOWN

log = logging.getLogger("asibot.base_driver.emulator")


def _hostport(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit():
        raise argparse.ArgumentTypeError(f"{text!r} is not HOST:PORT, e.g. 127.0.0.1:8101")
    return host, int(port)


def _pose(text: str) -> Pose:
    try:
        x, y, th = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not X,Y,THETA (metres, metres, radians)") from None
    return Pose(x, y, th)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m asibot.base_driver.emulator",
                                description="an emulated Pioneer P3-AT speaking ARCOS")
    p.add_argument("--listen", type=_hostport, default=("127.0.0.1", 8101), help="TCP HOST:PORT (default 127.0.0.1:8101)")
    p.add_argument("--pty", default=None, help="also serve on a pty, symlinked at this path")
    p.add_argument("--map", default=None, help="ROS map_server YAML, or a shipped map's name: apartment "
                        "(default: an empty 8 m x 6 m room)")
    p.add_argument("--start", type=_pose, default=Pose(), help="start pose X,Y,THETA in the map frame")
    p.add_argument("--subclass", default="p3at-sh", choices=sorted(KNOWN), help="controller to emulate")
    p.add_argument("--control", type=_hostport, default=None, help="fault-injection control socket HOST:PORT")
    p.add_argument("--garbage-every", type=float, default=0.0, help="inject 16 junk bytes every S seconds")
    p.add_argument("--log-level", default="info", choices=["debug", "info", "warning", "error"])
    args = p.parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(levelname)-7s emulator: %(message)s")
    if args.listen[0] not in ("127.0.0.1", "localhost", "::1") and not args.listen[0].startswith("127."):
        log.warning("listening on %s: the emulator is meant for loopback", args.listen[0])
    try:
        world = gridmap.load(args.map) if args.map else gridmap.room()
        robot = EmulatedP3at(world, args.start, KNOWN[args.subclass])
        emulator = ArcosEmulator(robot, args.listen, pty_link=args.pty, garbage_every=args.garbage_every)
    except (ValueError, OSError) as exc:
        print(f"emulator: {exc}", file=sys.stderr)
        return 2
    control = ControlServer(emulator, args.control).start() if args.control else None
    emulator.start()
    log.info("P3-AT (%s) on %s%s", args.subclass, emulator.url,
             f", control on {control.address[0]}:{control.address[1]}" if control else "")
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    stop.wait()
    if control:
        control.close()
    emulator.close()
    return 0
