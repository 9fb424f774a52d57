"""Intel RealSense cameras through librealsense (pyrealsense2): live on USB, or a recording.

Depth comes as z16 counts of the device's depth unit (1 mm on the D400 series, read from each
frame); colour as rgb8, aligned to the depth image by librealsense (`rs.align(depth)`), so one
CameraInfo, the depth stream's intrinsics, describes both, and the depth is the camera's own
(aligning depth to colour instead reprojects it and leaves holes). The price: a colour pixel
with no depth behind it (no return) is black. `FramesetSource` does the work on
any source of framesets; `RealSenseSource` gets them from a pipeline (a device or a file), and
the tests from librealsense's software device through a syncer.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Callable

import numpy as np

from asibot.camera.sources import (CameraUnavailable, EndOfRecording, Frame, Intrinsics, Source, SourceError,
                                   StreamOptions, depth_metres, now_ns)

log = logging.getLogger(__name__)

NO_DEVICE = ("No Intel RealSense camera was found. Check that it is plugged in (a USB 3 port and cable: "
             "a blue port, and a cable that carries data), that this user may open it (librealsense's udev "
             "rules, 99-realsense-libusb.rules, in /etc/udev/rules.d; in a container, the USB bus passed "
             "through), and that no other program (realsense-viewer, another camera service) holds it.")


def library() -> Any:
    """The pyrealsense2 module, or CameraUnavailable saying how to get it."""
    try:
        import pyrealsense2 as rs
    except ImportError as exc:
        raise CameraUnavailable(f"librealsense's Python module (pyrealsense2) cannot be loaded ({exc}): "
                                "install the stack's requirements (it has wheels for x86_64 Linux and Windows) "
                                "or build librealsense with its Python bindings.") from None
    return rs


def intrinsics_of(profile: Any) -> Intrinsics:
    i = profile.as_video_stream_profile().get_intrinsics()
    return Intrinsics(int(i.width), int(i.height), float(i.fx), float(i.fy), float(i.ppx), float(i.ppy))


def registered(depth: Any, colour: Any) -> bool:
    """Colour and depth share one picture (same intrinsics, no offset): no alignment needed
    (librealsense's align would still move some pixels by one)."""
    try:
        e = depth.get_extrinsics_to(colour)
    except RuntimeError:
        return False
    return (intrinsics_of(depth) == intrinsics_of(colour)
            and np.allclose(e.rotation, np.eye(3).ravel(), atol=1e-6) and np.allclose(e.translation, 0, atol=1e-6))


class FramesetSource(Source):
    """Framesets (depth and maybe colour) -> Frames. `wait(timeout_ms)` gives the next frameset or
    None; colour, when there is some, is aligned to depth."""

    def __init__(self, wait: Callable[[int], Any], options: StreamOptions = StreamOptions(), url: str = "") -> None:
        self.url, self.options = url, options
        self._wait = wait
        self._rs = library()
        self._align = self._rs.align(self._rs.stream.depth)
        self._registered: bool | None = None     # colour already in the depth image's pixels

    def start(self) -> None:
        pass

    def close(self) -> None:
        pass

    def read(self, timeout: float) -> Frame | None:
        frames = self._wait(max(1, int(timeout * 1000)))
        if frames is None:
            return None
        return self.convert(frames)

    def convert(self, frames: Any) -> Frame | None:
        stamp = now_ns()
        colour = frames.first_or_default(self._rs.stream.color) if self.options.colour else None
        if colour and frames.get_depth_frame():
            if self._registered is None:
                self._registered = registered(frames.get_depth_frame().get_profile(), colour.get_profile())
            if not self._registered:
                frames = self._align.process(frames)
        depth = frames.get_depth_frame()
        if not depth:
            return None
        raw = np.asanyarray(depth.get_data())
        colour = frames.get_color_frame() if self.options.colour else None
        rgb = None
        if colour:
            rgb = np.asanyarray(colour.get_data())
            fmt = colour.get_profile().format()
            if fmt == self._rs.format.bgr8:
                rgb = rgb[..., ::-1]
            elif fmt != self._rs.format.rgb8:
                raise SourceError(f"the colour stream is {fmt}; only rgb8 and bgr8 are read")
            rgb = np.ascontiguousarray(rgb)
        return Frame(depth=depth_metres(raw, depth.get_units(), self.options.max_depth), rgb=rgb,
                     intrinsics=intrinsics_of(depth.get_profile()), stamp=stamp)


class RealSenseSource(FramesetSource):
    """A pipeline on a USB camera (`serial`, or the only one) or on a recording (`recording`)."""

    def __init__(self, url: str, options: StreamOptions = StreamOptions(), serial: str | None = None,
                 recording: str | None = None) -> None:
        super().__init__(self._next, options, url)
        self.serial, self.recording = serial, recording
        self._pipe: Any = None
        self._playback: Any = None
        self._what = url

    def _next(self, timeout_ms: int) -> Any:
        ok, frames = self._pipe.try_wait_for_frames(timeout_ms)
        if ok:
            return frames
        if self._playback is not None and self._playback.current_status() == self._rs.playback_status.stopped:
            raise EndOfRecording(f"the recording {self.recording} has no more frames")
        return None

    def start(self) -> None:
        rs, opt = self._rs, self.options
        cfg = rs.config()
        if self.recording is not None:
            path = Path(self.recording)
            if not path.is_file():
                raise CameraUnavailable(f"There is no recording {path}: give the path of a librealsense "
                                        "recording (.db3, or .bag from librealsense before 2.59).")
            cfg.enable_device_from_file(str(path), repeat_playback=opt.loop)
        else:
            self._choose_device(cfg)
            cfg.enable_stream(rs.stream.depth, opt.width, opt.height, rs.format.z16, opt.fps)
            wrapper = rs.pipeline_wrapper(rs.pipeline())
            if opt.colour:
                cfg.enable_stream(rs.stream.color, opt.width, opt.height, rs.format.rgb8, opt.fps)
                if not cfg.can_resolve(wrapper):
                    log.warning("the camera has no %dx%d colour at %d Hz: depth only", opt.width, opt.height, opt.fps)
                    cfg.disable_stream(rs.stream.color)
            if not cfg.can_resolve(wrapper):
                raise CameraUnavailable(f"The RealSense camera has no {opt.width}x{opt.height} depth mode at "
                                        f"{opt.fps} Hz: choose another --width/--height/--fps (640x480 at 6, 15, 30 "
                                        "or 60 Hz suits the D400 series), or check it is on a USB 3 port "
                                        "(USB 2 offers fewer modes).")
        self._pipe = rs.pipeline()
        try:
            profile = self._pipe.start(cfg)
        except RuntimeError as exc:
            self._pipe = None
            if self.recording is not None:
                raise CameraUnavailable(f"librealsense cannot play {self.recording}: {exc}.") from None
            raise CameraUnavailable(f"The RealSense camera could not be started ({exc}). "
                                    f"{NO_DEVICE.split('. ', 1)[1]}") from None
        device = profile.get_device()
        if self.recording is not None:
            self._playback = device.as_playback()
            self._playback.set_real_time(self.options.realtime)     # at the recorded rate, or every frame
        info = rs.camera_info
        name = device.get_info(info.name) if device.supports(info.name) else "RealSense"
        serial = device.get_info(info.serial_number) if device.supports(info.serial_number) else "?"
        streams = ", ".join(f"{s.stream_type().name} {s.as_video_stream_profile().width()}x"
                            f"{s.as_video_stream_profile().height()} at {s.fps()} Hz" for s in profile.get_streams()
                            if s.stream_type() in (rs.stream.depth, rs.stream.color))
        self._what = f"{name} {serial} ({self.url}): {streams}"

    def _choose_device(self, cfg: Any) -> None:
        found = {}
        for dev in self._rs.context().query_devices():
            try:
                found[dev.get_info(self._rs.camera_info.serial_number)] = dev.get_info(self._rs.camera_info.name)
            except RuntimeError:
                continue
        if not found:
            raise CameraUnavailable(NO_DEVICE)
        if self.serial is None:
            if len(found) > 1:
                raise CameraUnavailable(f"{len(found)} RealSense cameras are plugged in: name one, "
                                        f"{' or '.join('realsense:' + s for s in sorted(found))}.")
            self.serial = next(iter(found))
        elif self.serial not in found:
            raise CameraUnavailable(f"No RealSense camera has the serial number {self.serial}; plugged in: "
                                    f"{', '.join(f'{n} realsense:{s}' for s, n in sorted(found.items()))}. "
                                    "Check the number (it is on the camera's label and in realsense-viewer).")
        cfg.enable_device(self.serial)

    def describe(self) -> str:
        return self._what

    def close(self) -> None:
        if self._pipe is not None:
            try:
                self._pipe.stop()
            except RuntimeError:
                pass
            self._pipe = None


def list_devices() -> list[str]:
    """The RealSense cameras plugged in, as camera names with what they are."""
    rs = library()
    out = []
    for dev in rs.context().query_devices():
        try:
            out.append(f"realsense:{dev.get_info(rs.camera_info.serial_number)}  {dev.get_info(rs.camera_info.name)}")
        except RuntimeError:
            continue
    return out
