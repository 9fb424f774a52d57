"""Joint tracking with a driver's safety rules, independent of MuJoCo and of the bus.

Why a separate class: the sim must behave exactly like a hardware driver (docs/foundation-api.md, "Contracts": driver
contract), and the rules (limits, max speeds, 200 ms watchdog, latched estop, following-error
fault) are easier to trust when they are tested without a physics engine. The class turns
`ArmCommand`s into a position reference per physics step; the physics engine then follows
that reference with stiff position servos, as the real drives do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from asibot.messages import COMMAND_WATCHDOG_S, ArmCommand
FEEDFORWARD_HORIZON_S = 0.05
"""Longest extrapolation of a position reference by its velocity feed-forward."""
FOLLOWING_ERROR_RAD = 0.25
FOLLOWING_ERROR_TIME_S = 0.5
"""A joint that lags its reference by more than this, for this long, is blocked: fault."""


class CommandRejected(ValueError):
    """A command that is malformed or not allowed now; the message says what to do."""


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
    _command_time: float = 0.0
    _velocity: np.ndarray = field(default_factory=lambda: np.zeros(0))
    _watchdog_fired: bool = False
    _lag_since: float | None = None

    def __post_init__(self) -> None:
        self.q_ref = np.clip(np.asarray(self.q_ref, float), self.limits.lower, self.limits.upper)
        self._velocity = np.zeros(len(self.q_ref))

    @property
    def n(self) -> int:
        return len(self.limits.names)

    # ------------------------------------------------------------------ inputs
    def command(self, cmd: ArmCommand, now: float) -> None:
        """Accept a command or raise CommandRejected (and change nothing)."""
        if len(cmd.values) != self.n:
            raise CommandRejected(
                f"arm command has {len(cmd.values)} values but the arm has {self.n} joints "
                f"({', '.join(self.limits.names)}); send one value per joint")
        if cmd.velocities and len(cmd.velocities) != self.n:
            raise CommandRejected(f"velocity feed-forward must be empty or have {self.n} values")
        values = np.asarray(cmd.values, float)
        ff = np.asarray(cmd.velocities, float) if cmd.velocities else None
        if not np.all(np.isfinite(values)) or (ff is not None and not np.all(np.isfinite(ff))):
            raise CommandRejected("arm command contains a value that is not finite; send real numbers")
        if self.estop:
            raise CommandRejected("the emergency stop is engaged; release it before moving the arm")
        if self.mode == "fault":
            raise CommandRejected(f"the arm is in fault ({self.fault}); call reset_fault first")
        self._command_time = now
        self._watchdog_fired = False
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

    def set_estop(self, engaged: bool, reason: str = "", stopped: str = "the arm is holding its position") -> None:
        """Latch or release the emergency stop; engaging stops the arm where it is."""
        if engaged and not self.estop:
            self.hold()
            self.notify(Notice("warning", "estop",
                               f"Emergency stop engaged{': ' + reason if reason else ''}; {stopped}."))
        elif not engaged and self.estop:
            self.notify(Notice("info", "estop_released", "Emergency stop released; the robot accepts commands again."))
        self.estop = engaged

    def hold(self) -> None:
        """Stop: zero velocity, keep the current reference."""
        self._velocity[:] = 0.0
        self._target = self.q_ref.copy()
        self._feedforward = None
        self._watchdog_fired = True  # already stopped: nothing left for the watchdog to do

    def reset_fault(self, q_measured: Sequence[float]) -> None:
        self.fault = ""
        self.mode = "idle"
        self.q_ref = np.clip(np.asarray(q_measured, float), self.limits.lower, self.limits.upper)
        self.hold()
        self._lag_since = None

    # ------------------------------------------------------------------ the step
    def step(self, q_measured: np.ndarray, dt: float, now: float) -> np.ndarray:
        """Advance the reference by dt and return it (rad), within limits and speeds."""
        if self.mode == "velocity" and not self._watchdog_fired and now - self._command_time > COMMAND_WATCHDOG_S:
            self._watchdog_fired = True
            self.hold()
            self.notify(Notice("warning", "watchdog",
                               f"No arm command for {COMMAND_WATCHDOG_S * 1000:.0f} ms in velocity mode; the arm stopped."))
        if self.mode == "velocity" and self._target is None:
            self.q_ref = np.clip(self.q_ref + self._velocity * dt, self.limits.lower, self.limits.upper)
        elif self._target is not None:
            goal = self._target
            if self._feedforward is not None:
                ahead = min(max(now - self._command_time, 0.0), FEEDFORWARD_HORIZON_S)
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
