"""Orientation conventions shared by the kinematics and the tools that show its poses.

A Cartesian point is [x, y, z, rot(y'), rot(z'')]: the first rotation is implied, about z by
the azimuth atan2(y, x) of the point (docs/asibot-conventions.md, "Kinematics"), so its orientation is
Rz(azimuth) Ry(rot y') Rz(rot z'').
"""

from __future__ import annotations

import math
from collections.abc import Sequence
import numpy as np


def _rot_z(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot_y(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def point_rotation(x: float, y: float, rot_y_rad: float, rot_z_rad: float) -> np.ndarray:
    """The 3x3 orientation of a point at (x, y, ...) with its two explicit rotations in rad."""
    return _rot_z(math.atan2(y, x)) @ _rot_y(rot_y_rad) @ _rot_z(rot_z_rad)


def quaternion_wxyz(r: np.ndarray) -> list[float]:
    """Unit quaternion (w, x, y, z), w >= 0, of a rotation matrix (Shepperd's method)."""
    r = np.asarray(r, float)
    t = r[0, 0] + r[1, 1] + r[2, 2]
    if t > 0:
        s = 2.0 * math.sqrt(1.0 + t)
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = [(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s]
    q = np.asarray(q) / np.linalg.norm(q)
    return (-q if q[0] < 0 else q).tolist()


def yaw_quaternion_wxyz(theta: float) -> list[float]:
    """A rotation of `theta` rad about z, as (w, x, y, z)."""
    return [math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2)]



#: The five coordinates of a point as users read and type them: name and unit.
POINT_AXES: tuple[tuple[str, str], ...] = (
    ("x", "m"), ("y", "m"), ("z", "m"), ("rot(y')", "deg"), ("rot(z'')", "deg"))
#: What the two rotations mean to someone who has not read the kinematics conventions.
POINT_AXIS_MEANINGS: dict[str, str] = {
    "rot(y')": "tool tilt: 0 up, 90 level, 180 down", "rot(z'')": "tool turn about itself"}


def user_point(pose: "Sequence[float] | np.ndarray") -> list[float]:
    """A 5-element pose in SI (m, rad) as the user's point (m, deg)."""
    p = [float(v) for v in pose]
    return p[:3] + [math.degrees(p[3]), math.degrees(p[4])]


def si_pose(point: "Sequence[float] | np.ndarray") -> list[float]:
    """The user's point (m, deg) as a 5-element pose in SI (m, rad)."""
    p = [float(v) for v in point]
    return p[:3] + [math.radians(p[3]), math.radians(p[4])]
