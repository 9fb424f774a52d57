"""Synthetic depth and colour scenes with known answers, for the depth geometry, the web's touch
and finding taught things: the kitchen camera (its intrinsics and pose as the simulation gives
them) looking at a counter top with upright cylinders and boxes on it, ray-cast exactly."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from asibot.messages import CameraInfo
from asibot.poses import quaternion_wxyz

#: The counter top in the arm's frame (kitchen.xml: counter top 0.9, arm mount 0.94), m.
COUNTER = -0.04
#: The red can: centre of its footprint, radius, top (kitchen.xml), m.
CAN_XY, CAN_R, CAN_TOP = (0.0, 0.5), 0.033, 0.08


def kitchen_info(width: int = 320, height: int = 240) -> CameraInfo:
    """The kitchen camera as the simulation publishes it (pos 1.5 0.2 1.0 on the station,
    xyaxes 0 1 0 -0.654 0 0.757, fovy 58), in the arm's frame."""
    x = np.array([0.0, 1.0, 0.0])
    y_up = np.array([-0.654, 0.0, 0.757])
    y_up /= np.linalg.norm(y_up)
    back = np.cross(x, y_up)
    rot = np.stack([x, -y_up, -back], axis=1)        # optical: x right, y down, z forward
    f = 0.5 * height / math.tan(math.radians(58) / 2)
    return CameraInfo(width=width, height=height, fx=f, fy=f, cx=(width - 1) / 2, cy=(height - 1) / 2,
                      pose=[1.5, 0.2, 0.96] + quaternion_wxyz(rot), frame="kitchen_optical")


#: Colours of the synthetic RGB picture (RGB, 0-255): the counter a light grey and the wall an
#: off-white, as a kitchen's are (no colour to seed on); pixels that hit nothing are black.
COUNTER_RGB, WALL_RGB, NOTHING_RGB = (190, 190, 185), (235, 235, 230), (0, 0, 0)
#: The colours things are painted when given none: the kitchen's red can, and a plain grey.
RED, GREEN, BLUE, GREY = (200, 30, 30), (40, 160, 60), (40, 80, 210), (128, 128, 128)


@dataclass
class Scene:
    """A horizontal plane at `floor` (None: no plane), upright cylinders (x, y, r, bottom, top),
    axis-aligned boxes (x0, y0, z0, x1, y1, z1) and a wall x = `wall` (None: no wall).
    `cylinder_colours` and `box_colours` paint them in the RGB picture (one RGB each, in the
    same order; a thing given none is grey)."""

    floor: float | None = COUNTER
    cylinders: list[tuple[float, float, float, float, float]] = field(default_factory=list)
    boxes: list[tuple[float, float, float, float, float, float]] = field(default_factory=list)
    wall: float | None = None
    cylinder_colours: list[tuple[int, int, int]] = field(default_factory=list)
    box_colours: list[tuple[int, int, int]] = field(default_factory=list)

    def depth(self, info: CameraInfo, noise: float = 0.0, seed: int = 0, pose: list[float] | None = None) -> np.ndarray:
        """The depth image (z along the optical axis, m; 0 = no return) of this scene, seen by a
        camera at `pose` (default its CameraInfo's)."""
        best, _ = self._cast(info, pose)
        depth = np.where(np.isfinite(best), best, 0.0)
        if noise:
            depth = depth + np.random.default_rng(seed).normal(0, noise, depth.shape) * (depth > 0)
        return depth.astype(np.float32)

    def rgb(self, info: CameraInfo, pose: list[float] | None = None) -> np.ndarray:
        """The colour picture (H x W x 3 uint8 RGB, registered with `depth`: the kitchen camera
        gives both from one viewpoint) of this scene, flat colours, no shading."""
        _, hit = self._cast(info, pose)
        things = ([self.cylinder_colours[i] if i < len(self.cylinder_colours) else GREY
                   for i in range(len(self.cylinders))]
                  + [self.box_colours[i] if i < len(self.box_colours) else GREY for i in range(len(self.boxes))])
        palette = np.array([NOTHING_RGB, COUNTER_RGB, WALL_RGB, *things], np.uint8)
        return palette[hit + 1]

    def _cast(self, info: CameraInfo, pose: list[float] | None) -> tuple[np.ndarray, np.ndarray]:
        """Per pixel, the depth of the nearest hit (inf: none) and what it hit: -1 nothing, 0 the
        floor, 1 the wall, 2 + i cylinder i, 2 + len(cylinders) + j box j."""
        from asibot.depth import pose_matrix
        t = pose_matrix(pose or info.pose)
        u, v = np.meshgrid(np.arange(info.width, dtype=float), np.arange(info.height, dtype=float))
        d_opt = np.stack([(u - info.cx) / info.fx, (v - info.cy) / info.fy, np.ones_like(u)], -1)
        d = d_opt @ t[:3, :3].T          # robot-frame direction per unit of depth
        o = t[:3, 3]
        best = np.full(u.shape, np.inf)
        hit_by = np.full(u.shape, -1)

        def nearer(hit: np.ndarray, s: np.ndarray, label: int) -> None:
            nonlocal best
            closer = hit & (s < best)
            best = np.where(closer, s, best)
            hit_by[closer] = label

        with np.errstate(divide="ignore", invalid="ignore"):
            if self.floor is not None:
                s = (self.floor - o[2]) / d[..., 2]
                nearer(s > 0, s, 0)
            if self.wall is not None:
                s = (self.wall - o[0]) / d[..., 0]
                nearer(s > 0, s, 1)
            for i, (cx, cy, r, z0, z1) in enumerate(self.cylinders):
                a = d[..., 0] ** 2 + d[..., 1] ** 2
                b = 2 * (d[..., 0] * (o[0] - cx) + d[..., 1] * (o[1] - cy))
                c = (o[0] - cx) ** 2 + (o[1] - cy) ** 2 - r * r
                disc = b * b - 4 * a * c
                s = (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a)
                z = o[2] + s * d[..., 2]
                nearer((disc >= 0) & (s > 0) & (z >= z0) & (z <= z1), s, 2 + i)
                s = (z1 - o[2]) / d[..., 2]
                x, y = o[0] + s * d[..., 0], o[1] + s * d[..., 1]
                nearer((s > 0) & ((x - cx) ** 2 + (y - cy) ** 2 <= r * r), s, 2 + i)
            for j, box in enumerate(self.boxes):
                lo, hi = np.array(box[:3]), np.array(box[3:])
                t0 = (lo - o) / d
                t1 = (hi - o) / d
                near = np.max(np.minimum(t0, t1), axis=-1)
                far = np.min(np.maximum(t0, t1), axis=-1)
                nearer((near <= far) & (near > 0), near, 2 + len(self.cylinders) + j)
        return best, hit_by


def kitchen_scene() -> Scene:
    """The counter with the red can on it."""
    return Scene(cylinders=[(CAN_XY[0], CAN_XY[1], CAN_R, COUNTER, CAN_TOP)], cylinder_colours=[RED])


def pixel_of(info: CameraInfo, point) -> tuple[float, float]:
    """Where a robot-frame point shows in the picture."""
    from asibot.depth import pose_matrix, project, transform
    t = np.linalg.inv(pose_matrix(info.pose))
    return project(info, transform(t, np.array([point]))[0])
