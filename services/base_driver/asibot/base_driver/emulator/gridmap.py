"""A 2D occupancy grid for the emulator's sonar and bumpers: ROS map_server PGM+YAML, or a room.

map_server convention (docs/maps.md): `image` (PGM), `resolution` m/cell, `origin` [x, y, yaw]
of the lower-left pixel, `negate`, `occupied_thresh`; occupancy p = (255 - v) / 255 (or
v / 255 when negated) and a cell is an obstacle when p > occupied_thresh. Row 0 is the top
(max y).
"""

from __future__ import annotations
from importlib import resources

import math
from pathlib import Path

import numpy as np
import yaml


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


def load(yaml_path: str | Path) -> GridMap:
    """Read a map_server YAML and its PGM (or a shipped map by name); errors say which file or
    field is wrong."""
    path = resolve(yaml_path)
    try:
        meta = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise ValueError(f"cannot read the map file {path}: {exc.strerror}") from None
    if not isinstance(meta, dict):
        raise ValueError(f"{path} is not a map_server YAML map (expected a mapping)")
    for field in ("image", "resolution", "origin"):
        if field not in meta:
            raise ValueError(f"{path} misses the map_server field {field!r}")
    image = path.parent / str(meta["image"])
    pixels = read_pgm(image)
    p = pixels.astype(float) / 255.0 if meta.get("negate", 0) else (255.0 - pixels) / 255.0
    occupied = p > float(meta.get("occupied_thresh", 0.65))
    origin = meta["origin"]
    return GridMap(np.flipud(occupied), float(meta["resolution"]), (float(origin[0]), float(origin[1])))


def read_pgm(path: Path) -> np.ndarray:
    """Binary (P5) or ASCII (P2) 8-bit PGM as a uint8 array, row 0 at the top."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ValueError(f"cannot read the map image {path}: {exc.strerror}") from None
    tokens: list[bytes] = []
    pos = 0
    while len(tokens) < 4:
        while pos < len(data) and data[pos:pos + 1].isspace():
            pos += 1
        if data[pos:pos + 1] == b"#":
            pos = data.index(b"\n", pos) + 1
            continue
        start = pos
        while pos < len(data) and not data[pos:pos + 1].isspace():
            pos += 1
        if start == pos:
            raise ValueError(f"{path} is not a PGM image (truncated header)")
        tokens.append(data[start:pos])
    magic, w, h, maxval = tokens[0], int(tokens[1]), int(tokens[2]), int(tokens[3])
    if maxval > 255:
        raise ValueError(f"{path}: only 8-bit PGM maps are supported (maxval {maxval})")
    if magic == b"P5":
        raw = np.frombuffer(data, dtype=np.uint8, count=w * h, offset=pos + 1)
    elif magic == b"P2":
        raw = np.array(data[pos:].split()[: w * h], dtype=np.uint8)
    else:
        raise ValueError(f"{path} is not a PGM image (magic {magic!r}; expected P5 or P2)")
    if raw.size != w * h:
        raise ValueError(f"{path} holds {raw.size} pixels, its header says {w}x{h}")
    return raw.reshape(h, w)
