"""The camera service: one real depth camera on the bus as the sim publishes its cameras.

`python -m asibot.camera --robot pioneer --name front --source realsense:123456789012`
publishes, at the camera's rate (each frame as it comes):

| key | message | what |
|---|---|---|
| `keys.camera_info(robot, name)` | `CameraInfo` | intrinsics, the pose on the robot (`--pose`, else mounts.toml), frame `<name>_optical`; with every frame, as the sim |
| `keys.camera_depth(robot, name)` | `DepthImage` | float32 m along the optical axis, 0 = no return (and beyond `--max-depth`, 8 m as the sim) |
| `keys.camera_rgb(robot, name)` | `RgbImage` | JPEG (quality 80, as the sim) of the colour picture registered to the depth image; none from a depth-only camera |
"""

from __future__ import annotations

import argparse
import logging
import threading
import time

import cv2
import numpy as np

from asibot import keys, runtime
from asibot import messages as m
from asibot.bus import Bus
from asibot.camera import mounts
from asibot.camera.sources import (FORMS, MAX_DEPTH_M, CameraUnavailable, EndOfRecording, Frame, Source,
                                   StreamOptions, open_source)
from asibot.runtime import Service

NAME = "camera"
JPEG_QUALITY = 80      # asibot.sim.cameras.JPEG_QUALITY
#: A camera silent this long gets a warning in the log (once, until it is back), s.
SILENT_AFTER = 2.0

log = logging.getLogger(__name__)


def jpeg(rgb: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise RuntimeError("OpenCV could not encode the camera image as JPEG")
    return buf.tobytes()


def messages_of(frame: Frame, pose: list[float], name: str) -> tuple[m.CameraInfo, m.DepthImage, m.RgbImage | None]:
    """The sim's three messages for one frame."""
    info = frame.intrinsics.info(pose, f"{name}_optical", frame.stamp)
    depth = m.DepthImage(depth=frame.depth, stamp=frame.stamp)
    rgb = None
    if frame.rgb is not None:
        rgb = m.RgbImage(jpeg=jpeg(frame.rgb), width=frame.rgb.shape[1], height=frame.rgb.shape[0], stamp=frame.stamp)
    return info, depth, rgb


class CameraService(Service):
    """Reads `source` (already started) and publishes each frame under `robot`'s camera `name`."""

    def __init__(self, bus: Bus, robot: str, name: str, source: Source, pose: list[float],
                 silent_after: float = SILENT_AFTER) -> None:
        self.bus, self.robot, self.name, self.source, self.pose = bus, robot, name, source, pose
        self.silent_after = silent_after
        self._info = bus.publisher(keys.camera_info(robot, name), m.CameraInfo)
        self._depth = bus.publisher(keys.camera_depth(robot, name), m.DepthImage)
        self._rgb = bus.publisher(keys.camera_rgb(robot, name), m.RgbImage)
        self.frames = 0
        self.ended: str | None = None          # why the frames stopped (a recording's end, a lost camera)
        self._last = time.monotonic()
        self._silent = False

    def publish(self, frame: Frame) -> None:
        info, depth, rgb = messages_of(frame, self.pose, self.name)
        self._info.put(info)
        self._depth.put(depth)
        if rgb is not None:
            self._rgb.put(rgb)
        self.frames += 1

    def step(self, timeout: float = 0.5) -> bool:
        """Wait for one frame and publish it; False once the source has ended."""
        try:
            frame = self.source.read(timeout)
        except EndOfRecording as exc:
            self.ended = str(exc)
            log.info("%s: stopping", exc)
            return False
        except CameraUnavailable as exc:
            self.ended = str(exc)
            log.error("%s", exc)
            return False
        now = time.monotonic()
        if frame is None:
            if not self._silent and now - self._last > self.silent_after:
                self._silent = True
                log.warning("the %s camera (%s) has sent no frame for %.0f s: check its USB cable and power",
                            self.name, self.source.url, now - self._last)
            return True
        if self._silent:
            log.info("the %s camera sends frames again", self.name)
            self._silent = False
        self._last = now
        self.publish(frame)
        return True

    def run(self, stop: threading.Event) -> None:
        while not stop.is_set() and self.step():
            pass
        if self.ended and not stop.is_set() and not self.ended.startswith("the recording"):
            raise SystemExit(1)     # a lost camera: the launcher restarts the service (the sentence is logged)

    def health(self) -> dict:
        return {"source": self.source.url, "frames": self.frames, "silent": self._silent}

    def close(self) -> None:
        self.source.close()


def _size(text: str) -> tuple[int, int]:
    w, sep, h = text.lower().partition("x")
    if not sep or not w.isdigit() or not h.isdigit():
        raise argparse.ArgumentTypeError(f"{text!r}: a size is WIDTHxHEIGHT, e.g. 640x480")
    return int(w), int(h)


def _numbers(count: int):
    def parse(text: str) -> list[float]:
        try:
            values = [float(v) for v in text.replace(",", " ").split()]
        except ValueError:
            values = []
        if len(values) != count:
            raise argparse.ArgumentTypeError(f"{text!r}: give {count} numbers, comma- or space-separated")
        return values
    return parse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--source", default=None, help=f"the camera: {', '.join(FORMS)}")
    p.add_argument("--name", default=None, help="the camera's name on the bus (front, back, rgb, kitchen...)")
    p.add_argument("--size", type=_size, default=(640, 480), help="a live camera's mode, WIDTHxHEIGHT (640x480)")
    p.add_argument("--fps", type=int, default=15, help="a live camera's frame rate, Hz (15; OpenNI2 picks its nearest)")
    p.add_argument("--max-depth", type=float, default=MAX_DEPTH_M,
                   help=f"farther is no return (0), m ({MAX_DEPTH_M:g}, as the sim)")
    p.add_argument("--no-colour", action="store_true", help="depth only")
    p.add_argument("--loop", action="store_true", help="a recording starts again at its end")
    p.add_argument("--pose", type=_numbers(7), default=None,
                   help="the optical frame in the robot's base frame: x,y,z,qw,qx,qy,qz (default: the mounts file)")
    p.add_argument("--mounts", default=None, help="a mounts file (TOML) instead of the packaged one; see docs/cameras.md")
    p.add_argument("--fov", type=_numbers(2), default=None,
                   help="OpenNI2: horizontal,vertical field of view in degrees, for a driver that does not say it")
    p.add_argument("--list", action="store_true", help="print the cameras plugged in, as --source names, and exit")


def resolve_pose(robot: str, name: str, args: argparse.Namespace) -> list[float]:
    if args.pose is not None:
        return mounts.check_pose(args.pose, "--pose")
    from pathlib import Path
    pose = mounts.pose_of(robot, name, Path(args.mounts) if args.mounts else None)
    if pose is None:
        log.warning("no pose for the %s camera of %s (--pose, or a mounts file): it says none, so the web page asks "
                    "for a calibration and perception leaves it out", name, robot)
        return list(mounts.UNKNOWN)
    return pose


def list_cameras() -> list[str]:
    found = []
    for module in ("realsense", "oni"):
        try:
            mod = __import__(f"asibot.camera.{module}", fromlist=["list_devices"])
            found += mod.list_devices()
        except CameraUnavailable as exc:
            found.append(f"({exc})")
    return found


def build(bus: Bus, args: argparse.Namespace) -> CameraService:
    robot = runtime.robot_id(args, example="pioneer")
    if not args.name:
        raise ValueError("--name is required: the camera's name on the bus, e.g. front")
    keys.camera_depth(robot, args.name)            # a ValueError with a sentence for a bad name
    if not args.source:
        raise ValueError(f"--source is required: the camera, one of {', '.join(FORMS)}")
    pose = resolve_pose(robot, args.name, args)
    options = StreamOptions(width=args.size[0], height=args.size[1], fps=args.fps, max_depth=args.max_depth,
                            colour=not args.no_colour, loop=args.loop)
    source = open_source(args.source, options)
    if args.fov is not None and hasattr(source, "fov_deg"):
        source.fov_deg = (args.fov[0], args.fov[1])
    source.start()
    log.info("the %s camera of %s: %s", args.name, robot, source.describe())
    return CameraService(bus, robot, args.name, source, pose)
