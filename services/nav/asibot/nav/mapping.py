"""Building the map of a new home from a drive: an occupancy grid with scan matching.

The carer drives the robot around (primitives or a joystick) while `Mapper.update(odom,
scan)` is fed each scan with the odometry pose where it was taken. The result, `to_grid()`,
is an `OccupancyGrid` that `mapfile.save_map` writes as a map_server map, on which AMCL,
the costmap and the planner then work.

- **Grid**: log-odds per cell at the map's resolution (5 cm), as gmapping and
  Probabilistic Robotics (table 9.2) keep it. Each integrated scan adds `hit` to the cell of
  every beam end and `miss` to every cell its beam passed through (at most once per cell per
  scan; the cell in front of a hit is left alone, so range noise does not eat walls). The
  cells a beam crosses are found by sampling every beam at half a cell (all beams at once,
  one (beams, samples) array; no loop per beam or per cell). REP 117 readings: NaN is
  unknown (the beam is left out), +inf or >= range_max is free up to the usable range
  `max_range` (gmapping's maxUrange) with no hit, and a hit beyond `max_range` only clears.
  The grid grows by `grow_margin` when a scan reaches past its edge.
- **Scan matching**: each new scan is matched against the map so far around the pose that
  odometry predicts (compose(last matched pose, odometry delta)): a correlative search
  (Olson 2009) over a window of x, y, theta, scored on a likelihood field of the map
  (exp(-d^2 / 2 sigma^2), d from OpenCV's distance transform to the nearest occupied cell),
  times a weak Gaussian prior on the distance from the prediction so that a corridor that
  says nothing along its length keeps the odometry. A coarse pass at whole cells and
  `theta_step`, then a fine pass at quarter steps with bilinear interpolation. A scan that
  matches poorly (too few hit beams, too little map, a low score) keeps the prediction.
- **When**: a scan is integrated only after the odometry moved `linear_update` or turned
  `angular_update` since the last one (gmapping's linearUpdate / angularUpdate), so a robot
  standing still does not pile up the same scan, and a map is not blurred by many copies.
- **Output**: ROS map_server thresholds on p = 1 - 1 / (1 + exp(l)): p > 0.65 occupied (100),
  p < 0.196 free (0), unknown (-1) otherwise, trimmed to the seen cells plus `trim_margin`.

Departures from gmapping: one pose estimate instead of a particle filter (a home is a few
rooms; the loop closes well enough when every scan is matched against the whole map so far),
so a very long corridor loop can still bend. Bad input (a NaN odometry pose, a scan whose
ranges are not one row of numbers) raises NavError with a sentence and changes nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from asibot.messages import LaserScan
from asibot.nav.errors import NavError
from asibot.nav.geometry import Pose, compose, relative, wrap
from asibot.nav.grid import FREE, OCCUPIED, UNKNOWN, GridInfo, OccupancyGrid
from asibot.nav.mapfile import SAVER_FREE, SAVER_OCCUPIED

#: Log-odds of map_server's (map_saver's) thresholds: above is occupied, below is free.
L_OCCUPIED = math.log(SAVER_OCCUPIED / (1.0 - SAVER_OCCUPIED))
L_FREE = math.log(SAVER_FREE / (1.0 - SAVER_FREE))


@dataclass(frozen=True)
class MapperParams:
    resolution: float = 0.05
    linear_update: float = 0.2         # m moved before the next scan is integrated (gmapping: 1.0)
    angular_update: float = 0.2        # rad turned before the next scan (gmapping: 0.5)
    max_range: float = 6.0             # m: beams are used up to here (gmapping's maxUrange)
    hit: float = 0.85                  # log-odds added at a beam's end (p 0.70)
    miss: float = -0.4                 # log-odds added along a beam (p 0.40)
    clamp: float = 5.0                 # log-odds kept in [-clamp, clamp], so a moved chair can leave
    grow_margin: float = 2.0           # m added around a scan that reaches past the grid
    trim_margin: int = 10              # unknown cells kept around the seen ones in `to_grid`
    match: bool = True                 # scan matching (off: the map is drawn at the odometry poses)
    search_xy: float = 0.20            # m either side of the predicted pose
    search_theta: float = 0.12         # rad either side
    theta_step: float = 0.015          # rad, coarse pass (0.1 m at 6 m: two cells)
    match_beams: int = 120             # hit beams used to match (evenly picked)
    sigma: float = 0.08                # m: the likelihood field's width
    prior_xy: float = 0.3              # m: std of the prior around the prediction
    prior_theta: float = 0.3           # rad
    min_beams: int = 20                # fewer hit beams: the prediction is kept
    min_map_cells: int = 100           # fewer occupied cells in the map: the prediction is kept
    min_score: float = 0.25            # mean field value of the best pose below this: the prediction is kept


@dataclass
class MapperStats:
    scans: int = 0          # integrated
    matched: int = 0        # of which corrected by matching
    last_shift: float = 0.0  # m the last match moved the predicted pose
    last_score: float = 0.0


def check_scan(scan: LaserScan) -> np.ndarray:
    """The ranges of a scan as float64, or NavError with a sentence when they cannot be used."""
    r = np.asarray(scan.ranges)
    if r.ndim != 1 or r.size < 2 or r.dtype.kind not in "fiu":
        raise NavError(f"A scan must be one row of at least two ranges (m); got an array of shape {r.shape} "
                       f"and type {r.dtype}; it was not used.")
    values = (scan.angle_min, scan.angle_increment, scan.range_min, scan.range_max)
    if not all(math.isfinite(v) for v in values) or scan.angle_increment == 0 or not 0 <= scan.range_min < scan.range_max:
        raise NavError("A scan needs finite angles, a non-zero angle increment and 0 <= range_min < range_max; "
                       f"got angle_min {scan.angle_min}, increment {scan.angle_increment}, range_min "
                       f"{scan.range_min}, range_max {scan.range_max}; it was not used.")
    return r.astype(np.float64)


def _bilinear(field: np.ndarray, fr: np.ndarray, fc: np.ndarray) -> np.ndarray:
    """field at fractional cell coordinates (row, col measured from cell centres); 0 outside."""
    h, w = field.shape
    r0, c0 = np.floor(fr).astype(np.int64), np.floor(fc).astype(np.int64)
    ar, ac = fr - r0, fc - c0
    ok = (r0 >= 0) & (r0 < h - 1) & (c0 >= 0) & (c0 < w - 1)
    r0, c0 = np.where(ok, r0, 0), np.where(ok, c0, 0)
    v = ((1 - ar) * ((1 - ac) * field[r0, c0] + ac * field[r0, c0 + 1])
         + ar * ((1 - ac) * field[r0 + 1, c0] + ac * field[r0 + 1, c0 + 1]))
    return np.where(ok, v, 0.0)


class Mapper:
    """An occupancy grid built from scans at odometry poses, corrected by scan matching.

    `start` is the robot's map pose when the odometry read `odom` (default: at the first scan);
    the map's frame is the one the robot believed in when mapping started."""

    def __init__(self, start: Pose = Pose(0.0, 0.0, 0.0), params: MapperParams = MapperParams(),
                 odom: Pose | None = None) -> None:
        if not all(math.isfinite(v) for v in (*start, *(odom or ()))):
            raise NavError(f"Mapping must start from a finite pose; got {tuple(start)} at odometry {odom}.")
        self.params = params
        self.res = params.resolution
        self.start = Pose(*start)
        self.stats = MapperStats()
        self._pose = self.start              # map pose at the last integrated scan
        self._odom = Pose(*odom) if odom is not None else None   # odometry pose at the last scan (or at start)
        # log-odds; cell [i, j] of the array is the global cell (i + r0, j + c0), whose lower-left
        # corner is at world ((j + c0) res, (i + r0) res)
        n = int(math.ceil((params.max_range + params.grow_margin) / self.res))
        gr, gc = int(math.floor(start.y / self.res)), int(math.floor(start.x / self.res))
        self.r0, self.c0 = gr - n, gc - n
        self.logodds = np.zeros((2 * n + 1, 2 * n + 1), np.float32)
        self._field: np.ndarray | None = None
        self._pad = int(math.ceil(params.search_xy / self.res)) + 1   # zero cells around the field

    # ---------------------------------------------------------------------------- queries

    @property
    def info(self) -> GridInfo:
        """The whole (untrimmed) grid's cells in the world."""
        h, w = self.logodds.shape
        return GridInfo(w, h, self.res, Pose(self.c0 * self.res, self.r0 * self.res, 0.0))

    def pose(self, odom: Pose) -> Pose:
        """The robot's map pose now: the last matched pose carried forward by odometry."""
        return self._pose if self._odom is None else compose(self._pose, relative(self._odom, odom))

    @property
    def area(self) -> float:
        """m^2 known (free or occupied) so far."""
        known = (self.logodds > L_OCCUPIED) | (self.logodds < L_FREE)
        return float(known.sum()) * self.res ** 2

    def summary(self) -> str:
        return f"{self.area:.1f} m\N{SUPERSCRIPT TWO} mapped from {self.stats.scans} scans"

    def to_grid(self) -> OccupancyGrid:
        """The map: 100 occupied, 0 free, -1 unknown (map_server's thresholds), trimmed to what
        was seen plus `trim_margin` cells."""
        lo = self.logodds
        data = np.where(lo > L_OCCUPIED, OCCUPIED, np.where(lo < L_FREE, FREE, UNKNOWN)).astype(np.int8)
        rows, cols = np.nonzero(data != UNKNOWN)
        if rows.size == 0:
            rows, cols = np.array([data.shape[0] // 2]), np.array([data.shape[1] // 2])
        m = self.params.trim_margin
        r_lo, r_hi = max(0, rows.min() - m), min(data.shape[0], rows.max() + m + 1)
        c_lo, c_hi = max(0, cols.min() - m), min(data.shape[1], cols.max() + m + 1)
        # the origin rounded to a micrometre: -12 * 0.05 is -0.6000000000000001, not for a YAML
        info = GridInfo(int(c_hi - c_lo), int(r_hi - r_lo), self.res,
                        Pose(round((self.c0 + c_lo) * self.res, 6), round((self.r0 + r_lo) * self.res, 6), 0.0))
        return OccupancyGrid(info, np.ascontiguousarray(data[r_lo:r_hi, c_lo:c_hi]))

    # ---------------------------------------------------------------------------- update

    def moved_enough(self, odom: Pose) -> bool:
        if self._odom is None or self.stats.scans == 0:
            return True
        d = relative(self._odom, odom)
        return math.hypot(d.x, d.y) >= self.params.linear_update or abs(d.theta) >= self.params.angular_update

    def update(self, odom: Pose, scan: LaserScan) -> bool:
        """Feed a scan and the odometry pose where it was taken; True when it was integrated
        (the first scan, then after the robot moved enough). NavError, changing nothing, for a
        NaN pose or a scan that cannot be used."""
        if not all(math.isfinite(v) for v in odom):
            raise NavError(f"The odometry pose is not finite: {tuple(odom)}; the scan was not mapped.")
        ranges = check_scan(scan)
        if not self.moved_enough(odom):
            return False
        odom = Pose(*odom)
        angles = scan.angle_min + scan.angle_increment * np.arange(ranges.size)
        valid = ~np.isnan(ranges) & (ranges >= scan.range_min)
        r, a = ranges[valid], angles[valid]
        hit = np.isfinite(r) & (r < scan.range_max) & (r <= self.params.max_range)
        r = np.minimum(np.where(np.isfinite(r), r, scan.range_max), min(scan.range_max, self.params.max_range))
        pose = self.pose(odom)
        if self.stats.scans and self.params.match:
            pose = self._match(pose, r[hit], a[hit])
        self._integrate(pose, r, a, hit)
        self._pose, self._odom = pose, odom
        self.stats.scans += 1
        return True

    # -------------------------------------------------------------------------- the grid

    def _cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Array (row, col) of world points (may lie outside the array)."""
        return (np.floor(y / self.res).astype(np.int64) - self.r0, np.floor(x / self.res).astype(np.int64) - self.c0)

    def _grow(self, x: np.ndarray, y: np.ndarray) -> None:
        """Pad the grid so that every point lies inside it, with `grow_margin` to spare."""
        rows, cols = self._cells(x, y)
        h, w = self.logodds.shape
        m = int(math.ceil(self.params.grow_margin / self.res))
        lo_r, hi_r, lo_c, hi_c = int(rows.min()), int(rows.max()), int(cols.min()), int(cols.max())
        pad = ((m - lo_r if lo_r < 0 else 0, hi_r - h + 1 + m if hi_r >= h else 0),
               (m - lo_c if lo_c < 0 else 0, hi_c - w + 1 + m if hi_c >= w else 0))
        if any(p for side in pad for p in side):
            self.logodds = np.pad(self.logodds, pad)
            self.r0 -= pad[0][0]
            self.c0 -= pad[1][0]

    def _integrate(self, pose: Pose, r: np.ndarray, a: np.ndarray, hit: np.ndarray) -> None:
        p = self.params
        th = pose.theta + a
        cos, sin = np.cos(th), np.sin(th)
        self._grow(np.r_[pose.x + r * cos, pose.x], np.r_[pose.y + r * sin, pose.y])
        lo = self.logodds
        h, w = lo.shape
        # free: samples every half cell, up to the end of a free beam and to a cell short of a hit
        step = 0.5 * self.res
        reach = np.where(hit, r - self.res, r)
        t = np.arange(int(math.ceil(max(float(reach.max(initial=0.0)), 0.0) / step)) + 1) * step
        along = t[None, :] <= reach[:, None]
        rows, cols = self._cells(pose.x + cos[:, None] * t[None, :], pose.y + sin[:, None] * t[None, :])
        touched = np.zeros(h * w, bool)
        touched[(rows * w + cols)[along]] = True
        hr, hc = self._cells(pose.x + r[hit] * cos[hit], pose.y + r[hit] * sin[hit])
        ends = hr * w + hc
        touched[ends] = False
        flat = lo.reshape(-1)
        free = np.flatnonzero(touched)
        flat[free] += p.miss
        ends = np.unique(ends)
        flat[ends] += p.hit
        both = np.r_[free, ends]
        flat[both] = np.clip(flat[both], -p.clamp, p.clamp)
        self._field = None

    # ------------------------------------------------------------------------- matching

    def _likelihood_field(self) -> np.ndarray:
        """exp(-d^2 / 2 sigma^2) per cell, d the distance to the nearest occupied cell, with a
        border of `_pad` zero cells, so that the coarse search never indexes outside it."""
        if self._field is None:
            occupied = self.logodds > L_OCCUPIED
            d = cv2.distanceTransform((~occupied).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE) * self.res
            self._field = np.pad(np.exp(-(d * d) / (2.0 * self.params.sigma ** 2)).astype(np.float32), self._pad)
        return self._field

    def _prior(self, dx: np.ndarray, dy: np.ndarray, dth: np.ndarray) -> np.ndarray:
        p = self.params
        return np.exp(-0.5 * ((dx * dx + dy * dy) / p.prior_xy ** 2 + dth * dth / p.prior_theta ** 2))

    def _coarse(self, predicted: Pose, bx: np.ndarray, by: np.ndarray) -> Pose:
        """The best pose on the whole-cell, `theta_step` lattice around `predicted`: for each
        heading the beam ends fall in cells, and a shift by whole cells is an index offset, so
        the lattice is one (headings, shifts, beams) gather."""
        p, field, k = self.params, self._likelihood_field(), self._pad - 1
        h, w = field.shape
        n = int(round(p.search_theta / p.theta_step))
        dth = np.arange(-n, n + 1) * p.theta_step
        c, s = np.cos(predicted.theta + dth)[:, None], np.sin(predicted.theta + dth)[:, None]
        rows, cols = self._cells(predicted.x + c * bx - s * by, predicted.y + s * bx + c * by)
        rows, cols = rows + self._pad, cols + self._pad
        inside = (rows >= k) & (rows < h - k) & (cols >= k) & (cols < w - k)
        flat = np.where(inside, rows * w + cols, k * w + k)
        shift = np.arange(-k, k + 1)
        offsets = (shift[:, None] * w + shift[None, :]).ravel()          # (row shift, col shift) row-major
        fit = (field.ravel()[flat[:, None, :] + offsets[None, :, None]] * inside[:, None, :]).mean(axis=2)
        dr, dc = np.meshgrid(shift * self.res, shift * self.res, indexing="ij")
        score = fit * self._prior(dc.ravel()[None, :], dr.ravel()[None, :], dth[:, None])
        t, o = np.unravel_index(int(np.argmax(score)), score.shape)
        return Pose(predicted.x + float(dc.ravel()[o]), predicted.y + float(dr.ravel()[o]), predicted.theta + float(dth[t]))

    def _fine(self, around: Pose, predicted: Pose, bx: np.ndarray, by: np.ndarray) -> tuple[Pose, float]:
        """The best pose within half a lattice step of `around`, at quarter steps, on the
        bilinearly interpolated field; and its fit (mean field value of the beam ends)."""
        p, q = self.params, np.arange(-2, 3) / 4.0
        gx, gy, gt = np.meshgrid(around.x + q * self.res, around.y + q * self.res, around.theta + q * p.theta_step,
                                 indexing="ij")
        x, y, th = gx.ravel()[:, None], gy.ravel()[:, None], gt.ravel()[:, None]
        c, s = np.cos(th), np.sin(th)
        fr = (y + s * bx + c * by) / self.res - self.r0 + self._pad - 0.5
        fc = (x + c * bx - s * by) / self.res - self.c0 + self._pad - 0.5
        fit = _bilinear(self._likelihood_field(), fr, fc).mean(axis=1)
        score = fit * self._prior(x[:, 0] - predicted.x, y[:, 0] - predicted.y, th[:, 0] - predicted.theta)
        i = int(np.argmax(score))
        return Pose(float(x[i, 0]), float(y[i, 0]), wrap(float(th[i, 0]))), float(fit[i])

    def _match(self, predicted: Pose, r: np.ndarray, a: np.ndarray) -> Pose:
        """The pose near `predicted` where the hit beams (r, a) best fit the map so far."""
        p = self.params
        self.stats.last_shift, self.stats.last_score = 0.0, 0.0
        if r.size < p.min_beams or int((self.logodds > L_OCCUPIED).sum()) < p.min_map_cells:
            return predicted
        pick = np.linspace(0, r.size - 1, min(p.match_beams, r.size)).round().astype(np.int64)
        bx, by = r[pick] * np.cos(a[pick]), r[pick] * np.sin(a[pick])
        best, fit = self._fine(self._coarse(predicted, bx, by), predicted, bx, by)
        self.stats.last_score = fit
        if fit < p.min_score:
            return predicted
        self.stats.matched += 1
        self.stats.last_shift = predicted.distance(best)
        return best
