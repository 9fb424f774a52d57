"""Obstacle warnings: the distance on the way, levels, hysteresis and no flood."""

import math

import numpy as np
import pytest

from asibot.perception.merge import ScanGrid
from asibot.perception.warnings import P3AT, ObstacleWarner, WarningLevels, clearance, travel_direction

GRID = ScanGrid()


def scan_with(points):
    ranges = np.full(GRID.beams, np.inf, np.float32)
    for x, y in points:
        GRID.add(ranges, np.array([x]), np.array([y]))
    return ranges


def test_clearance_is_the_gap_from_the_body_on_the_way():
    ranges = scan_with([(1.0, 0.0), (0.5, 0.6), (-0.8, 0.1)])   # ahead, off to the side, behind
    assert clearance(ranges, GRID, "ahead") == pytest.approx(1.0 - P3AT.front, abs=0.01)
    assert clearance(ranges, GRID, "behind") == pytest.approx(0.8 - P3AT.rear, abs=0.01)
    assert clearance(ranges, GRID, "around") == pytest.approx(math.hypot(0.5, 0.6) - P3AT.turning_radius, abs=0.01)
    assert clearance(scan_with([]), GRID, "ahead") == math.inf
    assert math.isnan(clearance(GRID.unknown(), GRID, "ahead"))          # unknown: neither free nor blocked
    behind_only = GRID.unknown()
    behind_only[np.cos(GRID.angles()) < -0.9] = np.inf
    assert math.isnan(clearance(behind_only, GRID, "ahead")) and clearance(behind_only, GRID, "behind") == math.inf


def test_a_way_nobody_watches_says_nothing_not_clear():
    w = ObstacleWarner()
    assert [e[1] for e in run(w, [0.5, math.nan, math.nan], dt=3.0)] == ["warning"]
    assert w.level == 2                                                   # held until the way is seen again


def test_direction_of_travel_from_odometry():
    assert travel_direction(None, None) == ("ahead", None)             # no odometry: assume ahead
    assert travel_direction(0.3, 0.0) == ("ahead", None)
    assert travel_direction(-0.2, 0.1) == ("behind", None)
    assert travel_direction(0.0, 0.5) == ("around", None)
    assert travel_direction(0.0, 0.0) == ("ahead", "info")             # standing still: only info


def run(warner, distances, direction="ahead", dt=0.1, start=0.0, cap=None):
    out = []
    for i, d in enumerate(distances):
        ev = warner.update(d, direction, start + i * dt, cap)
        if ev is not None:
            out.append((round(start + i * dt, 2), ev.level, ev.code, ev.text))
    return out


def test_approaching_an_obstacle_says_each_level_once():
    w = ObstacleWarner()
    events = run(w, [2.0, 1.5, 1.0, 0.9, 0.7, 0.6, 0.5, 0.4, 0.3, 0.25, 0.2, 0.2, 0.2])
    assert [e[1:] for e in events] == [
        ("info", "obstacle", "Obstacle ahead, 1.0 m."),
        ("warning", "obstacle", "Obstacle ahead, 0.6 m."),
        ("error", "obstacle", "Obstacle ahead, 0.3 m."),
    ]


def test_a_distance_dithering_at_a_threshold_gives_one_warning():
    w = ObstacleWarner()
    noisy = [0.6 + 0.05 * math.sin(i) for i in range(200)]            # 0.55 .. 0.65, 20 s
    events = run(w, noisy)
    assert [e[1] for e in events] == ["warning"]


def test_a_person_walking_in_and_out_of_range_is_not_a_flood():
    w = ObstacleWarner(WarningLevels(min_interval=2.0))
    distances = [0.5, 0.5, 2.0, 2.0] * 50                               # in and out, 5 times a second
    events = run(w, distances)
    assert 1 <= len(events) <= 20 / 2.0 + 1                            # at most one per min_interval
    times = [e[0] for e in events]
    assert all(b - a >= 2.0 - 1e-9 for a, b in zip(times, times[1:]))


def test_getting_closer_is_said_at_once_and_clear_once_after():
    w = ObstacleWarner()
    events = run(w, [0.5, 0.25, 0.25, 3.0, 3.0, 3.0], dt=1.0)
    assert [(e[1], e[2]) for e in events] == [("warning", "obstacle"), ("error", "obstacle"),
                                              ("info", "obstacle_clear")]
    assert events[-1][3] == "The way ahead is clear again."


def test_leaving_only_an_info_says_nothing_and_a_stopped_robot_hears_only_info():
    w = ObstacleWarner()
    assert [e[1] for e in run(w, [0.9, 3.0, 3.0], dt=3.0)] == ["info"]
    w = ObstacleWarner()
    assert [e[1] for e in run(w, [0.9, 0.5, 0.2], dt=3.0, cap="info")] == ["info"]


def test_a_new_direction_is_a_new_situation():
    w = ObstacleWarner()
    assert run(w, [0.5], "ahead")[0][3] == "Obstacle ahead, 0.5 m."
    assert run(w, [0.5], "behind", start=0.1)[0][3] == "Obstacle behind, 0.5 m."
    assert run(w, [0.1], "around", start=0.2)[0][3] == "Obstacle beside the robot while it turns, 0.1 m."


def test_bad_settings_and_directions_are_refused():
    with pytest.raises(ValueError, match="error < warning < info"):
        WarningLevels(info=0.5, warning=0.6)
    with pytest.raises(ValueError, match="direction"):
        ObstacleWarner().update(1.0, "sideways", 0.0)
