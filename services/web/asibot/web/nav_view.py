"""What the Base page draws of a mobile robot's navigation, from the nav service's messages.

Everything is in the map frame, in metres (and degrees for headings, as the rest of the page),
rounded to the centimetre and thinned to what a map on a screen can show: the page is pushed
this view up to 30 times a second, so a scan is at most SCAN_POINTS points, not 720 beams.
"""

from __future__ import annotations

import base64
import math
from typing import Any

import numpy as np

from asibot.messages import LaserScan, NavMap, NavPath, NavPose, NavStatus

#: At most this many points of each kind go to the page per push.
SCAN_POINTS = 180
PARTICLES = 120
PATH_POINTS = 120


def _thin(points: np.ndarray, most: int) -> np.ndarray:
    if len(points) <= most:
        return points
    return points[np.linspace(0, len(points) - 1, most).astype(int)]


def _rounded(points: np.ndarray) -> list[list[float]]:
    return np.round(points.astype(float), 2).tolist()


def scan_points(scan: LaserScan, x: float, y: float, theta: float) -> list[list[float]]:
    """The scan's returns as map points, seen from the robot at (x, y, theta)."""
    r = np.asarray(scan.ranges, float)
    a = scan.angle_min + scan.angle_increment * np.arange(len(r)) + theta
    hit = np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max)
    pts = np.c_[x + r[hit] * np.cos(a[hit]), y + r[hit] * np.sin(a[hit])]
    return _rounded(_thin(pts, SCAN_POINTS))


def nav_json(pose: NavPose | None, status: NavStatus | None, path: NavPath | None,
             scan: LaserScan | None, grid: NavMap | None = None) -> dict[str, Any] | None:
    """The live part of the Base page; None while the robot has no nav service. `map` names the
    map nav uses now (its stamp), so the page fetches it again when it changes (a new map
    while mapping, every few seconds)."""
    if pose is None and status is None:
        return None
    out: dict[str, Any] = {"pose": None, "particles": [], "scan": [], "path": [], "status": None,
                           "map": str(grid.stamp) if grid is not None else ""}
    if pose is not None:
        out["pose"] = {"x": round(pose.x, 3), "y": round(pose.y, 3),
                       "theta_deg": round(math.degrees(pose.theta), 1), "localised": pose.localised}
        out["particles"] = _rounded(_thin(np.asarray(pose.particles)[:, :2], PARTICLES))
        if scan is not None:
            out["scan"] = scan_points(scan, pose.x, pose.y, pose.theta)
    if path is not None and len(path.points):
        out["path"] = _rounded(_thin(np.asarray(path.points), PATH_POINTS))
    if status is not None:
        out["status"] = {"goal_id": status.goal_id, "state": status.state, "text": status.text,
                         "place": status.place, "goal": [round(v, 3) for v in status.goal[:2]],
                         "distance": round(status.distance, 2), "eta": round(status.eta, 1),
                         "recoveries": status.recoveries, "driving": status.driving,
                         "localised": status.localised, "speed": status.speed, "width": status.width,
                         "mapping": status.mapping}
    return out


def map_json(grid: NavMap) -> dict[str, Any]:
    """The occupancy grid for a canvas: cells row by row from the map's lower-left corner,
    int8 as ROS has them (0 free, 100 occupied, -1 unknown), base64-encoded."""
    data = np.ascontiguousarray(grid.data, dtype=np.int8)
    return {"name": grid.name, "stamp": str(grid.stamp), "resolution": grid.resolution, "origin": list(grid.origin[:2]),
            "width": int(data.shape[1]), "height": int(data.shape[0]),
            "cells": base64.b64encode(data.tobytes()).decode("ascii")}
