"""Occupancy grids: the cells of a map and where they are in the world.

Conventions are ROS's (nav_msgs/OccupancyGrid): `data[row, col]` with row 0 at the map's
origin, so rows grow with y (the *image* of a map_server map is the other way up: mapfile
flips it). Values are int8: 0 free, 100 occupied, -1 unknown (1..99 in scale mode). The origin
is the pose of the lower-left corner of cell (0, 0); its yaw is honoured both ways.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asibot.nav.geometry import Pose

FREE, OCCUPIED, UNKNOWN = 0, 100, -1


@dataclass(frozen=True)
class GridInfo:
    width: int
    height: int
    resolution: float
    origin: Pose = Pose(0.0, 0.0, 0.0)

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    @property
    def size_m(self) -> tuple[float, float]:
        return (self.width * self.resolution, self.height * self.resolution)

    def _local(self, x: np.ndarray | float, y: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        dx, dy = np.asarray(x, float) - self.origin.x, np.asarray(y, float) - self.origin.y
        if self.origin.theta == 0.0:
            return dx, dy
        c, s = math.cos(self.origin.theta), math.sin(self.origin.theta)
        return c * dx + s * dy, -s * dx + c * dy

    def to_cell(self, x: np.ndarray | float, y: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) int arrays of the cells holding world points; may lie outside the grid."""
        lx, ly = self._local(x, y)
        return (np.floor(ly / self.resolution).astype(np.int64), np.floor(lx / self.resolution).astype(np.int64))

    def to_world(self, row: np.ndarray | float, col: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """World (x, y) of cell centres."""
        lx = (np.asarray(col, float) + 0.5) * self.resolution
        ly = (np.asarray(row, float) + 0.5) * self.resolution
        if self.origin.theta == 0.0:
            return lx + self.origin.x, ly + self.origin.y
        c, s = math.cos(self.origin.theta), math.sin(self.origin.theta)
        return self.origin.x + c * lx - s * ly, self.origin.y + s * lx + c * ly

    def inside(self, row: np.ndarray, col: np.ndarray) -> np.ndarray:
        return (row >= 0) & (row < self.height) & (col >= 0) & (col < self.width)

    def contains(self, x: float, y: float) -> bool:
        r, c = self.to_cell(x, y)
        return bool(self.inside(r, c))

    def bounds(self) -> str:
        """The map's extent for a sentence, e.g. 'x -0.75..10.75 m, y -0.75..8.75 m'."""
        xs, ys = self.to_world(np.array([-0.5, -0.5, self.height - 0.5, self.height - 0.5]),
                               np.array([-0.5, self.width - 0.5, -0.5, self.width - 0.5]))
        return f"x {xs.min():.2f}..{xs.max():.2f} m, y {ys.min():.2f}..{ys.max():.2f} m"


@dataclass
class OccupancyGrid:
    info: GridInfo
    data: np.ndarray  # int8 (height, width), row 0 = origin

    def __post_init__(self) -> None:
        if self.data.shape != self.info.shape or self.data.dtype != np.int8:
            raise ValueError(f"grid data must be int8 of shape {self.info.shape}, got {self.data.dtype} {self.data.shape}")

    @property
    def occupied(self) -> np.ndarray:
        return self.data >= 65

    @property
    def free(self) -> np.ndarray:
        return (self.data >= 0) & (self.data <= 25)
