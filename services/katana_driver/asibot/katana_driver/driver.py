"""The Katana driver: the driver contract on top of `Katana`. No bus here.

One control thread owns the serial line: at CONTROL_RATE_HZ it reads every motor's position
and status ('N' twice), checks for a collision, advances the set-points (rate-limited to the
catalogue's max speeds, the firmware's own limit behind them) and sends the targets that
changed ('C'), then reports the arm and gripper state. Commands, the estop and the holder
arrive on other threads and only touch the set-points under a lock.

Estop, the command watchdog and a change of controller hold the arm where it is (every motor
MCF_FREEZE at its measured position); a fault (a collision, a silent controller, a refusal)
does the same and latches until reset_fault. After any of them a stream of commands from
before moves nothing until it pauses (asibot.safety.arming).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Callable

from asibot.katana_driver import protocol as p
from asibot.katana_driver.katana import (FIRMWARE_DEPENDENT_MOTOR, Interrupted, Katana, MotorParams, Silent,
                                         UnsupportedController, gripper_counts, gripper_opening)
from asibot.messages import ArmState, GripperState
from asibot.robots import RobotSpec
from asibot.safety.guarded_arm import EventSink, FaultError, GuardedArm
from asibot.safety.joint_reference import POSITION_TOLERANCE_RAD, check_gripper, check_limits
from asibot.timing import Ticker

log = logging.getLogger(__name__)

#: Cycles a second. One cycle is two 'N' (23 bytes each, request and reply) and at most six
#: 'C' (15 bytes each): 136 bytes, 24 ms at 57600 baud (10 bits a byte), within 40 ms.
CONTROL_RATE_HZ = 25
#: The fingers hold something when they were told to close this much further than they are.
GRIP_SLACK_M = 0.005

StateSink = Callable[[ArmState, GripperState], None]
__all__ = ["KatanaDriver", "FaultError"]


class KatanaDriver(GuardedArm):
    """Drives the arm of `spec` (the catalogue's Katana) through `katana`."""

    arm = "the Katana"
    line = "the serial cable"
    after_reset = "every motor holds its position"

    def __init__(self, katana: Katana, spec: RobotSpec, on_state: StateSink, on_event: EventSink, *,
                 calibrate: bool = True, rate_hz: float = CONTROL_RATE_HZ) -> None:
        super().__init__(list(spec.joint_names), on_event)
        self.katana = katana
        self.spec = spec
        self.joints: list[MotorParams] = list(katana.motors[:len(self.names)])
        self.gripper: MotorParams = katana.motors[len(self.names)]
        self.lower, self.upper, self.vmax = list(spec.lower), list(spec.upper), list(spec.max_velocity)
        self.n = len(self.names)
        self.on_state = on_state
        self.calibrate_first = calibrate
        self.period = 1.0 / rate_hz
        self._stop = threading.Event()
        self._abort_calibration = threading.Event()     # the estop or a shutdown during calibration
        self.fault = "The Katana is starting" + (" (calibrating)." if calibrate else ".")
        self._fault_code = "starting"
        self.mode = "idle"
        self.setpoint: list[float] = [0.0] * self.n   # rad, what the motors are told
        self._goal: list[float] = [0.0] * self.n
        self._velocity: list[float] = [0.0] * self.n
        self._sent: list[int | None] = [None] * (self.n + 1)
        self._gripper_goal: int | None = None
        self._gripper_command: float | None = None
        self._hold_pending = False
        self._measured: list[float] | None = None      # rad
        self._counts: list[int] | None = None
        self._rates: list[float] = [0.0] * self.n
        self._t_measured = 0.0
        self.counters["targets_sent"] = 0
        self._ticker: Ticker | None = None
        self._thread = threading.Thread(target=self._run, name="katana-control", daemon=True)

    # ------------------------------------------------------------ life cycle
    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._abort_calibration.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(3.0)
        try:
            if self._counts is not None and not self._faulted:
                self.katana.freeze(self._counts)
        except (Silent, p.ProtocolError, p.FirmwareError, OSError):
            pass

    # ------------------------------------------------------------ inputs (any thread)
    def command_gripper(self, opening: float, controller: str = "") -> bool:
        """Open the fingers to `opening` m; CommandRefused outside 0..max opening."""
        top = self.spec.gripper_max_opening
        check_gripper(opening, top)
        with self._lock:
            if not self.admits(controller, "the gripper"):
                return False
            self._gripper_command = opening
            self._gripper_goal = gripper_counts(opening, top, self.gripper)
            return True

    def status(self) -> dict:
        with self._lock:
            return {"names": self.names, "lower": self.lower, "upper": self.upper, "max_velocity": self.vmax,
                    "mode": self._mode(), "fault": self.fault, "estop": self.estop,
                    "control_rate_hz": round(1.0 / self.period, 3),
                    "counts": list(self._counts) if self._counts is not None else None}

    def health(self) -> dict:
        with self._lock:
            return {"mode": self._mode(), "fault": self.fault, **self.counters,
                    "requests": self.katana.requests, "retried": self.katana.retried}

    # ------------------------------------------------------------ the guarded arm's hooks, helpers (under the lock)
    def _mode(self) -> str:
        return "fault" if self._faulted else self.mode

    def _moving(self) -> bool:
        return any(v != 0.0 for v in self._velocity) or any(
            abs(g - s) > 1e-9 for g, s in zip(self._goal, self.setpoint))

    def _hold(self) -> None:
        """Stop where the arm is: set-points to the measured positions, frozen there next cycle."""
        if self._measured is not None:
            self.setpoint = list(self._measured)
        self._goal = list(self.setpoint)
        self._velocity = [0.0] * self.n
        self._gripper_goal = None
        self._hold_pending = True

    def _apply(self, mode: str, values: list[float], velocities: list[float], now: float) -> None:
        if mode == "position":
            self._goal = [min(max(v, lo), hi) if abs(v - min(max(v, lo), hi)) <= POSITION_TOLERANCE_RAD else v
                          for v, lo, hi in zip(values, self.lower, self.upper)]
            self._velocity = [0.0] * self.n
        else:
            self._velocity = [max(-m, min(m, v)) for v, m in zip(values, self.vmax)]
        self.mode = mode

    def _estop_engaged(self) -> None:
        self._abort_calibration.set()       # a calibration under way stops where it is

    def _streaming(self) -> bool:
        return self.mode == "velocity" and any(self._velocity)

    def _check_limits(self, mode: str, values: list[float], velocities: list[float]) -> None:
        here = [self.setpoint] + ([self._measured] if self._measured is not None else [])
        check_limits(self, mode, values, velocities, here)

    # ------------------------------------------------------------ the control thread
    def _run(self) -> None:
        try:
            self._bring_up()
        except Interrupted:
            self._enter_fault("startup", "The Katana's calibration was interrupted by the emergency stop: "
                              "every motor holds where it stands; release it, then call reset_fault to "
                              "calibrate again.")
        except UnsupportedController as exc:
            self._enter_fault("startup", str(exc))
        except (Silent, p.ProtocolError, p.FirmwareError, OSError) as exc:
            self._enter_fault("startup", self._sentence(exc, "starting"))
        self._ticker = Ticker(1.0 / self.period, self._stop)
        while self._ticker.wait():
            try:
                self._tick()
            except Exception:       # a bug must not silently stop the loop
                log.exception("control cycle failed")
                self._enter_fault("internal", "The Katana driver hit an internal error and stopped the arm; "
                                  "see its log, then call reset_fault.")

    def _bring_up(self) -> None:
        """KNI's order: the firmware asked (motor 3's counts per turn follow from it), then the
        calibration with collision detection off and each motor's search limits around its
        stopper search, then every motor's working limits and collision detection on."""
        self._identify()
        if self.calibrate_first:
            log.info("calibrating: every motor searches its mechanical stopper")
            with self._lock:
                if self.estop or self._stop.is_set():
                    raise Interrupted("the emergency stop is engaged")
                self._abort_calibration.clear()
            self.katana.calibrate(stop=self._abort_calibration)
        self._hold_here(self.katana.start())
        log.info("the Katana holds its position; motion commands are obeyed from now on")

    def _identify(self) -> None:
        joint = self.names[FIRMWARE_DEPENDENT_MOTOR - 1]
        identity = self.katana.identify(joint)
        log.info("Katana master firmware %d.%d, slave firmware %s", *identity.master,
                 ", ".join(f"motor {m.motor} {s if s is not None else '?'}"
                           for m, s in zip(self.katana.motors, identity.slaves)))
        with self._lock:
            self.joints = list(self.katana.motors[:self.n])
            self.gripper = self.katana.motors[self.n]
            for i, j in enumerate(self.joints):
                lo, hi = j.within_counter(self.spec.lower[i], self.spec.upper[i])
                if (lo, hi) != (self.spec.lower[i], self.spec.upper[i]):
                    log.warning("joint %s: %d counts per turn put part of its range beyond the 16-bit "
                                "positions of the line; it is driven within %.4f..%.4f rad", self.names[i],
                                j.encoders_per_cycle, lo, hi)
                self.lower[i], self.upper[i] = lo, hi

    def _hold_here(self, counts: list[int]) -> None:
        """The motors stand at `counts` and hold: the set-point is where they are, no fault."""
        with self._lock:
            self._take(counts, time.monotonic())
            self.setpoint = list(self._measured or self.setpoint)
            self._goal = list(self.setpoint)
            self._velocity = [0.0] * self.n
            self._sent = list(counts)
            self.fault, self._faulted, self._fault_code = "", False, ""
            self.mode = "idle"

    def _take(self, counts: list[int], now: float) -> None:
        rad = [j.to_rad(c) for j, c in zip(self.joints, counts)]
        if self._measured is not None and now > self._t_measured:
            dt = now - self._t_measured
            self._rates = [(a - b) / dt for a, b in zip(rad, self._measured)]
        self._measured, self._counts, self._t_measured = rad, list(counts), now

    def _tick(self) -> None:
        now = time.monotonic()
        if not (self._faulted and self._fault_code in ("silent", "startup")):   # silent: nothing to ask
            try:
                counts = self.katana.positions()
                statuses = self.katana.statuses()
                with self._lock:
                    self._take(counts, now)
                self._check_status(statuses)
                self._watch(now)
                self._send()
            except (Silent, p.ProtocolError, p.FirmwareError, OSError) as exc:
                code = "silent" if isinstance(exc, (Silent, OSError)) else "refused"
                self._enter_fault(code, self._sentence(exc, "running"))
        self.counters["cycles"] += 1
        self._publish()
        self._serve_reset()

    def _check_status(self, statuses: list[int]) -> None:
        for i, s in enumerate(statuses):
            if s == p.MSF_MOTCRASHED:
                what = f"joint {self.names[i]}" if i < self.n else "the gripper"
                self._enter_fault("collision", f"Motor {i + 1} ({what}) reports a collision (status "
                                  f"{s}, {p.status_name(s)}): the arm was stopped and holds where it is; "
                                  "free it, then call reset_fault.")
                return

    def _send(self) -> None:
        """Advance the set-points one period and send the targets that changed."""
        with self._lock:
            if self._faulted:
                return
            hold, self._hold_pending = self._hold_pending, False
            if hold:       # from where the arm stands now: what is frozen is the new set-point
                freeze = list(self._counts or [])
                if self._measured is not None:
                    self.setpoint = list(self._measured)
                    self._goal = list(self.setpoint)
            else:
                freeze = []
                dt = self.period
                new = []
                for i in range(self.n):
                    s, lo, hi, vmax = self.setpoint[i], self.lower[i], self.upper[i], self.vmax[i]
                    want = s + self._velocity[i] * dt if self.mode == "velocity" else self._goal[i]
                    step = max(-vmax * dt, min(vmax * dt, want - s))
                    new.append(min(max(s + step, min(lo, s)), max(hi, s)))
                self.setpoint = new
            targets = [j.to_counts(r) for j, r in zip(self.joints, self.setpoint)]
            gripper = self._gripper_goal
        if freeze:
            self.katana.freeze(freeze)
            with self._lock:
                self._sent = list(freeze)
            return
        for j, (m, t) in enumerate(zip(self.joints, targets)):
            if t != self._sent[j]:
                self.katana.set_target(m.motor, t)
                self._sent[j] = t
                self.counters["targets_sent"] += 1
        if gripper is not None and gripper != self._sent[self.n]:
            self.katana.set_target(self.gripper.motor, gripper)
            self._sent[self.n] = gripper
            self.counters["targets_sent"] += 1

    def _sentence(self, exc: Exception, when: str) -> str:
        if isinstance(exc, (Silent, OSError)):
            return (f"The Katana's controller stopped answering ({exc}): the arm was stopped; check its power "
                    "and the serial cable, then call reset_fault.")
        if isinstance(exc, p.FirmwareError):
            return f"While {when}, {exc}: the arm was stopped; call reset_fault."
        return f"While {when}, the Katana's answer made no sense ({exc}): the arm was stopped; call reset_fault."

    def _enter_fault(self, code: str, sentence: str) -> None:
        with self._lock:
            if self._faulted and self._fault_code not in ("starting",):
                return
            self._faulted = True
            self.fault, self._fault_code = sentence, code
            self._hold()
            counts = list(self._counts) if self._counts is not None else None
        self.counters["faults"] += 1
        if code not in ("silent", "startup") and counts is not None:
            try:
                self.katana.freeze(counts)      # hold where it stands; clears nothing
            except (Silent, p.ProtocolError, p.FirmwareError, OSError):
                pass
        log.error("%s", sentence)
        self.on_event("error", code, sentence)

    def _publish(self) -> None:
        with self._lock:
            if self._counts is None:
                return
            mode, fault = self._mode(), self.fault
            positions = list(self._measured or [])
            rates = list(self._rates)
            grip_counts = self._counts[self.n] if len(self._counts) > self.n else None
            commanded = self._gripper_command
        arm = ArmState(names=self.names, positions=positions, velocities=rates, mode=mode, fault=fault)
        top = self.spec.gripper_max_opening
        opening = gripper_opening(grip_counts, top, self.gripper) if grip_counts is not None else 0.0
        holding = commanded is not None and commanded + GRIP_SLACK_M < opening
        try:
            self.on_state(arm, GripperState(opening=opening, holding=holding))
        except Exception:
            log.exception("publishing the arm state failed")

    def _reset_failed(self, exc: Exception) -> FaultError | None:
        if isinstance(exc, UnsupportedController):
            return FaultError(str(exc))
        if isinstance(exc, Interrupted):
            return FaultError("The calibration was interrupted by the emergency stop; release it, then call "
                              "reset_fault again.")
        if isinstance(exc, (Silent, p.ProtocolError, p.FirmwareError, OSError)):
            return FaultError(self._sentence(exc, "resetting the fault").replace("call reset_fault",
                                                                                 "call reset_fault again"))
        return None

    def _reset(self) -> dict:
        was = self._fault_code
        if was in ("startup",):
            self._bring_up()
        else:
            counts = self.katana.positions()
            self.katana.freeze(counts)
            self._hold_here(counts)
        return {"was": was}
