"""The perception service on the bus: one instance per robot (`--robot pioneer-sim`).

In: each depth camera's CameraInfo and DepthImage (`keys.camera_info/camera_depth`), the RGB
camera's RgbImage and CameraInfo (`keys.camera_rgb`), the sonar ring (`keys.base_sonar`) and
the odometry (`keys.base_odom`, for the direction of travel). Out: one 360-degree LaserScan in
the base frame on `keys.scan(robot)` per camera cycle, obstacle and camera Events on
`keys.events(robot)`, and the `find` RPC on `keys.perception_rpc(robot, "find")`.

All the work is in plain classes that take arrays and times (rays, depth_to_scan, merge,
assembler, sonar, warnings, finder); this class only moves messages between them and the
bus. Bad input (a NaN depth, an image whose shape is not its CameraInfo's, a CameraInfo with
a zero focal length, a sonar message of the wrong length) is refused whole: counted and
logged by `Bus.reject`, named in `health()`, and nothing is published from it.

A robot with no depth camera (`--depth-cameras none`: the emulated or a bare P3-AT) gets
its scan from the sonar ring alone, one per reading (`SonarRing.scan`), on a coarser grid
(`SONAR_BEAMS`) so that localisation uses every echo.

A camera silent for longer than `freshness` (default 0.5 s, five frames at 10 Hz) is left
out of the scan, whose beams in its direction become unknown (NaN) rather than free; the
user hears it once ("The back camera has sent no depth image for 0.5 s ...") and again
when it is back. With every camera silent no scan is published.
"""

from __future__ import annotations

import argparse
import logging
import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from asibot import keys, runtime, verbs
from asibot import messages as m
from asibot.bus import Bus, OnDemand
from asibot.errors import RpcError
from asibot.runtime import Service
from asibot.verbs import Field, Text, Verb

from asibot.perception import finder
from asibot.perception.assembler import ScanAssembler
from asibot.perception.depth_to_scan import BandConfig, DepthToScan
from asibot.perception.errors import BadInput
from asibot.perception.merge import ScanGrid, merge
from asibot.perception.rays import CameraRays
from asibot.perception.sonar import SonarRing
from asibot.perception.warnings import ObstacleWarner, WarningLevels, clearance, travel_direction

log = logging.getLogger("asibot.perception")

NAME = "perception"

STARTUP_GRACE_S = 5.0
"""A camera is reported silent only this long after its first frame, or after the service's
start if none came: the sim's first frames come a second apart while it starts its renderers."""
WATCH_PERIOD_S = 0.25
RGB_STALE_S = 2.0
"""`find` refuses an RGB image older than this: the robot may have moved since."""
DEPTH_SYNC_S = 0.5
"""`find` uses the depth frames that arrived within this of the RGB image."""

#: The verbs of `keys.perception_rpc`. A colour is any text here: which colours the finder
#: knows (in any capitals) is its own check, whose sentence lists them.
VERBS = {
    "find": Verb({"color": Field(Text("a colour name", longest=40), default="red")},
                 doc="where the largest object of a colour in the RGB camera's view is, in the robot's base frame"),
}


@dataclass
class Options:
    depth_cameras: tuple[str, ...] = ("front", "back")
    rgb_camera: str | None = "rgb"
    band: BandConfig = field(default_factory=BandConfig)
    grid: ScanGrid = field(default_factory=ScanGrid)
    freshness: float = 0.5
    sonar: SonarRing | None = field(default_factory=SonarRing.p3at)
    levels: WarningLevels = field(default_factory=WarningLevels)


@dataclass
class _Camera:
    """What is known of one camera; replaced whole (no lock needed to read a consistent set)."""
    rays: CameraRays | None = None
    converter: DepthToScan | None = None
    info_error: str = ""
    depth: np.ndarray | None = None      # newest valid depth image
    depth_received: float = -math.inf
    rejected: int = 0


class PerceptionService(Service):
    """Depth -> scan, warnings and the object finder for one robot."""

    def __init__(self, bus: Bus, robot: str, options: Options = Options(),
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.bus, self.robot, self.opt, self.clock = bus, robot, options, clock
        self.started = clock()
        names = list(dict.fromkeys([*options.depth_cameras, *([options.rgb_camera] if options.rgb_camera else [])]))
        self._cams: dict[str, _Camera] = {n: _Camera() for n in names}
        self.assembler = ScanAssembler(options.depth_cameras, options.freshness)
        self.warner = ObstacleWarner(options.levels)
        self._lock = threading.Lock()           # publishing: scan, warner state, counters
        self._stop = threading.Event()
        self._sonar: tuple[m.Sonar, float] | None = None
        self._odom: tuple[m.Odometry, float] | None = None
        self._rgb: tuple[m.RgbImage, float] | None = None
        self._silent: set[str] = set()
        self._first_frame: dict[str, float] = {}   # when _watch first saw each camera's frame
        self.watched_at: float | None = None         # the clock when the cameras were last watched
        self.scans = 0
        self.events_sent = 0
        self._pub_scan = bus.publisher(keys.scan(robot), m.LaserScan)
        self._pub_event = bus.publisher(keys.events(robot), m.Event)
        for name in names:
            bus.subscribe(keys.camera_info(robot, name), m.CameraInfo,
                          lambda msg, name=name: self._on_info(name, msg))
        for name in options.depth_cameras:
            bus.subscribe(keys.camera_depth(robot, name), m.DepthImage,
                          lambda msg, name=name: self._on_depth(name, msg), maxsize=1)
        # The finder's pictures only while it is asked to find (the sim renders none nobody receives).
        self._pictures: OnDemand | None = None
        if options.rgb_camera:
            rgb_key = keys.camera_rgb(robot, options.rgb_camera)
            self._pictures = OnDemand(bus, lambda: bus.subscribe(rgb_key, m.RgbImage, self._on_rgb, maxsize=1),
                                      name="perception-pictures")
        if options.sonar is not None:
            bus.subscribe(keys.base_sonar(robot), m.Sonar, self._on_sonar)
        bus.subscribe(keys.base_odom(robot), m.Odometry, self._on_odom)
        verbs.serve(bus, lambda verb: keys.perception_rpc(robot, verb), VERBS, {"find": self._find})
        self._watcher = threading.Thread(target=self._watch, name="perception-watch", daemon=True)
        self._watcher.start()

    # ------------------------------------------------------------------ inputs
    def _on_info(self, name: str, info: m.CameraInfo) -> None:
        cam = self._cams[name]
        if cam.rays is not None and cam.rays.same(info):
            return
        try:
            rays = CameraRays.from_info(info, f"the {name} camera")
            converter = DepthToScan(rays, self.opt.band) if name in self.opt.depth_cameras else None
        except BadInput as exc:
            self.bus.reject(keys.camera_info(self.robot, name), exc)
            self._cams[name] = _Camera(info_error=str(exc), rejected=cam.rejected + 1)
            return
        log.info("%s camera: %dx%d, %s", name, rays.lens.width, rays.lens.height,
                 f"scan by {converter.mode}" if converter else "colour only")
        self._cams[name] = _Camera(rays=rays, converter=converter, rejected=cam.rejected)

    def _on_depth(self, name: str, msg: m.DepthImage) -> None:
        now = self.clock()
        cam = self._cams[name]
        if cam.converter is None:   # no (valid) CameraInfo yet: the frame cannot be placed
            cam.rejected += bool(cam.info_error)
            return
        try:
            scan = cam.converter.convert(msg.depth, f"the {name} camera")
        except BadInput as exc:
            cam.rejected += 1
            self.bus.reject(keys.camera_depth(self.robot, name), exc)
            return
        cam.depth, cam.depth_received = msg.depth, now
        frames = self.assembler.add(name, scan, now, msg.stamp)
        if frames:
            self._publish([f.scan for f in frames], max(f.stamp for f in frames), now)

    def _on_sonar(self, msg: m.Sonar) -> None:
        ring = self.opt.sonar
        if ring is None:    # subscribed only with a ring
            return
        try:
            ring.check(msg)
        except BadInput as exc:
            self.bus.reject(keys.base_sonar(self.robot), exc)
            return
        now = self.clock()
        self._sonar = (msg, now)
        if not self.opt.depth_cameras:          # a robot with sonar alone: its scan, per reading
            with self._lock:
                self._put_scan(ring.scan(self.opt.grid, msg), msg.stamp, now)

    def _on_odom(self, msg: m.Odometry) -> None:
        if math.isfinite(msg.vx) and math.isfinite(msg.wz):
            self._odom = (msg, self.clock())

    def _on_rgb(self, msg: m.RgbImage) -> None:
        self._rgb = (msg, self.clock())

    # ------------------------------------------------------------------ outputs
    def _publish(self, scans: list, stamp: int, now: float) -> None:
        with self._lock:
            ranges = merge(self.opt.grid, scans)
            ring = self.opt.sonar
            if ring is not None and self._sonar is not None and now - self._sonar[1] <= self.opt.freshness:
                ranges = ring.fuse(self.opt.grid, ranges, self._sonar[0])
            self._put_scan(ranges, stamp, now)

    def _put_scan(self, ranges: np.ndarray, stamp: int, now: float) -> None:
        """Publish a scan and warn of what is near in the direction of travel (under the lock)."""
        self._pub_scan.put(self.opt.grid.message(ranges, stamp))
        self.scans += 1
        odom = self._odom if self._odom is not None and now - self._odom[1] <= self.opt.freshness else None
        direction, cap = travel_direction(odom[0].vx if odom else None, odom[0].wz if odom else None)
        event = self.warner.update(clearance(ranges, self.opt.grid, direction), direction, now, cap)
        if event is not None:
            self._event(event)

    def _event(self, event: m.Event) -> None:
        self.events_sent += 1
        log.info("event %s/%s: %s", event.level, event.code, event.text)
        self._pub_event.put(event)

    def _watch(self) -> None:
        while not self._stop.wait(WATCH_PERIOD_S):
            self._watch_once(self.clock())

    def _watch_once(self, now: float) -> None:
        """Say once when a camera falls silent, and once when it is back; watched_at says when it looked."""
        for name in self.assembler.heard():
            self._first_frame.setdefault(name, now)
        silent = {name for name in self.assembler.silent(now)
                  if now - self._first_frame.get(name, self.started) >= STARTUP_GRACE_S}
        for name in sorted(silent - self._silent):
            watching = [c for c in self.opt.depth_cameras if c not in silent]
            rest = (f"the scan covers only the {' and '.join(watching)} camera{'s' if len(watching) > 1 else ''}"
                    if watching else "no scan is published")
            since = (f"for {self.opt.freshness:g} s." if name in self._first_frame else
                     f"since perception started {now - self.started:.0f} s ago (is the sim or the camera's "
                     "driver running?).")
            self._event(m.Event(level="warning", code="camera_silent",
                                text=f"The {name} camera has sent no depth image {since} Obstacles it watches "
                                     f"are not seen; {rest}."))
        for name in sorted(self._silent - silent):
            self._event(m.Event(level="info", code="camera_working", text=f"The {name} camera works again."))
        self._silent = silent
        self.watched_at = now

    # ------------------------------------------------------------------ RPC
    def _find(self, a: Any) -> dict:
        try:
            color = finder.check_color(a.color)
        except BadInput as exc:
            raise RpcError("bad_request", _sentence(exc)) from None
        name = self.opt.rgb_camera
        if not name or self._pictures is None:     # one means the other; both tell mypy
            raise RpcError("unavailable", "This perception service runs without an RGB camera (--rgb-camera).")
        self._pictures.want(lambda: self._rgb is not None and self.clock() - self._rgb[1] <= RGB_STALE_S)
        rgb, cam, now = self._rgb, self._cams[name], self.clock()
        if rgb is None:
            raise RpcError("unavailable", f"No image from the {name} camera yet: is the sim or the camera "
                                          "driver running?")
        if cam.rays is None:
            raise RpcError("unavailable", f"The {name} camera has no valid CameraInfo"
                                          f"{': ' + cam.info_error if cam.info_error else ' yet'}")
        age = now - rgb[1]
        if age > RGB_STALE_S:
            raise RpcError("unavailable", f"The newest image of the {name} camera is {age:.1f} s old; "
                                          "is the camera still running?")
        try:
            bgr = finder.decode_jpeg(rgb[0].jpeg, rgb[0].width, rgb[0].height)
            clouds = []
            for c in self.opt.depth_cameras:
                d = self._cams[c]
                if d.rays is not None and d.depth is not None and abs(d.depth_received - rgb[1]) <= DEPTH_SYNC_S:
                    clouds.append(d.rays.points(d.depth, stride=max(1, d.rays.lens.width // 320)))
            return finder.find(bgr, color, cam.rays, clouds)
        except BadInput as exc:
            raise RpcError("unavailable", f"The {name} camera's image cannot be used: {_sentence(exc)}") from None

    # ------------------------------------------------------------------ runtime
    def health(self) -> dict:
        now = self.clock()
        return {"scans": self.scans, "events": self.events_sent,
                "silent": self.assembler.silent(now),
                "cameras": {n: (c.converter.mode if c.converter else ("colour" if c.rays else c.info_error or "no info"))
                            for n, c in self._cams.items()},
                "rejected_frames": {n: c.rejected for n, c in self._cams.items() if c.rejected}}

    def close(self) -> None:
        self._stop.set()
        if self._pictures is not None:
            self._pictures.close()
        self._watcher.join(timeout=1.0)


def _sentence(exc: Exception) -> str:
    text = str(exc)
    return text[:1].upper() + text[1:]


# ---------------------------------------------------------------------- command line
def _names(text: str) -> tuple[str, ...]:
    if text.strip().lower() == "none":
        return ()
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise argparse.ArgumentTypeError("give at least one camera name, e.g. front,back, or none (sonar alone)")
    return names


#: Beams of a scan from sonar alone: AMCL uses at most 60 beams, every ((beams - 1) // 59)th,
#: so up to 118 it takes each; 90 (4 deg) places each echo within 2 deg of its bearing.
SONAR_BEAMS = 90


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--depth-cameras", type=_names, default=("front", "back"),
                   help="depth cameras merged into the scan, comma-separated (default front,back); "
                        "none: the scan from the sonar ring alone, at each reading")
    p.add_argument("--rgb-camera", default="rgb", help="camera for the object finder; '' for none (default rgb)")
    p.add_argument("--min-height", type=float, default=0.03, help="lowest obstacle above the floor, m (0.03)")
    p.add_argument("--max-height", type=float, default=1.0, help="highest obstacle that matters, m (1.0)")
    p.add_argument("--range-min", type=float, default=0.1, help="depth cameras' blind zone, m from the camera (0.1)")
    p.add_argument("--range-max", type=float, default=8.0,
                   help="reach, m: from each camera, and the scan's range_max from the base centre (8.0)")
    p.add_argument("--beams", type=int, default=None,
                   help=f"beams of the 360-degree scan (720: 0.5 deg; {SONAR_BEAMS} from sonar alone)")
    p.add_argument("--freshness", type=float, default=0.5,
                   help="s after which a silent camera or sonar is left out of the scan (0.5)")
    p.add_argument("--no-sonar", action="store_true", help="do not fuse the sonar ring")


def build(bus: Bus, args: argparse.Namespace) -> PerceptionService:
    # No default: which robot's cameras to read is the user's choice.
    robot = runtime.robot_id(args, example="pioneer-sim")
    rgb = args.rgb_camera or None
    for name in (*args.depth_cameras, *([rgb] if rgb else [])):
        keys.camera_depth(robot, name)          # a ValueError with a sentence for a bad name
    band = BandConfig(min_height=args.min_height, max_height=args.max_height,
                      range_min=args.range_min, range_max=args.range_max)
    band.check()
    if not args.freshness > 0:
        raise ValueError("--freshness must be a positive number of seconds")
    if not args.depth_cameras and args.no_sonar:
        raise ValueError("with no depth camera (--depth-cameras none) the scan comes from the sonar: "
                         "leave out --no-sonar")
    beams = args.beams or (720 if args.depth_cameras else SONAR_BEAMS)
    grid = ScanGrid(beams=beams, range_max=args.range_max)
    return PerceptionService(bus, robot, Options(
        depth_cameras=args.depth_cameras, rgb_camera=rgb, band=band, grid=grid, freshness=args.freshness,
        sonar=None if args.no_sonar else SonarRing.p3at()))
