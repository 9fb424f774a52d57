"""Poses in the plane and the few operations navigation needs on them.

A `Pose` is (x, y, theta) in metres and radians. `compose`/`relative` are the SE(2) product and
its inverse so odometry deltas can be carried from the odom frame to the map frame (what
AMCL's map->odom correction does) without matrices.
"""

from __future__ import annotations

import math
from typing import Iterable, NamedTuple

import numpy as np

from asibot.errors import quote
from asibot.nav.errors import NavError


class Pose(NamedTuple):
    x: float
    y: float
    theta: float

    def distance(self, other: "Pose") -> float:
        return math.hypot(other.x - self.x, other.y - self.y)

    def __str__(self) -> str:
        return f"({self.x:.2f}, {self.y:.2f}, {math.degrees(self.theta):.0f} deg)"


def wrap(a: float) -> float:
    """Angle in (-pi, pi]."""
    return math.atan2(math.sin(a), math.cos(a))


def wrap_array(a: np.ndarray) -> np.ndarray:
    return np.arctan2(np.sin(a), np.cos(a))


def compose(a: Pose, b: Pose) -> Pose:
    """a (+) b: pose b expressed in a's frame, returned in a's parent frame."""
    c, s = math.cos(a.theta), math.sin(a.theta)
    return Pose(a.x + c * b.x - s * b.y, a.y + s * b.x + c * b.y, wrap(a.theta + b.theta))


def relative(a: Pose, b: Pose) -> Pose:
    """(-a) (+) b: pose b seen from pose a (so compose(a, relative(a, b)) == b)."""
    c, s = math.cos(a.theta), math.sin(a.theta)
    dx, dy = b.x - a.x, b.y - a.y
    return Pose(c * dx + s * dy, -s * dx + c * dy, wrap(b.theta - a.theta))


def as_pose(value: object, what: str = "pose") -> Pose:
    """A Pose from (x, y, theta) numbers, or NavError with a sentence naming `what`."""
    if isinstance(value, dict):
        value = (value.get("x"), value.get("y"), value.get("theta", 0.0))
    items: list[object] | None = None
    if isinstance(value, Iterable):
        try:
            items = list(value)
        except TypeError:          # an iterable in name only: a 0-d array
            pass
    if items is None:
        raise NavError(f"The {what} must be three numbers x, y, theta (m, m, rad); got {quote(value)}.")
    if len(items) != 3:
        raise NavError(f"The {what} must be three numbers x, y, theta (m, m, rad); got {len(items)} values.")
    out = []
    for name, v in zip(("x", "y", "theta"), items):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(float(v)):
            raise NavError(f"The {what}'s {name} must be a finite number; got {quote(v)}.")
        if abs(float(v)) > 1e6:
            raise NavError(f"The {what}'s {name} = {float(v):g} is not a place in a home; check the units (m, rad).")
        out.append(float(v))
    return Pose(out[0], out[1], wrap(out[2]))
