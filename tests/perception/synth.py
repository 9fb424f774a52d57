"""Synthetic cameras and scenes with known geometry: a ray caster for boxes and the floor.

Everything in the robot's base frame (x forward, y left, z up, floor at z = 0). Depth is z
along the optical axis, 0 where nothing is hit within `max_depth`, as the sim publishes it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from asibot import messages as m
from asibot.perception.rays import CameraRays
from asibot.poses import quaternion_wxyz

FRONT = (0.32, 0.0, 0.3)      # the sim's front depth camera (services/sim/asibot/sim/worlds/apartment.xml)
BACK = (-0.32, 0.0, 0.3)


def camera_info(pos=FRONT, yaw: float = 0.0, pitch: float = 0.0, width: int = 160, height: int = 120,
                fovy_deg: float = 45.0) -> m.CameraInfo:
    """A pinhole camera at `pos` looking along `yaw`, pitched down by `pitch` (rad), with the
    ROS optical frame (x right, y down, z forward), pixel centres at integers as the sim's."""
    fwd = np.array([math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw), -math.sin(pitch)])
    right = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    down = np.cross(fwd, right)
    rot = np.stack([right, down, fwd], axis=1)
    f = 0.5 * height / math.tan(math.radians(fovy_deg) / 2)
    return m.CameraInfo(width=width, height=height, fx=f, fy=f, cx=(width - 1) / 2, cy=(height - 1) / 2,
                        pose=[*map(float, pos), *quaternion_wxyz(rot)], frame="synthetic_optical")


@dataclass(frozen=True)
class Box:
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    bgr: tuple[int, int, int] = (128, 128, 128)


def wall_x(x: float, bgr=(200, 200, 200)) -> Box:
    """A wall across the robot's way, its near face at `x` (negative: behind), 2.5 m high."""
    return Box((x, -20.0, 0.0), (x + 0.1, 20.0, 2.5), bgr) if x > 0 else Box((x - 0.1, -20.0, 0.0), (x, 20.0, 2.5), bgr)


def render(rays: CameraRays, boxes: list[Box], floor: bool = True, max_depth: float = 8.0
           ) -> tuple[np.ndarray, np.ndarray]:
    """(depth float32 H x W, label int H x W): label -1 nothing, 0 floor, i + 1 box i."""
    d = rays.direction                      # (3, H, W), optical z = 1: t along it is the depth
    p = rays.position
    best = np.full(d.shape[1:], np.inf)
    label = np.full(d.shape[1:], -1)
    if floor:
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(d[2] < 0, -p[2] / d[2], np.inf)
        hit = t < best
        best[hit], label[hit] = t[hit], 0
    for i, box in enumerate(boxes):
        lo, hi = np.asarray(box.lo)[:, None, None], np.asarray(box.hi)[:, None, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (lo - p[:, None, None]) / d, (hi - p[:, None, None]) / d
        inside = (lo <= p[:, None, None]) & (p[:, None, None] <= hi)
        near = np.where(d == 0, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
        far = np.where(d == 0, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
        tmin, tmax = near.max(axis=0), far.min(axis=0)
        hit = (tmin <= tmax) & (tmin > 0) & (tmin < best)
        best[hit], label[hit] = tmin[hit], i + 1
    depth = np.where(best <= max_depth, best, 0.0).astype(np.float32)
    label[best > max_depth] = -1
    return depth, label


def colour_image(label: np.ndarray, boxes: list[Box], floor_bgr=(90, 110, 120), sky_bgr=(235, 235, 235)) -> np.ndarray:
    lut = np.array([sky_bgr, floor_bgr, *[b.bgr for b in boxes]], np.uint8)
    return lut[label + 1]


def jpeg(bgr: np.ndarray) -> m.RgbImage:
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 90])
    assert ok
    return m.RgbImage(jpeg=buf.tobytes(), width=bgr.shape[1], height=bgr.shape[0])
