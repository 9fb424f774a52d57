"""Navigation's maps: a map_server map loaded as an OccupancyGrid, and saved as map_saver does.

Reading (YAML + PGM, PNG, BMP...) is asibot.rosmap's, shared with the base emulator so both see
the same cells; this module turns its values into nav's grid and writes maps back (docs/maps.md,
map_saver.cpp).

Saving: trinary is map_saver's (free 0..25 -> 254, occupied >= 65 -> 0, else 205; negate 0,
occupied_thresh 0.65, free_thresh 0.196, which puts 205 just above free_thresh so it reads back
unknown). raw writes each value as its byte. scale picks, for each value, a grey that loads
back to it; unknown cells cannot be told in scale mode without an alpha channel, which PGM
has not, so such a save is refused with a sentence rather than silently changed. The image is
always a binary PGM, as map_saver writes.

A robot's maps folder (the service's map_save and save_map, which a user's program may call)
is bounded: at most MAX_MAPS maps and MAX_MAPS_BYTES of files in it. A save past either is
refused, with a sentence that says how much is kept and how to free room, before anything is
written; saving over a map of the same name counts only what it adds.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asibot.errors import quote
from asibot.files import write_atomic
from asibot.nav.errors import MapError
from asibot.nav.geometry import Pose
from asibot.nav.grid import GridInfo, OccupancyGrid
from asibot.rosmap import MODES, MapFileError, MapSettings, occupancy_values, read_map

#: map_saver's thresholds (ROS 1): what `save_map` writes in the YAML.
SAVER_OCCUPIED, SAVER_FREE = 0.65, 0.196
#: map_saver's value thresholds: free is 0..25, occupied is >= 65.
SAVER_FREE_MAX, SAVER_OCCUPIED_MIN = 25, 65
#: How much a robot's maps folder keeps: maps (a YAML and its image each), and the bytes of
#: every file in it. A home's map at 5 cm is a few hundred KiB (the sim apartment's: 43 KiB).
MAX_MAPS = 20
MAX_MAPS_BYTES = 64 * 1024 * 1024


@dataclass
class LoadedMap:
    grid: OccupancyGrid
    meta: MapSettings   # the YAML's settings, so a map can be written back the way it came
    yaml_path: Path


# ------------------------------------------------------------------------------------- PGM

def pgm_bytes(img: np.ndarray, comment: str = "asibot.nav.mapfile") -> bytes:
    """A binary (P5) 8-bit PGM of a uint8 (height, width) image."""
    if img.dtype != np.uint8 or img.ndim != 2:
        raise ValueError("a PGM image is a 2-D uint8 array")
    h, w = img.shape
    return f"P5\n# {comment}\n{w} {h}\n255\n".encode() + np.ascontiguousarray(img).tobytes()


# ------------------------------------------------------------------------ pixel <-> value

def values_to_pixels(values: np.ndarray, mode: str) -> np.ndarray:
    """Greys that load back (negate 0, map_saver's thresholds) to `values` (int8, any row order)."""
    if mode == "trinary":
        return np.where((values >= 0) & (values <= SAVER_FREE_MAX), 254,
                        np.where(values >= SAVER_OCCUPIED_MIN, 0, 205)).astype(np.uint8)
    if mode == "raw":
        return values.astype(np.int8).view(np.uint8).copy()
    if (values < 0).any():
        raise MapError("This map has unknown cells, which a PGM cannot hold in scale mode (map_server needs an "
                       "alpha channel for that); save it in trinary or raw mode.")
    greys = np.arange(256, dtype=np.uint8)
    loaded = occupancy_values(greys.astype(np.float64), "scale", False, SAVER_OCCUPIED, SAVER_FREE).astype(np.int64)
    lut = np.empty(101, np.uint8)
    for want in range(101):  # 101 entries, once per save: the nearest value a grey can give
        lut[want] = greys[int(np.argmin(np.abs(loaded - want) * 512 + np.abs(greys.astype(int) - 128)))]
    return lut[np.clip(values.astype(np.int16), 0, 100)]


# ------------------------------------------------------------------------------- load/save

def load_map(yaml_path: str | os.PathLike[str]) -> LoadedMap:
    """The map a map_server YAML describes; MapError with a sentence for anything wrong."""
    try:
        m = read_map(yaml_path)
    except MapFileError as exc:
        raise MapError(str(exc)) from None
    height, width = m.values.shape
    info = GridInfo(width=width, height=height, resolution=m.settings.resolution, origin=Pose(*m.settings.origin))
    return LoadedMap(OccupancyGrid(info, m.values), m.settings, m.yaml_path)


def _fmt(x: float) -> str:
    return repr(float(x))


def yaml_text(image: str, info: GridInfo, mode: str) -> str:
    o = info.origin
    return (f"image: {image}\nresolution: {_fmt(info.resolution)}\n"
            f"origin: [{_fmt(o.x)}, {_fmt(o.y)}, {_fmt(o.theta)}]\n"
            f"negate: 0\noccupied_thresh: {SAVER_OCCUPIED}\nfree_thresh: {SAVER_FREE}\nmode: {mode}\n")


def _size_text(n: float) -> str:
    if n < 1024 * 1024:
        return f"{n / 1024:.0f} KiB" if n >= 1024 else f"{int(n)} bytes"
    return f"{n / 2**20:.1f}".removesuffix(".0") + " MiB"


def _folder_bytes(folder: Path) -> int:
    total = 0
    for top, _dirs, files in os.walk(folder):
        for f in files:
            try:
                total += os.lstat(os.path.join(top, f)).st_size
            except OSError:
                pass
    return total


def _file_bytes(path: Path) -> int:
    try:
        return path.lstat().st_size
    except OSError:
        return 0


def check_room(path: Path, size: int, owner: str = "this robot") -> None:
    """Refuse, with a sentence, a map of `size` bytes saved as `path` that would take its
    folder past MAX_MAPS maps or MAX_MAPS_BYTES; a map saved over one of the same name counts
    only what it adds."""
    folder = path.parent
    maps = [p for p in folder.iterdir() if p.suffix in (".yaml", ".yml") and p.is_file()]
    used = _folder_bytes(folder)
    how = (f"Save over a map you no longer use (the same name replaces it) or delete old maps in {folder}.")
    replaced = path.is_file()
    if not replaced and len(maps) >= MAX_MAPS:
        raise MapError(f"There are {len(maps)} maps of {owner} already, the most kept (they take {_size_text(used)} "
                       f"of {_size_text(MAX_MAPS_BYTES)}), so the map was not saved. {how}")
    grows = size - (_file_bytes(path) + _file_bytes(path.with_suffix(".pgm")) if replaced else 0)
    if grows > 0 and used + grows > MAX_MAPS_BYTES:
        raise MapError(f"The maps of {owner} take {_size_text(used)} of {_size_text(MAX_MAPS_BYTES)} ({len(maps)} maps, "
                       f"at most {MAX_MAPS}); this one needs {_size_text(grows)} more, so it was not saved. {how}")


def save_map(grid: OccupancyGrid, yaml_path: str | os.PathLike[str], mode: str = "trinary",
             bounded: str | None = None) -> tuple[Path, Path]:
    """Write `grid` as <name>.pgm + <name>.yaml (map_saver's format); returns both paths.
    `bounded` (the robot whose maps folder it is): refused first, nothing written, when the
    folder has no room for it (`check_room`).

    The image is written before the YAML, each atomically, so a reader never sees a YAML
    that names a half-written image."""
    if mode not in MODES:
        raise MapError(f"mode must be trinary, scale or raw; got {quote(mode)}.")
    path = Path(yaml_path)
    if path.suffix not in (".yaml", ".yml"):
        raise MapError(f"{path}: a map is saved by its YAML name, ending in .yaml.")
    if not path.parent.is_dir():
        raise MapError(f"Cannot save the map: the folder {path.parent} does not exist.")
    image = path.with_suffix(".pgm")
    img = np.flipud(values_to_pixels(grid.data, mode))
    pgm, yaml = pgm_bytes(np.ascontiguousarray(img)), yaml_text(image.name, grid.info, mode).encode()
    if bounded is not None:
        check_room(path, len(pgm) + len(yaml), bounded)
    write_atomic(image, pgm)
    write_atomic(path, yaml)
    return path, image
