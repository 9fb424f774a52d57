"""Read a ROS map_server map (a YAML naming an image) into occupancy values, as map_server does.

The map file format is part of the contract: navigation plans on these maps and the base
emulator builds its world from them, so both read them here and agree cell for cell. Facts are
in docs/maps.md (ROS 1 map_server image_loader.cpp, nav2 map_io.cpp); in short:

- the image is decoded by OpenCV: PGM/PPM (8 or 16 bit), PNG, BMP, and whatever else OpenCV
  reads, as map_server reads whatever SDL_image reads. Samples are put on 0..255 (a PNM maxval
  below 255 is stretched with SDL_image's rounding, 16 bits are divided by 257);
- a pixel's grey is the mean of its colour channels; in trinary mode an alpha channel is
  averaged in as well (map_server keeps that quirk "to preserve existing behaviour"), in scale
  and raw modes it is not. `negate` turns the grey v into 255 - v;
- occupancy p = (255 - v) / 255: p > occupied_thresh -> 100, p < free_thresh -> 0, otherwise
  -1 in trinary mode, and in scale mode -1 for a fully transparent pixel, else
  1 + 98 (p - free) / (occ - free) truncated; raw mode copies v (truncated) as the value;
- the image's first row is the top of the map (largest y), so rows are flipped into the grid.

Where ROS 1 reads beside the intent, this follows nav2: a paletted image is read by its
colours (not its palette indices) and an image without alpha is opaque (ROS 1 takes the last
colour byte for alpha). A 32-bit BMP whose alpha is zero everywhere is opaque, as SDL reads it.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import cv2
import numpy as np
import yaml

from asibot.errors import AsibotError, quote

MODES = ("trinary", "scale", "raw")
REQUIRED = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
#: Largest map read: 64 M cells is 400 m x 400 m at 5 cm, far beyond a home.
MAX_CELLS = 64_000_000
MAX_YAML_BYTES = 64 * 1024
#: What a map image should be, for sentences that tell how to fix one.
GOOD_IMAGE = "a PGM, PNG or BMP (8- or 16-bit, grey or colour)"

#: File signatures, only to name what a file is in an error sentence.
_SIGNATURES = ((b"\x89PNG\r\n\x1a\n", "PNG"), (b"\xff\xd8\xff", "JPEG"), (b"GIF8", "GIF"),
               (b"II*\x00", "TIFF"), (b"MM\x00*", "TIFF"), (b"P1", "PBM"), (b"P4", "PBM"),
               (b"P2", "PGM"), (b"P5", "PGM"), (b"P3", "PPM"), (b"P6", "PPM"), (b"BM", "BMP"))


class MapFileError(AsibotError, ValueError):
    """A map that cannot be read: the sentence names the file and what to change in it."""


@dataclass(frozen=True)
class MapSettings:
    """The YAML's keys, checked; kept so a map can be written back the way it came."""

    image: str
    resolution: float
    origin: tuple[float, float, float]
    negate: bool
    occupied_thresh: float
    free_thresh: float
    mode: str = "trinary"


@dataclass(frozen=True)
class RosMap:
    """What map_server would publish: the values, with the settings and files they came from."""

    settings: MapSettings
    values: np.ndarray  # int8 (height, width); row 0 is the lowest y, as in nav_msgs/OccupancyGrid
    yaml_path: Path
    image_path: Path


@dataclass(frozen=True)
class MapImage:
    """A decoded image as map_server averages it: per pixel the sum of its colour channels (each
    on 0..255), how many colour channels there are, and its alpha on 0..255 (None: opaque)."""

    colour_sum: np.ndarray
    colours: int
    alpha: np.ndarray | None

    def grey(self, with_alpha: bool) -> np.ndarray:
        """The channels' mean (float64), alpha averaged in when asked and present."""
        if with_alpha and self.alpha is not None:
            return (self.colour_sum + self.alpha) / (self.colours + 1)
        return self.colour_sum / self.colours


# ------------------------------------------------------------------------------------ YAML

def _number(doc: Mapping[str, Any], key: str, where: str, lo: float, hi: float) -> float:
    v = doc[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
        raise MapFileError(f"{where}: {key} must be a number in [{lo:g}, {hi:g}]; got {quote(v)}.")
    return float(v)


def _mapping(raw: bytes, where: str) -> dict:
    """The YAML document; an image or other non-YAML given instead is named as such."""
    try:
        doc = yaml.safe_load(raw.decode("utf-8"))
    except (UnicodeDecodeError, yaml.YAMLError) as exc:
        doc, problem = None, ("not a text file; a map is given by its map_server YAML"
                              if isinstance(exc, UnicodeDecodeError) else f"not valid YAML ({str(exc).splitlines()[0]})")
    else:
        problem = "not a map_server YAML: it must be a mapping with " + ", ".join(REQUIRED)
    if isinstance(doc, dict):
        return doc
    kind = image_kind(raw)
    if kind is not None:
        raise MapFileError(f"{where} is a {kind} image; give the map's YAML file, which names the image.")
    raise MapFileError(f"{where} is {problem}.")


def parse_settings(raw: bytes, where: str, defaults: Mapping[str, Any] | None = None) -> MapSettings:
    """The checked settings of a map_server YAML; MapFileError naming the key otherwise.

    `defaults` fill keys the YAML leaves out, for readers laxer than map_server (which needs
    every key but `mode`)."""
    doc = {**(defaults or {}), **_mapping(raw, where)}
    missing = [k for k in REQUIRED if k not in doc]
    if missing:
        raise MapFileError(f"{where}: {', '.join(missing)} {'is' if len(missing) == 1 else 'are'} missing; "
                           f"a map_server YAML needs {', '.join(REQUIRED)}.")
    image = doc["image"]
    if not isinstance(image, str) or not image.strip() or "\x00" in image:
        raise MapFileError(f"{where}: image must be the image file's name; got {quote(image)}.")
    resolution = _number(doc, "resolution", where, 0.0, 100.0)
    if resolution <= 0:
        raise MapFileError(f"{where}: resolution must be positive (metres per pixel); got {resolution:g}.")
    origin = doc["origin"]
    if (not isinstance(origin, list) or len(origin) != 3
            or any(isinstance(o, bool) or not isinstance(o, (int, float)) or not math.isfinite(o) or abs(o) > 1e6
                   for o in origin)):
        raise MapFileError(f"{where}: origin must be [x, y, yaw], three finite numbers; got {quote(origin)}.")
    negate = doc["negate"]
    if negate not in (0, 1) or isinstance(negate, float):
        raise MapFileError(f"{where}: negate must be 0 or 1; got {quote(negate)}.")
    occ = _number(doc, "occupied_thresh", where, 0.0, 1.0)
    free = _number(doc, "free_thresh", where, 0.0, 1.0)
    if not free < occ:
        raise MapFileError(f"{where}: free_thresh ({free:g}) must be below occupied_thresh ({occ:g}).")
    mode = doc.get("mode", "trinary")
    if mode not in MODES:
        raise MapFileError(f"{where}: mode must be trinary, scale or raw; got {quote(mode)}.")
    return MapSettings(image=image, resolution=resolution, origin=(float(origin[0]), float(origin[1]), float(origin[2])),
                       negate=bool(negate), occupied_thresh=occ, free_thresh=free, mode=mode)


# ----------------------------------------------------------------------------------- image

def image_kind(data: bytes) -> str | None:
    """The image format `data` starts like ("PNG", "PGM"...), or None."""
    return next((kind for magic, kind in _SIGNATURES if data.startswith(magic)), None)


def _pnm_maxval(data: bytes) -> int | None:
    """The maxval of a PGM/PPM header, or None: OpenCV leaves binary and 16-bit samples on it."""
    if data[:2] not in (b"P2", b"P3", b"P5", b"P6"):
        return None
    fields: list[int] = []
    for line in data[2:256].split(b"\n"):
        fields += [int(t) for t in line.split(b"#")[0].split() if t.isdigit()]
        if len(fields) >= 3:
            return fields[2] or None
    return None


def _decode(data: bytes) -> np.ndarray | None:
    """cv2.imdecode without its log lines: the caller says what went wrong in a sentence."""
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error:
        return None
    finally:
        cv2.utils.logging.setLogLevel(level)


def _on_255(img: np.ndarray, data: bytes) -> np.ndarray:
    """Samples on 0..255 (float64), whatever the bit depth or PNM maxval."""
    maxval = _pnm_maxval(data)
    stretched = data[:2] in (b"P2", b"P3") and img.dtype == np.uint8  # OpenCV did it for ASCII 8-bit
    if maxval is not None and maxval not in (255, 65535) and not stretched:
        clipped = np.minimum(img.astype(np.uint32), maxval)
        if img.dtype == np.uint8:   # SDL_image's table, which map_server reads through
            return ((clipped * 255 + maxval // 2) // maxval).astype(np.float64)
        return clipped * (255.0 / maxval)
    return img.astype(np.float64) * (255.0 / 65535.0) if img.dtype == np.uint16 else img.astype(np.float64)


def decode_image(data: bytes, name: str) -> MapImage:
    """The image in `data` as map_server sees its pixels; MapFileError naming `name` otherwise."""
    if not data:
        raise MapFileError(f"{name} is empty; a map image is {GOOD_IMAGE}.")
    img = _decode(data)
    if img is None:
        kind = image_kind(data)
        if kind is None:
            raise MapFileError(f"{name} is not an image OpenCV can read; a map image is {GOOD_IMAGE}.")
        raise MapFileError(f"{name} looks like a {kind} image but cannot be decoded: it is truncated or corrupt. "
                           f"Save the map image again as {GOOD_IMAGE}.")
    if img.dtype not in (np.uint8, np.uint16):
        raise MapFileError(f"{name} has {img.dtype} samples; a map image is {GOOD_IMAGE}.")
    if img.shape[0] * img.shape[1] > MAX_CELLS:
        raise MapFileError(f"{name} is {img.shape[1]} x {img.shape[0]} pixels; a map has at most {MAX_CELLS} cells.")
    px = _on_255(img, data).reshape(img.shape[0], img.shape[1], -1)
    colours = 3 if px.shape[2] == 4 else px.shape[2]
    alpha = px[:, :, 3] if px.shape[2] == 4 else None
    if alpha is not None and image_kind(data) == "BMP" and not alpha.any():
        alpha = None   # a 32-bit BMP writer that left alpha unset: SDL reads it opaque
    return MapImage(px[:, :, :colours].sum(axis=2), colours, alpha)


# ------------------------------------------------------------------------ pixel -> value

def occupancy_values(grey: np.ndarray, mode: str, negate: bool, occupied_thresh: float, free_thresh: float,
                     transparent: np.ndarray | None = None) -> np.ndarray:
    """map_server's per-pixel rule, vectorised: int8 values in the order of `grey` (0..255)."""
    v = 255.0 - grey if negate else grey
    if mode == "raw":
        return v.astype(np.uint8).view(np.int8)
    occ = (255.0 - v) / 255.0
    if mode == "trinary":
        mid = np.full(grey.shape, -1, np.int16)
    else:
        mid = (1.0 + 98.0 * (occ - free_thresh) / (occupied_thresh - free_thresh)).astype(np.int16)
        if transparent is not None:
            mid[transparent] = -1
    return np.where(occ > occupied_thresh, 100, np.where(occ < free_thresh, 0, mid)).astype(np.int8)


def values_of(image: MapImage, settings: MapSettings) -> np.ndarray:
    """The image's values in grid order (row 0 = lowest y) under the YAML's settings."""
    grey = image.grey(with_alpha=settings.mode == "trinary")
    transparent = image.alpha < 1.0 if image.alpha is not None else None
    values = occupancy_values(grey, settings.mode, settings.negate, settings.occupied_thresh,
                              settings.free_thresh, transparent)
    return np.ascontiguousarray(np.flipud(values))


# ------------------------------------------------------------------------------------ file

def read_map(yaml_path: str | os.PathLike[str], defaults: Mapping[str, Any] | None = None) -> RosMap:
    """The map a map_server YAML describes; MapFileError with a sentence for anything wrong."""
    path = Path(yaml_path)
    try:
        size = path.stat().st_size
        if size > MAX_YAML_BYTES:
            raise MapFileError(f"{path} is {size} bytes: that is not a map_server YAML; give the map's YAML file.")
        raw = path.read_bytes()
    except OSError as exc:
        raise MapFileError(f"Cannot read the map file {path}: {exc.strerror or exc}.") from None
    settings = parse_settings(raw, str(path), defaults)
    image_path = path.parent / settings.image   # an absolute `image` replaces the folder
    try:
        data = image_path.read_bytes()
    except OSError as exc:
        raise MapFileError(f"{path} names the image {settings.image!r}, which cannot be read: "
                           f"{exc.strerror or exc}.") from None
    image = decode_image(data, f"{image_path} (the image of {path})")
    return RosMap(settings, values_of(image, settings), path, image_path)
