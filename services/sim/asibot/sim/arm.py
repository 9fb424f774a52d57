"""Joint tracking with a driver's safety rules, independent of MuJoCo and of the bus.

Why a separate class: the sim must behave exactly like a hardware driver (docs/foundation-api.md, "Contracts": driver
contract), and the rules (limits, max speeds, the command watchdog, latched estop, following-error
fault) are easier to trust when they are tested without a physics engine. The class turns
`ArmCommand`s into a position reference per physics step; the physics engine then follows
that reference with stiff position servos, as the real drives do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from asibot.safety.events import CommandRefused, estop_said, quantity
from asibot.messages import ArmCommand
from asibot.safety.watchdog import Watchdog

FEEDFORWARD_HORIZON_S = 0.05
"""Longest extrapolation of a position reference by its velocity feed-forward."""
FOLLOWING_ERROR_RAD = 0.25
FOLLOWING_ERROR_TIME_S = 0.5
"""A joint that lags its reference by more than this, for this long, is blocked: fault."""
POSITION_TOLERANCE_RAD = 1e-4
VELOCITY_TOLERANCE = 1e-3
"""Numerical noise, clamped rather than refused, as in the CANopen arm driver (its motion.py
says why these values): a position 1e-4 rad past a limit (and never further out than where
the joint is measured now: MuJoCo's servos overshoot a limit by up to 9 mrad as they arrive,
and the kinematics service holds where it measured the arm), a speed 0.1 % over the max."""


class CommandRejected(ValueError):
    """A command that is malformed or not allowed now; the message says what to do."""

    reason = "state"


class BadCommand(CommandRejected, CommandRefused):
    """A command with a value the robot must not be sent (beyond a limit, not finite, the wrong
    size): refused whole, never clipped, like the drivers' CommandRefused (its `reason` keys
    the rate-limiting of the refusals)."""


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


@dataclass
class JointTracker:
    """Position reference generator obeying the driver contract for one arm."""

    limits: JointLimits
    q_ref: np.ndarray
    notify: Callable[[Notice], None] = lambda n: None
    mode: str = "idle"
    fault: str = ""
    estop: bool = False
    _target: np.ndarray | None = None
    _feedforward: np.ndarray | None = None
    watchdog: Watchdog = field(default_factory=Watchdog)   # fed by every command
    _velocity: np.ndarray = field(default_factory=lambda: np.zeros(0))
    _lag_since: float | None = None

    def __post_init__(self) -> None:
        self.q_ref = np.clip(np.asarray(self.q_ref, float), self.limits.lower, self.limits.upper)
        self._velocity = np.zeros(len(self.q_ref))

    @property
    def n(self) -> int:
        return len(self.limits.names)

    # ------------------------------------------------------------------ inputs
    def command(self, cmd: ArmCommand, now: float, q_measured: Sequence[float] | None = None) -> None:
        """Accept a command or raise CommandRejected (and change nothing: the arm keeps its
        previous motion). BadCommand for a value beyond a joint's limits or max speed, or not
        finite: refused whole, never clipped. `q_measured` is where the joints are now."""
        values, ff = self.check(cmd, q_measured)
        if self.estop:
            raise CommandRejected("the emergency stop is engaged; release it before moving the arm")
        if self.mode == "fault":
            raise CommandRejected(f"the arm is in fault ({self.fault}); call reset_fault first")
        self.watchdog.feed(now)
        # Only the tolerated noise (or a way back from outside the limits) is clipped here.
        if cmd.mode == "position":
            self.mode = "position"
            self._target = np.clip(values, self.limits.lower, self.limits.upper)
            self._feedforward = None if ff is None else np.clip(ff, -self.limits.max_velocity,
                                                               self.limits.max_velocity)
            self._velocity[:] = 0.0
        else:
            self.mode = "velocity"
            self._target = None
            self._velocity = np.clip(values, -self.limits.max_velocity, self.limits.max_velocity)

    def check(self, cmd: ArmCommand, q_measured: Sequence[float] | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """The command's values and feed-forward if every one is allowed; BadCommand if not."""
        if len(cmd.values) != self.n:
            raise BadCommand("malformed",
                             f"arm command has {len(cmd.values)} values but the arm has {self.n} joints "
                             f"({', '.join(self.limits.names)}); send one value per joint")
        if cmd.velocities and len(cmd.velocities) != self.n:
            raise BadCommand("malformed", f"velocity feed-forward must be empty or have {self.n} values")
        values = np.asarray(cmd.values, float)
        ff = np.asarray(cmd.velocities, float) if cmd.velocities else None
        for what, vector in (("", values), (" velocity feed-forward", ff)):
            if vector is not None and not np.all(np.isfinite(vector)):
                j = int(np.flatnonzero(~np.isfinite(vector))[0])
                raise BadCommand("not_finite", f"joint {self.limits.names[j]}{what} got {quantity(float(vector[j]))}, "
                                               "not a finite number")
        if cmd.mode == "position":
            self._within_limits(values, q_measured)
            if ff is not None:
                self._within_speeds(ff, "velocity feed-forward")
        else:
            self._within_speeds(values, "velocity")
        return values, ff

    def _within_limits(self, values: np.ndarray, q_measured: Sequence[float] | None) -> None:
        lo, hi = self.limits.lower, self.limits.upper
        here = [self.q_ref]
        if q_measured is not None and len(q_measured) == self.n and np.all(np.isfinite(q_measured)):
            here.append(np.asarray(q_measured, float))
        top = np.maximum.reduce([hi, *here]) + POSITION_TOLERANCE_RAD
        bottom = np.minimum.reduce([lo, *here]) - POSITION_TOLERANCE_RAD
        for j in range(self.n):
            v = float(values[j])
            if v > top[j]:
                raise BadCommand("position_limit", f"joint {self.limits.names[j]} position "
                                 f"{quantity(v, 'rad', hi[j])} is beyond its upper limit {quantity(hi[j], 'rad', v)}")
            if v < bottom[j]:
                raise BadCommand("position_limit", f"joint {self.limits.names[j]} position "
                                 f"{quantity(v, 'rad', lo[j])} is beyond its lower limit {quantity(lo[j], 'rad', v)}")

    def _within_speeds(self, values: np.ndarray, what: str) -> None:
        vmax = self.limits.max_velocity
        for j in range(self.n):
            v, m = float(values[j]), float(vmax[j])
            if abs(v) > m * (1.0 + VELOCITY_TOLERANCE):
                raise BadCommand("speed_limit", f"joint {self.limits.names[j]} {what} {quantity(v, 'rad/s', m)} "
                                                f"is beyond its max speed {quantity(m, 'rad/s', abs(v))}")

    def set_estop(self, engaged: bool, reason: str = "",
                  stopped: str = "the arm holds its position and ignores motion commands until it is released",
                  by: str = "") -> None:
        """Latch or release the emergency stop; engaging stops the arm where it is. `by` says
        who; `stopped`, what the robot does until the release (asibot.safety.events.estop_said)."""
        if engaged and not self.estop:
            self.hold()
        if engaged != self.estop:
            self.notify(Notice(*estop_said(engaged, reason, by, stopped)))
        self.estop = engaged

    def hold(self) -> None:
        """Stop: zero velocity, keep the current reference."""
        self._velocity[:] = 0.0
        self._target = self.q_ref.copy()
        self._feedforward = None
        self.watchdog.fired = True  # already stopped: nothing left for the watchdog to do

    def reset_fault(self, q_measured: Sequence[float]) -> None:
        self.fault = ""
        self.mode = "idle"
        self.q_ref = np.clip(np.asarray(q_measured, float), self.limits.lower, self.limits.upper)
        self.hold()
        self._lag_since = None

    # ------------------------------------------------------------------ the step
    def step(self, q_measured: np.ndarray, dt: float, now: float) -> np.ndarray:
        """Advance the reference by dt and return it (rad), within limits and speeds."""
        if self.watchdog.fires(now, self.mode == "velocity"):
            self.hold()
            self.notify(Notice("warning", "watchdog", self.watchdog.says("arm command in velocity mode",
                                                                         "the arm stopped")))
        if self.mode == "velocity" and self._target is None:
            self.q_ref = np.clip(self.q_ref + self._velocity * dt, self.limits.lower, self.limits.upper)
        elif self._target is not None:
            goal = self._target
            if self._feedforward is not None:
                ahead = min(max(now - self.watchdog.last, 0.0), FEEDFORWARD_HORIZON_S)
                goal = np.clip(goal + self._feedforward * ahead, self.limits.lower, self.limits.upper)
            step = np.clip(goal - self.q_ref, -self.limits.max_velocity * dt, self.limits.max_velocity * dt)
            self.q_ref = self.q_ref + step
        self._check_following(np.asarray(q_measured, float), now)
        return self.q_ref

    def _check_following(self, q: np.ndarray, now: float) -> None:
        if self.mode == "fault":
            return
        err = np.abs(self.q_ref - q)
        if float(err.max()) <= FOLLOWING_ERROR_RAD:
            self._lag_since = None
            return
        if self._lag_since is None:
            self._lag_since = now
        elif now - self._lag_since > FOLLOWING_ERROR_TIME_S:
            j = int(err.argmax())
            self.fault = (f"joint {self.limits.names[j]} cannot follow its command "
                          f"({math.degrees(err[j]):.0f} deg behind); clear the obstacle and reset the fault")
            self.mode = "fault"
            self.q_ref = np.clip(q, self.limits.lower, self.limits.upper)
            self.hold()
            self.notify(Notice("error", "following_error", f"Arm fault: {self.fault}."))
