"""What a depth camera's pixels mean in the robot's frame: plain numpy geometry, no bus, no HTTP.

A depth camera (messages.DepthImage + RgbImage + CameraInfo) is enough to see the world in the
arm's frame and to touch things in it: a pixel and its depth give a point in the camera's
optical frame (x right, y down, z forward; pixel centres at integer coordinates), and the
camera's pose [x y z qw qx qy qz] in the arm's base frame carries it into the arm's frame.
That pose is the simulation's own (CameraInfo.pose) or, for a real camera that knows none,
the one solved from marks touched with the tool (`fit_pose`): the same code uses either.

`object_at` answers "what is under this pixel": it grows a region of continuous surface
around the touched point, finds the horizontal surface the thing stands on, and keeps what
rises above it; the thing's top is its highest point, and its centre is the middle of its flat
top when the camera sees that (a camera above it: the kitchen's), else the nearest visible
surface pushed back by half the thing's width along the line of sight (exact for an upright
cylinder seen from the side).
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np

from asibot.messages import CameraInfo
from asibot.poses import quaternion_wxyz

#: Points a cloud carries at most (about: the image is subsampled by a whole stride).
CLOUD_POINTS = 5000
#: Two neighbouring pixels belong to one surface when their points are closer than this, m
#: (or than 2 pixels' footprint at that depth, for a surface seen at a grazing angle).
NEIGHBOUR_GAP = 0.015
#: A touched thing is looked for within this distance of the touched point, m.
OBJECT_REACH = 0.25
#: A thing rises at least this much above the surface it stands on, m; lower is that surface.
ABOVE_SUPPORT = 0.01
#: A pixel whose surface normal is this close to vertical (|n_z|) lies on a horizontal surface.
HORIZONTAL = 0.9
#: A thing's flat top seen by at least this many pixels tells where its middle is.
LID_PIXELS = 10
#: How far from the touched pixel a depth is looked for when it has none itself, pixels.
SEARCH_PX = 3


@dataclass(frozen=True)
class Intrinsics:
    """A pinhole camera's image size and focal lengths and principal point, pixels: what the
    sim renders with and what a real camera reports (CameraInfo carries them on the bus)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def of(cls, info: CameraInfo) -> "Intrinsics":
        """The intrinsics a CameraInfo carries."""
        return cls(info.width, info.height, info.fx, info.fy, info.cx, info.cy)

    def info(self, pose: Sequence[float], frame: str, stamp: int) -> CameraInfo:
        """The CameraInfo of a camera with these intrinsics, mounted at `pose` (x, y, z, qw, qx,
        qy, qz in the robot's base frame) with optical frame `frame`, for a frame taken at
        `stamp` (ns)."""
        return CameraInfo(width=self.width, height=self.height, fx=self.fx, fy=self.fy, cx=self.cx, cy=self.cy,
                          pose=list(pose), frame=frame, stamp=stamp)

    @classmethod
    def from_fovy(cls, width: int, height: int, fovy_deg: float) -> "Intrinsics":
        if width < 2 or height < 2:
            raise ValueError("camera resolution must be at least 2x2 pixels")
        f = 0.5 * height / math.tan(math.radians(fovy_deg) / 2)
        return cls(width, height, f, f, (width - 1) / 2, (height - 1) / 2)

    def rays(self) -> np.ndarray:
        """Unit ray directions, optical frame, (H*W, 3), row-major from the top-left pixel."""
        u, v = np.meshgrid(np.arange(self.width), np.arange(self.height))
        d = np.stack([(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones_like(u, float)], -1)
        return (d / np.linalg.norm(d, axis=-1, keepdims=True)).reshape(-1, 3)


class DepthError(ValueError):
    """A touch or a calibration that the depth cannot answer; the message is the sentence."""


# --- poses ------------------------------------------------------------------------------------
def quaternion_matrix(qw: float, qx: float, qy: float, qz: float) -> np.ndarray:
    """The 3x3 rotation of a quaternion (w, x, y, z); it need not be exactly unit."""
    q = np.array([qw, qx, qy, qz], float)
    n = np.linalg.norm(q)
    if not np.isfinite(n) or n < 1e-9:
        raise DepthError("The camera's pose has no valid orientation (its quaternion is zero).")
    w, x, y, z = q / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def pose_matrix(pose: Sequence[float]) -> np.ndarray:
    """The 4x4 transform of a pose [x y z qw qx qy qz]."""
    if len(pose) != 7 or not all(math.isfinite(float(v)) for v in pose):
        raise DepthError(f"A camera pose is 7 finite numbers [x y z qw qx qy qz]; got {list(pose)!r}.")
    t = np.eye(4)
    t[:3, :3] = quaternion_matrix(*pose[3:])
    t[:3, 3] = pose[:3]
    return t


def matrix_pose(t: np.ndarray) -> list[float]:
    """The pose [x y z qw qx qy qz] of a 4x4 transform (qw >= 0)."""
    t = np.asarray(t, float)
    return [float(v) for v in t[:3, 3]] + quaternion_wxyz(t[:3, :3])


def transform(t: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (N x 3) carried by a 4x4 transform."""
    return np.asarray(points, float) @ t[:3, :3].T + t[:3, 3]


# --- pixels and points ------------------------------------------------------------------------
def deproject(info: CameraInfo, u: float, v: float, depth: float) -> np.ndarray:
    """The optical-frame point of pixel (u, v) at `depth` m along the optical axis."""
    return np.array([(u - info.cx) / info.fx * depth, (v - info.cy) / info.fy * depth, depth])


def project(info: CameraInfo, point: Sequence[float]) -> tuple[float, float]:
    """The pixel (u, v) of an optical-frame point in front of the camera."""
    x, y, z = (float(c) for c in point)
    if z <= 0:
        raise DepthError("That point is behind the camera.")
    return info.fx * x / z + info.cx, info.fy * y / z + info.cy


def optical_points(depth: np.ndarray, info: CameraInfo) -> np.ndarray:
    """H x W x 3 optical-frame points of a depth image; NaN where it has no return (0)."""
    h, w = depth.shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    z = depth.astype(np.float64)
    z = np.where(z > 0, z, np.nan)
    return np.stack([(u - info.cx) / info.fx * z, (v - info.cy) / info.fy * z, z], -1)


def check_size(depth: np.ndarray, info: CameraInfo) -> None:
    if depth.ndim != 2 or depth.shape != (info.height, info.width):
        raise DepthError(f"The depth image is {depth.shape[::-1]} pixels but the camera says "
                         f"{info.width} x {info.height}; wait for the next frame.")


def decode_rgb(jpeg: bytes) -> np.ndarray:
    """H x W x 3 uint8 RGB of a JPEG (the cameras' RgbImage)."""
    image = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        raise DepthError("The camera's colour image is not a JPEG that can be read.")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def cloud(depth: np.ndarray, rgb: np.ndarray | None, info: CameraInfo, camera_pose: np.ndarray,
          most: int = CLOUD_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """The coloured points a camera sees, in the robot's frame: (N x 3 float32 m, N x 3 uint8).
    Every `stride`-th pixel of every `stride`-th row, so about `most` points at most; pixels with
    no return are left out. Without a colour image (a depth-only camera) the points are grey."""
    check_size(depth, info)
    h, w = depth.shape
    stride = max(1, math.ceil(math.sqrt(h * w / most)))
    small = depth[::stride, ::stride]
    v, u = np.nonzero(small > 0)
    z = small[v, u].astype(np.float64)
    u, v = u * stride, v * stride
    pts = np.stack([(u - info.cx) / info.fx * z, (v - info.cy) / info.fy * z, z], -1)
    xyz = transform(camera_pose, pts).astype(np.float32)
    if rgb is None:
        colours = np.full((len(z), 3), 160, np.uint8)
    else:
        if rgb.shape[:2] != (h, w):
            rgb = cv2.resize(rgb, (w, h), interpolation=cv2.INTER_NEAREST)
        colours = rgb[v, u].astype(np.uint8)
    return xyz, colours


def depth_at(depth: np.ndarray, u: int, v: int, search: int = SEARCH_PX) -> tuple[int, int]:
    """The pixel nearest (u, v) that has a depth, within `search` pixels: a touch between two
    returns, or on a speck of no return, still finds the surface."""
    h, w = depth.shape
    if not (0 <= u < w and 0 <= v < h):
        raise DepthError(f"The spot ({u}, {v}) is outside the picture ({w} x {h} pixels).")
    if depth[v, u] > 0:
        return u, v
    best: tuple[float, int, int] | None = None
    for dv in range(-search, search + 1):
        for du in range(-search, search + 1):
            uu, vv = u + du, v + dv
            if 0 <= uu < w and 0 <= vv < h and depth[vv, uu] > 0:
                d = du * du + dv * dv
                if best is None or d < best[0]:
                    best = (d, uu, vv)
    if best is None:
        raise DepthError("The camera has no depth at that spot (too far, too shiny or too close); "
                         "touch another spot.")
    return best[1], best[2]


# --- what is under a pixel --------------------------------------------------------------------
@dataclass(frozen=True)
class Touched:
    """What a touched pixel shows, in the robot's frame (m)."""

    surface: tuple[float, float, float]   # the touched point itself
    kind: str                              # "object" (rises above what it stands on) or "surface"
    top: float                             # the thing's highest point, z
    centre: tuple[float, float, float]     # the thing's centre (its middle height for an object)
    height: float                          # how far it rises above what it stands on (0: a surface)
    width: float                           # its width across the line of sight
    support: float | None                  # the height of the surface it stands on, if one was seen
    pixels: int                            # how many pixels it covers
    region: np.ndarray | None = field(default=None, repr=False, compare=False)   # its pixels (a mask)

    def as_json(self) -> dict:
        r = lambda v: round(float(v), 4)   # noqa: E731
        return {"surface": [r(v) for v in self.surface], "kind": self.kind, "top": r(self.top),
                "centre": [r(v) for v in self.centre], "height": r(self.height), "width": r(self.width),
                "support": None if self.support is None else r(self.support), "pixels": self.pixels}


def _grow(points: np.ndarray, seed: tuple[int, int], gap: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Pixels (a mask) connected to `seed` (row, col) through 4-neighbours whose points are
    within `gap` of each other, among the pixels of `keep`."""
    h, w = keep.shape
    region = np.zeros((h, w), bool)
    if not keep[seed]:
        return region
    # Plain lists: indexing numpy arrays one element at a time is ten times slower.
    pts, ok, gaps = np.nan_to_num(points).tolist(), keep.tolist(), (gap ** 2).tolist()
    seen = [[False] * w for _ in range(h)]
    seen[seed[0]][seed[1]] = True
    queue = collections.deque([seed])
    while queue:
        r, c = queue.popleft()
        px, py, pz = pts[r][c]
        limit = gaps[r][c]
        for rr, cc in ((r - 1, c), (r + 1, c), (r, c - 1), (r, c + 1)):
            if 0 <= rr < h and 0 <= cc < w and not seen[rr][cc] and ok[rr][cc]:
                qx, qy, qz = pts[rr][cc]
                if (px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2 < limit:
                    seen[rr][cc] = True
                    queue.append((rr, cc))
    region[:] = seen
    return region


def _vertical_normals(points: np.ndarray) -> np.ndarray:
    """|n_z| of each pixel's surface normal (central differences); 0 where it cannot be told."""
    dx = np.full_like(points, np.nan)
    dy = np.full_like(points, np.nan)
    dx[:, 1:-1] = points[:, 2:] - points[:, :-2]
    dy[1:-1, :] = points[2:, :] - points[:-2, :]
    n = np.cross(dx, dy)
    norm = np.linalg.norm(n, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        nz = np.abs(n[..., 2]) / norm
    return np.nan_to_num(nz, nan=0.0)


def object_at(depth: np.ndarray, info: CameraInfo, camera_pose: np.ndarray, u: float, v: float) -> Touched:
    """What stands under pixel (u, v): see the module's docstring."""
    check_size(depth, info)
    su, sv = depth_at(depth, int(round(u)), int(round(v)))
    z0 = float(depth[sv, su])
    # Look only near the touched point: a window of OBJECT_REACH around it (at its depth).
    half = int(math.ceil(max(info.fx, info.fy) * OBJECT_REACH / z0)) + 2
    r0, r1 = max(0, sv - half), min(info.height, sv + half + 1)
    c0, c1 = max(0, su - half), min(info.width, su + half + 1)
    crop = depth[r0:r1, c0:c1]
    optical = optical_points(depth, info)[r0:r1, c0:c1]
    valid = np.isfinite(optical[..., 2])
    pts = np.where(valid[..., None], transform(camera_pose, np.nan_to_num(optical).reshape(-1, 3)).reshape(optical.shape),
                   np.nan)
    seed = (sv - r0, su - c0)
    touched = pts[seed]
    footprint = 2.0 * crop.astype(np.float64) / min(info.fx, info.fy)
    gap = np.maximum(NEIGHBOUR_GAP, footprint)
    near = valid & (np.linalg.norm(np.nan_to_num(pts - touched, nan=1e9), axis=-1) < OBJECT_REACH)
    around = _grow(pts, seed, gap, near)
    heights = pts[..., 2]
    level = _vertical_normals(pts) > HORIZONTAL
    flat = around & level & (heights <= touched[2] + ABOVE_SUPPORT / 2)
    support = _support_height(heights[flat])
    if support is not None and touched[2] <= support + ABOVE_SUPPORT:
        return Touched(_xyz(touched), "surface", float(touched[2]), _xyz(touched), 0.0, 0.0, support,
                       int(around.sum()))
    thing = around if support is None else _grow(pts, seed, gap, near & (heights > support + ABOVE_SUPPORT))
    found = pts[thing]
    top = float(np.percentile(found[:, 2], 99))
    bottom = support if support is not None else float(found[:, 2].min())
    lid = pts[thing & (heights > top - ABOVE_SUPPORT)]
    centre_xy, width = _centre(found[:, :2], lid[:, :2], np.asarray(camera_pose)[:2, 3], touched[:2])
    centre = (float(centre_xy[0]), float(centre_xy[1]), (top + bottom) / 2)
    region = np.zeros(depth.shape, bool)
    region[r0:r1, c0:c1] = thing
    return Touched(_xyz(touched), "object", top, centre, top - bottom, width, support,
                   int(thing.sum()), region)


#: Colour names by hue (deg), the upper end of each range; red wraps round 360.
HUES = ((15, "red"), (40, "orange"), (70, "yellow"), (170, "green"), (260, "blue"), (335, "purple"), (360, "red"))


def colour_name(rgb: np.ndarray, region: np.ndarray) -> str | None:
    """The everyday name of a thing's colour ("red", "blue", "white") from its pixels of an RGB
    picture the size of the depth image; None when the picture does not match the depth."""
    if rgb.shape[:2] != region.shape or not region.any():
        return None
    r, g, b = (rgb[region].astype(np.float64).mean(axis=0) / 255.0)[:3]
    high, low = max(r, g, b), min(r, g, b)
    if high - low < 0.15 * max(high, 1e-6) or high - low < 0.06:      # hardly any colour
        return "white" if high > 0.75 else "black" if high < 0.25 else "grey"
    if high == r:
        hue = (60 * (g - b) / (high - low)) % 360
    elif high == g:
        hue = 60 * (b - r) / (high - low) + 120
    else:
        hue = 60 * (r - g) / (high - low) + 240
    return next(name for end, name in HUES if hue < end)


def _xyz(p: np.ndarray) -> tuple[float, float, float]:
    return float(p[0]), float(p[1]), float(p[2])


def _support_height(heights: np.ndarray) -> float | None:
    """The height of the horizontal surface most of the flat pixels near the touch lie on (1 cm
    bins, then the mean of the winning bin and its neighbours), or None when there is none."""
    if len(heights) < 20:
        return None
    bins = np.floor(heights / 0.01).astype(int)
    values, counts = np.unique(bins, return_counts=True)
    best = values[np.argmax(counts)]
    chosen = heights[np.abs(bins - best) <= 1]
    return float(np.median(chosen))


def _centre(xy: np.ndarray, lid: np.ndarray, camera_xy: np.ndarray, touched_xy: np.ndarray) -> tuple[np.ndarray, float]:
    """A thing's centre on the floor plan and its width across the line of sight. Its flat top
    (`lid`), when the camera sees it, spans the thing: the middle of its extent is the centre.
    Seen from the side, the nearest visible surface is pushed back by half the width along the
    horizontal line of sight (exact for an upright cylinder)."""
    sight = touched_xy - camera_xy
    length = float(np.linalg.norm(sight))
    along = sight / length if length > 1e-6 else np.array([1.0, 0.0])
    across = np.array([-along[1], along[0]])
    b_lo, b_hi = np.percentile(xy @ across, [1, 99])
    width = float(b_hi - b_lo)
    if len(lid) >= LID_PIXELS:
        a_lo, a_hi = np.percentile(lid @ along, [1, 99])
        l_lo, l_hi = np.percentile(lid @ across, [1, 99])
        return (a_lo + a_hi) / 2 * along + (l_lo + l_hi) / 2 * across, width
    nearest = float(np.percentile(xy @ along, 1))
    return (nearest + width / 2) * along + (b_lo + b_hi) / 2 * across, width


# --- calibration ------------------------------------------------------------------------------
#: Marks closer than this to one line cannot fix the rotation about it, m.
COLLINEAR = 0.01


def fit_pose(camera: Sequence[Sequence[float]], robot: Sequence[Sequence[float]]) -> tuple[np.ndarray, float]:
    """The camera's pose in the robot's frame (4x4) that carries the marks' camera-frame points
    onto the tool's robot-frame points, by the Kabsch method (rotation and translation, no
    scale), and the RMS of what is left, m. Refuses fewer than 3 pairs, or marks in a line."""
    if len(camera) < 3:
        raise DepthError(f"Touch at least 3 marks with the tool before solving; there "
                         f"{'is' if len(camera) == 1 else 'are'} {len(camera)}.")
    p, q = np.asarray(camera, float), np.asarray(robot, float)
    if p.ndim != 2 or q.shape != p.shape or p.shape[1:] != (3,):
        raise DepthError("Each mark needs a point in the camera and one of the tool (x, y, z).")
    if not (np.isfinite(p).all() and np.isfinite(q).all()):
        raise DepthError("A mark has a point that is not a number; start again.")
    for name, pts in (("camera", p), ("tool", q)):
        centred = pts - pts.mean(axis=0)
        spread = np.linalg.svd(centred, compute_uv=False)
        # The second singular value measures the distance from the best line (RMS * sqrt(n)).
        if spread[1] / math.sqrt(len(pts)) < COLLINEAR:
            raise DepthError(f"The marks lie in one line (as the {name} sees them), which leaves the camera free to "
                             f"turn about it: add a mark off that line, at least {COLLINEAR * 100:.0f} cm away.")
    pc, qc = p.mean(axis=0), q.mean(axis=0)
    h = (p - pc).T @ (q - qc)
    uu, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ uu.T))
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ uu.T
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = qc - rot @ pc
    rms = float(np.sqrt(np.mean(np.sum((transform(t, p) - q) ** 2, axis=1))))
    return t, rms
