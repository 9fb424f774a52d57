"""A camera's rays in the robot's base frame, computed once per CameraInfo.

Depth images here hold z, the distance along the optical axis (ROS's convention, and the
sim's: services/sim/asibot/sim/cameras.py), in the optical frame (x right, y down, z forward). A pixel
(u, v) then sees the point `position + z * direction[v, u]`, where `direction` is the ray
(u - cx)/fx, (v - cy)/fy, 1 turned into the base frame by the camera's pose. Scaling the ray
so that its optical z is 1 (not to unit length) is what makes every later step a multiply:
the heights, horizontal distances and points of a whole image are `z` times a precomputed
array, with no per-frame trigonometry and no per-pixel Python.

Validation lives here because everything else trusts a `CameraRays`: a CameraInfo with a
zero or NaN focal length, a tiny or absurd size, or a pose that is not a rotation is refused
with a sentence (`BadInput`) before anything is derived from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asibot.depth import Intrinsics, quaternion_matrix
from asibot.messages import CameraInfo
from asibot.perception.errors import BadInput

MAX_SIDE = 8192
"""Largest image side accepted; anything bigger is a corrupted CameraInfo, not a camera."""


def check_info(info: CameraInfo, name: str = "the camera") -> None:
    """Raise BadInput with a sentence when `info` cannot describe a real pinhole camera."""
    where = f"CameraInfo of {name}"
    for field in ("width", "height"):
        v = getattr(info, field)
        if not 2 <= v <= MAX_SIDE:
            raise BadInput(f"{where} has {field} {v}; it must be 2 to {MAX_SIDE} pixels: "
                           "fix the camera driver's resolution.")
    for field in ("fx", "fy"):
        v = getattr(info, field)
        if not (math.isfinite(v) and v > 0):
            raise BadInput(f"{where} has {field} = {v}; a focal length must be a positive number of "
                           "pixels: calibrate the camera or fix its driver.")
    for field in ("cx", "cy"):
        v = getattr(info, field)
        if not math.isfinite(v):
            raise BadInput(f"{where} has {field} = {v}; the principal point must be a finite pixel "
                           "coordinate.")
    pose = info.pose
    if len(pose) != 7 or not all(math.isfinite(v) for v in pose):
        raise BadInput(f"{where} has pose {pose!r:.80}; it must be 7 finite numbers x, y, z, qw, qx, qy, qz "
                       "(the optical frame in the robot's base frame).")
    norm = math.sqrt(sum(v * v for v in pose[3:]))
    if abs(norm - 1.0) > 0.01:
        raise BadInput(f"{where} has an orientation quaternion of norm {norm:.3g}; it must be a unit "
                       "quaternion qw, qx, qy, qz.")


@dataclass(frozen=True, eq=False)
class CameraRays:
    """One camera: intrinsics, pose on the robot, and the base-frame ray of every pixel."""

    lens: Intrinsics
    rotation: np.ndarray       # 3x3, optical frame -> base frame
    position: np.ndarray       # (3,), optical centre in the base frame, m
    direction: np.ndarray      # (3, H, W) float64: base-frame ray per pixel, optical z = 1
    key: tuple                 # what the rays were computed from (to notice a new CameraInfo)

    @classmethod
    def from_info(cls, info: CameraInfo, name: str = "the camera") -> "CameraRays":
        check_info(info, name)
        lens = Intrinsics.of(info)
        q = np.asarray(info.pose[3:], float)
        rot = quaternion_matrix(*(q / np.linalg.norm(q)))
        a = (np.arange(lens.width) - lens.cx) / lens.fx          # optical x / z per column
        b = (np.arange(lens.height) - lens.cy) / lens.fy         # optical y / z per row
        # direction = rot @ (a, b, 1), built from outer sums instead of an (H, W, 3) matmul
        direction = (rot[:, 0, None, None] * a[None, None, :]
                     + rot[:, 1, None, None] * b[None, :, None]
                     + rot[:, 2, None, None])
        return cls(lens, rot, np.asarray(info.pose[:3], float), np.ascontiguousarray(direction), _key(info))

    def same(self, info: CameraInfo) -> bool:
        """Whether `info` describes this very camera (CameraInfo arrives with every frame)."""
        return _same(self.key, _key(info))

    # ------------------------------------------------------------------ points
    def points(self, depth: np.ndarray, stride: int = 1) -> np.ndarray:
        """(N, 3) base-frame points of the pixels with a return (depth > 0), every `stride`-th
        row and column. `depth` must already be checked (`check_depth`)."""
        d = depth[::stride, ::stride]
        rows, cols = np.nonzero(d > 0)
        z = d[rows, cols].astype(np.float64)
        dirs = self.direction[:, ::stride, ::stride][:, rows, cols]
        return (self.position[:, None] + dirs * z).T

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pixel coordinates (u, v) and optical depth z of base-frame points (N, 3); points
        behind the camera get z <= 0 (and meaningless u, v)."""
        local = (points - self.position) @ self.rotation        # = rotation.T @ (p - position)
        z = local[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = self.lens.fx * local[:, 0] / z + self.lens.cx
            v = self.lens.fy * local[:, 1] / z + self.lens.cy
        return u, v, z

    def check_depth(self, depth: object, name: str = "the camera") -> np.ndarray:
        """The depth image as float32 H x W metres, or BadInput: a wrong type or shape, a NaN,
        an inf or a negative value refuses the whole frame (0 is 'no return')."""
        if not isinstance(depth, np.ndarray):
            raise BadInput(f"the depth image of {name} is a {type(depth).__name__}, not an array.")
        if depth.shape != (self.lens.height, self.lens.width):
            raise BadInput(f"the depth image of {name} is {'x'.join(map(str, depth.shape))} but its "
                           f"CameraInfo says {self.lens.height}x{self.lens.width} (rows x columns): the camera "
                           "and its CameraInfo disagree.")
        if depth.dtype not in (np.float32, np.float64):
            raise BadInput(f"the depth image of {name} holds {depth.dtype}; it must hold float32 "
                           "metres (0 = no return).")
        depth = depth.astype(np.float32, copy=False)
        lo, hi = float(depth.min()), float(depth.max())   # NaN propagates through both
        if math.isnan(lo) or math.isnan(hi):
            raise BadInput(f"the depth image of {name} contains NaN; mark pixels without a return "
                           "with 0, as the message contract says.")
        if lo < 0 or math.isinf(hi):
            raise BadInput(f"the depth image of {name} contains {'a negative value' if lo < 0 else 'inf'}; "
                           "depths must be metres >= 0, with 0 for no return.")
        return depth



def _key(info: CameraInfo) -> tuple:
    return (info.width, info.height, info.fx, info.fy, info.cx, info.cy, *info.pose)


def _same(a: tuple, b: tuple) -> bool:
    """The same camera: a simulated camera's pose on a moving base comes back with new
    rounding every frame (1e-9 m apart), and must not rebuild its rays each time."""
    return len(a) == len(b) and a[:2] == b[:2] and all(abs(x - y) <= 1e-6 for x, y in zip(a[2:], b[2:]))
