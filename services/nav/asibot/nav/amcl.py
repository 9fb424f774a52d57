"""AMCL: Monte Carlo localisation on the map, as ROS's amcl does it, vectorised with numpy.

Facts in docs/reference/navigation.md, 'AMCL' (amcl pf.c, amcl_laser.cpp, amcl_odom.cpp):

- Motion: the "diff-corrected" odometry model: the odometry delta is split into rot1,
  trans, rot2; each particle gets them with Gaussian noise whose *standard deviation* is
  sqrt(a1 rot^2 + a2 trans^2) etc. (the legacy "diff" model passed variances as sigmas, one
  cause of the "AMCL jumps while rotating" reports). Noise terms use min(|d|, |d - pi|), so
  driving backwards is not mistaken for a half turn.
- Sensor: the likelihood field. The distance from every cell to the nearest occupied cell is
  computed once (OpenCV's distance transform), and turned, per scan range_max, into a
  per-cell table of pz = z_hit exp(-d^2 / 2 sigma^2) + z_rand / range_max; 2000 particles x
  60 beams is one (2000, 60) gather, no loop. Two of amcl's models: "likelihood_field"
  multiplies a weight by 1 + sum(pz^3) (amcl's default ad-hoc cubic sum, so flat that a wrong
  pose scores only ~1.5 times lower than the right one and relocalising takes minutes), and
  "likelihood_field_prob" (the default here) by the product of pz, with amcl's beam skipping
  (a beam whose end fewer than 30 % of the particles put near a wall is an unmapped obstacle
  and is left out, unless that would leave out more than 90 % of them). amcl skips only once
  converged (every particle within 0.5 m); here also while the heaviest cluster is tight,
  since right after an injection the random particles make "converged" false exactly when
  a box that is not on the map would otherwise pull the estimate away.
- Resampling is KLD-adaptive: particles are drawn until their count exceeds
  ceil((k-1)/(2 kld_err) (1 - 2/(9(k-1)) + sqrt(2/(9(k-1))) kld_z)^3), k being the number of
  occupied 0.5 m x 0.5 m x 10 deg bins, clamped to [min, max]; kld_z is used as it is (0.99),
  as amcl does. Drawing all max_particles at once and cutting at the first count past the
  limit gives the same set as amcl's one-by-one loop. One deliberate difference: amcl returns
  max_particles when k = 1 (every particle in one bin, i.e. perfectly converged); here that
  gives min_particles.
- Recovery: augmented MCL. w_slow and w_fast follow the average likelihood with alpha_slow
  and alpha_fast; each resampled particle is replaced by a uniformly random free-space pose
  with probability max(0, 1 - w_fast / w_slow). Three deliberate differences from amcl, each
  because amcl's version stops a kidnapped robot from recovering: (1) the average is the
  particles' weighted mean likelihood per used beam, where amcl divides the weight sum by the
  particle count, so it drops whenever KLD adds particles, and moves with how many beams
  happen to hit something; (2) the averages start when the filter first localises (heaviest
  cluster tighter than `localised_std`), not from the spread-out initial cloud, which would
  set w_slow so low that nothing ever looks worse; (3) they are not reset after an injection
  (amcl's reset makes it inject once and stop); Probabilistic Robotics table 8.3 has no
  reset either. The injected share is capped by `max_injection`, so a crowd standing in
  front of the laser cannot scatter the whole filter.
- Leaps: amcl believes its heaviest cluster wherever it lands; here a tight estimate far from
  where odometry carried the last trusted one is held off (`leap_dist`, `holding`): believed
  after half a turn if it stayed where odometry put it and fits, else searched for as after a
  global spread.
- The filter updates only after the odometry moved update_min_d on x or y or update_min_a
  in heading; between updates, `pose(odom)` carries the last estimate forward by odometry
  (amcl's map->odom transform).
- The estimate is the weighted mean of the heaviest cluster (particles in connected 0.5 m
  bins, counting only bins that hold weight), with its covariance, taken from the weighted set before resampling (amcl takes it
  after, when the injected random poses weigh as much as the rest); "converged" is amcl's:
  every particle within 0.5 m of the mean.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from asibot.messages import LaserScan
from asibot.nav.errors import NavError
from asibot.nav.geometry import Pose, compose, relative, wrap, wrap_array
from asibot.nav.grid import OccupancyGrid


@dataclass(frozen=True)
class AmclParams:
    min_particles: int = 500
    max_particles: int = 2000
    kld_err: float = 0.05
    kld_z: float = 0.99
    alpha1: float = 0.2   # rotation noise from rotation
    alpha2: float = 0.2   # rotation noise from translation
    alpha3: float = 0.2   # translation noise from translation
    alpha4: float = 0.2   # translation noise from rotation
    #: "likelihood_field" (amcl's default: 1 + sum of pz^3) or "likelihood_field_prob" (the
    #: product of pz over beams, with amcl's beam skipping): sharper, relocalises much faster.
    laser_model: str = "likelihood_field_prob"
    beam_skip_distance: float = 0.5
    beam_skip_threshold: float = 0.3
    beam_skip_error_threshold: float = 0.9
    z_hit: float = 0.95
    z_rand: float = 0.05
    sigma_hit: float = 0.2
    max_beams: int = 60
    likelihood_max_dist: float = 2.0
    update_min_d: float = 0.2          # p2os amcl.launch
    update_min_a: float = 0.2          # nav2 (ROS 1: pi/6)
    resample_interval: int = 1
    recovery_alpha_slow: float = 0.001
    recovery_alpha_fast: float = 0.1
    max_injection: float = 0.5
    #: the recovery averages start once the heaviest cluster's std (m, and rad) is below this
    localised_std: float = 0.35
    #: initial covariance diagonal: amcl's initial_cov_xx, _yy (0.5^2) and _aa ((pi/12)^2)
    initial_cov: tuple[float, float, float] = (0.25, 0.25, (math.pi / 12) ** 2)
    converged_dist: float = 0.5
    bin_xy: float = 0.5
    bin_theta: float = math.radians(10.0)
    #: a 0.5 m bin joins the estimate's clusters when it holds at least this share of the
    #: heaviest bin's weight
    cluster_min_weight: float = 0.01
    #: A global spread searches until it has made this many updates (each after moving
    #: update_min_d or update_min_a: a turn in place makes about 31) and the scans fit its
    #: estimate (`fit`, per beam) at least `search_fit` times as well as they fitted while it
    #: was localised before (the slow average w_slow), or `fit_floor` when it never was. A
    #: camera's scan fits where the robot is about 0.72 in the sim, a 360 deg laser 0.94 in
    #: the tests' tiny sim and 0.67 at a place 7 m away that looks alike. Until then it is not
    #: localised: one scan can single out a tight, wrong cluster.
    global_min_updates: int = 30
    search_fit: float = 0.85
    fit_floor: float = 0.6
    #: while searching, each scan's log-likelihood is scaled by this: a product over beams is so
    #: sharp that the first scan after a global spread kills every other place that looks
    #: alike, before a turn in place has shown what tells them apart
    search_temper: float = 0.1
    #: particles while searching (spread over the whole map, and KLD's bound until found). With
    #: 2000 over the apartment a turn in place settled metres off in 8 % of random starts in the
    #: tests' sim (no particle near the truth, a look-alike place fitting best); with 10000, in
    #: none of 200, at 55 ms an update while the cloud is wide (tests/nav/test_lost.py)
    search_particles: int = 10000
    #: A tight estimate that lands further than `leap_dist` (m, plus `leap_per_m` per metre
    #: driven) or `leap_angle` (rad, plus `leap_per_rad` per radian turned) from where odometry
    #: carried the last trusted one is a leap: a place that looks alike, or the robot carried
    #: off. Near a box that is not on the map, random guesses that one scan favoured once took a
    #: robot at the sofa for one 9 m away, "localised". A leap is not believed: the pose is the
    #: trusted one carried by odometry (`holding`), and a share `hold_share` of each resampled
    #: set is drawn around it, so the scans can bring the estimate back. After `hold_m` metres or
    #: `hold_rad` radians without that, the leapt estimate is believed if odometry explained it
    #: for the last `leap_confirm_updates` updates and the scans fit it as well as before
    #: (`search_fit`): the robot was carried off. Otherwise the filter searches as after a
    #: global spread.
    leap_dist: float = 1.0
    leap_per_m: float = 0.1
    leap_angle: float = 0.6
    leap_per_rad: float = 0.1
    hold_m: float = 1.0
    hold_rad: float = math.pi
    hold_share: float = 0.5
    leap_confirm_updates: int = 8
    #: the spread (m, m, rad) of the poses drawn around the held pose
    hold_std: tuple[float, float, float] = (0.1, 0.1, 0.05)


@dataclass
class Estimate:
    pose: Pose
    covariance: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    converged: bool = False
    particles: int = 0
    #: the heaviest cluster's share of the weight: low while other places explain the scans too
    share: float = 1.0

    @property
    def std_xy(self) -> float:
        return float(math.sqrt(max(0.0, self.covariance[0, 0] + self.covariance[1, 1])))

    @property
    def std_theta(self) -> float:
        return float(math.sqrt(max(0.0, self.covariance[2, 2])))

    def within(self, std: float) -> bool:
        """Whether the heaviest cluster is tighter than `std` (m, and rad)."""
        return self.std_xy < std and self.std_theta < std


@dataclass
class _Trusted:
    """The last estimate the filter trusted, the odometry then, and what was driven since."""
    pose: Pose
    odom: Pose
    metres: float = 0.0
    radians: float = 0.0

    def carried(self, odom: Pose) -> Pose:
        """Where odometry says the robot is now, from the trusted pose."""
        return compose(self.pose, relative(self.odom, odom))


def kld_limit(k: np.ndarray, err: float, z: float, lo: int, hi: int) -> np.ndarray:
    """amcl's pf_resample_limit for bin counts k, clamped to [lo, hi] (k <= 1 gives lo)."""
    k = np.asarray(k, np.float64)
    km1 = np.maximum(k - 1.0, 1.0)
    b = 2.0 / (9.0 * km1)
    x = 1.0 - b + np.sqrt(b) * z
    n = np.ceil(km1 / (2.0 * err) * x ** 3)
    n = np.where(k <= 1, lo, n)
    return np.clip(n, lo, hi).astype(np.int64)


class Amcl:
    def __init__(self, grid: OccupancyGrid, params: AmclParams = AmclParams(), seed: int | None = None) -> None:
        if not 0 < params.min_particles <= params.max_particles:
            raise ValueError("min_particles must be positive and at most max_particles")
        self.params = params
        self.info = grid.info
        self.rng = np.random.default_rng(seed)
        occupied = grid.occupied
        dist = cv2.distanceTransform((~occupied).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        self.distance = np.minimum(dist * self.info.resolution, params.likelihood_max_dist).astype(np.float32)
        fr, fc = np.nonzero(grid.free)
        if fr.size == 0:
            raise NavError("The map has no free cell: the robot cannot be anywhere on it.")
        self._free = np.c_[self.info.to_world(fr, fc)]
        self._table_key: float | None = None
        self._table: np.ndarray = np.zeros(0)   # float64, as the pz table that replaces it
        self.poses = np.zeros((0, 3))
        self.weights = np.zeros(0)
        self.w_slow = self.w_fast = 0.0
        self._averaging = False
        self._odom: Pose | None = None       # odometry at the last filter update
        self._force = False
        self._updates = 0
        self._searching = False      # looking everywhere since a global spread
        self._search_updates = 0     # updates it still needs
        self._fit_needed = 0.0       # the fit that ends it
        self.fit = 0.0               # the last scan's fit, per beam (see search_fit)
        self.estimate: Estimate | None = None
        self._trusted: _Trusted | None = None
        self._holding = False        # a leap not believed: the pose is the trusted one, carried
        self._held_from = (0.0, 0.0)  # the trusted one's metres and radians when the hold began
        self._leapt: _Trusted | None = None   # the last tight estimate while holding
        self._leapt_updates = 0                # updates since then that odometry explained
        #: leaps not believed since the start (see leap_dist)
        self.leaps = 0

    # --------------------------------------------------------------------- initialising

    def set_pose(self, pose: Pose, cov: tuple[float, float, float] | None = None) -> None:
        """Start from a known pose (the charging station, or the user's "I am here")."""
        if not all(math.isfinite(v) for v in pose):
            raise NavError(f"The initial pose must be three finite numbers; got {tuple(pose)}.")
        if not self.info.contains(pose.x, pose.y):
            raise NavError(f"The initial pose ({pose.x:.2f}, {pose.y:.2f}) is outside the map ({self.info.bounds()}).")
        cxx, cyy, caa = cov if cov is not None else self.params.initial_cov
        if not all(math.isfinite(v) and v >= 0 for v in (cxx, cyy, caa)):
            raise NavError("The initial covariance must be three finite, non-negative variances (m^2, m^2, rad^2).")
        n = self.params.max_particles
        noise = self.rng.standard_normal((n, 3)) * np.sqrt([cxx, cyy, caa])
        self.poses = np.c_[pose.x + noise[:, 0], pose.y + noise[:, 1], wrap_array(pose.theta + noise[:, 2])]
        self.weights = np.full(n, 1.0 / n)
        # `pose` is where the robot is now, whatever the odometry said before: the next reading
        # is the new reference (a base driver that restarted, or a sim reset, zeroes its
        # odometry; the jump must not carry the new pose across the map)
        self._odom = None
        self._restart()

    def global_localization(self) -> None:
        """Spread `search_particles` uniformly over the free space (amcl's global_localization)."""
        self.poses = self._random_poses(self.params.search_particles)
        self.weights = np.full(len(self.poses), 1.0 / len(self.poses))
        typical = self.w_slow
        self._restart()
        self._search(typical)

    def _search(self, typical: float) -> None:
        """Trust no estimate until `global_min_updates` updates and a fit near `typical` (the
        scans' fit while localised before; 0 when it never was)."""
        self._searching = True
        self._trusted, self._holding, self._leapt = None, False, None
        self._search_updates = self.params.global_min_updates
        self._fit_needed = self.params.search_fit * typical if typical > 0 else self.params.fit_floor

    @property
    def holding(self) -> bool:
        """A leap was not believed (see `leap_dist`): the pose is the last trusted one, carried
        by odometry, until the scans agree again or `hold_m` / `hold_rad` run out."""
        return self._holding

    @property
    def searching(self) -> bool:
        """Still looking everywhere since a global spread (or a leap held too long): too few
        updates, or scans that do not fit the estimate, to trust it."""
        return self._searching

    def odometry_restarted(self) -> None:
        """The odometry started again (a base driver or the sim restarted): the next reading is
        the new reference, and the step from the old one is not the robot's motion."""
        self._odom = None
        self._trusted, self._holding, self._leapt = None, False, None

    def _restart(self) -> None:
        self._searching = False
        self._trusted, self._holding, self._leapt = None, False, None
        self.w_slow = self.w_fast = 0.0
        self._averaging = False
        self._force = True
        self._updates = 0
        self.estimate = self._cluster_estimate()

    def _random_poses(self, n: int) -> np.ndarray:
        i = self.rng.integers(0, len(self._free), n)
        jitter = (self.rng.random((n, 2)) - 0.5) * self.info.resolution
        return np.c_[self._free[i] + jitter, self.rng.uniform(-math.pi, math.pi, n)]

    # -------------------------------------------------------------------------- updates

    def moved_enough(self, odom: Pose) -> bool:
        if self._odom is None:
            return True
        # amcl compares the odometry delta per axis
        dx, dy, dth = odom.x - self._odom.x, odom.y - self._odom.y, wrap(odom.theta - self._odom.theta)
        return (abs(dx) > self.params.update_min_d or abs(dy) > self.params.update_min_d
                or abs(dth) > self.params.update_min_a)

    def update(self, odom: Pose, scan: LaserScan | None) -> bool:
        """Feed odometry (and the scan taken there); True when the filter updated."""
        if self.estimate is None:
            raise NavError("Localisation has no starting point yet: set the initial pose or start "
                           "global localisation first.")
        if not all(math.isfinite(v) for v in odom):
            raise NavError(f"The odometry pose is not finite: {tuple(odom)}; it was not used.")
        if self._odom is None:
            self._odom = odom
        if not (self._force or self.moved_enough(odom)):
            return False
        self.motion(self._odom, odom)
        self._drove(self._odom, odom)
        self._odom = odom
        resample = False
        if scan is not None and len(scan.ranges):
            self.sensor(scan)
            self._updates += 1
            if self._searching:
                self._search_updates = max(0, self._search_updates - 1)
                self._searching = self._search_updates > 0 or self.fit < self._fit_needed
            resample = self._updates % self.params.resample_interval == 0
        self._force = False
        # The estimate is taken from the weighted set, before resampling: once resampled, the
        # injected random poses weigh as much as the rest and, a few hundred of them joining up
        # bin to bin across the flat, make the heaviest cluster the whole apartment.
        self.estimate = self._cluster_estimate()
        self._judge_leap(odom)
        if resample:
            self.resample()
        return True

    def _drove(self, old: Pose, new: Pose) -> None:
        for track in (self._trusted, self._leapt):
            if track is not None:
                track.metres += math.hypot(new.x - old.x, new.y - old.y)
                track.radians += abs(wrap(new.theta - old.theta))

    def _explains(self, track: _Trusted, est: Estimate, odom: Pose) -> bool:
        """Whether `est` is tight and where odometry carried `track` (within the leap's tolerance)."""
        p = self.params
        expected = track.carried(odom)
        return (est.within(p.localised_std)
                and expected.distance(est.pose) <= p.leap_dist + p.leap_per_m * track.metres
                and abs(wrap(expected.theta - est.pose.theta)) <= p.leap_angle + p.leap_per_rad * track.radians)

    def _judge_leap(self, odom: Pose) -> None:
        """Trust a tight estimate that odometry explains; hold the trusted pose against one that
        leapt. At the end of the hold (`hold_m`, `hold_rad`), a leapt estimate that odometry
        explained for the last `leap_confirm_updates` updates and that the scans fit as well as
        before is believed (the robot was carried off); any other is searched for."""
        p, est, trusted = self.params, self.estimate, self._trusted
        assert est is not None
        if self._searching:
            return
        tight = est.within(p.localised_std)
        if trusted is None:
            if tight:
                self._trusted = _Trusted(est.pose, odom)
            return
        if self._explains(trusted, est, odom):
            self._trusted, self._holding, self._leapt = _Trusted(est.pose, odom), False, None
        elif self._holding:
            steady = self._leapt is not None and self._explains(self._leapt, est, odom)
            self._leapt_updates = self._leapt_updates + 1 if steady else 0
            self._leapt = _Trusted(est.pose, odom) if tight else None
            metres, radians = self._held_from
            if trusted.metres - metres > p.hold_m or trusted.radians - radians > p.hold_rad:
                if self._leapt_updates >= p.leap_confirm_updates and self.fit >= p.search_fit * self.w_slow:
                    self._trusted, self._holding, self._leapt = _Trusted(est.pose, odom), False, None
                else:
                    self._search(self.w_slow)
        elif tight:
            self.leaps += 1
            self._holding = True
            self._held_from = (trusted.metres, trusted.radians)
            self._leapt, self._leapt_updates = _Trusted(est.pose, odom), 0

    def motion(self, old: Pose, new: Pose) -> None:
        """The diff-corrected odometry model, applied to every particle with its own noise."""
        p = self.params
        dx, dy = new.x - old.x, new.y - old.y
        trans = math.hypot(dx, dy)
        rot1 = 0.0 if trans < 0.01 else wrap(math.atan2(dy, dx) - old.theta)
        rot2 = wrap(wrap(new.theta - old.theta) - rot1)
        r1n = min(abs(wrap(rot1)), abs(wrap(rot1 - math.pi)))
        r2n = min(abs(wrap(rot2)), abs(wrap(rot2 - math.pi)))
        sd = np.sqrt([p.alpha1 * r1n ** 2 + p.alpha2 * trans ** 2,
                      p.alpha3 * trans ** 2 + p.alpha4 * r1n ** 2 + p.alpha4 * r2n ** 2,
                      p.alpha1 * r2n ** 2 + p.alpha2 * trans ** 2])
        n = len(self.poses)
        e = self.rng.standard_normal((n, 3)) * sd
        r1 = rot1 - e[:, 0]
        tr = trans - e[:, 1]
        r2 = rot2 - e[:, 2]
        th = self.poses[:, 2]
        self.poses[:, 0] += tr * np.cos(th + r1)
        self.poses[:, 1] += tr * np.sin(th + r1)
        self.poses[:, 2] = wrap_array(th + r1 + r2)

    def _pz_table(self, range_max: float) -> np.ndarray:
        """Per-cell pz for this range_max, with one extra entry for off-map endpoints."""
        if self._table_key != range_max:
            p = self.params
            d = np.append(self.distance.ravel(), p.likelihood_max_dist).astype(np.float64)
            self._table = p.z_hit * np.exp(-d * d / (2 * p.sigma_hit ** 2)) + p.z_rand / range_max
            self._table_key = range_max
        return self._table

    def beams(self, scan: LaserScan) -> tuple[np.ndarray, np.ndarray]:
        """(ranges, angles) of the beams used: every step-th, amcl's rule, valid ones only."""
        r = np.asarray(scan.ranges, np.float64)
        n = len(r)
        step = max(1, (n - 1) // max(1, self.params.max_beams - 1))
        idx = np.arange(0, n, step)
        r = r[idx]
        a = scan.angle_min + scan.angle_increment * idx
        ok = np.isfinite(r) & (r < scan.range_max) & (r >= scan.range_min)
        return r[ok], a[ok]

    def beam_pz(self, poses: np.ndarray, scan: LaserScan) -> tuple[np.ndarray, np.ndarray]:
        """(pz (N, B) of each used beam at each pose, endpoint distance to the nearest wall (N, B))."""
        r, a = self.beams(scan)
        table = self._pz_table(float(scan.range_max))
        bx, by = r * np.cos(a), r * np.sin(a)
        c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
        ex = poses[:, 0, None] + c * bx - s * by
        ey = poses[:, 1, None] + s * bx + c * by
        rows, cols = self.info.to_cell(ex, ey)
        inside = self.info.inside(rows, cols)
        flat = np.where(inside, rows * self.info.width + cols, table.size - 1)
        return table[flat], np.append(self.distance.ravel(), self.params.likelihood_max_dist)[flat]

    def log_likelihood(self, poses: np.ndarray, scan: LaserScan) -> tuple[np.ndarray, int]:
        """(log of each pose's scan likelihood (N,) under the configured model, beams used)."""
        p = self.params
        pz, dist = self.beam_pz(poses, scan)
        if pz.shape[1] == 0:
            return np.zeros(len(poses)), 0
        if p.laser_model == "likelihood_field":
            return np.log1p((pz ** 3).sum(axis=1)), pz.shape[1]
        use = np.ones(pz.shape[1], bool)
        est = self.estimate
        if est is not None and (est.converged or est.within(p.localised_std)):
            # amcl's beam skipping: a beam most particles cannot explain is an unmapped obstacle
            agree = (dist < p.beam_skip_distance).mean(axis=0)
            use = agree >= p.beam_skip_threshold
            if use.mean() < 1.0 - p.beam_skip_error_threshold:
                use[:] = True
        return np.log(pz[:, use]).sum(axis=1), int(use.sum())

    def sensor(self, scan: LaserScan) -> None:
        p = self.params
        logl, n_beams = self.log_likelihood(self.poses, scan)
        n_beams = max(1, n_beams)
        top = float(logl.max())
        temper = p.search_temper if self._searching else 1.0
        w = self.weights * np.exp(temper * (logl - top))
        total = float(w.sum())
        if not total > 0 or not math.isfinite(total):
            self.weights = np.full(len(w), 1.0 / len(w))
            return
        w /= total
        self.weights = w
        # per-beam score of the set: weighted mean of each particle's geometric-mean pz
        if p.laser_model == "likelihood_field":
            w_avg = float(w @ (np.expm1(logl) / n_beams))
        else:
            w_avg = float(w @ np.exp(logl / n_beams))
        self.fit = w_avg
        if not self._averaging:
            est = self.estimate
            self._averaging = est is not None and est.within(p.localised_std)
        if self._averaging:
            self.w_slow = w_avg if self.w_slow == 0 else self.w_slow + p.recovery_alpha_slow * (w_avg - self.w_slow)
            self.w_fast = w_avg if self.w_fast == 0 else self.w_fast + p.recovery_alpha_fast * (w_avg - self.w_fast)

    def injection_share(self) -> float:
        if self.w_slow <= 0:
            return 0.0
        return float(min(self.params.max_injection, max(0.0, 1.0 - self.w_fast / self.w_slow)))

    def resample(self) -> None:
        """Draw with replacement, inject random poses, keep the KLD-sufficient count."""
        p = self.params
        m = p.search_particles if self._searching else p.max_particles
        cdf = np.cumsum(self.weights)
        draws = np.minimum(np.searchsorted(cdf, self.rng.random(m) * cdf[-1]), len(cdf) - 1)
        new = self.poses[draws]
        inject = self.rng.random(m) < self.injection_share()
        if inject.any():
            new[inject] = self._random_poses(int(inject.sum()))
        if self._holding and self._trusted is not None and self._odom is not None:
            held = self._trusted.carried(self._odom)
            near = ~inject & (self.rng.random(m) < p.hold_share)
            around = self.rng.standard_normal((int(near.sum()), 3)) * p.hold_std
            new[near] = np.c_[held.x, held.y, held.theta] + around
            new[near, 2] = wrap_array(new[near, 2])
        keys = ((np.floor(new[:, 0] / p.bin_xy).astype(np.int64) & 0xFFFFF) << 40
                | (np.floor(new[:, 1] / p.bin_xy).astype(np.int64) & 0xFFFFF) << 20
                | (np.floor(new[:, 2] / p.bin_theta).astype(np.int64) & 0xFFFFF))
        _, first = np.unique(keys, return_index=True)
        is_first = np.zeros(m, bool)
        is_first[first] = True
        k = np.cumsum(is_first)
        count = np.arange(1, m + 1)
        stop = np.nonzero(count > kld_limit(k, p.kld_err, p.kld_z, p.min_particles, m))[0]
        n = int(stop[0]) + 1 if stop.size else m
        self.poses = new[:n].copy()
        self.weights = np.full(n, 1.0 / n)

    # ------------------------------------------------------------------------- estimate

    def _cluster_estimate(self) -> Estimate:
        p = self.params
        x, y, th, w = self.poses[:, 0], self.poses[:, 1], self.poses[:, 2], self.weights
        bx = np.floor((x - x.min()) / p.bin_xy).astype(np.int64)
        by = np.floor((y - y.min()) / p.bin_xy).astype(np.int64)
        # Only bins that hold weight join clusters: a few hundred injected guesses that the last
        # scan ruled out would otherwise link up bin to bin across the flat, join the robot's
        # cluster and blur its covariance, or outweigh it together.
        bin_w = np.zeros((by.max() + 1, bx.max() + 1))
        np.add.at(bin_w, (by, bx), w)
        occ = (bin_w >= p.cluster_min_weight * bin_w.max()).astype(np.uint8)
        _, labels = cv2.connectedComponents(occ, connectivity=8)
        lab = np.where(occ[by, bx] > 0, labels[by, bx], 0)
        best = int(np.argmax(np.bincount(lab, weights=w)[1:])) + 1
        sel = lab == best
        ws = w[sel] / w[sel].sum()
        mx, my = float(ws @ x[sel]), float(ws @ y[sel])
        mt = math.atan2(float(ws @ np.sin(th[sel])), float(ws @ np.cos(th[sel])))
        d = np.c_[x[sel] - mx, y[sel] - my, wrap_array(th[sel] - mt)]
        cov = (d * ws[:, None]).T @ d
        all_w = w / w.sum()
        gx, gy = float(all_w @ x), float(all_w @ y)
        converged = bool((np.abs(x - gx) <= p.converged_dist).all() and (np.abs(y - gy) <= p.converged_dist).all())
        return Estimate(Pose(mx, my, mt), cov, converged, len(x), float(w[sel].sum() / w.sum()))

    def current_estimate(self) -> Estimate:
        """The last estimate; NavError before the filter has a starting point."""
        if self.estimate is None:
            raise NavError("Localisation has no starting point yet: set the initial pose first.")
        return self.estimate

    def pose(self, odom: Pose) -> Pose:
        """The robot's map pose now: the last estimate carried forward by odometry."""
        est = self.current_estimate()
        if self._holding and self._trusted is not None:
            return self._trusted.carried(odom)
        if self._odom is None:
            return est.pose
        return compose(est.pose, relative(self._odom, odom))
