"""One depth image -> the nearest obstacle per bearing, with depthimage_to_laserscan's semantics
but a band of heights instead of a band of rows.

depthimage_to_laserscan (docs/reference/navigation.md, 'Depth image to laser scan') keeps,
per image column, the nearest valid return of `scan_height` rows around cy: angles from the
intrinsics, `range_min`/`range_max` on the distance in the camera's x-z plane, a finite
in-range value beating no value. Its known failure (#69) is that a low obstacle, a shoe or a
table leg, lies below those rows and is never seen; pointcloud_to_laserscan's is cost (a
tf-transformed cloud per frame) and a `min_height` default that silently drops points at the
frame's z = 0 (#84).

Here every pixel counts whose point lies between `min_height` and `max_height` above the
floor in the robot's base frame (camera pose from CameraInfo), so the floor is never an
obstacle and anything taller than `min_height` is, wherever it is in the image. Per pixel,
height and horizontal distance are linear in the depth z (rays.py), so the band and the range
limits become a per-pixel interval [zlo, zhi] computed once per CameraInfo; a frame then costs
two comparisons, a masked minimum down the columns and a few per-column operations:

- "columns" mode, when the camera is level (its image columns are vertical planes, as the
  sim's front and back cameras): the nearest return of a column is its smallest z, at the
  column's one bearing. This is depthimage_to_laserscan's loop, vectorised.
- "bins" mode, for a pitched or rolled camera, whose columns sweep several bearings: pixels
  are grouped once by bearing (bins of `bin_width`), and a frame is a gather and a
  `np.minimum.reduceat` over those groups.

`range_min`/`range_max` apply to the horizontal distance from the camera (the sensor's blind
zone and reach); the merged scan measures from the base centre (merge.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import numpy as np

from asibot.perception.errors import BadInput
from asibot.perception.rays import CameraRays

@dataclass(frozen=True)
class BandConfig:
    """What counts as an obstacle: a return between two heights above the floor, within reach."""

    min_height: float = 0.03
    """m above the floor; above the depth noise on the floor at range_max, below a shoe."""
    max_height: float = 1.0
    """m; the robot with its arm fits under nothing lower than this."""
    range_min: float = 0.1
    """m, horizontal from the camera: nearer returns are the sensor's blind zone."""
    range_max: float = 8.0
    """m, horizontal from the camera (the sim's depth cameras report nothing beyond 8 m)."""
    bin_width: float = math.radians(0.25)
    """rad: bearing resolution of a pitched camera's scan ("bins" mode)."""

    def check(self) -> None:
        vals = (self.min_height, self.max_height, self.range_min, self.range_max, self.bin_width)
        if not all(math.isfinite(v) for v in vals):
            raise ValueError("the height band, the ranges and the bin width must be finite numbers")
        if not self.min_height < self.max_height:
            raise ValueError(f"the height band is empty: min height {self.min_height} m must be below "
                             f"max height {self.max_height} m")
        if not 0 < self.range_min < self.range_max:
            raise ValueError(f"ranges must satisfy 0 < range min ({self.range_min} m) < range max "
                             f"({self.range_max} m)")
        if not 0 < self.bin_width <= math.radians(5):
            raise ValueError("the bin width must be between 0 and 5 degrees")


@dataclass(frozen=True)
class CameraScan:
    """The nearest return per bearing of one camera at one instant, in the base frame.

    `bearing[i]` is a base-frame direction from the camera's optical centre `origin` (x, y)
    and `rho[i]` the horizontal distance along it to the nearest return (inf: none in the
    band). `fov` is the horizontal field of view as (centre bearing, lowest and highest offset
    from it), rad: merge.py derives from it which beams the camera watches.
    """

    origin: np.ndarray
    bearing: np.ndarray
    rho: np.ndarray
    fov: tuple[float, float, float]

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """Base-frame x, y of the returns (bearings without one are left out)."""
        hit = np.isfinite(self.rho)
        r, b = self.rho[hit].astype(np.float64), self.bearing[hit]
        return self.origin[0] + r * np.cos(b), self.origin[1] + r * np.sin(b)


def _circular_spread(angles: np.ndarray, ok: np.ndarray, axis: int) -> np.ndarray:
    """Largest deviation of `angles` (where `ok`) from their circular mean along `axis`."""
    c = np.where(ok, np.cos(angles), 0.0).sum(axis=axis, keepdims=True)
    s = np.where(ok, np.sin(angles), 0.0).sum(axis=axis, keepdims=True)
    mean = np.arctan2(s, c)
    dev = np.abs(np.angle(np.exp(1j * (angles - mean))))
    return np.where(ok, dev, 0.0).max(axis=axis)


class DepthToScan:
    """Converts the depth images of one camera (one CameraInfo) into CameraScans."""

    def __init__(self, rays: CameraRays, config: BandConfig = BandConfig()) -> None:
        config.check()
        self.rays, self.config = rays, config
        dx, dy, dz = rays.direction
        hn = np.hypot(dx, dy)                        # horizontal distance per metre of z
        tz = rays.position[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            # range limits on rho = z * hn
            lo = np.where(hn > 1e-6, config.range_min / hn, np.inf)
            hi = np.where(hn > 1e-6, config.range_max / hn, -np.inf)
            # height band on h = tz + z * dz
            a, b = (config.min_height - tz) / dz, (config.max_height - tz) / dz
            band_lo = np.where(dz > 0, a, np.where(dz < 0, b, -np.inf))
            band_hi = np.where(dz > 0, b, np.where(dz < 0, a, np.inf))
            if not config.min_height <= tz <= config.max_height:  # level rays stay out of the band
                band_lo = np.where(dz == 0, np.inf, band_lo)
        zlo = np.maximum(np.maximum(lo, band_lo), 1e-6)  # > 0: a 0 ("no return") is never valid
        zhi = np.minimum(hi, band_hi)
        usable = zlo <= zhi
        zlo = np.where(usable, zlo, np.inf)
        zhi = np.where(usable, zhi, -np.inf)
        bearing = np.arctan2(dy, dx)
        # Level camera: along each column the bearing and the horizontal scale hn are those of
        # the middle row, so the smallest z of a column is its nearest return.
        row = int(np.clip(round(rays.lens.cy), 0, rays.lens.height - 1))
        spread = _circular_spread(bearing, usable, axis=0)
        hn_dev = np.where(usable, np.abs(hn - hn[row]) / np.maximum(hn[row], 1e-9), 0.0)
        level = bool(np.all(spread <= config.bin_width / 2) and np.all(hn_dev <= 1e-4))
        self.mode = "columns" if level else "bins"
        self.origin = rays.position[:2].copy()
        if level:
            self._zlo, self._zhi = zlo.astype(np.float32), zhi.astype(np.float32)
            self._bearing = bearing[row].copy()
            self._hn = hn[row].astype(np.float32)
            # One axis of a 2-D mask: an array, which the stubs cannot tell from a scalar.
            self._cols_used = cast(np.ndarray, usable.any(axis=0))
        else:
            self._setup_bins(zlo, zhi, hn, bearing, usable)
        used = self._bearing[self._bin_used()]
        centre = math.atan2(np.sin(used).sum(), np.cos(used).sum()) if used.size else 0.0
        rel = np.angle(np.exp(1j * (used - centre)))
        self.fov = (centre, float(rel.min()), float(rel.max())) if used.size else (0.0, 0.0, -1.0)

    def _setup_bins(self, zlo, zhi, hn, bearing, usable) -> None:
        flat = np.flatnonzero(usable.ravel())
        width = self.config.bin_width
        # bins start at the smallest bearing, unwrapped around the camera's mean direction
        mean = math.atan2(np.sin(bearing.ravel()[flat]).sum(), np.cos(bearing.ravel()[flat]).sum())
        rel = np.angle(np.exp(1j * (bearing.ravel()[flat] - mean)))
        start = rel.min() if flat.size else 0.0
        idx = ((rel - start) / width).astype(np.int64)
        order = np.argsort(idx, kind="stable")
        self._order = flat[order]
        idx = idx[order]
        self._starts = np.flatnonzero(np.r_[True, idx[1:] != idx[:-1]]) if flat.size else np.zeros(0, np.int64)
        bins = idx[self._starts]
        self._bearing = mean + start + (bins + 0.5) * width
        self._zlo = zlo.ravel()[self._order].astype(np.float32)
        self._zhi = zhi.ravel()[self._order].astype(np.float32)
        self._hn = hn.ravel()[self._order].astype(np.float32)

    def _bin_used(self) -> np.ndarray:
        return self._cols_used if self.mode == "columns" else np.ones(len(self._bearing), bool)

    # ------------------------------------------------------------------ per frame
    def convert(self, depth: np.ndarray, name: str = "the camera") -> CameraScan:
        """The nearest in-band return per bearing of one depth image (H x W metres, 0 = none).
        Raises BadInput (nothing converted) for a frame that is not a valid depth image of
        this camera."""
        depth = self.rays.check_depth(depth, name)
        if self.mode == "columns":
            valid = (depth >= self._zlo) & (depth <= self._zhi)
            zmin = np.min(depth, axis=0, where=valid, initial=np.inf)
            rho = zmin * self._hn
            keep = self._cols_used
            return CameraScan(self.origin, self._bearing[keep], rho[keep], self.fov)
        if self._order.size == 0:
            return CameraScan(self.origin, self._bearing, np.zeros(0, np.float32), self.fov)
        z = depth.ravel()[self._order]
        valid = (z >= self._zlo) & (z <= self._zhi)
        rho = np.where(valid, z * self._hn, np.float32(np.inf))
        return CameraScan(self.origin, self._bearing, np.minimum.reduceat(rho, self._starts), self.fov)


def centre_rows(depth: np.ndarray, rays: CameraRays, scan_height: int = 1, range_min: float = 0.45,
                range_max: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """depthimage_to_laserscan itself, as the reference: (angles, ranges) in the camera's frame
    (x forward, angles counter-clockwise, one per column, left of the image = largest angle)
    from the `scan_height` rows around cy; r = hypot(x, z), NaN where no valid return."""
    lens = rays.lens
    if scan_height < 1 or scan_height // 2 > lens.cy or scan_height // 2 > lens.height - lens.cy:
        raise BadInput(f"scan_height {scan_height} does not fit around cy = {lens.cy} in a "
                       f"{lens.height}-row image.")
    top = int(lens.cy - scan_height // 2)
    a = (np.arange(lens.width) - lens.cx) / lens.fx
    band = depth[top:top + scan_height].astype(np.float32)
    r = band * np.sqrt(1 + a * a).astype(np.float32)
    ok = (band > 0) & (r >= range_min) & (r <= range_max)
    ranges = np.min(r, axis=0, where=ok, initial=np.inf)
    ranges[~ok.any(axis=0)] = np.nan
    return -np.arctan(a), ranges
