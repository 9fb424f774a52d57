"""Read and write ROS map_server maps (YAML + PGM) exactly as map_server does.

Facts in docs/maps.md (map_server image_loader.cpp, map_saver.cpp). Loading: a pixel v
(negated to 255 - v when `negate`) has occupancy p = (255 - v) / 255; p > occupied_thresh ->
100, p < free_thresh -> 0, otherwise -1 in trinary mode or 1 + 98 (p - free) / (occ - free)
(truncated) in scale mode; raw mode copies v. The image's first row is the top of the map
(largest y), so rows are flipped into the grid.

Saving: trinary is map_saver's (free 0..25 -> 254, occupied >= 65 -> 0, else 205; negate 0,
occupied_thresh 0.65, free_thresh 0.196, which puts 205 just above free_thresh so it reads back
unknown). raw writes each value as its byte. scale picks, for each value, a grey that loads
back to it; unknown cells cannot be told in scale mode without an alpha channel, which PGM
has not, so such a save is refused with a sentence rather than silently changed.

Only PGM images are read (P5 binary and P2 ASCII, up to 8 bits; a maxval below 255 is scaled
to 0..255 as SDL_image does): the maps here are PGM, and a PNG is one `convert` away.
Anything else, or a YAML with a missing or odd field, raises MapError with a sentence.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from asibot.errors import quote
from asibot.nav.errors import MapError
from asibot.files import write_atomic
from asibot.nav.geometry import Pose
from asibot.nav.grid import GridInfo, OccupancyGrid

MODES = ("trinary", "scale", "raw")
REQUIRED = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
#: Largest map read: 64 M cells is 400 m x 400 m at 5 cm, far beyond a home.
MAX_CELLS = 64_000_000
MAX_YAML_BYTES = 64 * 1024
#: map_saver's thresholds (ROS 1): what `save_map` writes in the YAML.
SAVER_OCCUPIED, SAVER_FREE = 0.65, 0.196
#: map_saver's value thresholds: free is 0..25, occupied is >= 65.
SAVER_FREE_MAX, SAVER_OCCUPIED_MIN = 25, 65


@dataclass(frozen=True)
class MapMeta:
    """The YAML's settings, kept so a map can be written back the way it came."""

    image: str
    mode: str = "trinary"
    negate: bool = False
    occupied_thresh: float = SAVER_OCCUPIED
    free_thresh: float = SAVER_FREE


@dataclass
class LoadedMap:
    grid: OccupancyGrid
    meta: MapMeta
    yaml_path: Path


# ------------------------------------------------------------------------------------- PGM

_TOKEN = re.compile(rb"\s*((?:#[^\n]*\n\s*)*)(\S+)")


def read_pgm(data: bytes, name: str = "the image") -> np.ndarray:
    """uint8 (height, width) pixels of a P5 or P2 PGM; MapError naming `name` otherwise."""
    if data[:2] not in (b"P5", b"P2"):
        kind = ("a PNG image" if data[:8] == b"\x89PNG\r\n\x1a\n" else "a JPEG image" if data[:2] == b"\xff\xd8"
                else "a colour PPM (P6/P3)" if data[:2] in (b"P6", b"P3") else "not a PGM image")
        raise MapError(f"{name} is {kind}; a map image must be a PGM (P5 or P2, 8-bit grey). "
                       f"Convert it, e.g. `convert map.png -depth 8 map.pgm`.")
    pos, fields = 2, []
    for _ in range(3):
        m = _TOKEN.match(data, pos)
        if not m or not m.group(2).isdigit():
            raise MapError(f"{name} has a broken PGM header (width, height and maxval must follow {data[:2].decode()}).")
        fields.append(int(m.group(2)))
        pos = m.end()
    width, height, maxval = fields
    if width <= 0 or height <= 0 or width * height > MAX_CELLS:
        raise MapError(f"{name} is {width} x {height} pixels; a map must have between 1 and {MAX_CELLS} cells.")
    if not 0 < maxval <= 255:
        raise MapError(f"{name} has maxval {maxval}: only 8-bit PGMs (maxval 1..255) are maps; save it as 8-bit.")
    n = width * height
    if data[:2] == b"P5":
        if pos >= len(data) or not data[pos:pos + 1].isspace():
            raise MapError(f"{name} has a broken PGM header (no whitespace after maxval).")
        raster = data[pos + 1:pos + 1 + n]
        if len(raster) < n:
            raise MapError(f"{name} is truncated: {len(raster)} of {n} pixel bytes ({width} x {height}).")
        img = np.frombuffer(raster, np.uint8).reshape(height, width)
    else:
        try:
            values = np.array(data[pos:].split(), dtype=np.int64)
        except ValueError:
            raise MapError(f"{name} is a P2 PGM with something other than numbers in its pixels.") from None
        if values.size < n:
            raise MapError(f"{name} is truncated: {values.size} of {n} pixels ({width} x {height}).")
        values = values[:n]
        if values.min() < 0 or values.max() > maxval:
            raise MapError(f"{name} has pixels outside 0..{maxval}.")
        img = values.astype(np.uint8).reshape(height, width)
    if maxval != 255:
        img = ((img.astype(np.uint32) * 255 + maxval // 2) // maxval).astype(np.uint8)
    return img.copy()


def pgm_bytes(img: np.ndarray, comment: str = "asibot.nav.mapfile") -> bytes:
    """A binary (P5) 8-bit PGM of a uint8 (height, width) image."""
    if img.dtype != np.uint8 or img.ndim != 2:
        raise ValueError("a PGM image is a 2-D uint8 array")
    h, w = img.shape
    return f"P5\n# {comment}\n{w} {h}\n255\n".encode() + np.ascontiguousarray(img).tobytes()


# ------------------------------------------------------------------------ pixel <-> value

def pixels_to_values(img: np.ndarray, mode: str, negate: bool, occupied_thresh: float,
                     free_thresh: float) -> np.ndarray:
    """map_server's per-pixel rule, vectorised; returns int8 values in image row order."""
    v = img.astype(np.float64)
    if negate:
        v = 255.0 - v
    if mode == "raw":
        return v.astype(np.uint8).view(np.int8)
    occ = (255.0 - v) / 255.0
    if mode == "trinary":
        mid = np.full(img.shape, -1, np.int16)
    else:
        mid = (1.0 + 98.0 * (occ - free_thresh) / (occupied_thresh - free_thresh)).astype(np.int16)
    out = np.where(occ > occupied_thresh, 100, np.where(occ < free_thresh, 0, mid))
    return out.astype(np.int8)


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
    loaded = pixels_to_values(greys, "scale", False, SAVER_OCCUPIED, SAVER_FREE).astype(np.int64)
    lut = np.empty(101, np.uint8)
    for want in range(101):  # 101 entries, once per save: the nearest value a grey can give
        lut[want] = greys[int(np.argmin(np.abs(loaded - want) * 512 + np.abs(greys.astype(int) - 128)))]
    return lut[np.clip(values.astype(np.int16), 0, 100)]


# ------------------------------------------------------------------------------------ YAML

def _number(doc: dict, key: str, where: str, lo: float, hi: float) -> float:
    v = doc[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
        raise MapError(f"{where}: {key} must be a number in [{lo:g}, {hi:g}]; got {quote(v)}.")
    return float(v)


def parse_yaml(text: str, where: str) -> tuple[MapMeta, float, Pose]:
    """(meta, resolution, origin) from a map_server YAML; MapError naming the field otherwise."""
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise MapError(f"{where} is not valid YAML ({str(exc).splitlines()[0]}).") from None
    if not isinstance(doc, dict):
        raise MapError(f"{where} is not a map_server YAML: it must be a mapping with {', '.join(REQUIRED)}.")
    missing = [k for k in REQUIRED if k not in doc]
    if missing:
        raise MapError(f"{where}: {', '.join(missing)} {'is' if len(missing) == 1 else 'are'} missing; "
                       f"a map_server YAML needs {', '.join(REQUIRED)}.")
    image = doc["image"]
    if not isinstance(image, str) or not image.strip() or "\x00" in image:
        raise MapError(f"{where}: image must be the image file's name; got {quote(image)}.")
    resolution = _number(doc, "resolution", where, 0.0, 100.0)
    if resolution <= 0:
        raise MapError(f"{where}: resolution must be positive (metres per pixel); got {resolution:g}.")
    origin = doc["origin"]
    if (not isinstance(origin, list) or len(origin) != 3
            or any(isinstance(o, bool) or not isinstance(o, (int, float)) or not math.isfinite(o) or abs(o) > 1e6
                   for o in origin)):
        raise MapError(f"{where}: origin must be [x, y, yaw], three finite numbers; got {quote(origin)}.")
    negate = doc["negate"]
    if negate not in (0, 1) or (isinstance(negate, float)):
        raise MapError(f"{where}: negate must be 0 or 1; got {quote(negate)}.")
    occ = _number(doc, "occupied_thresh", where, 0.0, 1.0)
    free = _number(doc, "free_thresh", where, 0.0, 1.0)
    if not free < occ:
        raise MapError(f"{where}: free_thresh ({free:g}) must be below occupied_thresh ({occ:g}).")
    mode = doc.get("mode", "trinary")
    if mode not in MODES:
        raise MapError(f"{where}: mode must be trinary, scale or raw; got {quote(mode)}.")
    meta = MapMeta(image=image, mode=mode, negate=bool(negate), occupied_thresh=occ, free_thresh=free)
    return meta, resolution, Pose(float(origin[0]), float(origin[1]), float(origin[2]))


def load_map(yaml_path: str | os.PathLike[str]) -> LoadedMap:
    """The map a map_server YAML describes; MapError with a sentence for anything wrong."""
    path = Path(yaml_path)
    try:
        if path.stat().st_size > MAX_YAML_BYTES:
            raise MapError(f"{path} is {path.stat().st_size} bytes: that is not a map_server YAML.")
        raw = path.read_bytes()
    except OSError as exc:
        raise MapError(f"Cannot read the map {path}: {exc.strerror or exc}.") from None
    if raw[:2] in (b"P5", b"P2", b"P6", b"P3") or raw[:4] == b"\x89PNG":
        raise MapError(f"{path} is an image; give the map's YAML file, which names the image.")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise MapError(f"{path} is not a text file; a map is given by its map_server YAML.") from None
    meta, resolution, origin = parse_yaml(text, str(path))
    image_path = Path(meta.image) if os.path.isabs(meta.image) else path.parent / meta.image
    try:
        data = image_path.read_bytes()
    except OSError as exc:
        raise MapError(f"{path} names the image {meta.image!r}, which cannot be read: {exc.strerror or exc}.") from None
    img = read_pgm(data, str(image_path))
    values = pixels_to_values(img, meta.mode, meta.negate, meta.occupied_thresh, meta.free_thresh)
    info = GridInfo(width=img.shape[1], height=img.shape[0], resolution=resolution, origin=origin)
    return LoadedMap(OccupancyGrid(info, np.flipud(values).copy()), meta, path)


def _fmt(x: float) -> str:
    return repr(float(x))


def yaml_text(image: str, info: GridInfo, mode: str) -> str:
    o = info.origin
    return (f"image: {image}\nresolution: {_fmt(info.resolution)}\n"
            f"origin: [{_fmt(o.x)}, {_fmt(o.y)}, {_fmt(o.theta)}]\n"
            f"negate: 0\noccupied_thresh: {SAVER_OCCUPIED}\nfree_thresh: {SAVER_FREE}\nmode: {mode}\n")


def save_map(grid: OccupancyGrid, yaml_path: str | os.PathLike[str], mode: str = "trinary") -> tuple[Path, Path]:
    """Write `grid` as <name>.pgm + <name>.yaml (map_saver's format); returns both paths.

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
    write_atomic(image, pgm_bytes(np.ascontiguousarray(img)))
    write_atomic(path, yaml_text(image.name, grid.info, mode).encode())
    return path, image
