"""librealsense's software device as a camera for the tests: depth (z16) and colour (rgb8)
streams with chosen intrinsics, frames pushed in by hand, read through a syncer, recorded with
`rs.recorder` when asked (librealsense 2.59 records ROS2 bags, .db3)."""

from __future__ import annotations

import numpy as np
import pyrealsense2 as rs

W, H = 64, 48
UNITS = 0.001
DEPTH_INTR = (50.0, 51.0, 31.5, 23.5)     # fx fy ppx ppy


def _intrinsics(w: int, h: int, fx: float, fy: float, ppx: float, ppy: float) -> rs.intrinsics:
    i = rs.intrinsics()
    i.width, i.height, i.fx, i.fy, i.ppx, i.ppy = w, h, fx, fy, ppx, ppy
    i.model, i.coeffs = rs.distortion.none, [0.0] * 5
    return i


def scene(i: int) -> tuple[np.ndarray, np.ndarray]:
    """Frame i: depth in counts (1 mm) with a hole of no return and a far corner beyond 8 m;
    a colour picture with a gradient that changes each frame."""
    v, u = np.mgrid[0:H, 0:W]
    depth = (500 + 10 * u + 7 * v + 50 * i).astype(np.uint16)
    depth[5:9, 5:9] = 0
    depth[-3:, -3:] = 9000
    rgb = np.stack([(4 * u + i) % 256, (5 * v) % 256, np.full_like(u, 40 * i % 256)], -1).astype(np.uint8)
    return depth, rgb


class SoftCam:
    """A software RealSense: `push(i)` feeds frame i; `wait(ms)` is a FramesetSource's `wait`.
    With `record=path` the frames also go into a recording at `path` (closed by `close`)."""

    def __init__(self, record: str | None = None, colour: bool = True) -> None:
        self.dev = rs.software_device()
        self.dev.register_info(rs.camera_info.name, "asibot software camera")
        self.dev.register_info(rs.camera_info.serial_number, "000000000001")
        # Two sensors, as a D400 has: the stereo module (depth) and the RGB camera.
        stereo = self.dev.add_sensor("Stereo Module")
        self.depth_profile = stereo.add_video_stream(self._stream(rs.stream.depth, 0, rs.format.z16, 2))
        stereo.add_read_only_option(rs.option.depth_units, UNITS)
        self.soft = {"depth": stereo}
        self.colour_profile = None
        if colour:
            # The same intrinsics as depth and no offset: colour aligned to depth is colour itself.
            rgb = self.dev.add_sensor("RGB Camera")
            self.colour_profile = rgb.add_video_stream(self._stream(rs.stream.color, 1, rs.format.rgb8, 3))
            self.depth_profile.register_extrinsics_to(self.colour_profile, _identity())
            self.soft["colour"] = rgb
        self.dev.create_matcher(rs.matchers.default)   # depth and colour of one timestamp make a frameset
        self.recorder = rs.recorder(record, self.dev) if record else None
        self.sensors = self.recorder.query_sensors() if self.recorder else self.dev.query_sensors()
        self.syncer = rs.syncer(64)    # keep every frameset (the default keeps the newest only)
        for sensor, profile in zip(self.sensors, [self.depth_profile, self.colour_profile]):
            sensor.open(profile)
            sensor.start(self.syncer)
        self.closed = False

    @staticmethod
    def _stream(kind: rs.stream, uid: int, fmt: rs.format, bpp: int) -> rs.video_stream:
        s = rs.video_stream()
        s.type, s.index, s.uid, s.width, s.height, s.fps, s.bpp, s.fmt = kind, 0, uid, W, H, 30, bpp, fmt
        s.intrinsics = _intrinsics(W, H, *DEPTH_INTR)
        return s

    def push(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        depth, rgb = scene(i)
        t = i * 1000.0 / 30    # ms, at the streams' 30 Hz: the syncer waits for a frame only when it is due
        self._frame("depth", self.depth_profile, depth, 2, t, i)
        if self.colour_profile is not None:
            self._frame("colour", self.colour_profile, rgb, 3, t, i)
        return depth, rgb

    def _frame(self, sensor: str, profile: rs.stream_profile, pixels: np.ndarray, bpp: int, t: float, i: int) -> None:
        f = rs.software_video_frame()
        f.pixels, f.bpp, f.stride, f.timestamp, f.frame_number = pixels, bpp, bpp * W, t, i
        f.domain = rs.timestamp_domain.hardware_clock
        f.profile = profile.as_video_stream_profile()
        self.soft[sensor].on_video_frame(f)

    def wait(self, timeout_ms: int):
        ok, frames = self.syncer.try_wait_for_frames(timeout_ms)
        return frames if ok else None

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            for sensor in self.sensors:
                sensor.stop()
                sensor.close()
            # The recording closes its file when the last reference to the recorder goes.
            self.sensors = []
            self.recorder = None


def _identity() -> rs.extrinsics:
    e = rs.extrinsics()
    e.rotation, e.translation = [1, 0, 0, 0, 1, 0, 0, 0, 1], [0, 0, 0]
    return e
