"""Where is the red can? A coloured blob in the RGB image, placed in 3D with the depth cameras.

Colour: the image in HSV, thresholded per colour (red wraps around hue 0, so it has two
ranges), opened with a 3x3 kernel against speckle, and the largest connected blob kept.
Saturation thresholds keep the apartment's parquet and wood (orange-brown, hue ~15 of 180,
saturation ~0.4) out of "red" and "orange".

Depth: the Pioneer's RGB camera is not registered with its depth cameras (services/sim:
"rgb" at 0.2 m ahead and 0.45 m up, pitched 15 deg down, 50 deg fov; "front" at 0.32 m and
0.3 m, level, 45 deg), so there is no depth *at* an RGB pixel. Instead every depth camera's
points (base frame, rays.py) are projected into the RGB image, as depth_image_proc's
register does, and the points that land on the blob are the object's. Seen from the RGB
camera, points hidden behind the object (visible to the depth camera from its other
viewpoint) land on the blob too, so only the nearest cluster is kept: points within
`cluster` of the 10th percentile of their distance from the RGB camera; and only the blob's
inside (eroded by 2 pixels) is used, since on its rim things in front of the object project
within a pixel of it. The answer is the
median of those: a point on the visible surface of the object, in the base frame. When
depth and RGB come from the same camera (the kitchen's), the same code is exact.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from asibot.perception.errors import BadInput
from asibot.perception.rays import CameraRays

#: HSV ranges of OpenCV (H 0-180, S and V 0-255), lower and upper inclusive.
COLORS: dict[str, tuple[tuple[tuple[int, int, int], tuple[int, int, int]], ...]] = {
    "red": (((0, 120, 70), (8, 255, 255)), ((170, 120, 70), (180, 255, 255))),
    "orange": (((9, 150, 80), (21, 255, 255)),),
    "yellow": (((22, 120, 80), (35, 255, 255)),),
    "green": (((40, 100, 50), (85, 255, 255)),),
    "blue": (((100, 120, 50), (130, 255, 255)),),
}


@dataclass(frozen=True)
class Blob:
    mask: np.ndarray             # H x W bool, the largest blob of the colour
    pixels: int
    centroid: tuple[float, float]   # (u, v), pixels


def check_color(color: object) -> str:
    if not isinstance(color, str) or color.lower() not in COLORS:
        raise BadInput(f"unknown colour {color!r:.40}: ask for one of {', '.join(COLORS)}.")
    return color.lower()


def decode_jpeg(jpeg: bytes, width: int, height: int) -> np.ndarray:
    """The BGR image of an RgbImage, or BadInput when it is not a JPEG of the size it claims."""
    bgr = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR) if jpeg else None
    if bgr is None:
        raise BadInput("the RGB image is not a readable JPEG; check the camera driver.")
    if bgr.shape[:2] != (height, width):
        raise BadInput(f"the RGB image is {bgr.shape[1]}x{bgr.shape[0]} but says {width}x{height}.")
    return bgr


def find_blob(bgr: np.ndarray, color: str, min_pixels: int = 20) -> Blob | None:
    """The largest blob of `color` in a BGR image, or None if none has `min_pixels`."""
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    mask = np.zeros(hsv.shape[:2], np.uint8)
    for lo, hi in COLORS[check_color(color)]:
        mask |= cv2.inRange(hsv, np.array(lo, np.uint8), np.array(hi, np.uint8))
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    n, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return None
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    area = int(stats[best, cv2.CC_STAT_AREA])
    if area < min_pixels:
        return None
    return Blob(labels == best, area, (float(centroids[best][0]), float(centroids[best][1])))


def locate(blob: Blob, rgb: CameraRays, clouds: Sequence[np.ndarray], min_points: int = 5,
           cluster: float = 0.05) -> tuple[np.ndarray, int] | None:
    """(point, n): the base-frame point of the blob from depth points (clouds of (N, 3) base-frame
    points) that project onto it, and how many did; None when fewer than `min_points` do."""
    pts = np.concatenate([c for c in clouds if len(c)]) if any(len(c) for c in clouds) else np.zeros((0, 3))
    if not len(pts):
        return None
    u, v, z = rgb.project(pts)
    # Only the blob's inside: on its rim, things in front of or behind the object project
    # within a pixel of it (a table's edge under a can seen from the table's height).
    inner = cv2.erode(blob.mask.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    mask = inner if inner.sum() >= min_points else blob.mask
    h, w = mask.shape
    with np.errstate(invalid="ignore"):
        ui, vi = np.rint(u), np.rint(v)
        inside = (z > 0.05) & (ui >= 0) & (ui < w) & (vi >= 0) & (vi < h)
    sel = np.flatnonzero(inside)
    sel = sel[mask[vi[sel].astype(np.int64), ui[sel].astype(np.int64)]]
    if len(sel) < min_points:
        return None
    dist = np.linalg.norm(pts[sel] - rgb.position, axis=1)
    near = sel[dist <= np.percentile(dist, 10) + cluster]
    return np.median(pts[near], axis=0), int(len(near))


def find(bgr: np.ndarray, color: str, rgb: CameraRays, clouds: Sequence[np.ndarray],
         min_pixels: int = 20) -> dict:
    """The `find` RPC's answer: {"found", "point" (base frame, m), "pixels", "depth_points"} or
    {"found": False, "pixels", "message"} with a sentence saying what to do."""
    color = check_color(color)
    if bgr.shape[:2] != (rgb.lens.height, rgb.lens.width):
        raise BadInput(f"the RGB image is {bgr.shape[1]}x{bgr.shape[0]} but its CameraInfo says "
                       f"{rgb.lens.width}x{rgb.lens.height}.")
    blob = find_blob(bgr, color, min_pixels)
    if blob is None:
        return {"found": False, "pixels": 0,
                "message": f"No {color} object is in view of the camera; turn the robot or move closer."}
    where = locate(blob, rgb, clouds)
    if where is None:
        return {"found": False, "pixels": blob.pixels,
                "message": f"A {color} object is in view ({blob.pixels} pixels) but no depth camera sees it, "
                           "so its position is unknown; turn the robot towards it or move closer."}
    point, n = where
    return {"found": True, "point": [round(float(v), 4) for v in point], "pixels": blob.pixels,
            "depth_points": n}
