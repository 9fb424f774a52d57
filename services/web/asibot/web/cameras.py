"""Camera images for the Video tab, as MJPEG streams an <img> can show with no script.

The cameras publish JPEG frames on the bus already; the server keeps the newest frame of each
(undecoded) and forwards frames to the pages that watch. It subscribes only while a page asks
for pictures (asibot.bus.OnDemand: the sim renders none that nobody receives). Which cameras exist
is learnt from their frames: a camera is listed while it sends.
"""

from __future__ import annotations

import threading
import time
from typing import Iterator

from asibot import keys, messages
from asibot.errors import MessageError
from asibot.bus import Bus, OnDemand
from asibot.messages import RgbImage

BOUNDARY = "frame"
#: A camera silent this long is no longer listed, and its watchers' streams end, s.
SILENT_S = 5.0


class Cameras:
    """The newest frame of every camera on the bus, by (robot, camera name)."""

    def __init__(self, bus: Bus) -> None:
        self._cond = threading.Condition()
        self._frames: dict[tuple[str, str], tuple[int, float, bytes]] = {}   # seq, time, payload
        every = keys.every_robot(keys.camera_rgb, "*")
        self._demand = OnDemand(bus, lambda: bus.subscribe_raw(every, self._on_frame, maxsize=4),
                                name="web-pictures")

    def _on_frame(self, key: str, payload: bytes, stamp_ns: int) -> None:
        robot, name = keys.robot_of(key), keys.camera_of(key)
        if robot and name:
            with self._cond:
                seq = self._frames.get((robot, name), (0, 0.0, b""))[0] + 1
                self._frames[(robot, name)] = (seq, time.monotonic(), payload)
                self._cond.notify_all()

    def names(self, robot: str) -> list[str]:
        """Cameras of `robot` that sent a frame in the last SILENT_S seconds."""
        self._demand.want(lambda: bool(self._sending(robot)))
        return self._sending(robot)

    def _sending(self, robot: str) -> list[str]:
        now = time.monotonic()
        with self._cond:
            return sorted(n for (r, n), (_, t, _) in self._frames.items() if r == robot and now - t < SILENT_S)

    def _fresh(self, robot: str, name: str) -> tuple[int, float, bytes] | None:
        with self._cond:
            kept = self._frames.get((robot, name))
        return kept if kept is not None and time.monotonic() - kept[1] < SILENT_S else None

    def since(self, robot: str, name: str, start: float, timeout: float) -> bool:
        """Wait (up to `timeout` s) for a picture received after `start` (time.monotonic()):
        one that shows the world as it is now, not as it was before the asker's moment."""
        deadline = time.monotonic() + timeout
        self._demand.want()
        with self._cond:
            while True:
                kept = self._frames.get((robot, name))
                if kept is not None and kept[1] > start:
                    return True
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)

    def newest(self, robot: str, name: str) -> RgbImage | None:
        """The camera's newest colour image (decoded from its message now), or None while it
        sends none; the world's point cloud takes its colours from it."""
        self._demand.want(lambda: self._fresh(robot, name) is not None)
        kept = self._fresh(robot, name)
        if kept is None:
            return None
        try:
            return messages.decode(RgbImage, kept[2])
        except MessageError:
            return None

    def frames(self, robot: str, name: str, stop: threading.Event) -> Iterator[bytes]:
        """JPEG frames of one camera as they come, until `stop` or SILENT_S of silence."""
        if name not in self.names(robot):
            raise KeyError(f"{robot} has no camera {name!r} sending images; it has: "
                           f"{', '.join(self.names(robot)) or 'none'}")
        return self._stream(robot, name, stop)

    def _stream(self, robot: str, name: str, stop: threading.Event) -> Iterator[bytes]:
        seen = 0
        while not stop.is_set():
            self._demand.want()         # a page that watches keeps the pictures coming
            with self._cond:
                fresh = self._cond.wait_for(
                    lambda: stop.is_set() or self._frames[(robot, name)][0] != seen, timeout=SILENT_S)
                if not fresh or stop.is_set():
                    return
                seen, _, payload = self._frames[(robot, name)]
            try:
                yield messages.decode(RgbImage, payload).jpeg
            except MessageError:
                continue

    def close(self) -> None:
        self._demand.close()


def mjpeg(frames: Iterator[bytes]) -> Iterator[bytes]:
    """multipart/x-mixed-replace parts, one per JPEG frame."""
    for jpeg in frames:
        yield (f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {len(jpeg)}\r\n\r\n").encode() + jpeg + b"\r\n"
