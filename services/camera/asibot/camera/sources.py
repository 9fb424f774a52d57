"""A depth camera chosen by a URL-like name, as python-can and the Zenoh drivers choose their bus.

| name | what |
|---|---|
| `realsense:` / `realsense:SERIAL` | the only (or that) Intel RealSense on USB (pyrealsense2) |
| `realsense-bag:/path/file.db3` (or `.bag`) | a librealsense recording played back |
| `openni2:` / `openni2:URI` | the first (or that) OpenNI2 device: Kinect v1 (libfreenect's OpenNI2 driver), Xtion, Astra; a URI is what `--list` prints, or an `.oni` recording |

Every source gives `Frame`s: depth as the simulation gives it (H x W float32 metres along the
optical axis, 0 = no return, beyond `max_depth` 0 too), the colour image registered to the depth
image (same size, same pixels: one CameraInfo serves both, as for the sim's kitchen camera) and
the intrinsics (pixel centres at integer coordinates, as librealsense and the sim count them).
A bad name raises `SourceError` naming the forms; a camera that cannot be opened raises
`CameraUnavailable`, whose message is the sentence to show (what to check), never a traceback.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from asibot.depth import Intrinsics

#: The forms a camera's name takes, for error messages and --help.
FORMS = ("realsense:", "realsense:SERIAL", "realsense-bag:/path/file.db3 (or .bag)", "openni2:", "openni2:URI")
#: Beyond this a camera reports 0 (no return), as the sim does (asibot.sim.cameras.MAX_DEPTH_M).
MAX_DEPTH_M = 8.0


class SourceError(ValueError):
    """A camera name that is not one of FORMS, or options that cannot work; the message says so."""


class CameraUnavailable(RuntimeError):
    """The camera cannot be opened or was lost; the message is the sentence (what to check)."""


class EndOfRecording(Exception):
    """A recording played back has no more frames."""


@dataclass(frozen=True)
class Frame:
    depth: np.ndarray           # H x W float32 m, 0 = no return
    rgb: np.ndarray | None      # H x W x 3 uint8 RGB registered to depth; None: a depth-only camera
    intrinsics: Intrinsics
    stamp: int                  # ns, this computer's clock when the frame arrived


@dataclass(frozen=True)
class StreamOptions:
    """What a live camera is asked for; a recording plays what it holds."""

    width: int = 640
    height: int = 480
    fps: int = 15
    max_depth: float = MAX_DEPTH_M
    colour: bool = True
    loop: bool = False          # a recording starts again at its end
    realtime: bool = True       # a recording plays at its rate (False: every frame, as fast as read)

    def check(self) -> None:
        if not (16 <= self.width <= 4096 and 16 <= self.height <= 4096):
            raise SourceError(f"--width/--height {self.width}x{self.height}: a camera's mode is 16 to 4096 pixels a side")
        if not 1 <= self.fps <= 300:
            raise SourceError(f"--fps {self.fps}: a camera runs at 1 to 300 frames a second")
        if not self.max_depth > 0:
            raise SourceError(f"--max-depth {self.max_depth}: it must be a positive number of metres")


class Source(ABC):
    """One camera: `start()` opens it (CameraUnavailable with a sentence if it cannot), `read()`
    waits up to `timeout` s for the next frame (None if none came), `close()` lets it go."""

    url: str = ""

    @abstractmethod
    def start(self) -> None: ...

    @abstractmethod
    def read(self, timeout: float) -> Frame | None: ...

    @abstractmethod
    def close(self) -> None: ...

    def describe(self) -> str:
        """What was opened, for the log ("Intel RealSense D435 123456, 640x480 at 15 Hz")."""
        return self.url


def bad_name(url: str, why: str = "") -> SourceError:
    forms = ", ".join(FORMS)
    return SourceError(f"{url!r} is not a camera name{': ' + why if why else ''}; a camera is named one of: {forms}")


def parse(url: str) -> tuple[str, str]:
    """(scheme, rest) of a camera name; SourceError naming the forms for anything else."""
    scheme, colon, rest = (url or "").strip().partition(":")
    if not colon or scheme not in ("realsense", "realsense-bag", "openni2"):
        raise bad_name(url)
    if scheme == "realsense" and rest and not rest.replace("-", "").isalnum():
        raise bad_name(url, "a RealSense serial number is letters and digits (realsense:123456789012)")
    if scheme == "realsense-bag" and not rest:
        raise bad_name(url, "realsense-bag: needs the recording's path (realsense-bag:/path/file.db3)")
    return scheme, rest


def open_source(url: str, options: StreamOptions = StreamOptions()) -> Source:
    """The Source a camera name says (not started). Imports the camera's library only here, so a
    robot without librealsense can still run an OpenNI2 camera and the other way round."""
    scheme, rest = parse(url)
    options.check()
    if scheme == "openni2":
        from asibot.camera.oni import OpenNI2Source
        return OpenNI2Source(rest or None, options, url=url)
    from asibot.camera.realsense import RealSenseSource
    if scheme == "realsense-bag":
        return RealSenseSource(url=url, options=options, recording=rest)
    return RealSenseSource(url=url, options=options, serial=rest or None)


def depth_metres(raw: np.ndarray, units: float, max_depth: float) -> np.ndarray:
    """A camera's integer depth (`units` m per count) as the sim's: float32 m, 0 = no return."""
    depth = np.asarray(raw).astype(np.float32) * np.float32(units)
    depth[depth > max_depth] = 0.0
    return depth


def now_ns() -> int:
    return time.time_ns()
