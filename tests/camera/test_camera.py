"""The camera service without hardware: librealsense's software device and a recording of it
played back, OpenNI2's own dummy device (in a child process) and a fake of its module."""

from __future__ import annotations

import json
import math
import gc
import os
import subprocess
import sqlite3
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from asibot import keys
from asibot import messages as m
from asibot.bus import Bus
from asibot.camera import mounts, service
from asibot.camera.oni import OpenNI2Source
from asibot.camera.realsense import FramesetSource
from asibot.camera.sources import (FORMS, CameraUnavailable, SourceError, StreamOptions, open_source, parse)
from asibot.perception.depth_to_scan import BandConfig, DepthToScan
from asibot.perception.rays import CameraRays
from asibot.testing import Inbox, wait_until

sys.path.insert(0, str(Path(__file__).parent))
from softcam import DEPTH_INTR, H, UNITS, W, SoftCam  # noqa: E402

ROBOT = "pioneer"
FRONT = mounts.pose_of("pioneer", "front")


def expected_depth(raw: np.ndarray) -> np.ndarray:
    d = raw.astype(np.float32) * np.float32(UNITS)
    d[d > 8.0] = 0.0
    return d


def coloured(raw: np.ndarray, rgb: np.ndarray) -> np.ndarray:
    """The soft camera's colour is registered to its depth already: the picture itself."""
    return rgb


@pytest.fixture
def softcam():
    cam = SoftCam()
    yield cam
    cam.close()


def warm_up(cam: SoftCam, source: FramesetSource) -> None:
    """The syncer matches depth and colour once it has seen both (frame 0 comes apart)."""
    cam.push(0)
    while source.read(0.2) is not None:
        pass


def test_a_bad_name_names_every_form():
    for bad in ("", "usb:0", "realsense", "kinect:", "realsense:12 34", "realsense-bag:"):
        with pytest.raises(SourceError) as err:
            parse(bad)
        for form in FORMS:
            assert form in str(err.value)


def test_the_software_device_publishes_what_it_was_fed(memory_bus, softcam):
    bus, listener = Bus("camera"), Bus("test")
    got = {kind: Inbox() for kind in ("info", "depth", "rgb")}
    listener.subscribe(keys.camera_info(ROBOT, "front"), m.CameraInfo, got["info"])
    listener.subscribe(keys.camera_depth(ROBOT, "front"), m.DepthImage, got["depth"])
    listener.subscribe(keys.camera_rgb(ROBOT, "front"), m.RgbImage, got["rgb"])
    source = FramesetSource(softcam.wait, url="realsense:software")
    svc = service.CameraService(bus, ROBOT, "front", source, FRONT)
    warm_up(softcam, source)
    for i in (1, 2, 3):
        raw, rgb = softcam.push(i)
        frame = source.read(2.0)
        assert frame is not None and frame.rgb is not None
        np.testing.assert_array_equal(frame.depth, expected_depth(raw))
        np.testing.assert_array_equal(frame.rgb, coloured(raw, rgb))
        svc.publish(frame)
        wait_until(lambda: len(got["depth"]) == i and len(got["rgb"]) == i and len(got["info"]) == i, 5)
        depth = got["depth"].last().depth
        assert depth.dtype == np.float32 and depth.shape == (H, W)
        np.testing.assert_array_equal(depth, expected_depth(raw))
        assert depth[6, 6] == 0 and depth[-1, -1] == 0          # no return, and beyond 8 m: 0 as the sim
        assert depth[0, 0] == pytest.approx((500 + 50 * i) / 1000, abs=1e-6)
        picture = got["rgb"].last()
        decoded = cv2.cvtColor(cv2.imdecode(np.frombuffer(picture.jpeg, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        assert (picture.width, picture.height) == (W, H) and decoded.shape == rgb.shape
        assert np.abs(decoded.astype(int) - coloured(raw, rgb)).mean() < 4         # JPEG at quality 80, as the sim
    info = got["info"].last()
    assert (info.width, info.height, info.fx, info.fy, info.cx, info.cy) == (W, H, *DEPTH_INTR)
    assert info.pose == FRONT and info.frame == "front_optical"
    bus.close()
    listener.close()


def _unlocked(path) -> bool:
    """Whether no one holds a lock on the SQLite file at `path` (a recording still written)."""
    if not path.is_file():
        return False
    db = sqlite3.connect(path, timeout=0)
    try:
        db.execute("BEGIN EXCLUSIVE")
        db.rollback()
        return True
    except sqlite3.OperationalError:
        return False
    finally:
        db.close()


def test_a_recording_plays_back_into_the_same_frames(tmp_path):
    path = tmp_path / "short.db3"
    cam = SoftCam(record=str(path))
    fed = {}
    try:
        source = FramesetSource(cam.wait)
        warm_up(cam, source)
        for i in range(1, 11):
            fed[i] = cam.push(i)
            assert source.read(2.0) is not None
    finally:
        cam.close()
    del cam, source
    gc.collect()
    # librealsense's writer closes the file from its own thread: wait until SQLite may lock it.
    wait_until(lambda: _unlocked(path), 10, message=f"{path} stays locked by its writer")
    assert path.stat().st_size < 1_000_000
    played = open_source(f"realsense-bag:{path}", StreamOptions(realtime=False))   # every frame, none dropped
    played.start()
    seen = {}
    try:
        from asibot.camera.sources import EndOfRecording
        with pytest.raises(EndOfRecording):
            for _ in range(100):
                frame = played.read(1.0)
                if frame is None or frame.rgb is None:
                    continue
                i = int(round((frame.depth[0, 0] * 1000 - 500) / 50))
                seen[i] = frame
    finally:
        played.close()
    # The playback's syncer, like the live one, pairs depth and colour once it has seen both:
    # the first frames may come apart (and are skipped above). librealsense's recorder (only this
    # test's fixture: sessions are recorded to MCAP) drops frames on a loaded machine: as few as
    # 2 of 10 came back with both cores busy. Every pair played is one fed, exactly.
    assert set(seen) & set(fed), f"played back {sorted(seen)} of {sorted(fed)}"
    for i in set(fed) & set(seen):
        raw, rgb = fed[i]
        np.testing.assert_array_equal(seen[i].depth, expected_depth(raw))
        np.testing.assert_array_equal(seen[i].rgb, coloured(raw, rgb))
        assert seen[i].intrinsics.fx == DEPTH_INTR[0] and seen[i].intrinsics.cy == DEPTH_INTR[3]


def test_a_missing_recording_says_so(tmp_path):
    with pytest.raises(CameraUnavailable, match="There is no recording"):
        open_source(f"realsense-bag:{tmp_path}/none.db3").start()


def test_no_realsense_plugged_in_says_what_to_check():
    for name in ("realsense:", "realsense:123456789012"):
        with pytest.raises(CameraUnavailable) as err:
            open_source(name).start()
        text = str(err.value)
        assert "USB" in text and "udev" in text and "Traceback" not in text


def test_perception_turns_the_published_frames_into_a_scan(softcam):
    source = FramesetSource(softcam.wait)
    warm_up(softcam, source)
    softcam.push(1)
    frame = source.read(2.0)
    assert frame is not None
    info, depth, _ = service.messages_of(frame, FRONT, "front")
    info, depth = m.decode(m.CameraInfo, m.encode(info)), m.decode(m.DepthImage, m.encode(depth))
    scan = DepthToScan(CameraRays.from_info(info, "front"), BandConfig()).convert(np.asarray(depth.depth), "front")
    assert np.isfinite(scan.rho).any()        # returns within the height band, in the base frame


def test_the_pioneer_mounts_are_the_simulated_pioneers():
    world = Path(__import__("asibot.sim", fromlist=["x"]).__file__).parent / "worlds" / "apartment.xml"
    pioneer = ET.parse(world).getroot().find(".//body[@name='pioneer']")
    for cam in pioneer.findall("camera"):
        x, y = (np.array(v.split(), float) for v in (cam.get("xyaxes")[:0] or [" ".join(cam.get("xyaxes").split()[:3]),
                                                                                 " ".join(cam.get("xyaxes").split()[3:])]))
        x /= np.linalg.norm(x)
        y = y - x * (x @ y)
        y /= np.linalg.norm(y)
        rot = np.stack([x, y, np.cross(x, y)], 1) @ np.diag([1.0, -1.0, -1.0])
        pose = mounts.pose_of("pioneer", cam.get("name"))
        assert pose is not None, cam.get("name")
        np.testing.assert_allclose(pose[:3], [float(v) for v in cam.get("pos").split()])
        q = pose[3:]
        from asibot.depth import quaternion_matrix
        np.testing.assert_allclose(quaternion_matrix(*q), rot, atol=1e-5)


def test_a_mount_measured_as_xyz_rpy_is_the_optical_pose(tmp_path):
    f = tmp_path / "mounts.toml"
    f.write_text('[pioneer.front]\nxyz = [0.32, 0, 0.3]\nrpy = [0, 0, 0]\n[pioneer.bad]\npose = [1, 2]\n')
    np.testing.assert_allclose(mounts.pose_of("pioneer", "front", f), FRONT, atol=1e-9)
    assert mounts.pose_of("pioneer", "side", f) is None
    with pytest.raises(SourceError, match="7 numbers"):
        mounts.pose_of("pioneer", "bad", f)


def args(**kw):
    base = dict(robot=ROBOT, name="front", source=None, size=(640, 480), fps=15, max_depth=8.0, no_colour=False,
                loop=False, pose=None, mounts=None, fov=None, list=False)
    base.update(kw)
    return SimpleNamespace(**base)


def test_build_refuses_with_sentences(memory_bus):
    bus = Bus("camera")
    with pytest.raises(ValueError, match="--source is required"):
        service.build(bus, args())
    with pytest.raises(SourceError, match="realsense:SERIAL"):
        service.build(bus, args(source="webcam:0"))
    with pytest.raises(CameraUnavailable, match="USB"):
        service.build(bus, args(source="realsense:"))
    with pytest.raises(SourceError, match="7 numbers"):
        service.build(bus, args(source="realsense:", pose=[0, 0, 0]))
    bus.close()


# --- OpenNI2 ----------------------------------------------------------------------------------
def _libopenni2() -> bool:
    import ctypes.util
    return ctypes.util.find_library("OpenNI2") is not None


needs_libopenni2 = pytest.mark.skipif(not _libopenni2(), reason="libOpenNI2.so.0 is not installed (Debian: libopenni2-0)")

CHILD = """
import json, os, sys
from asibot.camera.oni import OpenNI2Source
src = OpenNI2Source("Dummy", url="openni2:Dummy")
src.start()
frames = [src.read(2.0) for _ in range(3)]
f = frames[-1]
d = f.depth
print(json.dumps({"describe": src.describe(), "intr": list(f.intrinsics.__dict__.values()), "shape": list(d.shape),
                  "dtype": str(d.dtype), "max": float(d.max()), "zeros": int((d == 0).sum()),
                  "steps": sorted({round(float(v) * 1000, 3) for v in d[d > 0].ravel()})[:3],
                  "rgb": None if f.rgb is None else list(f.rgb.shape)}))
sys.stdout.flush()
src.close()
os._exit(0)     # OpenNI2's shutdown crashes after its dummy device (a bug of that test driver)
"""


@needs_libopenni2
def test_openni2_dummy_device_gives_metres_and_intrinsics():
    """OpenNI2's own dummy driver (libopenni2-0 ships it): the real library and bindings, a
    320x240 depth stream in mm. It sits in a child process: OpenNI2 crashes at exit after it."""
    out = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["shape"] == [240, 320] and got["dtype"] == "float32" and got["rgb"] == [240, 320, 3]
    assert 0.9 < got["max"] <= 2.0                     # its pattern: 2000 mm at most, in metres
    assert all(float(s).is_integer() for s in got["steps"])   # whole millimetres
    w, h, fx, fy, cx, cy = got["intr"]
    assert (w, h, cx, cy) == (320, 240, 159.5, 119.5)
    assert fx == pytest.approx(160 / math.tan(math.radians(29)), rel=1e-6)   # the default 58 x 45 deg
    assert fy == pytest.approx(120 / math.tan(math.radians(22.5)), rel=1e-6)


@needs_libopenni2
def test_openni2_with_no_device_says_what_to_check():
    code = ("from asibot.camera.sources import open_source, CameraUnavailable\n"
            "try:\n    open_source('openni2:').start()\nexcept CameraUnavailable as e:\n    print(e)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "No OpenNI2 camera was found" in out.stdout and "USB" in out.stdout and "udev" in out.stdout


class FakeOpenNI2:
    """The small surface of `openni.openni2` the source uses, with no device plugged in."""

    class Device:
        @staticmethod
        def open_any():
            raise Exception(1, b"DeviceOpen using default: no devices found", None)

        def __init__(self, uri):
            raise Exception(1, b"DeviceOpen: Couldn't open device '" + uri + b"'", None)

        @staticmethod
        def enumerate_uris():
            return [b"2bc5/0401@1/5"]


def test_openni2_errors_against_a_fake_module():
    with pytest.raises(CameraUnavailable, match="No OpenNI2 camera was found.*no devices found"):
        OpenNI2Source(None, StreamOptions(), lib=FakeOpenNI2).start()
    with pytest.raises(CameraUnavailable, match="found are openni2:2bc5/0401@1/5"):
        OpenNI2Source("1d27/0601@2/3", StreamOptions(), url="openni2:1d27/0601@2/3", lib=FakeOpenNI2).start()


def test_openni2_without_the_library_says_how_to_install(monkeypatch):
    import ctypes.util

    from asibot.camera import oni
    monkeypatch.setattr(ctypes.util, "find_library", lambda name: None)
    monkeypatch.delenv("OPENNI2_REDIST", raising=False)
    fake = SimpleNamespace(is_initialized=lambda: False, loaded_dll_directory=None)
    with pytest.raises(CameraUnavailable, match="apt-get install libopenni2-0"):
        oni.initialise(fake, None)
    assert os.environ.get("OPENNI2_REDIST") is None
