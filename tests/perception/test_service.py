"""The perception service on the in-memory bus: CameraInfo + DepthImage in, LaserScan and Events out."""

import argparse
import math

import numpy as np
import pytest

from asibot import keys
from asibot import messages as m
from asibot.bus import Bus
from asibot.errors import RpcError
from asibot.perception import service as perception
from asibot.perception.rays import CameraRays
from asibot.perception.service import Options, PerceptionService
from asibot.testing import Inbox, wait_until

from .synth import BACK, FRONT, Box, camera_info, colour_image, jpeg, render, wall_x

ROBOT = "pioneer-sim"
INFOS = {"front": camera_info(FRONT), "back": camera_info(BACK, yaw=math.pi),
         "rgb": camera_info((0.2, 0.0, 0.45), pitch=math.radians(15), width=320, height=240, fovy_deg=50)}


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


class Harness:
    """The service, a test bus publishing the cameras, and what the service publishes."""

    def __init__(self, clock=None) -> None:
        self.svc_bus, self.bus = Bus("perception"), Bus("test")
        self.svc = PerceptionService(self.svc_bus, ROBOT, Options(), **({"clock": clock} if clock else {}))
        self.scans, self.events = Inbox(), Inbox()
        self.bus.subscribe(keys.scan(ROBOT), m.LaserScan, self.scans)
        self.bus.subscribe(keys.events(ROBOT), m.Event, self.events)
        self.pubs = {}
        for name in INFOS:
            self.pubs[name] = {"info": self.bus.publisher(keys.camera_info(ROBOT, name), m.CameraInfo),
                               "depth": self.bus.publisher(keys.camera_depth(ROBOT, name), m.DepthImage),
                               "rgb": self.bus.publisher(keys.camera_rgb(ROBOT, name), m.RgbImage)}
        self.odom = self.bus.publisher(keys.base_odom(ROBOT), m.Odometry)
        self.sonar = self.bus.publisher(keys.base_sonar(ROBOT), m.Sonar)

    def info(self, name: str, info: m.CameraInfo | None = None) -> None:
        info = info or INFOS[name]
        self.pubs[name]["info"].put(info)
        wait_until(lambda: self.svc._cams[name].rays is not None and self.svc._cams[name].rays.same(info)
                   or self.svc._cams[name].info_error, 5, message=f"the service never took the {name} CameraInfo")

    def depth(self, name: str, boxes, stamp: int | None = None) -> None:
        rays = CameraRays.from_info(INFOS[name])
        kw = {} if stamp is None else {"stamp": stamp}
        self.pubs[name]["depth"].put(m.DepthImage(depth=render(rays, boxes)[0], **kw))

    def close(self) -> None:
        self.svc.close()
        self.bus.close()
        self.svc_bus.close()


@pytest.fixture
def h(memory_bus):
    harness = Harness()
    yield harness
    harness.close()


def test_depth_images_on_the_bus_give_one_scan_and_an_obstacle_event(h):
    h.info("front"), h.info("back")
    h.odom.put(m.Odometry(x=0, y=0, theta=0, vx=0.3, wz=0.0))
    wait_until(lambda: h.svc._odom is not None, 5)
    scene = [wall_x(0.8), wall_x(-3.0)]
    h.depth("front", scene, stamp=111)
    wait_until(lambda: len(h.scans) == 1, 5, message="no scan for the first front frame")
    h.depth("back", scene, stamp=222)
    wait_until(lambda: "back" in h.svc.assembler.heard(), 5)
    h.depth("front", scene, stamp=333)
    wait_until(lambda: len(h.scans) == 2, 5, message="no scan for the front + back cycle")
    scan = h.scans.last()
    assert scan.stamp == 333 and len(scan.ranges) == 720 and scan.angle_min == -math.pi
    a = scan.angle_min + scan.angle_increment * np.arange(720)
    ahead, behind = np.abs(a) < 0.3, np.abs(a) > math.pi - 0.3
    np.testing.assert_allclose(scan.ranges[ahead], 0.8 / np.cos(a[ahead]), rtol=5e-3)
    np.testing.assert_allclose(scan.ranges[behind], 3.0 / -np.cos(a[behind]), rtol=5e-3)
    wait_until(lambda: len(h.events), 5, message="no obstacle event")
    ev = h.events.all()[0]
    assert (ev.level, ev.code, ev.text) == ("warning", "obstacle", "Obstacle ahead, 0.5 m.")
    assert len(h.events) == 1 and h.svc.health()["scans"] == 2


def test_bad_frames_are_refused_and_nothing_is_published(h):
    h.info("front")
    bad = [np.full((120, 160), np.nan, np.float32), np.ones((60, 80), np.float32)]
    for i, depth in enumerate(bad, 1):
        h.pubs["front"]["depth"].put(m.DepthImage(depth=depth))
        wait_until(lambda: h.svc._cams["front"].rejected == i, 5, message="the bad frame was not refused")
    assert h.svc_bus.rejected == 2 and h.svc.health()["rejected_frames"] == {"front": 2}
    # a camera whose CameraInfo has no focal length: its frames cannot be used either
    broken = camera_info(BACK, yaw=math.pi)
    broken.fx = 0.0
    h.info("back", broken)
    assert "fx = 0.0" in h.svc.health()["cameras"]["back"]
    h.depth("back", [wall_x(-1.0)])
    wait_until(lambda: h.svc._cams["back"].rejected == 2, 5)     # its info and its frame
    h.depth("front", [wall_x(1.0)])                               # a good frame still works
    wait_until(lambda: len(h.scans), 5)
    assert len(h.scans) == 1 and np.isnan(h.scans.last().ranges[0])   # back: unknown


def test_the_sonar_on_the_bus_is_fused(h):
    h.info("front")
    angles = [math.radians(d) for d in (90, 50, 30, 10, -10, -30, -50, -90, -90, -130, -150, -170, 170, 150, 130, 90)]
    ranges = [4.335] * 16
    ranges[3] = ranges[4] = 0.755                 # a glass door 1 m ahead
    h.sonar.put(m.Sonar(ranges=ranges, angles=angles))
    wait_until(lambda: h.svc._sonar is not None, 5)
    h.depth("front", [wall_x(3.0)])
    wait_until(lambda: len(h.scans), 5)
    assert h.scans.last().ranges[360] == pytest.approx(1.0, abs=0.03)
    h.sonar.put(m.Sonar(ranges=ranges[:8], angles=angles[:8]))    # the wrong ring: refused
    wait_until(lambda: h.svc_bus.rejected == 1, 5)


def test_with_no_depth_camera_each_sonar_reading_is_a_scan_with_one_return_per_echo(memory_bus):
    """A P3-AT with sonar alone (the emulated one, a bare robot): the scan AMCL, the costmap and
    the warnings read, from each reading; no echo is unknown, not free."""
    bus, svc_bus = Bus("test"), Bus("perception")
    svc = perception.build(svc_bus, args(depth_cameras=perception._names("none"), rgb_camera=""))
    scans, events = Inbox(), Inbox()
    bus.subscribe(keys.scan(ROBOT), m.LaserScan, scans)
    bus.subscribe(keys.events(ROBOT), m.Event, events)
    try:
        assert svc.opt.depth_cameras == () and svc.opt.grid.beams == perception.SONAR_BEAMS
        angles = [math.radians(d) for d in (90, 50, 30, 10, -10, -30, -50, -90, -90, -130, -150, -170, 170, 150,
                                            130, 90)]
        ranges = [4.335] * 16                          # no echo anywhere...
        ranges[3] = ranges[4] = 0.5                    # ...but a wall 0.75 m ahead (sonar 3 and 4 at +-10 deg)
        ranges[11] = 2.0                               # and something behind, to the right
        bus.publisher(keys.base_odom(ROBOT), m.Odometry).put(m.Odometry(x=0, y=0, theta=0, vx=0.3, wz=0.0))
        wait_until(lambda: svc._odom is not None, 5)
        bus.publisher(keys.base_sonar(ROBOT), m.Sonar).put(m.Sonar(ranges=ranges, angles=angles, stamp=4242))
        wait_until(lambda: len(scans), 5, message="no scan from the sonar")
        scan = scans.last()
        assert scan.stamp == 4242 and len(scan.ranges) == perception.SONAR_BEAMS
        hit = np.flatnonzero(np.isfinite(scan.ranges))
        assert len(hit) == 3, scan.ranges                 # three echoes, every other beam unknown
        a = scan.angle_min + scan.angle_increment * hit
        x, y = scan.ranges[hit] * np.cos(a), scan.ranges[hit] * np.sin(a)
        ahead = x > 0
        assert ahead.sum() == 2 and np.allclose(x[ahead], 0.245 + 0.5 * math.cos(math.radians(10)), atol=0.03)
        behind = ~ahead
        heading = math.radians(-170)                      # sonar 11, at (-0.241, -0.027) m
        expected = (-0.241 + 2.0 * math.cos(heading), -0.027 + 2.0 * math.sin(heading))
        assert math.hypot(x[behind][0] - expected[0], y[behind][0] - expected[1]) < 0.1   # 4 deg beams
        wait_until(lambda: len(events), 5, message="no obstacle event from the sonar")
        assert events.all()[0].code == "obstacle" and "ahead" in events.all()[0].text
    finally:
        svc.close()
        bus.close()
        svc_bus.close()


def test_with_no_depth_camera_the_sonar_cannot_be_left_out(memory_bus):
    bus = Bus("perception")
    try:
        with pytest.raises(ValueError, match="leave out --no-sonar"):
            perception.build(bus, args(depth_cameras=(), no_sonar=True))
    finally:
        bus.close()


def test_a_silent_camera_is_announced_once_and_its_return_too(memory_bus):
    clock = Clock()
    h = Harness(clock)

    def frame_at(name: str, t: float) -> None:
        clock.t = t
        h.depth(name, scene)
        wait_until(lambda: getattr(h.svc.assembler._newest.get(name), "received", None) == t, 5)

    try:
        h.info("front"), h.info("back")
        scene = [wall_x(2.0), wall_x(-2.0)]
        frame_at("back", 100.0)                   # the first frames, then a second with none, as
        frame_at("front", 100.0)                  # the sim's renderers start: not a word yet
        clock.t = 101.0
        wait_until(lambda: h.svc.watched_at == 101.0, 5, message="the cameras were not watched")
        assert h.svc.events_sent == 0
        frame_at("back", 106.0)
        frame_at("front", 106.0)
        frame_at("front", 106.4)
        frame_at("front", 106.8)                  # the back camera's frame is 0.8 s old now
        wait_until(lambda: len(h.events), 5, message="the silent back camera was not announced")
        clock.t = 116.0                           # now the front camera is silent too
        wait_until(lambda: len(h.events) == 2, 5, message="the silent front camera was not announced")
        frame_at("front", 116.1)
        wait_until(lambda: len(h.events) == 3, 5)
        assert [(e.level, e.code, e.text) for e in h.events.all()] == [
            ("warning", "camera_silent", "The back camera has sent no depth image for 0.5 s. Obstacles it "
                                         "watches are not seen; the scan covers only the front camera."),
            ("warning", "camera_silent", "The front camera has sent no depth image for 0.5 s. Obstacles it "
                                         "watches are not seen; no scan is published."),
            ("info", "camera_working", "The front camera works again."),
        ]
        behind = h.scans.last().ranges[np.r_[0:20, 700:720]]
        assert np.isnan(behind).all()             # the silent back camera's sector is unknown, not free
    finally:
        h.close()


def test_a_camera_that_never_sends_a_frame_is_announced_after_the_start_up_grace(memory_bus):
    clock = Clock()
    h = Harness(clock)
    try:
        h.info("front"), h.info("back")
        clock.t += perception.STARTUP_GRACE_S - 1
        wait_until(lambda: h.svc.watched_at == clock.t, 5, message="the cameras were not watched")
        assert h.svc.events_sent == 0             # the sim may still be starting
        clock.t += 2
        wait_until(lambda: len(h.events) == 2, 5, message="the cameras' silence was not announced")
        assert [e.text for e in h.events.all()] == [
            "The back camera has sent no depth image since perception started 6 s ago (is the sim or the camera's "
            "driver running?). Obstacles it watches are not seen; no scan is published.",
            "The front camera has sent no depth image since perception started 6 s ago (is the sim or the camera's "
            "driver running?). Obstacles it watches are not seen; no scan is published.",
        ]
    finally:
        h.close()


# ---------------------------------------------------------------------- the finder's RPC
def test_find_the_red_can_over_the_bus(h):
    can = Box((1.4, -0.233, 0.45), (1.466, -0.167, 0.57), (20, 20, 200))
    scene = [can, Box((1.0, -0.5, 0.0), (1.8, 0.3, 0.45), (75, 115, 150)), wall_x(3.0)]
    key = keys.perception_rpc(ROBOT, "find")
    assert h.bus.wait_for(key, 5)
    with pytest.raises(RpcError, match="No image from the rgb camera yet") as exc:
        h.bus.call(key, {"color": "red"})
    assert exc.value.code == "unavailable"
    h.info("front"), h.info("rgb")
    rgb = CameraRays.from_info(INFOS["rgb"])
    h.pubs["rgb"]["rgb"].put(jpeg(colour_image(render(rgb, scene)[1], scene)))
    h.depth("front", scene)
    wait_until(lambda: h.svc._rgb is not None and h.svc._cams["front"].depth is not None, 5)
    reply = h.bus.call(key, {"color": "red"})
    assert reply["ok"] and reply["found"] and reply["pixels"] > 100
    assert reply["point"][:2] == pytest.approx([1.4, -0.2], abs=0.02)
    with pytest.raises(RpcError, match="Unknown colour 'purple': ask for one of red") as exc:
        h.bus.call(key, {"color": "purple"})
    assert exc.value.code == "bad_request"
    with pytest.raises(RpcError, match="find takes only color; 'colour' is not one of them"):
        h.bus.call(key, {"colour": "red"})


# ---------------------------------------------------------------------- command line
def args(**kw) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    p.add_argument("--robot", default=ROBOT)
    perception.add_arguments(p)
    ns = p.parse_args([])
    for k, v in kw.items():
        setattr(ns, k, v)
    return ns


@pytest.mark.parametrize("kw, words", [
    ({"robot": None}, "--robot is required"),
    ({"depth_cameras": ("front", "a/b")}, "camera name 'a/b' is not a valid name"),
    ({"min_height": 1.0, "max_height": 0.5}, "height band is empty"),
    ({"beams": 3}, "8 to 36000 beams"),
    ({"freshness": 0.0}, "--freshness"),
    ({"range_max": float("nan")}, "finite"),
])
def test_build_refuses_bad_arguments_with_a_sentence(memory_bus, kw, words):
    bus = Bus("perception")
    try:
        with pytest.raises(ValueError, match=words):
            perception.build(bus, args(**kw))
    finally:
        bus.close()


def test_build_makes_the_service(memory_bus):
    bus = Bus("perception")
    try:
        svc = perception.build(bus, args(depth_cameras=("front",), rgb_camera="", no_sonar=True))
        assert svc.opt.depth_cameras == ("front",) and svc.opt.rgb_camera is None and svc.opt.sonar is None
        svc.close()
    finally:
        bus.close()
