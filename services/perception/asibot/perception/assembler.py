"""When to publish the merged scan, with cameras that arrive at different times or not at all.

Each camera's newest CameraScan is kept with the time it arrived (the caller's clock). A scan
goes out once per camera cycle, so at the camera rate however many cameras there are:

- when every *fresh* camera (one whose newest frame is younger than `freshness`) has
  delivered a frame since the last scan, or
- when a camera delivers its second frame of a cycle: another camera is late or slower, and
  the scan does not wait for it (its newest frame is still used while fresh).

The scan merges the newest frame of each fresh camera. A camera silent for longer than
`freshness` is left out: its sector becomes unknown (NaN, merge.py), never "free", and
`silent()` names it so the service can say so once. With every camera silent nothing is
published (a scan of NaN only would tell a consumer nothing, and its absence is what a
watchdog notices). Thread-safe: each camera's frames arrive on their own subscriber thread.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Sequence

from asibot.perception.depth_to_scan import CameraScan


@dataclass(frozen=True)
class Frame:
    scan: CameraScan
    received: float     # s, the assembler's caller's clock (monotonic)
    stamp: int          # ns, the producer's stamp of the depth image


class ScanAssembler:
    """Collects the cameras' scans and says when a merged scan is due."""

    def __init__(self, cameras: Sequence[str], freshness: float = 0.5) -> None:
        """`cameras` may be none (a robot with sonar alone): then no scan is ever due here."""
        if not freshness > 0:
            raise ValueError("the freshness window must be a positive number of seconds")
        self.cameras = tuple(cameras)
        self.freshness = freshness
        self._lock = threading.Lock()
        self._newest: dict[str, Frame] = {}
        self._cycle: set[str] = set()

    def add(self, camera: str, scan: CameraScan, received: float, stamp: int) -> list[Frame] | None:
        """Keep `camera`'s newest frame; the frames to merge when a scan is due now, else None."""
        if camera not in self.cameras:
            raise ValueError(f"{camera!r} is not one of the scan's cameras {', '.join(self.cameras)}")
        with self._lock:
            repeat = camera in self._cycle
            self._newest[camera] = Frame(scan, received, stamp)
            self._cycle.add(camera)
            fresh = self._fresh(received)
            if not repeat and any(c not in self._cycle for c in fresh):
                return None
            self._cycle = set()
            return [self._newest[c] for c in fresh]

    def _fresh(self, now: float) -> list[str]:
        return [c for c in self.cameras
                if c in self._newest and now - self._newest[c].received <= self.freshness]

    def silent(self, now: float) -> list[str]:
        """The cameras without a frame younger than the freshness window."""
        with self._lock:
            fresh = set(self._fresh(now))
        return [c for c in self.cameras if c not in fresh]

    def heard(self) -> list[str]:
        """The cameras that delivered at least one frame."""
        with self._lock:
            return [c for c in self.cameras if c in self._newest]
