"""`python -m asibot.sim --robot asibot-sim` (kitchen) or `--robot pioneer-sim` (apartment)."""

from __future__ import annotations

import argparse
import logging
import threading

from asibot import runtime
from asibot.bus import Bus
from asibot.sim import viewer
from asibot.sim.scene import WORLDS
from asibot.sim.service import Options, SimService
from asibot.sim.simulation import Simulation, world_for

log = logging.getLogger("asibot.sim")


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"camera size must look like 320x240, not {text!r}") from None
    if not (16 <= w <= 1920 and 16 <= h <= 1080):
        raise argparse.ArgumentTypeError("camera size must be between 16x16 and 1920x1080")
    return w, h


def _noise(text: str) -> tuple[float, float]:
    try:
        lin, ang = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"odometry noise must look like 0.02,0.05, not {text!r}") from None
    if lin < 0 or ang < 0:
        raise argparse.ArgumentTypeError("odometry noise fractions must be >= 0")
    return lin, ang


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--world", choices=sorted(WORLDS), help="world to load (default: the robot's world)")
    p.add_argument("--fast", action="store_true", help="step as fast as possible instead of real time")
    p.add_argument("--viewer", action="store_true", help="open MuJoCo's viewer (needs a DISPLAY)")
    p.add_argument("--camera-hz", type=float, default=10.0, help="camera frame rate; 0 disables cameras")
    p.add_argument("--camera-size", type=_size, default=(320, 240), help="camera resolution WxH")
    p.add_argument("--depth-method", choices=["render", "ray"], default="render",
                   help="depth by OSMesa rendering (default, faster) or by ray casting")
    p.add_argument("--odom-noise", type=_noise, default=(0.02, 0.05),
                   help="odometry noise: linear,angular standard deviation as a fraction of speed")
    p.add_argument("--seed", type=int, default=None, help="seed of the odometry noise")


class _Running:
    """What runtime.run drives: the service, plus the viewer on the main thread if asked."""

    def __init__(self, service: SimService, show: bool) -> None:
        self.service, self.show = service, show

    def run(self, stop: threading.Event) -> None:
        if self.show:
            viewer.run(self.service.sim, stop)
            stop.set()
        else:
            self.service.run(stop)

    def health(self) -> dict:
        return self.service.health()

    def close(self) -> None:
        self.service.close()


def build(bus: Bus, args: argparse.Namespace) -> _Running:
    robot = args.robot or (WORLDS[args.world] if args.world else None)
    if robot is None:
        raise ValueError("say which robot to simulate: --robot asibot-sim or --robot pioneer-sim (or --world)")
    world = args.world or world_for(robot)
    sim = Simulation(robot, world, odom_noise=args.odom_noise, seed=args.seed)
    width, height = args.camera_size
    service = SimService(bus, sim, Options(fast=args.fast, camera_hz=args.camera_hz, width=width,
                                           height=height, depth_method=args.depth_method))
    show = args.viewer and viewer.available()
    if args.viewer and not show:
        log.warning("--viewer ignored: no DISPLAY; running headless")
    log.info("simulating %s in the %s world (%s)", robot, world, "fast" if args.fast else "real time")
    return _Running(service, show)


def main(argv: list[str] | None = None) -> int:
    return runtime.run("sim", build, add_arguments=add_arguments, argv=argv)


if __name__ == "__main__":
    raise SystemExit(main())
