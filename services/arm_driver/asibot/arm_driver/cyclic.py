"""The frames the master repeats at a fixed period: SYNC, the CSP set-points, its heartbeat.

Why not send them from the control loop: the loop is a Python thread that also reads feedback,
publishes states and runs fault resets, so its rhythm is Python's scheduling (issue 29: SYNC
stopped for 340-490 ms during every reset_fault and jittered up to p99 ~50 ms under load).
`PeriodicFrames` hands each frame to the interface's own periodic sender instead: on SocketCAN
that is the kernel's broadcast manager (BCM), which keeps sending at its period whatever the
process does and stops when the process dies (its socket closes). Interfaces without one get
python-can's sender thread, which does nothing but send. The control loop only updates the data
in place (`put`), so a late loop delays a new set-point, never SYNC.

`SyncedFrames` (the default since issue 53) sends SYNC and the CSP set-points from one clock
of its own, a sample for each SYNC: the periodic sender repeated each set-point independently
of SYNC, so a control period that came late left one SYNC without a new set-point and the next
with two steps at once (50 deg/s applied against a 25 deg/s joint). A drive in cyclic
synchronous position follows each step within one period, so the master's trajectory must be
sampled on the SYNC clock: a late control period is a late sample, the motion lags (counted in
`late`), never a bigger step.

`LoopFrames` is the old rhythm (the control loop sends every frame on each tick), kept so that
bench/bench_sync.py can measure both in one run.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from typing import Callable, Protocol

import can
from can.broadcastmanager import CyclicSendTaskABC, ModifiableCyclicTaskABC, ThreadBasedCyclicSendTask

log = logging.getLogger(__name__)

SYNC_COB_ID = 0x080


class CyclicFrames(Protocol):
    """Frames sent every `period` seconds until dropped."""

    error: str          # the last transmit error of a periodic sender, "" when none

    def put(self, cob_id: int, data: bytes, period: float) -> None:
        """Start sending `data` on `cob_id` every `period` s, or change the data of a running one in place."""

    def drop(self, cob_id: int) -> None:
        """Stop sending `cob_id` (no-op when it is not being sent)."""

    def sending(self) -> list[int]:
        """The COB-IDs being sent, lowest first."""

    def tick(self) -> None:
        """Called by the control loop once per period, after its set-points."""

    def room(self) -> bool:
        """Whether a new sample of set-points may be made now (False: the control loop holds
        its trajectory back for a period, so that none is lost or sent twice)."""

    def close(self) -> None:
        """Stop every frame."""


def _frame(cob_id: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=cob_id, data=data, is_extended_id=False)


def _check(cob_id: int, period: float) -> None:
    if not 0 <= cob_id <= 0x7FF:
        raise ValueError(f"COB-ID 0x{cob_id:X} is not an 11-bit CAN identifier")
    if not period > 0:
        raise ValueError(f"the period of COB-ID 0x{cob_id:03X} must be positive, got {period!r} s")


class PeriodicFrames:
    """Each frame is one task of the interface's periodic sender (SocketCAN: a BCM task)."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus
        self.error = ""
        self._tasks: dict[int, tuple[CyclicSendTaskABC, float]] = {}
        self._send_lock = threading.Lock()      # python-can's sender threads must not send at once
        # An interface has its own periodic sender when it overrides BusABC's thread fallback.
        self.native = type(bus)._send_periodic_internal is not can.BusABC._send_periodic_internal

    def put(self, cob_id: int, data: bytes, period: float) -> None:
        _check(cob_id, period)
        running = self._tasks.get(cob_id)
        if running is not None and running[1] != period:
            self.drop(cob_id)                   # a period cannot be changed in place
            running = None
        if running is None:
            self._tasks[cob_id] = (self._start(_frame(cob_id, data), period), period)
            return
        task = running[0]
        if bytes(task.messages[0].data) == data:
            return
        if isinstance(task, ModifiableCyclicTaskABC):
            task.modify_data(_frame(cob_id, data))   # the timer keeps running: no phase jump
        else:                                        # a sender that cannot: restart it with the data
            self.drop(cob_id)
            self._tasks[cob_id] = (self._start(_frame(cob_id, data), period), period)

    def _start(self, msg: can.Message, period: float) -> CyclicSendTaskABC:
        if self.native:
            return self.bus.send_periodic(msg, period, store_task=False)
        return ThreadBasedCyclicSendTask(self.bus, self._send_lock, msg, period, on_error=self._failed)

    def _failed(self, exc: Exception) -> bool:
        # Keep trying, as a CAN controller does after a full buffer; the control loop reports it.
        self.error = str(exc) or type(exc).__name__
        return True

    def drop(self, cob_id: int) -> None:
        running = self._tasks.pop(cob_id, None)
        if running is not None:
            try:
                running[0].stop()
            except (can.CanError, OSError):     # the interface may already be gone
                log.debug("stopping the periodic 0x%03X failed", cob_id, exc_info=True)

    def sending(self) -> list[int]:
        return sorted(self._tasks)

    def tick(self) -> None:
        pass

    def room(self) -> bool:
        return True

    def close(self) -> None:
        for cob_id in list(self._tasks):
            self.drop(cob_id)


class LoopFrames:
    """The control loop sends the frames itself on tick(): set-points first, SYNC last."""

    def __init__(self, send: Callable[[int, bytes], None]) -> None:
        self.error = ""
        self._send = send
        self._frames: dict[int, tuple[bytes, float]] = {}
        self._due: dict[int, float] = {}

    def put(self, cob_id: int, data: bytes, period: float) -> None:
        _check(cob_id, period)
        self._frames[cob_id] = (data, period)
        self._due.setdefault(cob_id, 0.0)

    def drop(self, cob_id: int) -> None:
        self._frames.pop(cob_id, None)
        self._due.pop(cob_id, None)

    def sending(self) -> list[int]:
        return sorted(self._frames)

    def tick(self) -> None:
        now = time.monotonic()
        for cob_id in sorted(self._frames, key=lambda c: c == SYNC_COB_ID):
            data, period = self._frames[cob_id]
            if now >= self._due[cob_id] - period / 2:        # once per tick at the control rate
                self._due[cob_id] = max(self._due[cob_id] + period, now)
                self._send(cob_id, data)

    def room(self) -> bool:
        return True

    def close(self) -> None:
        self._frames.clear()
        self._due.clear()


#: The shortest gap between two SYNCs, as a share of the period: a SYNC that came late is
#: followed by the next at least this much later, never at once (no burst of catch-up steps).
MIN_GAP = 0.5


class SyncedFrames:
    """SYNC and the set-points from one clock: before each SYNC, the set-points of one sample.

    The control loop writes each drive's set-point with `put(cob_id, data, period)` (the SYNC
    period) and closes the sample with `tick()`; up to `depth` samples wait, and each SYNC takes
    at most one. With none waiting, the SYNC repeats the last (the drives hold: the motion lags,
    counted in `late`); with `depth` waiting, `room()` is False and the loop makes no new one.
    A drive's first set-point (after `drop`, a reset) is sent as it is: it holds where the drive
    stands. Frames of any other period (the heartbeat) go to the interface's periodic sender.
    """

    def __init__(self, bus: can.BusABC, period: float, send: Callable[[int, bytes], None],
                 depth: int = 2) -> None:
        _check(SYNC_COB_ID, period)
        self.period = period
        self.depth = depth
        self.error = ""
        self.syncs = 0
        self.late = 0               # SYNCs that found no new sample: the loop was late
        self.longest_late = 0       # the most in a row
        self._others = PeriodicFrames(bus)
        self._send = send
        self._lock = threading.Lock()
        self._current: dict[int, bytes] = {}            # what the drives hold: sent before each SYNC
        self._sample: dict[int, bytes] = {}             # the sample the loop is making
        self._waiting: deque[dict[int, bytes]] = deque()
        self._run_late = 0
        self._streaming = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # ------------------------------------------------------------ the control loop's side
    def put(self, cob_id: int, data: bytes, period: float) -> None:
        _check(cob_id, period)
        if cob_id == SYNC_COB_ID:
            if period != self.period:
                raise ValueError(f"SYNC runs every {self.period:g} s here, not {period:g} s")
            self._start()
            return
        if period != self.period:
            self._others.put(cob_id, data, period)
            return
        with self._lock:
            if cob_id in self._current:
                self._sample[cob_id] = data
            else:
                self._current[cob_id] = data            # a drive's first: where it stands

    def tick(self) -> None:
        with self._lock:
            if self._sample:
                self._waiting.append(self._sample)
                self._sample = {}
                self._streaming = True

    def room(self) -> bool:
        with self._lock:
            return len(self._waiting) < self.depth

    def drop(self, cob_id: int) -> None:
        if cob_id == SYNC_COB_ID:
            self._halt()
            return
        self._others.drop(cob_id)
        with self._lock:
            self._current.pop(cob_id, None)
            self._sample.pop(cob_id, None)
            for sample in self._waiting:
                sample.pop(cob_id, None)

    def sending(self) -> list[int]:
        with self._lock:
            ours = set(self._current) | ({SYNC_COB_ID} if self._thread is not None else set())
        return sorted(ours | set(self._others.sending()))

    def close(self) -> None:
        self._halt()
        self._others.close()
        with self._lock:
            self._current.clear()
            self._sample.clear()
            self._waiting.clear()
            self._streaming, self._run_late = False, 0

    # ------------------------------------------------------------ the clock
    def _start(self) -> None:
        if self._thread is not None:
            return
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(self._stop,), name="canopen-sync", daemon=True)
        self._thread.start()

    def _halt(self) -> None:
        thread, self._thread = self._thread, None
        if thread is not None:
            self._stop.set()
            if thread is not threading.current_thread():
                thread.join(1.0)

    def _run(self, stop: threading.Event) -> None:
        due = time.monotonic()
        while True:
            wait = due - time.monotonic()
            if stop.wait(wait) if wait > 0 else stop.is_set():
                return
            frames = self._next()
            sent = time.monotonic()
            try:
                for cob_id, data in frames:
                    self._send(cob_id, data)
                self._send(SYNC_COB_ID, b"")
            except (can.CanError, OSError) as exc:
                self.error = str(exc) or type(exc).__name__     # the control loop reports it
            self.syncs += 1
            due = max(due + self.period, sent + MIN_GAP * self.period)

    def _next(self) -> list[tuple[int, bytes]]:
        """The set-points for this SYNC: the next sample over what the drives hold."""
        with self._lock:
            if self._waiting:
                self._current.update(self._waiting.popleft())
                self._run_late = 0
            elif self._streaming:
                self.late += 1
                self._run_late += 1
                self.longest_late = max(self.longest_late, self._run_late)
            return sorted(self._current.items())
