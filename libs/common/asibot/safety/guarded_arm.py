"""What every arm driver does the same way around its own motion, written once.

An arm driver (the ASIBOT's over CANopen, the Katana's over its serial line) owns a control
thread and a way of holding its motors; the rest is the same for every arm beside a person:

- a command is checked whole before anything changes: its shape, then the arm's own limits
  (`_check_limits`), then whether its controller may move the arm now (asibot.safety.arming);
  under the emergency stop or a fault it is ignored, never queued;
- the emergency stop holds the arm where it is and, once released, arms it again only for a
  new stream of commands;
- a change of the controller that holds the arm stops a moving arm and does the same;
- the command watchdog stops a stream that went quiet;
- a fault reset is asked for on any thread and done on the control thread, which alone
  talks to the motors (`reset_fault` waits for `_serve_reset`, which the control thread
  calls once a cycle).

Each of these tells the user through `on_event(level, code, text)` in the same words for
every arm. A subclass gives `_hold`, `_moving`, `_streaming`, `_check_limits`, `_apply` and
`_reset`, and sets `arm` (its name in a sentence), `line` (what to check when a reset hangs),
`after_reset` (how the arm stands then) and `held` (what the estop leaves it doing). The sim
gives its own clock (simulated time) and lock (the physics step's), and serves a reset at once
(`_wait_for_reset`): whoever holds its lock is its control thread.
"""

from __future__ import annotations

import abc
import threading
import time
from typing import Callable

from asibot.safety.arming import Arming
from asibot.safety.events import estop_said
from asibot.safety.joint_reference import JointReference
from asibot.safety.watchdog import Watchdog

EventSink = Callable[[str, str, str], None]      # level, code, text
MODES = ("position", "velocity")


class FaultError(Exception):
    """reset_fault could not clear the fault; the message says why and what to do."""


class GuardedArm(abc.ABC):
    """The safety around an arm driver's motion (see the module). Not a driver by itself."""

    arm = "the arm"
    """The arm's name in a sentence: "the ASIBOT has 6 joints"."""
    line = "the cable"
    """What to check when a fault reset does not finish: "the CAN bus", "the serial cable"."""
    after_reset = "the arm holds its position"
    """How the arm stands after a fault reset, in "The fault was reset: ..."."""
    held = "the arm holds its position and ignores motion commands until it is released"
    """What the robot does under the emergency stop, in its Event (asibot.safety.events.estop_said)."""

    def __init__(self, names: list[str], on_event: EventSink, *, clock: Callable[[], float] = time.monotonic,
                 lock: threading.RLock | None = None) -> None:
        self.names = list(names)
        self.on_event = on_event
        self.clock = clock
        self._lock = lock if lock is not None else threading.RLock()
        self.estop = False
        self._faulted = True               # until the control thread has brought the arm up
        self.arming = Arming()             # a driver starts armed (asibot.safety.arming says why)
        self.watchdog = Watchdog()
        self._reset_request: tuple[threading.Event, list[dict | Exception]] | None = None
        self.counters = {"cycles": 0, "rejected_commands": 0, "ignored_commands": 0, "not_ready": 0, "faults": 0}

    # ------------------------------------------------------------ what a driver gives
    @abc.abstractmethod
    def _hold(self) -> None:
        """Stop where the arm is, now (called under the lock)."""

    @abc.abstractmethod
    def _moving(self) -> bool:
        """Whether the arm is on its way somewhere (under the lock)."""

    @abc.abstractmethod
    def _streaming(self) -> bool:
        """Whether a stream of commands moves the arm, which the watchdog must see go on (under the lock)."""

    @abc.abstractmethod
    def _check_limits(self, mode: str, values: list[float], velocities: list[float]) -> None:
        """Refuse (CommandRefused, a ValueError) a command beyond the arm's limits (under the lock)."""

    @abc.abstractmethod
    def _apply(self, mode: str, values: list[float], velocities: list[float], now: float) -> None:
        """Move as the command says: it was checked, and may move the arm (under the lock)."""

    @abc.abstractmethod
    def _reset(self) -> dict:
        """Clear the latched fault, on the control thread; what the reply says. Raise to fail it."""

    def _estop_engaged(self) -> None:
        """Whatever else the emergency stop stops (under the lock, the arm already held)."""

    def _reset_failed(self, exc: Exception) -> FaultError | None:
        """The sentence of a reset that raised `exc`, or None for a bug (it is raised on)."""
        return None

    # ------------------------------------------------------------ inputs (any thread)
    def command(self, mode: str, values: list[float], velocities: list[float] | None = None,
                controller: str = "") -> bool:
        """Apply an ArmCommand of `controller` (the holder: the service checked). Raises
        ValueError (and changes nothing: the arm keeps its previous motion) on bad input;
        CommandRefused for a value beyond a joint's limits or max speed, or not finite: such a
        command is refused whole, never clipped; arming's NotReady for a command that
        continues a stream from before the last recovery.

        Returns False when the command was ignored because of the estop or a fault.
        """
        n = len(self.names)
        if mode not in MODES:
            self._reject(f"mode must be 'position' or 'velocity', got {mode!r}")
        if len(values) != n:
            self._reject(f"{self.arm} has {n} joints ({', '.join(self.names)}); the command has {len(values)} values")
        if velocities and len(velocities) != n:
            self._reject(f"velocities must be empty or have {n} values, not {len(velocities)}")
        values, velocities = [float(v) for v in values], [float(v) for v in velocities or []]
        with self._lock:
            try:
                self._check_limits(mode, values, velocities)
            except ValueError:
                self.counters["rejected_commands"] += 1
                raise
            now = self.clock()
            if not self._may_move(controller, now, "the arm"):
                return False
            self.watchdog.feed(now)        # a command of the arm's, not the gripper's, keeps a stream going
            self._apply(mode, values, velocities, now)
            return True

    def heard(self, controller: str) -> None:
        """A command of a controller that does not hold the arm (refused by the service): noted,
        so that its stream does not move the arm the moment it takes over."""
        with self._lock:
            self.arming.heard(controller, self.clock())

    def set_estop(self, engaged: bool, reason: str = "", by: str = "") -> None:
        with self._lock:
            if engaged == self.estop:
                return
            self.estop = engaged
            who = f" by {by}" if by else ""
            if engaged:
                self._hold()
                self._estop_engaged()
            else:
                self.arming.disarm(f"the emergency stop was released{who}")
                ready = self.arming.ready_text("The arm")
        self.on_event(*estop_said(engaged, reason, by, self.held))
        if not engaged:
            self.on_event("info", "ready", ready)

    def set_controller(self, holder: str | None) -> None:
        """The controller that holds the arm changed (asibot.safety.ownership): stop if the arm was
        moving, and arm again for the new holder, if any."""
        with self._lock:
            moving = self._moving()
            if moving:
                self._hold()
            if holder is not None:
                self.arming.disarm(f"controller {holder!r} took hold of it")
                ready = self.arming.ready_text("The arm")
            else:
                self.arming.disarm("its controller disappeared")
        if moving:
            self.on_event("warning", "controller_lost",
                          "The controller of the arm changed or disappeared while the arm was moving: the arm stopped.")
        if holder is not None:
            self.on_event("info", "ready", ready)

    def reset_fault(self, timeout: float = 10.0) -> dict:
        """Clear a latched fault, on the control thread; FaultError with a sentence when it cannot."""
        done = threading.Event()
        result: list[dict | Exception] = []
        with self._lock:
            if self._reset_request is not None:
                raise FaultError("A fault reset is already running; wait for it to finish.")
            self._reset_request = (done, result)
        self._wait_for_reset(done, timeout)
        outcome = result[0]
        if isinstance(outcome, Exception):
            raise FaultError(str(outcome))
        return outcome

    def admits(self, controller: str, what: str) -> bool:
        """Whether a checked command of `controller` for `what` ("the gripper") moves it now, by
        the arm's rules (`_may_move`): False under the estop or a fault; arming's NotReady for a
        stream from before a recovery."""
        with self._lock:
            return self._may_move(controller, self.clock(), what)

    # ------------------------------------------------------------ for the driver
    def _wait_for_reset(self, done: threading.Event, timeout: float) -> None:
        """Until the control thread has served the reset asked for (`_serve_reset`)."""
        if not done.wait(timeout):
            raise FaultError(f"The fault reset did not finish within {timeout:g} s; check {self.line}.")

    def _reject(self, sentence: str) -> None:
        self.counters["rejected_commands"] += 1
        raise ValueError(sentence)

    def _may_move(self, controller: str, now: float, what: str) -> bool:
        """Whether a checked command of `controller` moves `what` now (under the lock): False when
        the estop or a fault ignores it, arming's NotReady for a stream from before a recovery."""
        may_move = self.arming.admit(controller, now)      # noted even when ignored below
        if self.estop or self._faulted:
            self.counters["ignored_commands"] += 1
            return False
        if not may_move:
            self.counters["not_ready"] += 1
            raise self.arming.refusal(what)
        return True

    def _watch(self, now: float) -> None:
        """The command watchdog, once a cycle on the control thread."""
        with self._lock:
            fired = self.watchdog.fires(now, self._streaming())
            if fired:
                self._hold()
        if fired:
            self.on_event("warning", "watchdog", self.watchdog.says("velocity command",
                                                                    "the arm stopped and holds its position"))

    def _serve_reset(self) -> None:
        """Do a fault reset asked for, once a cycle on the control thread."""
        with self._lock:
            request, self._reset_request = self._reset_request, None
        if request is None:
            return
        done, result = request
        try:
            try:
                reply = self._reset()
            except Exception as exc:
                failed = self._reset_failed(exc)
                if failed is None:
                    raise
                result.append(failed)
                return
            with self._lock:               # before the caller hears of it: its next command is a new stream
                self.arming.disarm("the fault was reset")
                ready = self.arming.ready_text("The arm")
            self.on_event("info", "fault_reset", f"The fault was reset: {self.after_reset}.")
            self.on_event("info", "ready", ready)
            result.append(reply)
        finally:
            if not result:                 # a bug: the caller hears so, the control thread logs it
                result.append(FaultError("The fault reset hit an internal error; see the driver's log."))
            done.set()


class ReferencedArm(GuardedArm):
    """A GuardedArm whose motors follow a JointReference's set-points (asibot.safety.joint_reference):
    the CANopen driver's drives in cyclic synchronous position, the sim's servos. It sets `ref`,
    and gives `_measured` (where the joints are, rad, or None before they report), `_reset` and
    how its motors are driven."""

    ref: JointReference

    @abc.abstractmethod
    def _measured(self) -> list[float] | None:
        """Where the joints are now (rad); None while not every joint has reported."""

    def _check_limits(self, mode: str, values: list[float], velocities: list[float]) -> None:
        self.ref.check(mode, values, velocities, self._measured())

    def _apply(self, mode: str, values: list[float], velocities: list[float], now: float) -> None:
        if mode == "position":
            self.ref.position(values, velocities, now, self._measured())
        else:
            self.ref.velocity(values, now)

    def _hold(self) -> None:
        self.ref.hold()

    def _moving(self) -> bool:
        return self.ref.moving

    def _streaming(self) -> bool:
        return self.ref.streaming
