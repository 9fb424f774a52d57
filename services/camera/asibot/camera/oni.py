"""OpenNI2 cameras (PrimeSense Carmine, Asus Xtion, Orbbec Astra; Kinect v1 through
libfreenect's OpenNI2 driver) through the primesense bindings (`openni`) and the system's
libOpenNI2.so.0 (Debian: libopenni2-0).

Depth comes in 1 mm (or 100 um) counts. When the device can register depth to colour in
hardware it does, so one CameraInfo serves both images; intrinsics come from the stream's
field of view (pixel centres at integer coordinates, cx = (width - 1) / 2, as in the sim).
A driver that does not say its field of view (libfreenect's, OpenNI2's dummy device) gets
the PrimeSense sensor's datasheet figures, 58 x 45 degrees, and a warning in the log.
"""

from __future__ import annotations

import ctypes.util
import logging
import math
import os
from typing import Any

import cv2
import numpy as np

from asibot.camera.sources import (CameraUnavailable, Frame, Intrinsics, Source, StreamOptions, depth_metres,
                                   now_ns)

log = logging.getLogger(__name__)

#: The PrimeSense PS1080's depth field of view (Kinect v1: 57 x 43; Xtion, Carmine: 58 x 45), degrees.
DEFAULT_FOV_DEG = (58.0, 45.0)

NO_DEVICE = ("No OpenNI2 camera was found. Check that it is plugged in (and, for a Kinect v1, powered by its "
             "own adapter), that this user may open it (the udev rules of libopenni2-0 or of the camera's "
             "vendor; in a container, the USB bus passed through), that its driver is installed "
             "(a Kinect v1 needs libfreenect's OpenNI2 driver in OpenNI2's Drivers folder) and that no other "
             "program holds it.")

NO_LIBRARY = ("OpenNI2 cannot be loaded ({why}): install it (Debian: apt-get install libopenni2-0) or set "
              "OPENNI2_REDIST to the folder holding libOpenNI2.so.")


def library() -> Any:
    """The `openni.openni2` module, with libOpenNI2 loaded and initialised."""
    try:
        from openni import _openni2 as c_api
        from openni import openni2
    except ImportError as exc:
        raise CameraUnavailable(NO_LIBRARY.format(why=f"the Python module openni is missing: {exc}")) from None
    initialise(openni2, c_api)
    return openni2


def initialise(openni2: Any, c_api: Any) -> None:
    """Load libOpenNI2 once. The bindings look for `libOpenNI2.so` in given folders; Debian ships
    only `libOpenNI2.so.0` (the bare name comes with -dev), so the library is loaded here."""
    if openni2.is_initialized():
        return
    redist = os.environ.get("OPENNI2_REDIST")
    path = os.path.join(redist, "libOpenNI2.so") if redist else ctypes.util.find_library("OpenNI2")
    if not path:
        raise CameraUnavailable(NO_LIBRARY.format(why="libOpenNI2.so.0 is not installed"))
    try:
        if not openni2.loaded_dll_directory:
            c_api.load_dll(path)
            openni2.loaded_dll_directory = os.path.dirname(path) or path
        openni2.initialize()
    except Exception as exc:      # OSError from ctypes, OpenNIError from oniInitialize
        raise CameraUnavailable(NO_LIBRARY.format(why=f"{path}: {exc}")) from None


def _closest(modes: list, fmt: Any, width: int, height: int, fps: int) -> Any:
    ok = [m for m in modes if m.pixelFormat == fmt] or list(modes)
    return min(ok, key=lambda m: (abs(m.resolutionX * m.resolutionY - width * height), abs(m.fps - fps))) if ok else None


class OpenNI2Source(Source):
    def __init__(self, uri: str | None, options: StreamOptions = StreamOptions(), url: str = "openni2:",
                 fov_deg: tuple[float, float] | None = None, lib: Any = None) -> None:
        self.uri, self.options, self.url = uri, options, url
        self.fov_deg = fov_deg
        self._lib = lib
        self._device: Any = None
        self._depth: Any = None
        self._colour: Any = None
        self._rgb: np.ndarray | None = None
        self._intr: Intrinsics | None = None
        self._units = 0.001
        self._what = url

    def start(self) -> None:
        ni = self._lib = self._lib or library()
        try:
            self._device = ni.Device.open_any() if self.uri is None else ni.Device(self.uri.encode())
        except Exception as exc:
            found = []
            try:
                found = [u.decode(errors="replace") if isinstance(u, bytes) else str(u) for u in ni.Device.enumerate_uris()]
            except Exception:
                pass
            if self.uri is None or not found:
                raise CameraUnavailable(f"{NO_DEVICE} (OpenNI2: {_why(exc)})") from None
            raise CameraUnavailable(f"OpenNI2 cannot open {self.uri!r} ({_why(exc)}); the devices found are "
                                    f"{', '.join('openni2:' + u for u in found)}.") from None
        try:
            self._open_streams(ni)
        except CameraUnavailable:
            self.close()
            raise
        except Exception as exc:
            self.close()
            raise CameraUnavailable(f"The OpenNI2 camera opened but its depth stream did not start ({_why(exc)}); "
                                    "unplug it, plug it in again and retry.") from None

    def _open_streams(self, ni: Any) -> None:
        opt, dev = self.options, self._device
        if not dev.has_sensor(ni.SENSOR_DEPTH):
            raise CameraUnavailable("This OpenNI2 device has no depth sensor.")
        depth = self._depth = dev.create_depth_stream()
        mode = _closest(depth.get_sensor_info().videoModes, ni.PIXEL_FORMAT_DEPTH_1_MM, opt.width, opt.height, opt.fps)
        if mode is not None:
            _try(depth.set_video_mode, mode)              # a driver with one fixed mode refuses
        _try(depth.set_mirroring_enabled, False)        # the picture as the camera sees it, as the sim's
        registered = False
        if opt.colour and dev.has_sensor(ni.SENSOR_COLOR):
            colour = self._colour = dev.create_color_stream()
            dm = depth.get_video_mode()
            cm = _closest(colour.get_sensor_info().videoModes, ni.PIXEL_FORMAT_RGB888, dm.resolutionX, dm.resolutionY, dm.fps)
            if cm is not None:
                _try(colour.set_video_mode, cm)
            _try(colour.set_mirroring_enabled, False)
            if _try(dev.is_image_registration_mode_supported, ni.IMAGE_REGISTRATION_DEPTH_TO_COLOR) is True:
                registered = _try(dev.set_image_registration_mode, ni.IMAGE_REGISTRATION_DEPTH_TO_COLOR) is not _FAILED
            _try(dev.set_depth_color_sync_enabled, True)
        depth.start()
        if self._colour is not None:
            self._colour.start()
        dm = depth.get_video_mode()
        self._units = 0.0001 if dm.pixelFormat == ni.PIXEL_FORMAT_DEPTH_100_UM else 0.001
        # Registered depth lies in the colour camera's picture: its field of view is the colour's.
        self._intr = self._intrinsics(self._colour if registered else depth, dm.resolutionX, dm.resolutionY)
        info = _try(dev.get_device_info)
        name = " ".join(v.decode(errors="replace") for v in (getattr(info, "vendor", b""), getattr(info, "name", b"")) if v) or "OpenNI2"
        self._what = (f"{name} ({self.url}): depth {dm.resolutionX}x{dm.resolutionY} at {dm.fps} Hz"
                      + (", colour" + (" registered" if registered else " (not registered)") if self._colour else ""))

    def _intrinsics(self, stream: Any, width: int, height: int) -> Intrinsics:
        if self.fov_deg is not None:
            hfov, vfov = (math.radians(v) for v in self.fov_deg)
        else:
            h, v = _try(stream.get_horizontal_fov), _try(stream.get_vertical_fov)
            if h is _FAILED or v is _FAILED or not (0 < h < math.pi and 0 < v < math.pi):
                log.warning("the camera does not say its field of view: using %s x %s degrees (--fov to give it)",
                            *DEFAULT_FOV_DEG)
                h, v = (math.radians(a) for a in DEFAULT_FOV_DEG)
            hfov, vfov = h, v
        return Intrinsics(width, height, fx=width / 2 / math.tan(hfov / 2), fy=height / 2 / math.tan(vfov / 2),
                          cx=(width - 1) / 2, cy=(height - 1) / 2)

    def read(self, timeout: float) -> Frame | None:
        ni = self._lib
        if ni.wait_for_any_stream([self._depth], timeout) is None:
            return None
        frame = self._depth.read_frame()
        stamp = now_ns()
        h, w = frame.height, frame.width
        raw = np.frombuffer(frame.get_buffer_as_uint16(), np.uint16)
        raw = raw.reshape(h, -1)[:, :w]
        if self._colour is not None and ni.wait_for_any_stream([self._colour], min(timeout, 0.05)) is not None:
            c = self._colour.read_frame()
            rgb: np.ndarray = np.frombuffer(c.get_buffer_as_uint8(), np.uint8).reshape(c.height, -1)[:, :3 * c.width]
            rgb = rgb.reshape(c.height, c.width, 3)
            if (c.width, c.height) != (w, h):
                rgb = np.asarray(cv2.resize(rgb, (w, h), interpolation=cv2.INTER_AREA), np.uint8)
            self._rgb = rgb.copy()
        assert self._intr is not None
        return Frame(depth=depth_metres(raw, self._units, self.options.max_depth),
                     rgb=None if self._rgb is None else self._rgb, intrinsics=self._intr, stamp=stamp)

    def describe(self) -> str:
        return self._what

    def close(self) -> None:
        # OpenNI2 itself stays loaded (its shutdown runs at exit): it is the process's, not a camera's.
        for stream in (self._colour, self._depth):
            if stream is not None:
                _try(stream.stop)
                _try(stream.close)
        if self._device is not None:
            _try(self._device.close)
        self._colour = self._depth = self._device = None


def list_devices() -> list[str]:
    ni = library()
    return [f"openni2:{u.decode(errors='replace') if isinstance(u, bytes) else u}" for u in ni.Device.enumerate_uris()]


_FAILED = object()


def _try(call: Any, *args: Any) -> Any:
    """`call(*args)`, or _FAILED when the driver does not support it (OpenNIError)."""
    try:
        return call(*args)
    except Exception as exc:
        log.debug("OpenNI2: %s%r not supported: %s", getattr(call, "__name__", call), args, exc)
        return _FAILED


def _why(exc: Exception) -> str:
    """OpenNIError's own words (its second argument), else the exception's."""
    args: tuple[Any, ...] = tuple(getattr(exc, "args", ()))
    if len(args) >= 2 and isinstance(args[1], bytes):
        return args[1].decode(errors="replace")
    return str(exc) or type(exc).__name__
