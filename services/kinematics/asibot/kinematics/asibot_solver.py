"""The ASIBOT closed-form solver, with the published conventions (docs/asibot-conventions.md,
"Kinematics": dimensions, limits, points, fwdKin, invKin, Jacobian).

Points are [x, y, z, rot(y'), rot(z'')] in metres and degrees: a ZYZ Euler triple whose
first angle is the azimuth atan2(y, x) of the position. Joints are in degrees.

Orientation fix (the published fwdKin caveat): the published fwdKin returns rot(y') = q2+q3+q4,
rot(z'') = q5, which is wrong when the tip leans behind the q1 azimuth (rP < 0), because
the azimuth of the position is then q1 + 180. We return (-oyP, ozPP + 180) in that case,
so the 5-tuple always means Rz(atan2(y, x)) Ry(rot(y')) Rz(rot(z'')). With this, the FORWARD
and REVERSED configurations of one pose give the same point, and fwd(inv(x)) == x.
When rP == 0 (tip on the q1 axis) the azimuth is undefined: fwd then reports the unfixed
(oyP, q5), i.e. the azimuth is q1, and inv keeps q1 from q_guess for such targets.

IK follows AsibotSolver::invKin: reach checks, four configurations (FORWARD/REVERSED x
elbow UP/DOWN), angles folded into (-180, 180] (without the published snap of |q| < 0.001
deg to 0, which costs up to 0.001 deg of accuracy for no gain) but also tried +-360 for q1
and q5 (their limits are +-360, roboticslab-uc3m/kinematics-dynamics issue #111), limits
with 0.001 deg tolerance, and the leastOverallAngularDisplacement selection with its tie rules: of the two configurations with
the smallest sums of |q - q_guess| (equal sums ranked FU, FD, RU, RD), the one with the smaller
|dq2| if both are FORWARD or both REVERSED, elbow UP if that ties too. Two configurations exactly
as far from the guess are thus decided by |dq2|, which is what the seed's own tests expect
(elbow DOWN in testAsibotSolverFromFile.cpp InvKin3 and InvKin4).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from asibot.poses import point_rotation

from .errors import JointLimit, Unreachable

A = (0.3, 0.4, 0.4, 0.3)  # A0..A3 [m], docs/asibot-conventions.md "Kinematics"
LIMITS_DEG = ((-360.0, 360.0), (-135.0, 135.0), (-135.0, 135.0), (-135.0, 135.0), (-360.0, 360.0))  # deg, same section
TOL = 1e-3  # deg, AsibotConfiguration limit tolerance
_R = math.pi / 180.0
_D = 180.0 / math.pi


def _wrap180(a: float) -> float:
    """Fold an angle in degrees into (-180, 180]."""
    a = math.fmod(a, 360.0)
    if a > 180.0:
        a -= 360.0
    elif a <= -180.0:
        a += 360.0
    return a


_norm = _wrap180  # AsibotConfiguration also snaps |q| < 0.001 deg to 0; we do not (see above)


def _fmt(x: Sequence[float]) -> str:
    return "[" + ", ".join(f"{v:.3g}" for v in x) + "]"


def tool_frame(x: Sequence[float] | None) -> np.ndarray | None:
    """The 4x4 transform of a tool (TCP) frame [x, y, z, rx, ry, rz]: offset in m and rotation
    vector (axis times angle) in rad, relative to the frame it is attached to; None when x is
    None or all zeros (no tool). Raises ValueError for anything but 6 finite numbers."""
    if x is None:
        return None
    if len(x) != 6 or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                              and math.isfinite(v) for v in x):
        raise ValueError(f"A tool frame is 6 finite numbers [x, y, z, rx, ry, rz] in m and rad; got {list(x)!r}.")
    if not any(x):
        return None
    h = np.eye(4)
    w = np.array(x[3:], float)
    t = float(np.linalg.norm(w))
    if t > 0:
        k = w / t
        kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        h[:3, :3] = np.eye(3) + math.sin(t) * kx + (1 - math.cos(t)) * kx @ kx
    h[:3, 3] = x[:3]
    return h


def point_transform(x: Sequence[float]) -> np.ndarray:
    """4x4 transform of a point [x, y, z, rot(y'), rot(z'')] (m, deg)."""
    h = np.eye(4)
    h[:3, :3] = point_rotation(x[0], x[1], x[3] * _R, x[4] * _R)
    h[:3, 3] = x[:3]
    return h


def transform_point(h: np.ndarray, azimuth_deg: float | None = None) -> list[float]:
    """Point [x, y, z, rot(y'), rot(z'')] (m, deg) of a 4x4 transform whose orientation is
    Rz(azimuth) Ry(b) Rz(g); `azimuth_deg` stands in for atan2(y, x) on the z axis."""
    x, y, z = (float(v) for v in h[:3, 3])
    a = math.atan2(y, x) if azimuth_deg is None or math.hypot(x, y) > 1e-12 else azimuth_deg * _R
    r = np.array([[math.cos(a), math.sin(a), 0], [-math.sin(a), math.cos(a), 0], [0, 0, 1.0]]) @ h[:3, :3]
    b = math.atan2(r[0, 2], r[2, 2])
    g = math.atan2(r[1, 0], r[1, 1])
    return [x, y, z, b * _D, _wrap180(g * _D)]


class AsibotSolver:
    """Closed-form FK/IK of the ASIBOT; degrees and metres as in the published solver."""

    def __init__(self, a: Sequence[float] = A, limits: Sequence[tuple[float, float]] = LIMITS_DEG) -> None:
        self.a0, self.a1, self.a2, self.a3 = (float(v) for v in a)
        self.lower = [float(lo) for lo, _ in limits]
        self.upper = [float(hi) for _, hi in limits]
        self._tool: np.ndarray | None = None

    # -- tools ---------------------------------------------------------------------------
    def set_tool(self, x: Sequence[float] | None) -> None:
        """Replace the tool (TCP) frame, given as [x, y, z, rx, ry, rz] (m, axis-angle rad)
        relative to the flange; None or all zeros removes it (BasicCartesianControl::tool)."""
        self._tool = tool_frame(x)

    @property
    def tool(self) -> np.ndarray | None:
        """A copy of the 4x4 tool frame on the flange, or None when there is no tool."""
        return None if self._tool is None else self._tool.copy()

    # -- forward -------------------------------------------------------------------------
    def flange(self, q: Sequence[float]) -> list[float]:
        """Point (m, deg) of the flange for joints q (deg): fwd without the tool."""
        q1, q2, q3, q4, q5 = (v * _R for v in q)
        s2, s23, s234 = math.sin(q2), math.sin(q2 + q3), math.sin(q2 + q3 + q4)
        c2, c23, c234 = math.cos(q2), math.cos(q2 + q3), math.cos(q2 + q3 + q4)
        rp = self.a1 * s2 + self.a2 * s23 + self.a3 * s234
        hp = self.a1 * c2 + self.a2 * c23 + self.a3 * c234
        oyp = q[1] + q[2] + q[3]
        ozpp = q[4]
        if rp < -1e-12:  # the published fwdKin caveat, fixed: azimuth is q1 + 180
            oyp, ozpp = -oyp, ozpp + 180.0
        return [rp * math.cos(q1), rp * math.sin(q1), hp + self.a0, oyp, _wrap180(ozpp)]

    def fwd(self, q: Sequence[float]) -> list[float]:
        """Point [x, y, z, rot(y'), rot(z'')] (m, deg) of joints q (deg)."""
        _check(q, 5, "joint values")
        x = self.flange(q)
        if self._tool is None:
            return x
        return transform_point(self.flange_transform(q) @ self._tool, q[0])

    def flange_transform(self, q: Sequence[float]) -> np.ndarray:
        """4x4 flange transform straight from the joints q (deg); keeps q1 as the azimuth
        when the tip is on the axis."""
        q1, q5 = q[0] * _R, q[4] * _R
        p = self.flange(q)
        b = (q[1] + q[2] + q[3]) * _R
        rz = lambda t: np.array([[math.cos(t), -math.sin(t), 0], [math.sin(t), math.cos(t), 0], [0, 0, 1.0]])
        ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1.0, 0], [-math.sin(b), 0, math.cos(b)]])
        h = np.eye(4)
        h[:3, :3] = rz(q1) @ ry @ rz(q5)
        h[:3, 3] = p[:3]
        return h

    # -- inverse -------------------------------------------------------------------------
    def inv(self, x: Sequence[float], q_guess: Sequence[float]) -> list[float]:
        """Joints (deg) reaching point x, the valid configuration closest to q_guess.

        Raises Unreachable or JointLimit with a sentence for the user."""
        _check(x, 5, "point")
        _check(q_guess, 5, "joint guess")
        if self._tool is not None:
            h = point_transform(x) @ np.linalg.inv(self._tool)
            xf = transform_point(h, q_guess[0])
        else:
            xf = list(x)
        cands = self.configurations(xf, q_guess, x)
        valid = [(i, c) for i, c in enumerate(cands) if self._within(c)]
        if not valid:
            worst = min(cands, key=self._excess)
            j = max(range(5), key=lambda k: self._joint_excess(worst, k))
            raise JointLimit(f"The point {_fmt(x)} needs joint q{j + 1} at {worst[j]:.1f} deg, beyond its "
                             f"limits [{self.lower[j]:.0f}, {self.upper[j]:.0f}] deg in every arm configuration; "
                             "choose a closer or less tilted point.")
        return list(_select(valid, q_guess))

    def configurations(self, x: Sequence[float], q_guess: Sequence[float],
                       shown: Sequence[float] | None = None) -> list[list[float]]:
        """The four joint solutions (deg) of flange point x, in the order FORWARD UP, FORWARD
        DOWN, REVERSED UP, REVERSED DOWN, limits not checked; q_guess gives q1 on the axis
        and the turns of q1 and q5. Raises Unreachable (about `shown`, default x)."""
        shown = x if shown is None else shown
        xd, yd, zd = x[0], x[1], x[2]
        rpd = math.hypot(xd, yd)
        hpd = zd - self.a0
        reach = self.a1 + self.a2 + self.a3
        dist = math.hypot(rpd, hpd)
        if dist > reach + 1e-12:
            raise Unreachable(f"The point {_fmt(shown)} is {dist - reach:.3g} m beyond the arm's reach "
                              f"({reach:.2f} m from the shoulder); choose a closer point.")
        q1 = math.atan2(yd, xd) * _D if rpd > 1e-12 else q_guess[0]
        oyp = x[3] * _R
        rw = rpd - self.a3 * math.sin(oyp)
        hw = hpd - self.a3 * math.cos(oyp)
        l2 = rw * rw + hw * hw
        l = math.sqrt(l2)
        if l > self.a1 + self.a2 + 1e-12:
            raise Unreachable(f"The point {_fmt(shown)} is reachable only with another tilt: its wrist is "
                              f"{l - self.a1 - self.a2:.3g} m beyond reach at rot(y') = {x[3]:.1f} deg; "
                              "tilt the tool towards the point or move the point closer.")
        if l < 1e-9:
            raise Unreachable(f"The point {_fmt(shown)} puts the wrist on the shoulder axis, where the elbow "
                              "angle is undefined; move the point a little.")
        c3 = max(-1.0, min(1.0, (l2 - self.a1 * self.a1 - self.a2 * self.a2) / (2 * self.a1 * self.a2)))
        s3 = math.sqrt(1.0 - c3 * c3)
        q3 = math.atan2(s3, c3) * _D
        k1, k2 = self.a1 + self.a2 * c3, self.a2 * s3
        q2u = math.atan2(k1 * rw - k2 * hw, k1 * hw + k2 * rw) * _D
        q2d = math.atan2(k1 * rw + k2 * hw, k1 * hw - k2 * rw) * _D
        q4u = x[3] - q2u - q3
        q4d = x[3] - q2d + q3
        q5 = x[4]
        # Shared angles are folded once: q1, q5 for FORWARD and REVERSED; q2, q3 come from atan2.
        t1f, t1r = self._turn(q1, q_guess, 0), self._turn(q1 + 180.0, q_guess, 0)
        t5f, t5r = self._turn(q5, q_guess, 4), self._turn(q5 + 180.0, q_guess, 4)
        w4u = q4u if -180.0 < q4u <= 180.0 else _wrap180(q4u)
        w4d = q4d if -180.0 < q4d <= 180.0 else _wrap180(q4d)
        return [[t1f, q2u, q3, w4u, t5f], [t1f, q2d, _neg(q3), w4d, t5f],
                [t1r, _neg(q2u), _neg(q3), _neg(w4u), t5r], [t1r, _neg(q2d), q3, _neg(w4d), t5r]]

    def _turn(self, v: float, q_guess: Sequence[float], j: int) -> float:
        """Circular joint j: v folded into (-180, 180], or one turn away if nearer the guess within limits."""
        if not -180.0 < v <= 180.0:
            v = _wrap180(v)
        d = v - q_guess[j]
        if d > 180.0 and v - 360.0 >= self.lower[j] - TOL:
            return v - 360.0
        if d < -180.0 and v + 360.0 <= self.upper[j] + TOL:
            return v + 360.0
        return v

    def _joint_excess(self, c: Sequence[float], j: int) -> float:
        return max(self.lower[j] - c[j], c[j] - self.upper[j], 0.0)

    def _excess(self, c: Sequence[float]) -> float:
        return sum(self._joint_excess(c, j) for j in range(5))

    def _within(self, c: Sequence[float]) -> bool:
        lo, hi = self.lower, self.upper
        return (lo[0] - TOL <= c[0] <= hi[0] + TOL and lo[1] - TOL <= c[1] <= hi[1] + TOL
                and lo[2] - TOL <= c[2] <= hi[2] + TOL and lo[3] - TOL <= c[3] <= hi[3] + TOL
                and lo[4] - TOL <= c[4] <= hi[4] + TOL)

    # -- differential --------------------------------------------------------------------
    def jacobian(self, q: Sequence[float]) -> np.ndarray:
        """6x5 base-frame Jacobian (the published one): rows vx, vy, vz [m/rad], wx, wy, wz [rad/rad]
        of the flange, columns q1..q5 in rad (q itself is given in degrees)."""
        _check(q, 5, "joint values")
        q1, q2, q3, q4, _ = (v * _R for v in q)
        s1, c1 = math.sin(q1), math.cos(q1)
        s2, s23, s234 = math.sin(q2), math.sin(q2 + q3), math.sin(q2 + q3 + q4)
        c2, c23, c234 = math.cos(q2), math.cos(q2 + q3), math.cos(q2 + q3 + q4)
        a1, a2, a3 = self.a1, self.a2, self.a3
        r = a3 * s234 + a2 * s23 + a1 * s2
        cr2, cr3, cr4 = a3 * c234 + a2 * c23 + a1 * c2, a3 * c234 + a2 * c23, a3 * c234
        return np.array([
            [-s1 * r, c1 * cr2, c1 * cr3, c1 * cr4, 0.0],
            [c1 * r, s1 * cr2, s1 * cr3, s1 * cr4, 0.0],
            [0.0, -r, -(a3 * s234 + a2 * s23), -a3 * s234, 0.0],
            [0.0, -s1, -s1, -s1, c1 * s234],
            [0.0, c1, c1, c1, s1 * s234],
            [1.0, 0.0, 0.0, 0.0, c234]])

    # -- batch ---------------------------------------------------------------------------
    def fwd_batch(self, q: np.ndarray) -> np.ndarray:
        """fwd for N joint rows (deg) at once, at the tool frame if one is set: N x 5 points."""
        from .batch import fwd_batch
        return fwd_batch(self, q)

    def inv_batch(self, x: np.ndarray, q_guess: Sequence[float] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """inv for N points at once, of the tool frame if one is set: returns (N x 5 joints in
        deg, ok mask); rows that fail are NaN. q_guess is one row for all or N rows."""
        from .batch import inv_batch
        return inv_batch(self, x, q_guess)


def _neg(a: float) -> float:
    """-a within (-180, 180]."""
    return 180.0 if a == 180.0 else -a


def _first(r: tuple) -> float:
    return r[0]


def _select(valid: list[tuple[int, list[float]]], q_guess: Sequence[float]) -> list[float]:
    """leastOverallAngularDisplacement with the published tie rules (module docstring)."""
    g0, g1, g2, g3, g4 = q_guess
    # Ranked by the sum, equal sums in the order FU, FD, RU, RD (a stable sort). The runner-up
    # is the next in the ranking even when its sum is equal: an exact tie is decided by the
    # |dq2| rule below, as the seed decides it (its std::map would drop the second of two equal
    # keys, but its snap of |q| < 0.001 deg to 0 breaks such ties by a hair, so its own tests
    # pick elbow DOWN for the tie [-0.318, 0.379, 1.195, 45, 0] from [0, 45, 0, 0, 0]).
    ranked = sorted([(abs(g0 - c[0]) + abs(g1 - c[1]) + abs(g2 - c[2]) + abs(g3 - c[3]) + abs(g4 - c[4]), i, c)
                     for i, c in valid], key=_first)
    _, best_i, best = ranked[0]
    if len(ranked) > 1:
        _, sec_i, sec = ranked[1]
        if (best_i < 2) == (sec_i < 2):  # same FORWARD/REVERSED
            db, ds = abs(q_guess[1] - best[1]), abs(q_guess[1] - sec[1])
            if ds < db or (ds == db and sec_i % 2 == 0):
                best = sec
    return best


def _check(v: Sequence[float], n: int, what: str) -> None:
    try:  # one float sum is the cheap test: NaN and inf propagate through it
        ok = len(v) == n and math.isfinite(math.fsum(v))
    except (TypeError, OverflowError):
        ok = False
    if not ok:
        raise ValueError(f"The {what} must be {n} finite numbers, got {list(v)!r}.")
