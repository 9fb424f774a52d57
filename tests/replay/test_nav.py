"""Replay tests: today's perception and localisation against a committed drive of the Pioneer.

The fixture (recordings/fixtures/nav_drive.mcap, made by record_nav.py) holds what the
simulated apartment, perception and nav said while the robot drove 1 m, turned left 90
degrees and back, and drove 0.5 m. The tests recompute perception's scans from the recorded depth
images and sonar, and nav's poses from the recorded odometry and scans, so a change of a
convention (a camera's pose, a beam's angle, odometry's frame) shows as a difference from a
real session, not only from numbers typed into a test.
"""

from __future__ import annotations

import bisect
import math
from pathlib import Path

import numpy as np
import pytest

from asibot import keys, messages as m
from asibot.nav.amcl import Amcl
from asibot.nav.geometry import Pose
from asibot.nav.mapfile import load_map
from asibot.nav.pilot import odometry_at
from asibot.perception.depth_to_scan import DepthToScan
from asibot.perception.merge import ScanGrid, merge
from asibot.perception.rays import CameraRays
from asibot.perception.sonar import SonarRing
from asibot.recorder.reader import iter_messages, summarize

ROOT = Path(__file__).resolve().parents[2]
ROBOT = "pioneer-sim"
FIXTURE = ROOT / "recordings" / "fixtures" / "nav_drive.mcap"
MAP = ROOT / "libs" / "common" / "asibot" / "maps" / "apartment.yaml"
CAMERAS = ("front", "back")
TYPES = {keys.base_odom(ROBOT): m.Odometry, keys.base_sonar(ROBOT): m.Sonar, keys.scan(ROBOT): m.LaserScan,
         keys.nav_pose(ROBOT): m.NavPose, keys.sim_truth(ROBOT): m.Pose2D, keys.base_cmd_vel(ROBOT): m.Twist,
         **{keys.camera_depth(ROBOT, c): m.DepthImage for c in CAMERAS},
         **{keys.camera_info(ROBOT, c): m.CameraInfo for c in CAMERAS}}


@pytest.fixture(scope="module")
def session() -> list[tuple[str, int, object]]:
    """(key, log time ns, decoded message) in recorded order; every payload must decode."""
    return [(r.key, r.log_time, m.decode(TYPES[r.key], r.payload)) for r in iter_messages(FIXTURE)]


def of(session, key) -> list:
    return [msg for k, _, msg in session if k == key]


def test_the_fixture_is_a_whole_drive(session):
    s = summarize(FIXTURE)
    assert s.complete and set(s.counts) == set(TYPES)
    truth = of(session, keys.sim_truth(ROBOT))
    a, b = truth[0], truth[-1]
    assert abs(math.hypot(b.x - a.x, b.y - a.y) - 1.5) < 0.1          # 1 m and 0.5 m east
    turned = np.unwrap([t.theta for t in truth]) - a.theta
    assert abs(math.degrees(turned.max()) - 90) < 10 and abs(math.degrees(turned[-1])) < 10


def test_perceptions_scans_are_recomputed_from_the_recorded_depth_and_sonar(session):
    """Each recorded scan is the merge of the newest frame of each camera up to its stamp,
    fused with the newest sonar reading before it."""
    grid, sonar = ScanGrid(), SonarRing.p3at()
    converters: dict[str, DepthToScan] = {}
    newest: dict[str, m.DepthImage] = {}
    last_sonar = None
    frames: dict[str, list[m.DepthImage]] = {c: [] for c in CAMERAS}
    compared = matched = 0
    for key, _, msg in session:
        camera = keys.camera_of(key)
        if key in (keys.camera_info(ROBOT, c) for c in CAMERAS) and camera not in converters:
            converters[camera] = DepthToScan(CameraRays.from_info(msg, f"the {camera} camera"))
        elif camera in CAMERAS and isinstance(msg, m.DepthImage):
            frames[camera].append(msg)
        elif key == keys.base_sonar(ROBOT):
            last_sonar = msg
        elif key == keys.scan(ROBOT) and len(converters) == len(CAMERAS) and last_sonar is not None:
            for c in CAMERAS:
                used = [f for f in frames[c] if f.stamp <= msg.stamp]
                if used:
                    newest[c] = used[-1]
            if set(newest) != set(CAMERAS) or max(f.stamp for f in newest.values()) != msg.stamp:
                continue       # a frame the recorder has not got yet, or missed: nothing to compare
            scans = [converters[c].convert(newest[c].depth) for c in CAMERAS]
            ranges = sonar.fuse(grid, merge(grid, scans), last_sonar)
            recorded = np.asarray(msg.ranges)
            both = np.isfinite(ranges) & np.isfinite(recorded)
            same = (np.isnan(ranges) == np.isnan(recorded)).mean() > 0.97 and \
                np.mean(np.abs(ranges[both] - recorded[both]) <= 0.01) > 0.97
            compared += 1
            matched += bool(same)
    assert compared >= 20, f"only {compared} scans could be recomputed"
    # the sonar reading perception used may be one newer or older than the recorder's order says
    assert matched >= 0.9 * compared, f"{matched} of {compared} recorded scans recomputed"


def test_localisation_is_recomputed_from_the_recorded_odometry_and_scans(session):
    """AMCL fed the recorded odometry and scans, from the recorded first pose, follows the
    sim's ground truth and agrees with what nav said during the drive."""
    loaded = load_map(MAP)
    amcl = Amcl(loaded.grid, seed=7)
    first = of(session, keys.nav_pose(ROBOT))[0]
    amcl.set_pose(Pose(first.x, first.y, first.theta), cov=(0.02 ** 2, 0.02 ** 2, 0.02 ** 2))
    history, recomputed, truth_at = [], [], []
    truths = [(t, msg) for k, t, msg in session if k == keys.sim_truth(ROBOT)]
    truth_times = [t for t, _ in truths]

    class Reading:   # what odometry_at reads: the pose and the producer's stamp
        def __init__(self, o: m.Odometry) -> None:
            self.pose, self.stamp = Pose(o.x, o.y, o.theta), o.stamp

    for key, t, msg in session:
        if key == keys.base_odom(ROBOT):
            history.append(Reading(msg))
        elif key == keys.scan(ROBOT) and history:
            at = odometry_at(history, msg.stamp)
            if at is None:
                continue
            amcl.update(at, msg)
            here = amcl.pose(history[-1].pose)
            i = min(bisect.bisect_left(truth_times, t), len(truths) - 1)
            recomputed.append(here)
            truth_at.append(truths[i][1])
    assert len(recomputed) > 30
    err = np.array([math.hypot(p.x - q.x, p.y - q.y) for p, q in zip(recomputed, truth_at)])
    yaw = np.array([abs(math.remainder(p.theta - q.theta, 2 * math.pi)) for p, q in zip(recomputed, truth_at)])
    assert np.median(err) < 0.08 and err.max() < 0.25, f"median {np.median(err):.3f} m, worst {err.max():.3f} m"
    assert np.median(yaw) < math.radians(3), f"median {math.degrees(np.median(yaw)):.1f} deg"
    said = of(session, keys.nav_pose(ROBOT))[-1]
    end = recomputed[-1]
    assert math.hypot(said.x - end.x, said.y - end.y) < 0.1, (said, end)
