"""The frames the master repeats at a fixed period: SYNC, the CSP set-points, its heartbeat.

Why not send them from the control loop: the loop is a Python thread that also reads feedback,
publishes states and runs fault resets, so its rhythm is Python's scheduling (issue 29: SYNC
stopped for 340-490 ms during every reset_fault and jittered up to p99 ~50 ms under load).
`PeriodicFrames` hands each frame to the interface's own periodic sender instead: on SocketCAN
that is the kernel's broadcast manager (BCM), which keeps sending at its period whatever the
process does and stops when the process dies (its socket closes). Interfaces without one get
python-can's sender thread, which does nothing but send. The control loop only updates the data
in place (`put`), so a late loop delays a new set-point, never SYNC.

`LoopFrames` is the old rhythm (the control loop sends every frame on each tick), kept so that
bench/bench_sync.py can measure both in one run.
"""

from __future__ import annotations

import logging
import threading
import time
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
        """Called by the control loop once per period."""

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

    def close(self) -> None:
        self._frames.clear()
        self._due.clear()
