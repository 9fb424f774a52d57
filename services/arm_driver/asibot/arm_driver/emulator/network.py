"""Five (or any number of) emulated drives on one python-can bus, with fault injection.

One thread reads the bus, routes each frame to the drives it concerns, lets time pass for
them, and writes their answers back. Absolute encoder boards (`encoder.py`) answer polls
with their joint's real angle. Faults are injected from any thread: over-current (EMCY
0x2310), heartbeat loss, a silent (unplugged) drive, a reboot or power cycle, bus-off, and a
silent or failing encoder board.
Bus-off is what the master's own controller would report: an error frame with the SocketCAN
CAN_ERR_BUSOFF class, then no traffic in either direction until it recovers.

`start_private()` is what `--can emulated` uses: the drives run in the driver's process on a
private python-can virtual channel. Why in-process: python-can's only interfaces that link two
processes without hardware are udp_multicast (not allowed on loopback-only machines) and vcan
(needs a kernel module); a hand-written TCP bus would add a second, untested wire to the one
under test. In-process keeps the frames byte-identical to a real bus and needs nothing.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from typing import Iterable

import can

from asibot.arm_driver.config import ArmConfig
from asibot.arm_driver.emulator import encoder
from asibot.arm_driver.emulator.drive import EmulatedDrive

log = logging.getLogger("asibot.arm_driver.emulator")

CAN_ERR_BUSOFF = 0x00000040      # linux/can/error.h error classes, as python-can delivers them
CAN_ERR_RESTARTED = 0x00000100
POLL_S = 0.005


def encoders_of(config: ArmConfig) -> dict[int, tuple[int, bool]]:
    """The `encoders` argument that emulates the absolute encoders a configuration names."""
    return {j.absolute.can_id: (j.node, j.absolute.reverse) for j in config.joints if j.absolute}


class DriveEmulator:
    """Runs EmulatedDrives on `bus` until close()."""

    def __init__(self, bus: can.BusABC, nodes: Iterable[int] = (1, 2, 3, 4, 5), *,
                 supports_csp: bool = True, max_speed: float = math.radians(30),
                 counts_per_rad: float = 160 * 4096 / (2 * math.pi),
                 positions: dict[int, float] | None = None,
                 encoders: dict[int, tuple[int, bool]] | None = None) -> None:
        self.bus = bus
        self.drives = {n: EmulatedDrive(n, supports_csp=supports_csp, max_speed=max_speed,
                                        counts_per_rad=counts_per_rad,
                                        position=(positions or {}).get(n, 0.0)) for n in nodes}
        self.encoders = dict(encoders or {})      # CAN id -> (drive node, reverse)
        self._encoder_faults: dict[int, str] = {}
        self._silent: set[int] = set()
        self._bus_off_until = 0.0
        self._bus_off_reported = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self.frames_in = 0
        self.frames_out = 0
        self._thread = threading.Thread(target=self._run, name="can-emulator", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------ fault injection
    def over_current(self, node: int) -> None:
        with self._lock:
            self._send(node, self._drive(node).inject_over_current())

    def heartbeat_loss(self, node: int, lost: bool = True) -> None:
        with self._lock:
            self._drive(node).heartbeat_lost = lost

    def silent(self, node: int, silent: bool = True) -> None:
        """Unplug (or plug back) one drive: it neither hears nor says anything."""
        with self._lock:
            self._drive(node)
            (self._silent.add if silent else self._silent.discard)(node)

    def reboot(self, node: int) -> None:
        with self._lock:
            self._drive(node).reboot()

    def power_cycle(self, node: int) -> None:
        """Switch one drive off and on: its position counter restarts at 0 where the joint is."""
        with self._lock:
            self._drive(node).power_cycle()

    def encoder_fault(self, can_id: int, fault: str | None) -> None:
        """An absolute encoder board goes 'silent', answers 'error' (the PIC's 0xC4), or None: works."""
        if can_id not in self.encoders:
            raise ValueError(f"no emulated absolute encoder with CAN id {can_id}; there are {sorted(self.encoders)}")
        if fault not in (None, "silent", "error"):
            raise ValueError("an encoder fault is 'silent', 'error' or None")
        with self._lock:
            if fault is None:
                self._encoder_faults.pop(can_id, None)
            else:
                self._encoder_faults[can_id] = fault

    def bus_off(self, duration: float) -> None:
        """The master's controller goes bus-off for `duration` seconds."""
        if not (math.isfinite(duration) and duration > 0):
            raise ValueError("bus-off duration must be a positive number of seconds")
        with self._lock:
            self._bus_off_until = time.monotonic() + duration
            self._bus_off_reported = True
            self._error_frame(CAN_ERR_BUSOFF)

    def clear(self) -> None:
        """Plug every drive and encoder back in and restore heartbeats (drive faults stay until
        reset by the master)."""
        with self._lock:
            self._silent.clear()
            self._encoder_faults.clear()
            for d in self.drives.values():
                d.heartbeat_lost = False

    def positions(self) -> dict[int, float]:
        """Joint positions in rad, per node, as the drives count them."""
        with self._lock:
            return {n: d.position / d.counts_per_rad for n, d in self.drives.items()}

    def joint_angles(self) -> dict[int, float]:
        """Where the joints really are, rad, per node (differs from positions() after a power cycle)."""
        with self._lock:
            return {n: d.joint_angle for n, d in self.drives.items()}

    def velocities(self) -> dict[int, float]:
        with self._lock:
            return {n: d.velocity / d.counts_per_rad for n, d in self.drives.items()}

    def states(self) -> dict[int, str]:
        with self._lock:
            return {n: d.state.value for n, d in self.drives.items()}

    def _drive(self, node: int) -> EmulatedDrive:
        if node not in self.drives:
            raise ValueError(f"no emulated drive with node id {node}; there are {sorted(self.drives)}")
        return self.drives[node]

    # ------------------------------------------------------------ the loop
    def _run(self) -> None:
        while not self._stop.is_set():
            # Everything queued is read before time advances for the drives, so that a stall of
            # this thread does not make a heartbeat still in the queue look missing.
            received: list[can.Message] = []
            try:
                msg = self.bus.recv(timeout=POLL_S)
                while msg is not None:
                    received.append(msg)
                    msg = self.bus.recv(timeout=0) if len(received) < 256 else None
            except (can.CanError, ValueError, OSError):
                if self._stop.is_set():
                    return
                log.exception("emulator could not read the bus")
                time.sleep(0.1)
                continue
            now = time.monotonic()
            with self._lock:
                if self._bus_off_until and now >= self._bus_off_until:
                    self._bus_off_until = 0.0
                    if self._bus_off_reported:
                        self._bus_off_reported = False
                        self._error_frame(CAN_ERR_RESTARTED)
                for m in received:
                    if not m.is_error_frame and not m.is_remote_frame:
                        self.frames_in += 1
                        self._route(m.arbitration_id, bytes(m.data), now)
                for node, drive in self.drives.items():
                    self._send(node, drive.poll(now))

    def _route(self, cob_id: int, data: bytes, now: float) -> None:
        if self._bus_off_until:
            return
        if cob_id in self.encoders:
            self._encoder(cob_id, data)
            return
        if cob_id == 0x080:
            for node, drive in self.drives.items():
                if node not in self._silent:
                    self._send(node, drive.on_sync(now))
            return
        if 0x701 <= cob_id <= 0x77F:            # a heartbeat: every drive may consume it
            for node, drive in self.drives.items():
                if node not in self._silent:
                    self._send(node, drive.heard_heartbeat(cob_id - 0x700, now))
            return
        for node, drive in self.drives.items():
            if node in self._silent:
                continue
            if cob_id == 0x000 or cob_id & 0x7F == node:
                self._send(node, drive.handle(cob_id, data, now))

    def _encoder(self, can_id: int, data: bytes) -> None:
        """An absolute encoder board answers a poll with its joint's angle, in 12-bit steps."""
        node, reverse = self.encoders[can_id]
        frame = encoder.answer(can_id, data, self.drives[node].joint_angle, reverse,
                               self._encoder_faults.get(can_id))
        if frame is not None:
            self._put([frame])

    def _send(self, node: int, frames: list[tuple[int, bytes]]) -> None:
        if node in self._silent or self._bus_off_until:
            return
        self._put(frames)

    def _put(self, frames: list[tuple[int, bytes]]) -> None:
        for cob_id, data in frames:
            if not data and cob_id & 0x780 == 0x580:
                continue   # an SDO abort from the client needs no answer
            try:
                self.bus.send(can.Message(arbitration_id=cob_id, data=data, is_extended_id=False))
                self.frames_out += 1
            except can.CanError:
                log.warning("emulator could not send 0x%03X", cob_id)

    def _error_frame(self, error_class: int) -> None:
        try:
            self.bus.send(can.Message(arbitration_id=error_class, is_error_frame=True, dlc=8,
                                      data=bytes(8), is_extended_id=False))
        except can.CanError:
            log.warning("emulator could not send an error frame")

    def close(self) -> None:
        """Stop the drives and shut their bus down (the emulator owns the bus it was given)."""
        self._stop.set()
        if threading.current_thread() is not self._thread:
            self._thread.join(1.0)
        self.bus.shutdown()


def start_private(channel: str, nodes: list[int], **kwargs) -> tuple[can.BusABC, DriveEmulator]:
    """Start drives on virtual `channel`; return (the master's bus, the emulator)."""
    emulator = DriveEmulator(can.Bus(interface="virtual", channel=channel), nodes, **kwargs)
    return can.Bus(interface="virtual", channel=channel), emulator
