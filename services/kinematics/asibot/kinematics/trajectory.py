"""Trajectories: the seed's order-one and order-three generators, movj and movl planning.

Facts from docs/asibot-conventions.md, sections "TrajGen" (OrderOneTraj, OrderThreeTraj) and
"Control states" (isochronous movj, movl reference speed 0.05 m/s). Everything here is SI and
vectorised over joints or pose elements; no bus, no clock: callers pass the time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from asibot.errors import RpcError

#: movl reference speed, m/s (BasicCartesianControl trajectoryRefSpeed, "Control states").
DEFAULT_LINEAR_SPEED = 0.05
#: movl reference rotation speed, rad/s (real ASIBOT refSpeed 10 deg/s, "Kinematics" limits).
DEFAULT_ANGULAR_SPEED = np.radians(10.0)
#: Fraction of each joint's max velocity a default movj uses (refSpeed 10 / maxVel 25, "Kinematics" limits).
DEFAULT_JOINT_SPEED_FRACTION = 10.0 / 25.0
#: The cubic's peak velocity is 1.5 times its mean velocity (derivative of 3s^2 - 2s^3 at s = 1/2).
CUBIC_PEAK = 1.5
#: movl path check resolution: one sample per 5 mm or per 1 % of the path, whichever is finer.
CHECK_STEP = 0.005
#: Most samples a movl path check takes (a straight line across a 1.4 m arm's workspace with
#: a full turn of the tool is about 1,500): beyond it the move is refused, not sampled.
MAX_PATH_SAMPLES = 5000


class Profile(Protocol):
    duration: float

    def get(self, t: float) -> np.ndarray: ...
    def getdot(self, t: float) -> np.ndarray: ...


class OrderOneTraj:
    """Constant velocity from xi to xf over T (the seed's OrderOneTraj); holds xf after T."""

    def __init__(self, xi: np.ndarray, xf: np.ndarray, duration: float) -> None:
        if not duration > 0:
            raise ValueError("duration must be positive")
        self.xi, self.xf = np.asarray(xi, float), np.asarray(xf, float)
        self.duration = float(duration)
        self.m = (self.xf - self.xi) / self.duration

    def get(self, t: float) -> np.ndarray:
        t = min(max(t, 0.0), self.duration)
        return self.xi + self.m * t

    def getdot(self, t: float) -> np.ndarray:
        return self.m.copy() if 0.0 <= t < self.duration else np.zeros_like(self.m)


class OrderThreeTraj:
    """Cubic with null initial and final velocity (the seed's OrderThreeTraj); holds xf after T."""

    def __init__(self, xi: np.ndarray, xf: np.ndarray, duration: float) -> None:
        if not duration > 0:
            raise ValueError("duration must be positive")
        self.xi, self.xf = np.asarray(xi, float), np.asarray(xf, float)
        T = self.duration = float(duration)
        self.a3 = 2.0 * (self.xi - self.xf) / T**3
        self.a2 = (self.xf - self.xi) / T**2 - self.a3 * T

    def get(self, t: float) -> np.ndarray:
        t = min(max(t, 0.0), self.duration)
        return self.xi + self.a2 * t**2 + self.a3 * t**3

    def getdot(self, t: float) -> np.ndarray:
        if not 0.0 <= t < self.duration:
            return np.zeros_like(self.xi)
        return 2.0 * self.a2 * t + 3.0 * self.a3 * t**2


def isochronous_duration(q0: np.ndarray, q1: np.ndarray, joint_speed: np.ndarray) -> float:
    """Time for the slowest joint at its speed (peak of the cubic), so all joints end together."""
    delta = np.abs(np.asarray(q1, float) - np.asarray(q0, float))
    return float(np.max(CUBIC_PEAK * delta / np.asarray(joint_speed, float), initial=0.0))


@dataclass
class JointPlan:
    """A planned motion in joint space: reference q(t) and feed-forward qdot(t)."""
    duration: float
    q_at: Callable[[float], np.ndarray]
    qdot_at: Callable[[float], np.ndarray]


def plan_movj(q0: np.ndarray, q1: np.ndarray, max_velocity: np.ndarray, *,
              duration: float | None = None, speed: float | None = None) -> JointPlan:
    """Isochronous cubic from q0 to q1.

    `speed` is a fraction (0, 1] of each joint's max velocity; `duration` in s. The duration
    is stretched when it would exceed any joint's max velocity.
    """
    q0, q1, vmax = (np.asarray(a, float) for a in (q0, q1, max_velocity))
    fraction = DEFAULT_JOINT_SPEED_FRACTION if speed is None else float(speed)
    if not 0.0 < fraction <= 1.0:
        raise RpcError("bad_request", f"speed is a fraction of the maximum joint speed, in (0, 1]; got {speed}.")
    fastest = isochronous_duration(q0, q1, vmax)
    T = isochronous_duration(q0, q1, vmax * fraction) if duration is None else float(duration)
    if duration is not None and not (np.isfinite(T) and T > 0):
        raise RpcError("bad_request", f"duration must be a positive number of seconds; got {duration}.")
    T = max(T, fastest)
    if T <= 0.0:
        return JointPlan(0.0, lambda t: q1.copy(), lambda t: np.zeros_like(q1))
    traj = OrderThreeTraj(q0, q1, T)
    return JointPlan(T, traj.get, traj.getdot)


class Kinematics(Protocol):
    def inv_path(self, poses: np.ndarray, q0: np.ndarray) -> tuple[np.ndarray, RpcError | None]: ...


def line_pose(p0: np.ndarray, p1: np.ndarray, s: float | np.ndarray) -> np.ndarray:
    """Pose at fraction s of a straight line: position and orientation angles interpolated
    linearly (broadcasts: p0[None, :], p1[None, :], s[:, None] give one pose per row)."""
    return p0 + (p1 - p0) * s


def path_length(p0: np.ndarray, p1: np.ndarray) -> tuple[float, float]:
    """(translation m, largest orientation change rad) between two SI poses."""
    d = np.asarray(p1, float) - np.asarray(p0, float)
    return float(np.linalg.norm(d[:3])), float(np.max(np.abs(d[3:]), initial=0.0))


def movl_min_duration(s: np.ndarray, qs: np.ndarray, vmax: np.ndarray) -> float:
    """Shortest duration of the order-three law over path samples `qs` (at fractions `s`)
    that keeps every joint within `vmax`.

    Joint speed is dq/ds * ds/dt, and the law's ds/dt = 6 tau (1 - tau) / T is small where
    it starts and ends. Taking each segment at its own ds/dt, not the law's peak, matters near
    a stretched-arm singularity (home): dq/ds grows without bound there, but only where the
    law is already slowing down, so the joints stay finite and the move takes seconds, not minutes.
    """
    tau = np.linspace(0.0, 1.0, 2001)
    rate = 6 * tau * (1 - tau)                                # ds/dt * T along the law
    s_of_tau = 3 * tau ** 2 - 2 * tau ** 3
    # The reference crosses each segment at its constant slope, so take the fastest ds/dt
    # inside the segment: at one of its ends, or the law's peak if the segment contains it.
    at = np.interp(s, s_of_tau, rate)
    seg_rate = np.maximum(at[1:], at[:-1])
    seg_rate[(s[:-1] <= 0.5) & (s[1:] >= 0.5)] = CUBIC_PEAK
    dq_ds = np.abs(np.diff(qs, axis=0)) / np.diff(s)[:, None]  # per segment, per joint
    return float(np.max(dq_ds * seg_rate[:, None] / vmax, initial=0.0))


def plan_movl(model: Kinematics, q0: np.ndarray, p0: np.ndarray, p1: np.ndarray,
              lower: np.ndarray, upper: np.ndarray, max_velocity: np.ndarray, *,
              duration: float | None = None, speed: float | None = None,
              describe: Callable[[np.ndarray], str] = lambda p: str(np.round(p, 3).tolist())) -> JointPlan:
    """Straight Cartesian line p0 -> p1 (SI poses), checked end to end before any motion.

    The end point is checked for reach first (an out-of-reach target is refused at once,
    with the solver's sentence); a line too long to sample (MAX_PATH_SAMPLES) is refused.
    Then the path is sampled, each sample solved by IK from the previous solution (model.inv_path,
    one unit conversion for the whole path); the first unreachable sample, joint-limit
    violation or configuration jump refuses the whole move with the percentage of the path
    where it happens. `speed` is in m/s. The duration is stretched so no joint exceeds its max
    velocity.
    """
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    lower, upper, vmax = (np.asarray(a, float) for a in (lower, upper, max_velocity))
    lin, ang = path_length(p0, p1)
    if speed is not None and not (np.isfinite(speed) and speed > 0):
        raise RpcError("bad_request", f"speed must be a positive number of m/s; got {speed}.")
    if duration is not None and not (np.isfinite(duration) and duration > 0):
        raise RpcError("bad_request", f"duration must be a positive number of seconds; got {duration}.")
    # The end point first: one IK, not a path of samples, says that a point is out of reach
    # (a movl to x = 1e5 m would otherwise sample 2e7 poses before refusing).
    _, failure = model.inv_path(p1[None, :], np.asarray(q0, float))
    if failure is not None:
        raise failure
    if not (np.isfinite(lin) and np.isfinite(ang)):
        raise RpcError("bad_request", f"The line from {describe(p0)} to {describe(p1)} is not finite.")
    n = int(max(100, np.ceil(lin / CHECK_STEP), np.ceil(ang / np.radians(0.5))))
    if n > MAX_PATH_SAMPLES:
        raise RpcError("bad_request", f"The line from {describe(p0)} to {describe(p1)} is {lin:.3g} m long and turns "
                                      f"the tool {np.degrees(ang):.0f} deg: too long to check in steps of 5 mm and "
                                      f"0.5 deg (at most {MAX_PATH_SAMPLES} steps); split it with intermediate points.")
    s = np.linspace(0.0, 1.0, n + 1)
    poses = line_pose(p0[None, :], p1[None, :], s[:, None])
    qs, failure = model.inv_path(poses, np.asarray(q0, float))
    qs = np.asarray(qs, float)

    def where(i: int) -> str:  # only built for the refusal, not per sample
        return f"at {s[i] * 100:.0f} % of the path: {describe(poses[i])}"

    # The first problem along the path wins: a joint limit, a jump, or the IK failure after them.
    over = np.any((qs < lower - 1e-9) | (qs > upper + 1e-9), axis=1)
    jump = np.zeros(len(qs), bool)
    jump[1:] = np.max(np.abs(np.diff(qs, axis=0)), axis=1, initial=0.0) > np.radians(20.0)
    first = np.flatnonzero(over | jump)
    if first.size:
        i = int(first[0])
        if over[i]:
            j = int(np.flatnonzero((qs[i] < lower - 1e-9) | (qs[i] > upper + 1e-9))[0])
            raise RpcError("joint_limit", f"Joint {j + 1} would pass its limit ({np.degrees(qs[i, j]):.1f} deg, "
                                          f"allowed {np.degrees(lower[j]):.0f}..{np.degrees(upper[j]):.0f} deg) "
                                          f"{where(i)}. Choose another target or go there with movj.")
        raise RpcError("unreachable", f"The straight line passes a singularity or configuration change "
                                      f"{where(i)}; use movj for this move or pick an intermediate point.")
    if failure is not None:
        exc, at = failure, where(len(qs))
        raise type(exc)(exc.code, f"The point is unreachable {at} ({exc.message})"
                        if exc.code == "unreachable" else f"{exc.message} ({at})") from None
    if lin == 0.0 and ang == 0.0:
        return JointPlan(0.0, lambda t: qs[-1].copy(), lambda t: np.zeros(len(q0)))
    T = duration if duration is not None else max(lin / (speed or DEFAULT_LINEAR_SPEED),
                                                  ang / DEFAULT_ANGULAR_SPEED)
    T = max(float(T), movl_min_duration(s, qs, vmax))
    law = OrderThreeTraj(np.zeros(1), np.ones(1), T)

    def q_at(t: float) -> np.ndarray:
        si = float(law.get(t)[0])
        return np.array([np.interp(si, s, qs[:, j]) for j in range(qs.shape[1])])

    def qdot_at(t: float) -> np.ndarray:
        si, sdot = float(law.get(t)[0]), float(law.getdot(t)[0])
        k = min(int(si * n), n - 1)
        return (qs[k + 1] - qs[k]) * n * sdot

    return JointPlan(T, q_at, qdot_at)
