"""The simulated arm's driver: the same rules as a hardware arm driver, in front of MuJoCo.

Why it is a GuardedArm: the sim must behave exactly like a hardware driver (docs/foundation-api.md,
"Contracts": driver contract), so it keeps the rules every arm driver keeps, written once in
asibot.safety.guarded_arm (the estop, a change of controller, re-arming, the watchdog, the
fault reset, each said in the same words), and the drives' set-point stream of the CANopen
driver (asibot.safety.joint_reference: limits refused whole, speeds, feed-forward). What is its
own is what a drive does by itself: the physics engine follows the set-point with stiff
position servos, and a joint that cannot follow it (blocked) faults, as a drive's following
error does. Independent of MuJoCo and of the bus, so that the rules are tested without physics.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from asibot.safety.guarded_arm import EventSink, ReferencedArm
from asibot.safety.joint_reference import JointReference, check_gripper

FOLLOWING_ERROR_RAD = 0.25
FOLLOWING_ERROR_TIME_S = 0.5
"""A joint that lags its set-point by more than this, for this long, is blocked: fault."""


@dataclass
class Notice:
    """Something the driver tells the user (becomes an asibot Event)."""
    level: str
    code: str
    text: str


@dataclass
class JointLimits:
    names: list[str]
    lower: np.ndarray
    upper: np.ndarray
    max_velocity: np.ndarray

    @classmethod
    def of(cls, names: Sequence[str], lower: Sequence[float], upper: Sequence[float],
           max_velocity: Sequence[float]) -> "JointLimits":
        return cls(list(names), np.asarray(lower, float), np.asarray(upper, float),
                   np.asarray(max_velocity, float))


class SimArm(ReferencedArm):
    """One simulated arm and its gripper: commands in (GuardedArm.command, `command_gripper`),
    set-points per physics step out (`step`, `gripper_goal`).

    `measured()` is where the joints are (rad); `clock()` the simulated time; `lock` the
    physics step's, so that the thread holding it is the arm's control thread.
    """

    line = "the simulation"

    def __init__(self, limits: JointLimits, home: Sequence[float], dt: float, on_event: EventSink, *,
                 clock: Callable[[], float], lock: threading.RLock, measured: Callable[[], Sequence[float]],
                 max_opening: float, held: str | None = None) -> None:
        super().__init__(limits.names, on_event, clock=clock, lock=lock)
        if held is not None:
            self.held = held
        self.limits = limits
        self._where = measured
        self.ref = JointReference(limits.lower.tolist(), limits.upper.tolist(), limits.max_velocity.tolist(),
                                  dt, limits.names)
        self.watchdog = self.ref.watchdog     # one watchdog: the set-points', which their feed-forward reads
        self.fault = ""
        self._lag_since: float | None = None
        self.max_opening = max_opening
        self.gripper_goal = max_opening
        """The opening (m) the fingers' servos follow: a fault reset leaves it, so nothing held drops."""
        self.restart(home)

    def command_gripper(self, opening: float, controller: str = "") -> bool:
        """Open the fingers to `opening` m; CommandRefused outside 0..max_opening; False when
        ignored (the estop, a fault), as an arm driver's gripper."""
        check_gripper(opening, self.max_opening)
        with self._lock:
            if not self.admits(controller, "the gripper"):
                return False
            self.gripper_goal = min(max(opening, 0.0), self.max_opening)   # within the tolerance
            return True

    def restart(self, q: Sequence[float]) -> None:
        """Stand still at `q`, no fault: the arm as it is switched on."""
        with self._lock:
            self._stand_at(q)
            self.fault, self._faulted, self._lag_since = "", False, None

    def _stand_at(self, q: Sequence[float]) -> None:
        """The set-point at `q`, clipped into the limits (MuJoCo's servos overshoot them a little)."""
        self.ref.reset(np.clip(np.asarray(q, float), self.limits.lower, self.limits.upper).tolist())

    @property
    def mode(self) -> str:
        """idle, position, velocity or fault: the ArmState's mode."""
        return "fault" if self._faulted else self.ref.mode

    @property
    def q_ref(self) -> np.ndarray:
        """The set-point the servos follow (rad)."""
        return np.asarray(self.ref.target)

    # ------------------------------------------------------------------ ReferencedArm's parts
    def _measured(self) -> list[float]:
        return [float(q) for q in self._where()]

    def _reset(self) -> dict:
        self.restart(self._measured())
        return {}

    def _wait_for_reset(self, done: threading.Event, timeout: float) -> None:
        with self._lock:                   # the physics step's lock: this thread is the control thread now
            self._serve_reset()

    # ------------------------------------------------------------------ the step
    def step(self, q_measured: Sequence[float], now: float) -> list[float]:
        """One physics step: the set-point (rad) the servos follow, within limits and speeds."""
        self._watch(now)
        if self._faulted:
            return self.ref.target
        target = self.ref.step(now)
        self._check_following(target, q_measured, now)
        return target

    def _check_following(self, target: list[float], q: Sequence[float], now: float) -> None:
        # Plain floats: 500 times a second, on a handful of joints, faster than numpy.
        err = [abs(t - float(v)) for t, v in zip(target, q)]
        if max(err) <= FOLLOWING_ERROR_RAD:
            self._lag_since = None
            return
        if self._lag_since is None:
            self._lag_since = now
            return
        if now - self._lag_since <= FOLLOWING_ERROR_TIME_S:
            return
        j = err.index(max(err))
        self.fail("following_error", f"joint {self.limits.names[j]} cannot follow its command "
                                     f"({math.degrees(err[j]):.0f} deg behind); clear the obstacle and reset the fault", q)

    def fail(self, code: str, fault: str, q: Sequence[float]) -> None:
        """The arm faults, as a drive does by itself: it holds at `q` (where it stands), ignores
        commands until a fault reset, and says `fault` once (Event `code`)."""
        with self._lock:
            self.fault, self._faulted = fault, True
            self.counters["faults"] += 1
            self._stand_at(q)
        self.on_event("error", code, f"Arm fault: {fault}.")
