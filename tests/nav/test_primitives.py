"""The thesis's driving primitives in the tiny simulator (noisy odometry), judged by ground truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from asibot.nav.errors import NavError
from asibot.nav.geometry import Pose, relative
from asibot.nav.grid import GridInfo, OccupancyGrid
from asibot.nav.primitives import PRIMITIVES, Motion, Primitives, Settings

from .tinysim import TinySim

START = Pose(4.0, 4.0, 0.0)          # the middle of an empty 8 m x 8 m room, facing +x


@pytest.fixture(scope="module")
def room():
    """8 m x 8 m, walls one cell thick on every side (the inside runs from 0.05 to 7.95 m)."""
    data = np.zeros((160, 160), np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    return OccupancyGrid(GridInfo(160, 160, 0.05), data)


def run(room, name: str, start: Pose = START, continuous: bool = False, settings: Settings | None = None,
        limit: float = 40.0, seed: int = 4) -> tuple[TinySim, Primitives, Motion]:
    sim = TinySim(room, pose=start, odom=Pose(0.0, 0.0, 0.0), seed=seed)
    prim = Primitives(settings or Settings())
    now, dt = 0.0, 0.05
    prim.start(now, name, sim.odom, continuous)
    motion = None
    while now < limit:
        motion = prim.step(now, sim.odom, sim.scan())
        if not motion.active:
            break
        sim.step(motion.vx, motion.wz, dt)
        now += dt
    for _ in range(20):                 # let the ramp bring it to rest
        sim.step(0.0, 0.0, dt)
    assert motion is not None and not motion.active
    return sim, prim, motion


def moved(sim: TinySim, start: Pose = START) -> Pose:
    return relative(start, sim.pose)


@pytest.mark.parametrize("name, sign", [("forward", 1), ("backward", -1)])
def test_a_step_is_one_metre_within_5_cm(room, name, sign):
    sim, _, end = run(room, name)                     # width 3: 1 m steps
    d = moved(sim)
    assert end.done and end.text == f"{name}: done"
    assert abs(d.x - sign * 1.0) <= 0.05 and abs(d.y) <= 0.05 and abs(d.theta) <= math.radians(3)
    assert not sim.collided


@pytest.mark.parametrize("name, angle", [("turn left 90", 90.0), ("turn right 90", -90.0),
                                         ("turn around", 180.0), ("turn left", 45.0), ("turn right", -45.0)])
def test_turns_end_within_5_degrees(room, name, angle):
    sim, _, end = run(room, name)
    d = moved(sim)
    err = math.degrees(math.remainder(d.theta - math.radians(angle), 2 * math.pi))
    assert abs(err) <= 5.0, f"{name}: {math.degrees(d.theta):.1f} deg"
    assert math.hypot(d.x, d.y) < 0.03 and end.done and end.text == f"{name}: done"


@pytest.mark.parametrize("name, direction, side", [("curve forward left", 1, 1), ("curve forward right", 1, -1),
                                                   ("curve backward left", -1, 1), ("curve backward right", -1, -1)])
def test_curves_end_on_their_arc(room, name, direction, side):
    sim, _, end = run(room, name)                          # width 3: 1 m along a 0.8 m radius
    assert end.done and end.text == f"{name}: done"
    phi = 1.0 / 0.8
    d = moved(sim)
    want = Pose(direction * 0.8 * math.sin(phi), side * 0.8 * (1 - math.cos(phi)), direction * side * phi)
    assert math.hypot(d.x - want.x, d.y - want.y) <= 0.05
    assert abs(math.remainder(d.theta - want.theta, 2 * math.pi)) <= math.radians(5)


def test_stops_before_a_wall(room):
    facing_wall = Pose(4.0, 1.2, -math.pi / 2)             # the wall's face is at y = 0.05
    sim, _, end = run(room, "forward", facing_wall, continuous=True)
    assert not end.done and end.text.startswith("stopped: obstacle ahead, ")
    assert not sim.collided
    front = sim.pose.y - 0.313 - 0.05
    assert 0.0 < front <= 0.35                              # close, but not touching


def test_a_turn_beside_a_wall_is_refused(room):
    tight = Pose(4.0, 0.38, 0.0)                            # side 0.08 m from the wall: corners would hit
    sim, _, end = run(room, "turn left 90", tight)
    assert not end.done and end.text.startswith("stopped: obstacle beside the robot") and not sim.collided


def test_continuous_motion_ends_at_the_longest_time(room):
    sim, _, end = run(room, "turn left", continuous=True, settings=Settings(longest_s=2.0))
    assert not end.done and end.text == "stopped: 2 s is the longest a motion lasts"
    assert abs(moved(sim).theta) > math.radians(30)


def test_stop_and_no_scan(room):
    prim = Primitives()
    prim.start(0.0, "forward", Pose(0.0, 0.0, 0.0), continuous=True)
    waiting = prim.step(0.0, Pose(0.0, 0.0, 0.0), None)          # blind: it stands still and waits
    assert (waiting.vx, waiting.wz, waiting.active) == (0.0, 0.0, True)
    assert waiting.text == prim.last_text == "waiting: I cannot see obstacles (no scan)"
    assert prim.step(1.9, Pose(0.0, 0.0, 0.0), None).active
    ended = prim.step(2.0, Pose(0.0, 0.0, 0.0), None)             # Settings.blind_timeout
    assert (ended.vx, ended.wz, ended.active, ended.done) == (0.0, 0.0, False, False)
    assert ended.text == "stopped: I cannot see obstacles (no scan)" and not prim.active
    prim.start(0.0, "Turn  Left", Pose(0.0, 0.0, 0.0), continuous=True)
    assert prim.start(0.1, "stop", Pose(0.0, 0.0, 0.0)) == "stopped" and not prim.active
    m = prim.step(0.2, Pose(0.0, 0.0, 0.0), None)
    assert (m.vx, m.wz, m.active) == (0.0, 0.0, False)


@pytest.mark.parametrize("blind_from, blind_s", [(0.0, 1.0), (1.0, 1.5)], ids=["at the start", "mid-turn"])
def test_a_turn_without_scans_for_a_moment_pauses_and_still_ends_on_its_angle(room, blind_from, blind_s):
    """The scan came late on a busy machine (CI: `asibot nav turn 180` ended "no scan" at once):
    the turn stands still while it is blind, then goes on, closed-loop on odometry as before."""
    sim = TinySim(room, pose=START, odom=Pose(0.0, 0.0, 0.0), seed=4)
    prim = Primitives()
    now, dt, said = 0.0, 0.05, []
    prim.start(now, "turn around", sim.odom)
    while now < 40.0:
        blind = blind_from <= now < blind_from + blind_s
        motion = prim.step(now, sim.odom, None if blind else sim.scan())
        said.append(motion.text)
        if blind:
            assert (motion.vx, motion.wz) == (0.0, 0.0) and motion.active, motion
        if not motion.active:
            break
        sim.step(motion.vx, motion.wz, dt)
        now += dt
    for _ in range(20):
        sim.step(0.0, 0.0, dt)
    assert motion.done and motion.text == "turn around: done", motion
    assert "waiting: I cannot see obstacles (no scan)" in said and said[-2] == "turn around, 180 deg"
    assert abs(abs(math.degrees(moved(sim).theta)) - 180.0) <= 3.0 and not sim.collided


def test_bad_primitive_is_a_sentence():
    prim = Primitives()
    for bad in ("fly", None, "forward; rm -rf /"):
        with pytest.raises(NavError, match="is not a driving primitive; use one of forward, backward"):
            prim.start(0.0, bad, Pose(0.0, 0.0, 0.0))
    with pytest.raises(NavError, match="not finite"):
        prim.start(0.0, "forward", Pose(math.nan, 0.0, 0.0))
    assert not prim.active
    assert len(PRIMITIVES) == 12


def test_movement_width_levels():
    prim = Primitives(Settings(speed=4, width=1))
    assert prim.faster() == "speed 5 of 5: 0.5 m/s"
    assert prim.faster() == "speed 5 of 5: 0.5 m/s (already the highest)"
    assert prim.slower().startswith("speed 4 of 5")
    assert prim.narrower().endswith("(already the lowest)")
    assert prim.wider() == "width 2 of 5: steps of 0.50 m and 30 deg, curves 0.6 m wide"
    assert prim.start(0.0, "forward", Pose(0.0, 0.0, 0.0)) == "forward, 0.50 m"
