"""A 2D occupancy grid for the emulator's sonar and bumpers: a ROS map_server map, or a room.

Maps are read by asibot.rosmap (docs/maps.md), as navigation reads them, so the emulated world
and navigation's map agree cell for cell: a cell is an obstacle when map_server marks it
occupied (100). A hand-written world may leave out negate and the thresholds (map_saver's are
used), which map_server itself would refuse.
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

import numpy as np

from asibot.rosmap import read_map


class GridMap:
    """Obstacle cells in a world frame; queries in metres."""

    def __init__(self, occupied: np.ndarray, resolution: float, origin: tuple[float, float] = (0.0, 0.0)) -> None:
        if occupied.ndim != 2 or resolution <= 0:
            raise ValueError("a grid map needs a 2D occupancy array and a positive resolution")
        self.occupied = occupied.astype(bool)   # [row, col], row 0 = lowest y
        self.resolution = float(resolution)
        self.origin = (float(origin[0]), float(origin[1]))

    @property
    def height(self) -> int:
        return self.occupied.shape[0]

    @property
    def width(self) -> int:
        return self.occupied.shape[1]

    def is_occupied(self, x: float, y: float) -> bool:
        """Outside the map counts as an obstacle: the robot cannot leave the known world."""
        col = int(math.floor((x - self.origin[0]) / self.resolution))
        row = int(math.floor((y - self.origin[1]) / self.resolution))
        if not (0 <= row < self.height and 0 <= col < self.width):
            return True
        return bool(self.occupied[row, col])

    def disc_hits(self, x: float, y: float, radius: float) -> bool:
        """True when a disc of `radius` around (x, y) touches an obstacle (sampled on its rim and centre)."""
        if self.is_occupied(x, y):
            return True
        steps = max(8, int(2 * math.pi * radius / self.resolution))
        return any(self.is_occupied(x + radius * math.cos(2 * math.pi * k / steps),
                                    y + radius * math.sin(2 * math.pi * k / steps)) for k in range(steps))

    def raycast(self, x: float, y: float, angle: float, max_range: float) -> float:
        """Distance to the first obstacle along a ray, or max_range; samples every half cell."""
        return float(self.raycast_many([(x, y, angle)], max_range)[0])

    def raycast_many(self, rays: list[tuple[float, float, float]], max_range: float) -> np.ndarray:
        """`raycast` for many (x, y, angle) rays at once, vectorised (the emulator's sonar ring)."""
        r = np.asarray(rays, dtype=float).reshape(-1, 3)
        d = np.arange(0.0, max_range, self.resolution / 2.0)
        px = r[:, :1] + d[None, :] * np.cos(r[:, 2:3])
        py = r[:, 1:2] + d[None, :] * np.sin(r[:, 2:3])
        col = np.floor((px - self.origin[0]) / self.resolution).astype(int)
        row = np.floor((py - self.origin[1]) / self.resolution).astype(int)
        inside = (row >= 0) & (row < self.height) & (col >= 0) & (col < self.width)
        hit = ~inside
        hit[inside] = self.occupied[row[inside], col[inside]]
        first = np.argmax(hit, axis=1)
        return np.where(hit.any(axis=1), d[first], max_range)


def room(width: float = 8.0, depth: float = 6.0, resolution: float = 0.05) -> GridMap:
    """The default world: an empty rectangular room centred on the origin, 10 cm walls."""
    cols, rows = int(round(width / resolution)), int(round(depth / resolution))
    grid = np.zeros((rows, cols), dtype=bool)
    wall = max(1, int(round(0.1 / resolution)))
    grid[:wall, :] = grid[-wall:, :] = True
    grid[:, :wall] = grid[:, -wall:] = True
    return GridMap(grid, resolution, (-width / 2.0, -depth / 2.0))


#: Maps shipped with the stack, generated from the simulation's worlds (libs/common/asibot/maps).
SHIPPED_MAPS = Path(str(resources.files("asibot.maps")))


def resolve(name: str | Path) -> Path:
    """A map file path, or the name of a shipped map (`apartment`), as a YAML path."""
    path = Path(name)
    if path.suffix or len(path.parts) > 1:
        return path
    shipped = SHIPPED_MAPS / f"{name}.yaml"
    if not shipped.exists():
        known = ", ".join(sorted(p.stem for p in SHIPPED_MAPS.glob("*.yaml"))) or "none"
        raise ValueError(f"no shipped map named {name!r} (shipped: {known}); or give a YAML path")
    return shipped


#: What a hand-written world may leave out of its YAML: map_saver's values.
LAX_DEFAULTS = {"negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.196}


def load(yaml_path: str | Path) -> GridMap:
    """A map_server map (or a shipped map by name) as obstacles; a ValueError (asibot.rosmap's
    MapFileError) says which file or key is wrong."""
    m = read_map(resolve(yaml_path), defaults=LAX_DEFAULTS)
    return GridMap(m.values == 100, m.settings.resolution, m.settings.origin[:2])
