"""The Cartesian control state machine, free of any bus: the server feeds it measurements and
requests, and asks it at every tick for the next joint reference.

States follow the seed's ccnc, ccjc, cclc, ccvc (docs/asibot-conventions.md, "Control states")
plus `pointer` ("Pointer mode").
Rules: motion is refused while the estop is engaged ("estop"), without a driver
("unavailable"), with a faulted driver ("fault"), and while another planned motion runs
("busy"; stop or wait first). Streaming modes (movv, pointer) stop after 200 ms without a new
command, like the driver's own watchdog (docs/foundation-api.md, "Contracts").

Planning never holds the controller: a movj or movl is planned (`plan_movj`, `plan_movl`)
from a snapshot of the measured joints taken under the lock, without the lock, and only
`start` takes it again to begin the planned motion. Stop, state and the control loop are
therefore never blocked by a request, however long its path check takes. A plan starts only
if nothing happened to the controller since its snapshot; otherwise it is refused and
nothing moves:
- the estop was engaged (even if released since): "estop";
- the arm reported a new fault: "fault"; the driver vanished: "unavailable";
- a `stop` came: "busy", a stop cancels the motions being planned as well as the running one;
- another motion started meanwhile (a movj, movl, movv or pointer): "busy".
Asking for a movj or movl ends a running stream (movv, pointer) first: the arm holds still
while the new motion is planned, so the plan starts where the arm is.

Re-arming (asibot.safety.arming): after the controller's own start, an estop release, a fault
cleared or the driver back, a stream of requests (movv, movjv, pointer) that was still
arriving moves nothing ("busy", with a sentence) until it pauses for a watchdog period or is
restarted; a movj or movl is a new request and moves. A `stop` does not re-arm: a jog
button pressed again at once after its stop moves at once.

Jog steps (the server's `jog`) are a movj or movl that carries its target (`Planned.jog`).
While one runs, `jog_from` answers that target, so that the next step adds to it and not to
where the arm happens to be; the target lives and dies with its motion: its end, a stop, the
estop, a fault or the driver's loss forget it, and a motion of another verb has none. The next
step checks itself first (`check_joint_limits`, `check_line`) and only then stops the running
one, so that a step refused changes nothing.

Where a motion ends (its last point, or the hold after a stop) is sent again every RESEND_S
until the arm is measured there or SETTLE_S has passed: commands go out without waiting for
the network (they drop rather than queue up late), and the driver keeps the last set-point it
got, so one lost message would leave the arm on a point from the middle of the motion.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Any, Protocol, Sequence

import numpy as np

from asibot.safety.arming import Arming
from asibot.errors import RpcError
from asibot.messages import COMMAND_WATCHDOG_S
from asibot.safety.watchdog import Watchdog

from . import trajectory

NOT_CONTROLLING = "not_controlling"
MOVJ = "movj"
MOVL = "movl"
MOVV = "movv"
MOVJV = "movjv"
POINTER = "pointer"
STREAMS = (MOVV, MOVJV, POINTER)
STATES = (NOT_CONTROLLING, MOVJ, MOVL) + STREAMS
#: rad: a new stream continues from the held reference when every joint is this close to it
#: (a servo's lag under load, well under a jog step); farther, the arm was moved otherwise.
CONTINUE_WITHIN = np.radians(2.0)
#: rad: `wait` counts the arm arrived when every joint is this close to the motion's end
#: (the sim's servo rests within 0.5 degrees of its reference under gravity).
SETTLED_WITHIN = np.radians(0.5)
#: s: `wait` waits at most this long after a plan's end for the arm to catch up (an arm pushing
#: on something never does; the motion is over all the same).
SETTLE_S = 3.0
#: s: how often the end of a motion is sent again while the arm is not there (see the module).
RESEND_S = 0.1


class Model(Protocol):
    pose_size: int
    def fwd(self, q: np.ndarray) -> np.ndarray: ...
    def inv(self, pose: np.ndarray, q_guess: np.ndarray) -> np.ndarray: ...
    def inv_path(self, poses: np.ndarray, q0: np.ndarray) -> tuple[np.ndarray, RpcError | None]: ...


class Spec(Protocol):
    joint_names: list[str]
    lower: list[float]
    upper: list[float]
    max_velocity: list[float]


@dataclass
class Planned:
    """A motion planned outside the lock, to be started with Controller.start."""
    state: str                  # MOVJ or MOVL
    plan: trajectory.JointPlan
    ticket: int                 # the controller's epoch at the snapshot
    #: A jog step's target (SI: the joints of a movj, the pose of a movl), which the next step
    #: adds to while this motion runs; None for any other motion.
    jog: np.ndarray | None = None


@dataclass
class Reference:
    """What the server sends as ArmCommand(mode="position")."""
    positions: list[float]
    velocities: list[float]


class Controller:
    """Holds the measured state, the active motion and the outcome of the last motion."""

    def __init__(self, model: Model, spec: Spec, started: float | None = None) -> None:
        """`started`: when the controller starts, on the clock of the requests' `now` (the
        server's); a stream arriving then may have been running against a controller before
        this one. None: armed from the start (tests that step time by hand)."""
        self.model, self.spec = model, spec
        self.lower = np.asarray(spec.lower, float)
        self.upper = np.asarray(spec.upper, float)
        self.vmax = np.asarray(spec.max_velocity, float)
        self.n = len(spec.joint_names)
        self._lock = threading.RLock()
        self._done = threading.Condition(self._lock)
        self.state = NOT_CONTROLLING
        self.q: np.ndarray | None = None
        self.driver_alive = False
        self.fault = ""
        self.estop = False
        self.estop_reason = ""
        self.outcome: RpcError | None = None   # why the last motion ended early, None if it completed
        self._plan: trajectory.JointPlan | None = None
        self._jog: np.ndarray | None = None     # the running motion's Planned.jog
        self._t0 = 0.0
        self._hold: np.ndarray | None = None
        self._stream_pose: np.ndarray | None = None
        self._stream_vel = np.zeros(0)
        self._stream_turn = 0.0                 # rad/s about the base axis (stream)
        self.watchdog = Watchdog()     # a streamed motion lapses when its requests stop
        self._last_tick: float | None = None
        self._send_hold = False
        # The tick time of the next resend of _hold, and the last (see RESEND_S); None: no resend.
        self._resend_at: float | None = None
        self._resend_until = 0.0
        # The end of the last planned motion while the arm catches up with it (see wait).
        self._settle: np.ndarray | None = None
        self._settle_by = 0.0
        # Bumped by everything that must cancel a motion being planned (stop, estop, fault,
        # driver loss, another motion), with what it was, for the refusal's sentence.
        self._epoch = 0
        self._interrupt = RpcError("busy", "The controller changed")
        self.arming = Arming(started)
        if started is not None:
            self.arming.disarm("a start of the controller")

    # --- inputs -------------------------------------------------------------------------
    def on_arm_state(self, positions: Sequence[float], fault: str) -> None:
        with self._lock:
            q = np.asarray(positions, float)
            if q.shape != (self.n,) or not np.all(np.isfinite(q)):
                return
            self.q = q
            self._check_settled()
            if fault and not self.fault:
                self._cancel(RpcError("fault", f"The arm reports a fault: {fault} Reset it, then retry."),
                             "A fault of the arm")
            elif self.fault and not fault:
                self.arming.disarm("the fault was cleared")
            self.fault = fault

    def on_estop(self, engaged: bool, reason: str) -> None:
        with self._lock:
            if self.estop and not engaged:
                self.arming.disarm("the emergency stop was released")
            self.estop, self.estop_reason = bool(engaged), reason
            if engaged:
                self._cancel(RpcError("estop", f"Stopped by the emergency stop{': ' + reason if reason else ''}."),
                             "The emergency stop")

    def on_driver(self, alive: bool) -> None:
        with self._lock:
            if alive and not self.driver_alive:
                self.arming.disarm("the arm driver appeared")
            self.driver_alive = alive
            if not alive:
                self.q = None
                self._cancel(RpcError("unavailable", "The arm driver disappeared; the motion was stopped. "
                                                     "Start the driver (or the sim), then retry."),
                             "The loss of the arm driver")

    # --- requests -----------------------------------------------------------------------
    def check_can_move(self) -> np.ndarray:
        """The measured joints if motion is allowed now; otherwise the refusal."""
        if self.estop:
            raise RpcError("estop", "The emergency stop is engaged"
                           f"{' (' + self.estop_reason + ')' if self.estop_reason else ''}; release it before moving.")
        if not self.driver_alive or self.q is None:
            raise RpcError("unavailable", "No arm driver is running for this robot; start the driver or the sim.")
        if self.fault:
            raise RpcError("fault", f"The arm reports a fault: {self.fault} Reset it, then retry.")
        return self.q.copy()

    def _check_idle(self) -> None:
        if self.state in (MOVJ, MOVL):
            raise RpcError("busy", f"A {self.state} is still running; call wait() or stop() first.")

    def movj(self, q_target: np.ndarray, now: float, *, duration: float | None = None,
             speed: float | None = None) -> float:
        """Plan and start a joint-space move; returns its duration in s."""
        return self.start(self.plan_movj(q_target, duration=duration, speed=speed), now)

    def movl(self, pose_target: np.ndarray, now: float, *, duration: float | None = None,
             speed: float | None = None, describe: Any = None) -> float:
        """Plan and start a straight-line move to an SI pose after checking the whole path."""
        return self.start(self.plan_movl(pose_target, duration=duration, speed=speed, describe=describe), now)

    def _snapshot(self) -> tuple[np.ndarray, int]:
        """The measured joints to plan from and the epoch to start against; refuses what
        cannot move now. Ends a running stream: the arm holds while the motion is planned."""
        with self._lock:
            q0 = self.check_can_move()
            self._check_idle()
            if self.state in STREAMS:
                self._abort(None)
            return q0, self._epoch

    def check_joint_limits(self, q_target: np.ndarray) -> None:
        """Refuse ("joint_limit") joints (rad) outside their limits, naming the first."""
        q1 = np.asarray(q_target, float)
        bad = np.flatnonzero(~((q1 >= self.lower) & (q1 <= self.upper)))
        if bad.size:
            j = int(bad[0])
            raise RpcError("joint_limit", f"Joint {j + 1} target {np.degrees(q1[j]):.1f} deg is outside its limits "
                                          f"{np.degrees(self.lower[j]):.0f}..{np.degrees(self.upper[j]):.0f} deg.")

    def plan_movj(self, q_target: np.ndarray, *, duration: float | None = None,
                  speed: float | None = None) -> Planned:
        """Plan an isochronous joint move from the measured joints (the lock is held only for
        the snapshot); `start` begins it."""
        q1 = np.asarray(q_target, float)
        self.check_joint_limits(q1)
        q0, ticket = self._snapshot()
        return Planned(MOVJ, trajectory.plan_movj(q0, q1, self.vmax, duration=duration, speed=speed), ticket)

    def plan_movl(self, pose_target: np.ndarray, *, duration: float | None = None,
                  speed: float | None = None, describe: Any = None) -> Planned:
        """Plan a straight line from the measured joints to an SI pose, checking the whole
        path, without holding the lock (only for the snapshot); `start` begins it."""
        q0, ticket = self._snapshot()
        return Planned(MOVL, self._line(q0, pose_target, duration, speed, describe), ticket)

    def check_line(self, pose_target: np.ndarray, *, speed: float | None = None, describe: Any = None) -> None:
        """Refuse what plan_movl would refuse for a line from where the arm is now to an SI
        pose, without stopping the motion that runs: a jog step checks its line before it stops
        the step it follows, so that a step refused leaves that one running."""
        with self._lock:
            q0 = self.check_can_move()
        self._line(q0, pose_target, None, speed, describe)

    def _line(self, q0: np.ndarray, pose_target: np.ndarray, duration: float | None, speed: float | None,
              describe: Any) -> trajectory.JointPlan:
        """The straight line from the joints q0 to an SI pose, checked end to end (no lock)."""
        p0 = np.asarray(self.model.fwd(q0), float)
        kw = {"describe": describe} if describe else {}
        return trajectory.plan_movl(self.model, q0, p0, pose_target, self.lower, self.upper, self.vmax,
                                    duration=duration, speed=speed, **kw)

    def jog_from(self, state: str) -> tuple[np.ndarray, bool]:
        """Where the next jog step of kind `state` (MOVJ: joints, MOVL: a pose; SI) starts, and
        whether a planned motion runs (the step stops it first). While a jog step of the same
        kind runs: its target, so that steps touched while the arm moves add up and the arm
        does not stop short; otherwise where the arm is measured. Refuses what cannot move now."""
        with self._lock:
            q = self.check_can_move()
            running = self.state in (MOVJ, MOVL)
            if running and self.state == state and self._jog is not None:
                return self._jog.copy(), True
        return (q if state == MOVJ else np.asarray(self.model.fwd(q), float)), running

    def start(self, planned: Planned, now: float) -> float:
        """Begin a planned motion at time `now` (read it after planning); returns its duration.
        Refused, and nothing moves, if the controller changed since the plan's snapshot
        (see the module's docstring for what answers what)."""
        with self._lock:
            self.check_can_move()
            self._check_idle()
            if planned.ticket != self._epoch:
                why = self._interrupt
                raise RpcError(why.code, f"{why.message} came while this {planned.state} was being planned, "
                                         "so it was not started; nothing moved.")
            self._start(planned.state, planned.plan, now, planned.jog)
            return planned.plan.duration

    def stream(self, velocity: np.ndarray, now: float, mode: str = MOVV, *, turn: float = 0.0) -> None:
        """Set or refresh a streamed velocity (SI): of the pose, or of the joints in mode MOVJV;
        it lapses after COMMAND_WATCHDOG_S seconds. `turn` (rad/s, counter-clockwise) turns the
        pose's position about the base's vertical axis as well (the pointer's yaw). Refused
        ("busy") when it continues a stream from before a recovery (see the module's docstring)."""
        with self._lock:
            may_move = self.arming.admit("stream", now)   # noted even when refused below
            q0 = self.check_can_move()
            self._check_idle()
            if not may_move:
                ms = f"{COMMAND_WATCHDOG_S * 1000:.0f} ms"
                raise RpcError("busy", f"This {mode} did not move the arm: the controller was re-armed after "
                                       f"{self.arming.why}, and this request continues a stream of requests that was "
                                       f"running before; pause it for {ms} (or restart it) to move the arm again.")
            v = np.asarray(velocity, float)
            size = self.n if mode == MOVJV else self.model.pose_size
            if v.shape != (size,) or not np.all(np.isfinite(v)):
                raise RpcError("bad_request", f"A velocity needs {size} finite numbers.")
            if not math.isfinite(turn) or (turn and mode == MOVJV):
                raise RpcError("bad_request", "A turn needs a finite rate, in a stream of poses.")
            if self.state != mode:
                self._bump(RpcError("busy", f"A {mode}"))
                self._settle = None
                start = self._continued(q0)
                self._stream_pose = np.asarray(self.model.fwd(start), float)
                self._hold = start
                self._last_tick = None
                self.outcome = None
            self.state = mode
            self._stream_vel, self._stream_turn = v, float(turn)
            self.watchdog.feed(now)

    def _continued(self, measured: np.ndarray) -> np.ndarray:
        """Where a new stream starts: the reference the arm is holding when the arm is close to
        it, else where the arm is. An arm under load lags its reference (gravity, the servo);
        a stream started from the lagging measurement moves the reference back to it, and a
        stream restarted again and again (a phone's messages late on Wi-Fi, each lapse a
        restart) would let the tip sink a lag at every restart."""
        hold = self._hold
        if hold is not None and hold.shape == measured.shape and np.max(np.abs(hold - measured)) <= CONTINUE_WITHIN:
            return hold.copy()
        return measured

    def stop(self) -> None:
        """Stop any motion; the arm holds its last reference. With no motion of its own running,
        the arm is told to hold where it is measured: `stop` stops the arm whoever moved it."""
        with self._lock:
            idle = self.state == NOT_CONTROLLING
            self._cancel(None, "A stop")
            if idle and self.q is not None:
                self._hold = self.q.copy()
                self._send_hold = True

    def wait(self, timeout: float | None) -> bool:
        """Block until no planned motion runs and the arm has caught up with the end of the last
        one (every joint within SETTLED_WITHIN, or SETTLE_S after the plan's end, whichever
        comes first); False on timeout (the motion keeps running). A program that closes the
        gripper after `wait` closes it where the arm is meant to be: the plan ends before the
        arm, which lags it (1.8 degrees on a loaded machine)."""
        end = None if timeout is None else time.monotonic() + timeout
        with self._lock:
            while True:
                now = time.monotonic()
                planned = self.state in (MOVJ, MOVL)
                if not planned and (self._settle is None or now >= self._settle_by):
                    return True
                wake = self._settle_by if not planned else math.inf
                if end is not None:
                    if now >= end:
                        return False
                    wake = min(wake, end)
                self._done.wait(None if wake == math.inf else wake - now)

    # --- the loop -----------------------------------------------------------------------
    def tick(self, now: float) -> Reference | None:
        """The joint reference for this instant, or None when nothing should be sent."""
        with self._lock:
            if self.state in (MOVJ, MOVL) and self._plan is not None:
                t = now - self._t0
                if t >= self._plan.duration:
                    q = self._plan.q_at(self._plan.duration)
                    self._finish(q)
                    return self._ended(q, now)
                return Reference(self._plan.q_at(t).tolist(), self._plan.qdot_at(t).tolist())
            if self.state in STREAMS:
                return self._stream_tick(now)
            if self._send_hold and self._hold is not None:
                self._send_hold = False
                return self._ended(self._hold, now)
            return self._resend(now)

    def _ended(self, hold: np.ndarray, now: float) -> Reference:
        """The reference where a motion ended (_hold), sent now and again until the arm is there."""
        self._resend_at, self._resend_until = now + RESEND_S, now + SETTLE_S
        return self._still_at(hold)

    def _still_at(self, q: np.ndarray) -> Reference:
        """Stay at q: the one shape of every hold, first sent, resent or asked for."""
        return Reference(q.tolist(), [0.0] * self.n)

    def _resend(self, now: float) -> Reference | None:
        if self._resend_at is None or self._hold is None:
            return None
        there = self.q is not None and np.max(np.abs(self.q - self._hold)) <= SETTLED_WITHIN
        if there or self.estop or self.fault or now >= self._resend_until:
            self._resend_at = None       # the driver ignores or refuses it under the estop or a fault
            return None
        if now < self._resend_at:
            return None
        self._resend_at = now + RESEND_S
        return self._still_at(self._hold)

    def _stream_tick(self, now: float) -> Reference | None:
        if self.watchdog.silent(now):
            self._abort(RpcError("timeout", self.watchdog.says("streamed command", "the motion was stopped")))
            return self.tick(now)
        dt = 0.0 if self._last_tick is None else now - self._last_tick
        self._last_tick = now
        hold, pose = self._hold, self._stream_pose
        if hold is None or pose is None:
            raise RuntimeError("a stream state without its start: stream() sets both before entering one")
        if self.state == MOVJV:
            return self._joint_stream_tick(hold, dt)
        target = self._advance(pose, dt)
        q = self._solve(target, hold)
        if q is None:
            return self._stream_refused(hold)
        qdot = (q - hold) / dt if dt > 0 else np.zeros(self.n)
        over = float(np.max(np.abs(qdot) / self.vmax))
        if over > 1.0:  # near a singularity: slow the stream down instead of exceeding joint speeds
            target = self._advance(pose, dt / (over * 1.05))
            q = self._solve(target, hold)
            if q is None:
                return self._stream_refused(hold)
            qdot = (q - hold) / dt
            if np.any(np.abs(qdot) > self.vmax):
                return self._stream_refused(hold)
        self._stream_pose, self._hold = target, q
        return Reference(q.tolist(), qdot.tolist())

    def _advance(self, pose: np.ndarray, dt: float) -> np.ndarray:
        """The streamed pose `dt` seconds on: turned about the base axis, then moved."""
        target = pose + self._stream_vel * dt
        if self._stream_turn:
            c, s = math.cos(self._stream_turn * dt), math.sin(self._stream_turn * dt)
            target[0], target[1] = c * target[0] - s * target[1], s * target[0] + c * target[1]
        return target

    def _joint_stream_tick(self, hold: np.ndarray, dt: float) -> Reference:
        """Joints at their streamed speeds (capped at each joint's maximum), stopping at the limits."""
        qdot = np.clip(self._stream_vel, -self.vmax, self.vmax)
        q = np.clip(hold + qdot * dt, self.lower, self.upper)
        qdot = (q - hold) / dt if dt > 0 else np.zeros(self.n)
        self._hold = q
        return Reference(q.tolist(), qdot.tolist())

    def _solve(self, pose: np.ndarray, near: np.ndarray) -> np.ndarray | None:
        """IK near the joints `near`, or None when out of reach or past a limit."""
        try:
            q = np.asarray(self.model.inv(pose, near), float)
        except RpcError:
            return None
        if np.any(q < self.lower) or np.any(q > self.upper):
            return None
        return q

    def _stream_refused(self, hold: np.ndarray) -> Reference:
        """Hold still at the edge of the workspace instead of jumping; streaming goes on."""
        return self._still_at(hold)

    # --- internals ----------------------------------------------------------------------
    def _bump(self, what: RpcError) -> None:
        """Something happened that a motion being planned must not outlive (see start)."""
        self._epoch += 1
        self._interrupt = what
        self._resend_at = None         # an old end is not sent again over what comes next

    def _cancel(self, why: RpcError | None, what: str) -> None:
        """Abort the running motion (if any) and the motions being planned."""
        self._bump(RpcError(why.code if why is not None else "busy", what))
        self._abort(why)

    def _start(self, state: str, plan: trajectory.JointPlan, now: float, jog: np.ndarray | None) -> None:
        self._bump(RpcError("busy", f"A {state}"))
        self._settle = None
        self.outcome = None
        self._plan, self._t0, self.state = plan, now, state
        self._jog = None if jog is None else np.array(jog, float)   # a copy: the caller keeps its own
        self._hold = plan.q_at(plan.duration)

    def _finish(self, q: np.ndarray) -> None:
        self._plan, self._jog, self._hold, self.state = None, None, q, NOT_CONTROLLING
        self._settle, self._settle_by = q, time.monotonic() + SETTLE_S
        self._check_settled()
        self._done.notify_all()

    def _check_settled(self) -> None:
        """Forget the target the arm was catching up with once it is there (wakes `wait`)."""
        if self._settle is not None and self.q is not None and np.max(np.abs(self.q - self._settle)) <= SETTLED_WITHIN:
            self._settle = None
            self._done.notify_all()

    def _abort(self, why: RpcError | None) -> None:
        self._settle = None                      # stopped short: there is nothing to catch up with
        if self.state == NOT_CONTROLLING:
            self._done.notify_all()
            return
        if self._plan is not None and self.q is not None:
            self._hold = self.q.copy()
        self.outcome = why
        self._send_hold = True
        self._plan, self._jog, self.state = None, None, NOT_CONTROLLING
        self._done.notify_all()

    def hold_reference(self) -> Reference | None:
        """After a stop: where the arm should stay (measured position at the stop)."""
        with self._lock:
            return None if self._hold is None else self._still_at(self._hold)
