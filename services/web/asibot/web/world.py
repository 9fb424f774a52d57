"""The world as the robots' depth cameras see it, for the page: a coloured point cloud in the
robot's frame for the 3D view, and "what is there" when a spot of a camera's picture is touched,
with the tool poses that go above it and reach it, and the joints that do it (or the kinematics'
sentence saying why they cannot).

The server keeps the newest depth image and CameraInfo of every camera on the bus (undecoded,
as web/cameras.py keeps the colour images, whose newest frame it borrows), and decodes them only
when a page asks; it subscribes to the depth images only while pages ask (asibot.bus.OnDemand).
Where a camera stands in the robot's frame is the installer's calibration when there is one
(userdata/calibration.py), else the camera's own CameraInfo.pose (the simulation knows it); a
camera with neither asks for a calibration first. Both go through the
same code, so a real camera and the simulated one behave the same once calibrated.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import struct
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from asibot import depth, keys, messages, robots, things
from asibot.bus import Bus, OnDemand
from asibot.errors import MessageError, RpcError
from asibot.messages import CameraInfo, DepthImage
from asibot.poses import point_rotation
from asibot.web.cameras import SILENT_S, Cameras
from asibot.web.userdata.calibration import Calibration, Calibrations
from asibot.web.userdata.errors import UserDataError
from asibot.web.userdata.folder import Folder

#: "Go above it": the fingertips this far above the touched thing's top, m, tool pointing down.
ABOVE_HEIGHT = 0.12
#: A look waits this long at most for each camera's first pictures taken after it was asked, s.
FRESH_WAIT_S = 2.0
#: "Reach it" on a surface (nothing stands there): the fingertips this far above it, m.
SURFACE_CLEARANCE = 0.01
#: The tool pointing straight down: rot(y') and rot(z''), deg (the worked pick's DOWN).
TOOL_DOWN = (180.0, 0.0)
#: The cloud's wire form: a little-endian uint32 count N, then N x 3 float32 x y z (m, the
#: robot's frame), then N x 3 uint8 r g b. Typed arrays read it as it is; about 75 kB for 5000 points.
CLOUD_HEADER = struct.Struct("<I")


@dataclass(frozen=True)
class _Cloud:
    """A cloud made, and what it was made from."""
    seq: int                    # the depth image's number as kept
    pose: tuple                 # the camera's pose, rounded
    image: np.ndarray           # the depth image
    jpeg: bytes                 # the colour picture
    count: int
    body: bytes
    version: int


def _decoded(jpeg: bytes) -> np.ndarray | None:
    """A colour picture decoded; None without one (or a broken frame: grey points, no colour
    name, this once)."""
    if not jpeg:
        return None
    try:
        return depth.decode_rgb(jpeg)
    except depth.DepthError:
        return None


@dataclass
class _Kept:
    """The newest message of one stream of one camera, undecoded."""

    seq: int
    time: float
    payload: bytes


class World:
    """The depth cameras of every robot, and what their pictures show in the robot's frame."""

    def __init__(self, bus: Bus, cameras: Cameras, folder: Folder,
                 inverse: Callable[[str, list[float]], list[float]],
                 tool_point: Callable[[str], list[float] | None]) -> None:
        self.cameras = cameras
        self.calibrations = Calibrations(folder)
        self.inverse = inverse
        self.tool_point = tool_point
        self._lock = threading.Lock()
        self._kept: dict[tuple[str, str, str], _Kept] = {}
        self._clouds: dict[tuple[str, str], _Cloud] = {}
        self._cloud_versions = itertools.count(1)
        self._seen_marks: dict[tuple[str, str], np.ndarray] = {}   # a calibration mark touched, not yet paired
        # A CameraInfo costs no rendering: it is kept all the time, the depth images on demand.
        bus.subscribe_raw(keys.every_robot(keys.camera_info, "*"), self._keeper("info"), maxsize=2)
        every = keys.every_robot(keys.camera_depth, "*")
        self._depths = OnDemand(bus, lambda: bus.subscribe_raw(every, self._keeper("depth"), maxsize=2),
                                name="web-depths")

    def _keeper(self, stream: str) -> Callable[[str, bytes, int], None]:
        def keep(key: str, payload: bytes, stamp_ns: int) -> None:
            robot, name = keys.robot_of(key), keys.camera_of(key)
            if robot and name:
                with self._lock:
                    old = self._kept.get((robot, name, stream))
                    self._kept[(robot, name, stream)] = _Kept((old.seq if old else 0) + 1, time.monotonic(), payload)
        return keep

    def close(self) -> None:
        self._depths.close()

    # --- what is known of a camera --------------------------------------------------------
    def names(self, robot: str) -> list[str]:
        """Cameras of `robot` that sent a depth image and a CameraInfo in the last SILENT_S s."""
        self._depths.want(lambda: bool(self._sending(robot)))
        return self._sending(robot)

    def _sending(self, robot: str) -> list[str]:
        now = time.monotonic()
        with self._lock:
            depth_names = {n for (r, n, s), k in self._kept.items() if r == robot and s == "depth" and now - k.time < SILENT_S}
            info_names = {n for (r, n, s), k in self._kept.items() if r == robot and s == "info" and now - k.time < SILENT_S}
        return sorted(depth_names & info_names)

    def listing(self, robot: str) -> list[dict[str, Any]]:
        """The depth cameras of `robot` as the page needs them: picture size, whether it has a
        colour picture to touch, and where its pose comes from ("calibration", "camera", None)."""
        self._depths.want()     # subscribed now: the wait for pictures below is the wait for depth too
        colour = set(self.cameras.names(robot))
        out = []
        for name in self.names(robot):
            info = self._info(robot, name)
            out.append({"name": name, "width": info.width, "height": info.height, "picture": name in colour,
                        "pose_from": self._pose_source(robot, name, info)})
        return out

    def _fresh(self, robot: str, name: str, stream: str) -> _Kept | None:
        with self._lock:
            kept = self._kept.get((robot, name, stream))
        return kept if kept is not None and time.monotonic() - kept.time < SILENT_S else None

    def _newest(self, robot: str, name: str, stream: str) -> _Kept:
        if stream == "depth":
            self._depths.want(lambda: self._fresh(robot, name, stream) is not None)
        kept = self._fresh(robot, name, stream)
        if kept is None:
            sending = ", ".join(self.names(robot)) or "none"
            raise RpcError("unavailable", f"{robot} has no depth camera {name!r} sending images; its depth cameras: {sending}.")
        return kept

    def _info(self, robot: str, name: str) -> CameraInfo:
        try:
            return messages.decode(CameraInfo, self._newest(robot, name, "info").payload)
        except MessageError as exc:
            raise RpcError("unavailable", f"The {name} camera's description cannot be read: {exc}") from None

    def _depth(self, robot: str, name: str) -> tuple[int, np.ndarray]:
        kept = self._newest(robot, name, "depth")
        try:
            return kept.seq, np.asarray(messages.decode(DepthImage, kept.payload).depth, np.float32)
        except MessageError as exc:
            raise RpcError("unavailable", f"The {name} camera's depth image cannot be read: {exc}") from None

    def _pose_source(self, robot: str, name: str, info: CameraInfo) -> str | None:
        if self.calibrations.get(robot, name).pose is not None:
            return "calibration"
        try:
            depth.pose_matrix(info.pose)
            return "camera"
        except depth.DepthError:
            return None

    def pose(self, robot: str, name: str, info: CameraInfo) -> np.ndarray:
        """Where the camera stands in the robot's frame: the calibration's pose, else its own."""
        solved = self.calibrations.get(robot, name).pose
        if solved is not None:
            return depth.pose_matrix(solved)
        try:
            return depth.pose_matrix(info.pose)
        except depth.DepthError:
            raise RpcError("unavailable", f"The {name} camera does not say where it stands: calibrate the camera first "
                                          "(Calibrate the camera, beside its picture).") from None

    # --- the point cloud -------------------------------------------------------------------
    def cloud(self, robot: str, name: str) -> tuple[int, bytes, int]:
        """(N, the cloud's wire form: see CLOUD_HEADER, its version) of the newest depth image;
        made once per image and pose, however many pages ask. The version changes only when
        the cloud does: a still world's camera sends the same pictures again, and a page that
        has this version draws nothing again."""
        info = self._info(robot, name)
        pose = self.pose(robot, name, info)
        seq, image = self._depth(robot, name)
        where = tuple(np.round(pose, 9).ravel())
        with self._lock:
            cached = self._clouds.get((robot, name))
        if cached is not None and cached.seq == seq and cached.pose == where:
            return cached.count, cached.body, cached.version
        picture = self.cameras.newest(robot, name)
        jpeg = b"" if picture is None else picture.jpeg
        if (cached is not None and cached.pose == where and cached.jpeg == jpeg
                and np.array_equal(cached.image, image)):
            made = dataclasses.replace(cached, seq=seq)
        else:
            try:
                xyz, colours = depth.cloud(image, _decoded(jpeg), info, pose)
            except depth.DepthError as exc:
                raise RpcError("unavailable", str(exc)) from None
            body = CLOUD_HEADER.pack(len(xyz)) + xyz.astype("<f4").tobytes() + colours.tobytes()
            made = _Cloud(seq, where, image, jpeg, len(xyz), body, next(self._cloud_versions))
        with self._lock:
            self._clouds[(robot, name)] = made
        return made.count, made.body, made.version

    def _rgb(self, robot: str, name: str) -> np.ndarray | None:
        """The camera's newest colour picture, decoded; None without one."""
        picture = self.cameras.newest(robot, name)
        return None if picture is None else _decoded(picture.jpeg)

    # --- touch to reach --------------------------------------------------------------------
    def touch(self, robot: str, name: str, u: float, v: float) -> dict[str, Any]:
        """What is at pixel (u, v) of the camera's picture, and the two tool poses the page
        offers: "above" (pointing down, the fingertips ABOVE_HEIGHT over its top) and "reach"
        (the grasp: the fingertips the robot's grip depth below its top, at its centre), each
        with its joints or the kinematics' sentence."""
        spec = _spec(robot)
        info = self._info(robot, name)
        pose = self.pose(robot, name, info)
        _, image = self._depth(robot, name)
        try:
            found = depth.object_at(image, info, pose, u, v)
        except depth.DepthError as exc:
            raise RpcError("bad_request", str(exc)) from None
        above, reach = grasp_points(found, spec)
        rgb = self._rgb(robot, name)
        colour = depth.colour_name(rgb, found.region) if rgb is not None and found.region is not None else None
        return {"found": found.as_json(), "colour": colour, "says": describe(found, colour),
                "above": self._candidate(robot, above), "reach": self._candidate(robot, reach),
                "names": spec.joint_names}

    # --- a taught thing, found again ---------------------------------------------------------
    def find(self, robot: str, thing: things.Thing) -> dict[str, Any]:
        """Where `thing` stands now, as every camera of `robot` with a colour picture sees it,
        and the points above it and to grasp it from there (asibot.things): what a taught
        pick looks for when it runs, so it finds the can where it stands today. RpcError
        "not_found" says what the cameras saw instead, "unreachable" why the arm cannot."""
        asked = time.monotonic()
        spec = _spec(robot)
        colour = set(self.cameras.names(robot))
        seen: list[things.Seen] = []
        for name in self.names(robot):
            if name not in colour:
                continue
            # Pictures taken after the question: the thing may have been moved a moment ago.
            self._depths.want()
            while not self._received_since(robot, name, asked) and time.monotonic() < asked + FRESH_WAIT_S:
                time.sleep(0.01)
            self.cameras.since(robot, name, asked, FRESH_WAIT_S)
            info = self._info(robot, name)
            pose = self.pose(robot, name, info)
            _, image = self._depth(robot, name)
            try:
                seen += things.objects_in_view(image, self._rgb(robot, name), info, pose, name)
            except depth.DepthError:   # a frame that does not match its description: the other cameras still look
                continue
        if not colour:
            raise RpcError("unavailable", f"{robot} has no camera sending colour pictures, so it cannot look "
                                          f"for the {thing.name}.")
        best = things.choose(thing, seen)
        if best is None:
            raise RpcError("not_found", things.not_found(thing, seen))
        above, reach = (self._candidate(robot, p) for p in grasp_points(best.found, spec))
        moved = things.moved(thing, best)
        for candidate in (above, reach):
            if candidate["unreachable"] is not None:
                raise RpcError("unreachable", f"I see the {thing.name} ({best.words()}, {moved * 100:.0f} cm from where "
                                              f"it was taught), but the arm cannot get to it: {candidate['unreachable']}")
        return {"says": f"I see the {thing.name}, {moved * 100:.0f} cm from where it was taught.",
                "above": above["point"], "reach": reach["point"], "moved": round(moved, 3),
                "seen": [s.words() for s in seen]}

    def _received_since(self, robot: str, name: str, start: float) -> bool:
        with self._lock:
            kept = self._kept.get((robot, name, "depth"))
        return kept is not None and kept.time > start

    def _candidate(self, robot: str, point: list[float]) -> dict[str, Any]:
        point = [round(float(c), 4) for c in point]
        try:
            return {"point": point, "joints": self.inverse(robot, point), "unreachable": None}
        except RpcError as exc:
            return {"point": point, "joints": None, "unreachable": exc.message}

    # --- calibration ---------------------------------------------------------------------
    def calibration(self, robot: str, name: str) -> dict[str, Any]:
        return self.calibrations.get(robot, name).as_json()

    def see_mark(self, robot: str, name: str, u: float, v: float) -> dict[str, Any]:
        """Where the camera sees the mark at pixel (u, v), kept until the tool is on it. Read
        now, while the mark is in view: once the fingertips are on it, the camera sees them."""
        info = self._info(robot, name)
        _, image = self._depth(robot, name)
        try:
            depth.check_size(image, info)
            su, sv = depth.depth_at(image, int(round(u)), int(round(v)))
        except depth.DepthError as exc:
            raise RpcError("bad_request", str(exc)) from None
        seen = depth.deproject(info, su, sv, float(image[sv, su]))
        with self._lock:
            self._seen_marks[(robot, name)] = seen
        return {"seen": [round(float(c), 4) for c in seen]}

    def add_mark(self, robot: str, name: str) -> dict[str, Any]:
        """Pair the mark seen last with where the fingertips are now (the arm's newest point,
        as a capture reads it)."""
        spec = _spec(robot)
        here = self.tool_point(robot)
        if here is None:
            raise RpcError("unavailable", f"No position from {robot} yet: is its kinematics service running?")
        with self._lock:
            seen = self._seen_marks.pop((robot, name), None)
        if seen is None:
            raise RpcError("bad_request", "Touch the mark in the picture first, then put the fingertips on it.")
        return self._checked(lambda: self.calibrations.add_mark(robot, name, seen.tolist(), fingertips(here, spec)))

    def solve(self, robot: str, name: str) -> dict[str, Any]:
        return self._checked(lambda: self.calibrations.solve(robot, name))

    def clear(self, robot: str, name: str) -> dict[str, Any]:
        self.calibrations.clear(robot, name)
        return Calibration().as_json()

    @staticmethod
    def _checked(action: Callable[[], Calibration]) -> dict[str, Any]:
        try:
            return action().as_json()
        except UserDataError as exc:
            raise RpcError("bad_request", str(exc)) from None


def _spec(robot: str) -> robots.RobotSpec:
    try:
        return robots.get(robot)
    except KeyError:
        raise RpcError("bad_request", f"There is no robot {robot!r}; choose one of {', '.join(robots.ids())}.") from None


def grasp_points(found: depth.Touched, spec: robots.RobotSpec) -> tuple[list[float], list[float]]:
    """The tool points above what was found (pointing down, the fingertips ABOVE_HEIGHT over
    its top) and to reach it (an object: the fingertips the robot's grip depth below its top,
    at its centre; a surface: just over it)."""
    fingers = spec.finger_length
    if found.kind == "object":
        x, y = found.centre[:2]
        reach_z = found.top - spec.grip_depth + fingers
    else:
        x, y = found.surface[:2]
        reach_z = found.top + SURFACE_CLEARANCE + fingers
    return [x, y, found.top + ABOVE_HEIGHT + fingers, *TOOL_DOWN], [x, y, reach_z, *TOOL_DOWN]


def fingertips(point: list[float], spec: robots.RobotSpec) -> list[float]:
    """Where the fingertips end for a tool point [x y z rot(y') rot(z'')] (m, deg): the robot's
    fingertip reach along the tool's z axis (what touches a calibration mark)."""
    rot = point_rotation(point[0], point[1], math.radians(point[3]), math.radians(point[4]))
    return [float(c) for c in np.asarray(point[:3]) + rot[:, 2] * spec.fingertip_reach]


def describe(found: depth.Touched, colour: str | None = None) -> str:
    """What was touched, in the user's words: "a red object 12 cm tall, 0.50 m away" (from the arm)."""
    x, y = (found.centre if found.kind == "object" else found.surface)[:2]
    away = math.hypot(x, y)
    if found.kind == "object":
        article = "an" if colour is None or colour[0] in "aeiou" else "a"
        return f"{article} {colour + ' ' if colour else ''}object {found.height * 100:.0f} cm tall, {away:.2f} m away"
    return f"a flat surface {away:.2f} m away"
