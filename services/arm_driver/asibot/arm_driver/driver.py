"""The ASIBOT arm driver: the driver contract on top of the CANopen master. No Zenoh here.

One control thread owns the CAN master: at the control rate it checks the drives (EMCY,
heartbeats, statuswords, bus-off), advances the set-points, sends them with SYNC and reports
the arm state. Commands, estop and liveliness arrive from other threads and only touch the
set-point generator under a lock. Any fault quick-stops every drive and latches until
reset_fault; estop, the command watchdog and a vanished controller hold position instead.
Whose commands are obeyed is decided by the service (asibot.safety.ownership); after a fault reset,
an estop release or a change of controller, a stream of commands from before moves nothing
until it pauses (asibot.safety.arming).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Callable

from asibot.arm_driver import emcy, objects
from asibot.arm_driver.cia402 import State
from asibot.arm_driver.config import ArmConfig
from asibot.arm_driver.master import CanopenMaster, DriveError, Feedback, LoopStalled
from asibot.safety.joint_reference import JointReference
from asibot.messages import ArmState
from asibot.safety.guarded_arm import EventSink, FaultError, ReferencedArm
from asibot.timing import Ticker

log = logging.getLogger(__name__)

StateSink = Callable[[ArmState], None]
MODE_NAMES = {objects.MODE_CSP: "cyclic synchronous position", objects.MODE_PROFILE_POSITION: "profile position"}

__all__ = ["ArmDriver", "FaultError"]


class ArmDriver(ReferencedArm):
    """Drives the arm described by `config` through `master`."""

    arm = "the ASIBOT"
    line = "the CAN bus"
    after_reset = "the drives are enabled and hold their position"

    def __init__(self, master: CanopenMaster, config: ArmConfig, on_state: StateSink, on_event: EventSink) -> None:
        super().__init__(config.names, on_event)
        self.master = master
        self.config = config
        self.on_state = on_state
        self.joints = config.joints
        self.ref = JointReference([j.lower for j in config.joints], [j.upper for j in config.joints],
                                  [j.max_velocity for j in config.joints], config.period, names=config.names)
        self.watchdog = self.ref.watchdog       # one watchdog: the reference's, which its feed-forward reads
        self._stop = threading.Event()
        self._up: set[int] = set()
        self.fault = "The drives are starting."
        self._fault_code: tuple[str, int] = ("starting", 0)
        self._reported: set[tuple[str, int]] = set()
        self._feedback: dict[int, Feedback] = {}
        self.counters["tx_errors"] = 0
        self._ticker: Ticker | None = None
        self._thread = threading.Thread(target=self._run, name="arm-control", daemon=True)

    # ------------------------------------------------------------ life cycle
    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(2.0)
        for node in list(self._up):
            try:
                self.master.quick_stop(node)
            except DriveError:
                pass
        self.master.close()

    # ------------------------------------------------------------ the guarded arm's hooks (under the lock)
    def _measured(self) -> list[float] | None:
        fb = self._feedback
        return [j.units.to_rad(fb[j.node].position) for j in self.joints] if all(j.node in fb for j in self.joints) \
            else None

    # ------------------------------------------------------------ state (any thread)
    def status(self) -> dict:
        with self._lock:
            fb = self._feedback
            drives = [{
                "joint": j.name, "node": j.node,
                "state": fb[j.node].state.value if j.node in fb else "unknown",
                "nmt": fb[j.node].nmt_state if j.node in fb else None,
                "mode": self._mode_name(j.node),
            } for j in self.joints]
            return {
                "names": self.config.names,
                "lower": [j.lower for j in self.joints], "upper": [j.upper for j in self.joints],
                "max_velocity": [j.max_velocity for j in self.joints],
                "mode": self._mode(), "fault": self.fault, "estop": self.estop, "drives": drives,
                "control_rate_hz": self.config.control_rate_hz,
            }

    def health(self) -> dict:
        with self._lock:
            stats = self._ticker.stats() if self._ticker else {}
            return {"mode": self._mode(), "fault": self.fault, **self.counters,
                    "frames_sent": self.master.frames_sent, **self.master.lag(),
                    "period_jitter_p99_ms": round(stats.get("p99", 0.0) * 1000, 3)}

    def _mode(self) -> str:
        return "fault" if self._faulted else self.ref.mode

    # ------------------------------------------------------------ the control thread
    def _run(self) -> None:
        try:
            # SYNC and the heartbeat first: each drive enabled below is then never without them.
            self.master.start_cyclic()
            self._bring_up(self.config.nodes)
        except DriveError as exc:
            self._enter_fault("startup", 0, str(exc))
        self._ticker = Ticker(self.config.control_rate_hz, self._stop)
        while self._ticker.wait():
            try:
                self._tick()
            except Exception:       # a bug must not silently stop the SYNC loop
                log.exception("control cycle failed")
                self._enter_fault("internal", 0, "The arm driver hit an internal error and stopped the arm; "
                                  "see its log, then call reset_fault.")

    def _bring_up(self, nodes: list[int]) -> None:
        # No NMT reset first: it would restart a drive's position counter, and q1/q5 have no
        # absolute encoder to recover it from (docs/canopen.md, "Absolute encoders"). Configuring
        # is idempotent. Every drive is configured before any is enabled, so that a drive that
        # cannot be configured (an encoder without an angle) leaves the arm off. SYNC and each
        # enabled drive's held set-point keep flowing meanwhile (the periodic sender's).
        with self.master.bringing_up():
            for node in nodes:
                self.master.configure(node)
                self.master.start(node)
            for node in self.config.nodes:
                self.master.enable(node)
                self._up.add(node)      # enabled: a fault from here on quick-stops it
        fb = self.master.snapshot()
        with self._lock:
            self._feedback = fb
            self._up = set(self.config.nodes)
            self.ref.reset([j.units.to_rad(fb[j.node].position) for j in self.joints])
            self.fault, self._faulted, self._fault_code = "", False, ("", 0)
            self._reported.clear()
        log.info("drives enabled in %s", ", ".join(sorted({MODE_NAMES[m] for m in self.master.modes.values()})))

    def _tick(self) -> None:
        try:
            self.master.pulse()
        except LoopStalled as exc:
            self._enter_fault("loop_stalled", 0, str(exc))
        now = time.monotonic()
        fb = self.master.snapshot()
        with self._lock:
            self._feedback = fb
        self._check(fb, now)
        self._watch(now)
        with self._lock:
            if not self.master.room():
                targets = {}        # SYNC has not taken the last samples: the motion lags, never jumps
            elif self._faulted:
                targets = {n: fb[n].position for n in self.master.modes}
            else:
                rad = self.ref.step(now)
                targets = {j.node: j.units.to_counts(r) for j, r in zip(self.joints, rad)}
        try:
            self.master.cycle(targets)
        except DriveError as exc:
            self.counters["tx_errors"] += 1
            self._enter_fault("bus_off", 0, str(exc))
        self.counters["cycles"] += 1
        self._publish(fb)
        self._serve_reset()

    def _check(self, fb: dict[int, Feedback], now: float) -> None:
        # A drive is silent when, on the bus's own clock, others spoke well after its heartbeat
        # was due. Frame time stamps, not the time we read them: a busy machine can stall the
        # CAN reader, and frames read in a burst afterwards must not make the ones still queued
        # look missing. A bus on which nobody speaks at all is caught here, after two timeouts.
        timeout = self.config.heartbeat_timeout
        heard = max(max(f.heartbeat_time, f.position_time) for f in fb.values())
        if self._up and now - heard > 2 * timeout:
            self._enter_fault("bus_silent", 0, f"No drive has said anything on CAN for {now - heard:.2f} s: "
                              "the arm was stopped; check the drives' power and the CAN cable, then call "
                              "reset_fault.")
        for j in self.joints:
            f = fb[j.node]
            who = f"Drive {j.node} (joint {j.name})"
            for e in f.emcys:
                if not e.is_reset:
                    self._enter_fault(f"emcy_{e.code:04x}", j.node, emcy.sentence(e, j.node, j.name))
            if j.node not in self._up:
                continue
            if f.booted:
                self._enter_fault("drive_restarted", j.node, f"{who} restarted (boot-up message): the arm was "
                                  "stopped; check its power supply "
                                  "and that the position it reports is right, then call reset_fault.")
            elif self._silent(f, fb, now):
                self._enter_fault("heartbeat_lost", j.node, f"{who} went silent (no heartbeat for "
                                  f"{now - f.heartbeat_time:.2f} s): the arm was stopped; check its power and "
                                  "CAN cable, then call reset_fault.")
            elif f.state in (State.FAULT, State.FAULT_REACTION_ACTIVE) and not any(
                    c.startswith("emcy_") and n == j.node for c, n in self._reported):
                self._enter_fault("drive_fault", j.node, f"{who} is in fault (statusword 0x{f.statusword:04X}, "
                                  f"motion error register 0x{f.mer:04X}): the arm was stopped; call reset_fault.")
            elif not self._faulted and f.state is not State.OPERATION_ENABLED:
                self._enter_fault("drive_disabled", j.node, f"{who} left operation enabled (now "
                                  f"'{f.state.value}'): the arm was stopped; check its enable input, then call "
                                  "reset_fault.")
        if self.master.bus_off:
            self._enter_fault("bus_off", 0, "The CAN controller went bus-off (too many transmission errors): "
                              "the arm was stopped; check the cable, termination and bit rate, then call reset_fault.")

    def _silent(self, f: Feedback, fb: dict[int, Feedback], now: float) -> bool:
        timeout = self.config.heartbeat_timeout
        if now - f.heartbeat_time <= timeout:
            return False
        if len(fb) == 1 or f.heartbeat_stamp is None:
            return True
        return max(g.stamp for g in fb.values()) - f.heartbeat_stamp > timeout

    def _enter_fault(self, code: str, node: int, sentence: str) -> None:
        if (code, node) in self._reported:
            return
        self._reported.add((code, node))
        with self._lock:
            first = not self._faulted
            self._faulted = True
            # The first fault explains the stop; an EMCY refines a bare statusword fault of its drive.
            replace = first or self._fault_code[0] == "starting" or (
                code.startswith("emcy_") and self._fault_code == ("drive_fault", node))
            if replace:
                self.fault, self._fault_code = sentence, (code, node)
            self.ref.hold()
        self.counters["faults"] += 1
        if first:
            self._quick_stop_all()
        log.error("%s", sentence)
        self.on_event("error", code, sentence)

    def _quick_stop_all(self) -> None:
        for n in sorted(self._up):
            try:
                self.master.quick_stop(n)
            except DriveError:
                self.counters["tx_errors"] += 1

    def _publish(self, fb: dict[int, Feedback]) -> None:
        with self._lock:
            mode, fault = self._mode(), self.fault
        state = ArmState(names=self.config.names,
                         positions=[j.units.to_rad(fb[j.node].position) for j in self.joints],
                         velocities=[j.units.to_rad(fb[j.node].velocity) for j in self.joints],
                         mode=mode, fault=fault)
        try:
            self.on_state(state)
        except Exception:
            log.exception("publishing the arm state failed")

    def _reset_failed(self, exc: Exception) -> FaultError | None:
        if not isinstance(exc, DriveError):
            return None
        with self._lock:
            self.fault = str(exc)
            self._faulted = True
        self._quick_stop_all()      # the drives this reset enabled before it failed
        return FaultError(str(exc))

    def _reset(self) -> dict:
        self.master.bus_off = False
        self.master.tx_error = ""
        now = time.monotonic()
        fb = self.master.snapshot()
        # A drive that went silent is brought up again even when its heartbeat came back before
        # this reset was served: its own heartbeat consumer may have left it pre-operational.
        lost = [j.node for j in self.joints
                if j.node not in self._up or fb[j.node].booted or self._silent(fb[j.node], fb, now)
                or ("heartbeat_lost", j.node) in self._reported]
        log.info("resetting the fault; re-initialising drives %s", lost or "none")
        self.master.start_cyclic()      # again, if the loop guard had stopped SYNC and the heartbeat
        self._bring_up(lost)
        self.master.snapshot()          # the error-reset EMCYs of this reset are not news
        return {"reinitialised": [self._name(n) for n in lost]}

    def _mode_name(self, node: int) -> str:
        mode = self.master.modes.get(node)
        return "not configured" if mode is None else MODE_NAMES.get(mode, "not configured")

    def _name(self, node: int) -> str:
        return next(j.name for j in self.joints if j.node == node)
