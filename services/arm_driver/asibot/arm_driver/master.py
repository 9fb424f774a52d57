"""The CiA 402 master: brings the drives up and exchanges their cyclic data. No Zenoh here.

canopen does the SDO client, NMT commands, heartbeat reception and EMCY decoding; this module
adds what canopen lacks for a drive master: the PDO configuration sequence without an EDS, the
CiA 402 enable handshake, per-cycle RPDO + SYNC, and bus-off detection from error frames and
failed writes. Start-up follows TechnosoftIpos' initialize() (docs/canopen.md, "Start-up"): ping,
absolute encoder sync (a joint with an absolute encoder gets its position counter set from
it), software limits, profile velocity/acceleration, TPDO/RPDO mapping, heartbeat producer,
heartbeat consumer of the master's heartbeat and connection-loss option, NMT start, then
shutdown -> switch on -> enable operation.

SYNC, the master's heartbeat and the CSP set-points are repeated by the interface's periodic
sender (asibot.arm_driver.cyclic): the control loop updates set-points in place, so neither a
busy loop nor a drive being reset stops the others' SYNC.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import can
import canopen
from canopen.objectdictionary import ObjectDictionary

from asibot.arm_driver import cia402, cui, objects
from asibot.arm_driver.cia402 import State
from asibot.arm_driver.config import ArmConfig, Joint
from asibot.arm_driver.cyclic import SYNC_COB_ID, CyclicFrames, LoopFrames, PeriodicFrames, SyncedFrames
from asibot.arm_driver.emcy import Emcy
from asibot.arm_driver.pdo import ON_CHANGE, PDO_INVALID, Layout

log = logging.getLogger(__name__)

CAN_ERR_BUSOFF = 0x00000040
CAN_ERR_RESTARTED = 0x00000100
NMT_START = 0x01
NMT_OPERATIONAL = 0x05
SYNC_MODES = ("synced", "periodic", "loop")
#: s without a control period (outside a bring-up, whose calls have their own time-outs) after
#: which the loop is taken as hung: the periodic sender would otherwise keep the drives holding
#: on their last set-points for ever, deaf to the estop. Well above the stalls a loaded machine
#: makes (~0.1 s), so a busy machine does not stop the arm.
LOOP_STALL_S = 1.0


class DriveError(Exception):
    """A drive could not be brought up or commanded; the message is a sentence for the user."""


class LoopStalled(DriveError):
    """The control loop itself stalled (LOOP_STALL_S): the drives stopped by themselves."""


@dataclass
class Feedback:
    """What one drive last told us. Times are time.monotonic()."""

    statusword: int = 0
    state: State = State.NOT_READY_TO_SWITCH_ON
    mode_display: int = 0
    position: int = 0            # counts
    velocity: float = 0.0        # counts/s, from consecutive TPDOs
    torque: int = 0
    mer: int = 0
    der: int = 0
    position_time: float = 0.0
    heartbeat_time: float = 0.0
    # The same moments on the bus's clock (frame time stamps), which a stalled reader cannot
    # compress: None until a heartbeat arrives after configuration.
    heartbeat_stamp: float | None = None
    stamp: float = 0.0           # the newest frame from this drive, bus clock
    nmt_state: int | None = None
    booted: bool = False         # a boot-up message arrived since we configured the drive
    emcys: list[Emcy] = field(default_factory=list)


def _bus_time(ts: float | None) -> float:
    """A frame's time stamp; an adapter that gives none gets the time it was read."""
    return ts if ts else time.time()


class _ErrorFrames(can.Listener):
    def __init__(self, on_error_class: Callable[[int], None]) -> None:
        # Not `on_error`: can.Listener.on_error(exc) is the notifier's hook for a failing reader.
        self.on_error_class = on_error_class

    def on_message_received(self, msg: can.Message) -> None:
        if msg.is_error_frame:
            self.on_error_class(msg.arbitration_id)


class CanopenMaster:
    """One CAN bus, the drives of one arm.

    `sync="synced"` (the default) sends SYNC and a sample of set-points before each from one
    clock (cyclic.SyncedFrames), the heartbeat from the interface's periodic sender;
    `"periodic"` has the periodic sender repeat the set-points too, as after issue 29, and
    `"loop"` sends every frame from cycle(), as before it (both kept to measure against,
    bench/bench_sync.py).
    """

    def __init__(self, bus: can.BusABC, config: ArmConfig, sync: str = "synced") -> None:
        if sync not in SYNC_MODES:
            raise ValueError(f"sync must be one of {', '.join(SYNC_MODES)}, got {sync!r}")
        self.config = config
        self.bus = bus
        self.network = canopen.Network(bus)
        self.network.NOTIFIER_CYCLE = 0.1   # the reader notices a stop within 0.1 s (default 1 s)
        # canopen types Network.listeners as list[MessageListener]; can.Notifier takes any can.Listener.
        self.network.listeners.append(_ErrorFrames(self._on_error_frame))  # type: ignore[arg-type]
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        self.feedback: dict[int, Feedback] = {j.node: Feedback() for j in config.joints}
        self.modes: dict[int, int] = {}
        self._last_cw: dict[int, int] = {}
        self._last_target: dict[int, int] = {}
        self.bus_off = False
        self.tx_error: str = ""
        self.frames_sent = 0
        self._absolute: dict[int, bytes] = {}       # encoder CAN id -> its last poll reply
        for j in config.joints:
            if j.absolute is not None:
                self.network.subscribe(j.absolute.can_id + cui.REPLY_POLL, self._on_absolute)
        for j in config.joints:
            node = self.network.add_node(canopen.RemoteNode(j.node, ObjectDictionary()))
            node.sdo.RESPONSE_TIMEOUT = config.sdo_timeout_s
            node.emcy.add_callback(functools.partial(self._on_emcy, j.node))
            self.network.subscribe(0x700 + j.node, self._on_heartbeat)
            for layout in config.pdos.values():
                if layout.kind == "tpdo":
                    self.network.subscribe(layout.cob_id(j.node), functools.partial(self._on_tpdo, j.node, layout))
        self.network.connect()
        self.frames: CyclicFrames = (
            SyncedFrames(bus, config.period, self.network.send_message) if sync == "synced"
            else PeriodicFrames(bus) if sync == "periodic" else LoopFrames(self._send))
        # The loop's pulse, watched by a guard thread while the periodic sender runs.
        self._ticked = time.monotonic()
        self._bringing_up = 0
        self.stalled = 0.0                      # s the loop had stalled when the guard stopped the drives
        self._stall_told = False
        self._guard_stop = threading.Event()
        self._guard: threading.Thread | None = None

    # ------------------------------------------------------------ receive side (notifier thread)
    def _on_tpdo(self, node: int, layout: Layout, cob_id: int, data: bytearray, ts: float) -> None:
        try:
            values = layout.decode(bytes(data))
        except ValueError as exc:
            log.warning("drive %d: %s", node, exc)
            return
        now = time.monotonic()
        with self._changed:
            fb = self.feedback[node]
            fb.stamp = max(fb.stamp, _bus_time(ts))
            sw = values.get(objects.STATUSWORD)
            if sw is None and objects.MANUFACTURER_STATUS in values:
                sw = values[objects.MANUFACTURER_STATUS] & 0xFFFF    # iPOS: low word of 0x1002
            if sw is not None:
                fb.statusword, fb.state = sw, cia402.state_of(sw)
            if objects.MODES_DISPLAY in values:
                fb.mode_display = values[objects.MODES_DISPLAY]
            pos = values.get(objects.POSITION_INTERNAL, values.get(objects.POSITION_ACTUAL))
            if pos is not None:
                if fb.position_time:
                    period = self.config.period
                    dt = min(max(now - fb.position_time, 0.5 * period), 2.0 * period)
                    fb.velocity = (pos - fb.position) / dt
                fb.position, fb.position_time = pos, now
            if objects.TORQUE_ACTUAL in values:
                fb.torque = values[objects.TORQUE_ACTUAL]
            if objects.MOTION_ERROR in values:
                fb.mer = values[objects.MOTION_ERROR]
            if objects.DETAILED_ERROR in values:
                fb.der = values[objects.DETAILED_ERROR]
            self._changed.notify_all()

    def _on_heartbeat(self, cob_id: int, data: bytearray, ts: float) -> None:
        if len(data) < 1:
            return
        node, state = cob_id - 0x700, data[0] & 0x7F
        with self._changed:
            fb = self.feedback[node]
            fb.heartbeat_time = time.monotonic()
            fb.heartbeat_stamp = _bus_time(ts)
            fb.stamp = max(fb.stamp, fb.heartbeat_stamp)
            fb.nmt_state = state
            if state == 0:
                fb.booted = True
            self._changed.notify_all()

    def _on_absolute(self, cob_id: int, data: bytearray, ts: float) -> None:
        with self._changed:
            self._absolute[cob_id - cui.REPLY_POLL] = bytes(data)
            self._changed.notify_all()

    def _on_emcy(self, node: int, error: canopen.emcy.EmcyError) -> None:
        emcy = Emcy(error.code, error.register, bytes(error.data))
        with self._changed:
            self.feedback[node].emcys.append(emcy)
            self._changed.notify_all()

    def _on_error_frame(self, error_class: int) -> None:
        with self._changed:
            if error_class & CAN_ERR_BUSOFF:
                self.bus_off = True
            self._changed.notify_all()

    def snapshot(self) -> dict[int, Feedback]:
        """A copy of every drive's feedback, taking (and clearing) the EMCYs received since last time."""
        with self._lock:
            out = {}
            for n, fb in self.feedback.items():
                out[n] = Feedback(**{**fb.__dict__, "emcys": list(fb.emcys)})
                fb.emcys.clear()
            return out

    # ------------------------------------------------------------ send side (control thread)
    def _send(self, cob_id: int, data: bytes) -> None:
        try:
            self.network.send_message(cob_id, data)
            self.frames_sent += 1
        except can.CanError as exc:
            self.tx_error = str(exc) or type(exc).__name__
            raise DriveError(f"The CAN adapter refuses to send ({self.tx_error}); the bus may be off or "
                             "unplugged: check the cable and termination, then call reset_fault.") from exc

    def controlword(self, node: int, cw: int) -> None:
        rpdo1 = self.config.pdos["rpdo1"]
        self._send(rpdo1.cob_id(node), rpdo1.encode({objects.CONTROLWORD: cw}))
        self._last_cw[node] = cw

    def start_cyclic(self) -> None:
        """Start the master's heartbeat and SYNC; they run until close(), through fault resets
        (again after the guard stopped them: a reset_fault calls this)."""
        with self._lock:
            self._ticked, self.stalled, self._stall_told = time.monotonic(), 0.0, False
        if not isinstance(self.frames, LoopFrames) and self._guard is None:
            self._guard = threading.Thread(target=self._guard_loop, name="canopen-loop-guard", daemon=True)
            self._guard.start()
        try:
            self.frames.put(0x700 + self.config.master_node, bytes([NMT_OPERATIONAL]),
                            self.config.master_heartbeat_ms / 1000.0)
            self.frames.put(SYNC_COB_ID, b"", self.config.period)
        except (can.CanError, OSError) as exc:
            raise DriveError(f"The CAN adapter refuses to send periodic frames ({exc}): check the cable, "
                             "then call reset_fault.") from exc

    def stop_cyclic(self) -> None:
        """Stop SYNC, the heartbeat and every set-point: what the drives see when the master dies."""
        self.frames.close()

    @contextlib.contextmanager
    def bringing_up(self) -> Iterator[None]:
        """Configuring and enabling drives blocks the control loop for up to their own time-outs
        (SDO, state changes): the guard does not count that as a stall."""
        with self._lock:
            self._bringing_up += 1
        try:
            yield
        finally:
            with self._lock:
                self._bringing_up -= 1
                self._ticked = time.monotonic()

    def pulse(self) -> None:
        """The control loop is alive: called first in each period. Raises LoopStalled once after
        the guard found the loop hung (before what the drives reported meanwhile is read)."""
        with self._lock:
            self._ticked = time.monotonic()
            tell = bool(self.stalled) and not self._stall_told
            self._stall_told = self._stall_told or tell
        if tell:
            raise LoopStalled(f"The arm driver's control loop stalled for {self.stalled:.1f} s, so its heartbeat "
                              "was stopped and the drives stopped by themselves: see the driver's log, then call "
                              "reset_fault.")

    def _guard_loop(self) -> None:
        """A control loop that stops (a deadlock, a hung call) stops the periodic frames, so each
        drive quick-stops by itself once its heartbeat consumer time has passed; the loop, if it
        comes back, faults with a sentence (cycle)."""
        while not self._guard_stop.wait(LOOP_STALL_S / 10):
            with self._lock:
                quiet = time.monotonic() - self._ticked
                hung = quiet > LOOP_STALL_S and not self._bringing_up and not self.stalled
                if hung:
                    self.stalled = quiet
            if hung:
                log.error("the control loop has not run for %.1f s: stopping SYNC and the heartbeat, the drives "
                          "stop by themselves", quiet)
                self.frames.close()

    def _hold(self, node: int, counts: int) -> None:
        """The CSP set-point the periodic sender repeats for `node`, changed in place."""
        rpdo3 = self.config.pdos["rpdo3"]
        self.frames.put(rpdo3.cob_id(node), rpdo3.encode({objects.TARGET_POSITION: counts}), self.config.period)

    def lag(self) -> dict:
        """How the set-points kept up with SYNC, for health: the SYNCs that found no new sample
        (the control loop was late: the motion lagged) and the longest such lag, ms."""
        frames = self.frames
        if not isinstance(frames, SyncedFrames):
            return {}
        return {"late_syncs": frames.late, "longest_lag_ms": round(frames.longest_late * frames.period * 1000, 1)}

    def room(self) -> bool:
        """Whether SYNC has taken the set-points made so far, so the loop may make the next
        (False: the motion lags a period; see cyclic.SyncedFrames)."""
        return self.frames.room()

    def cycle(self, targets: dict[int, int]) -> None:
        """One control period: each drive's set-point (CSP: a sample sent before a SYNC)."""
        if self.stalled:           # the guard stopped every periodic frame: none until reset_fault starts them
            return
        if self.frames.error:      # a periodic sender failed since the last period (taken: reported once)
            self.tx_error, self.frames.error = self.frames.error, ""
            raise DriveError(f"The CAN adapter refuses to send ({self.tx_error}); the bus may be off or "
                             "unplugged: check the cable and termination, then call reset_fault.")
        rpdo3 = self.config.pdos["rpdo3"]
        for node, counts in targets.items():
            mode = self.modes.get(node)
            if mode == objects.MODE_CSP:
                self._hold(node, counts)
            elif mode == objects.MODE_PROFILE_POSITION and counts != self._last_target.get(node):
                # Profile position: new target, then a rising edge of "new set-point" with
                # "change set immediately", then clear the bit for the next edge.
                self._send(rpdo3.cob_id(node), rpdo3.encode({objects.TARGET_POSITION: counts}))
                base = cia402.ENABLE_OPERATION | cia402.CW_CHANGE_IMMEDIATELY
                self.controlword(node, base | cia402.CW_NEW_SETPOINT)
                self.controlword(node, base)
            self._last_target[node] = counts
        self.frames.tick()

    # ------------------------------------------------------------ SDO helpers
    def _joint(self, node: int) -> Joint:
        return next(j for j in self.config.joints if j.node == node)

    def _who(self, node: int) -> str:
        return f"Drive {node} (joint {self._joint(node).name})"

    def write(self, node: int, index: int, sub: int, value: int) -> None:
        data = objects.type_of(index, sub).encode(value)
        try:
            self.network[node].sdo.download(index, sub, data)
        except canopen.SdoAbortedError as exc:
            raise DriveError(f"{self._who(node)} refused writing 0x{index:04X}:{sub:02X} = {value} "
                             f"({exc}): check the drive setup.") from exc
        except canopen.SdoCommunicationError as exc:
            raise DriveError(f"{self._who(node)} does not answer on CAN (SDO 0x{index:04X}:{sub:02X}: {exc}): "
                             "check its power and cable, then call reset_fault.") from exc
        except can.CanError as exc:
            raise DriveError(f"The CAN adapter refuses to send ({exc}): check the cable, then call reset_fault.") from exc

    def read(self, node: int, index: int, sub: int = 0) -> int:
        try:
            data = self.network[node].sdo.upload(index, sub)
        except canopen.SdoAbortedError as exc:
            raise DriveError(f"{self._who(node)} refused reading 0x{index:04X}:{sub:02X} ({exc}).") from exc
        except canopen.SdoCommunicationError as exc:
            raise DriveError(f"{self._who(node)} does not answer on CAN (SDO 0x{index:04X}:{sub:02X}: {exc}): "
                             "check its power and cable, then call reset_fault.") from exc
        except can.CanError as exc:
            raise DriveError(f"The CAN adapter refuses to send ({exc}): check the cable, then call reset_fault.") from exc
        return objects.type_of(index, sub).decode(data)

    # ------------------------------------------------------------ start-up
    def configure(self, node: int) -> int:
        """SDO configuration and PDO mapping of one drive (pre-operational); returns the mode chosen."""
        cfg, joint = self.config, self._joint(node)
        # This drive is being reset on its own: its set-point stops (it is remapped, and its
        # counter may have restarted) while the others keep theirs and SYNC.
        self.frames.drop(cfg.pdos["rpdo3"].cob_id(node))
        self.read(node, objects.DEVICE_TYPE)                        # SDO ping
        if joint.absolute is not None and self._counter_may_be_stale(node):
            self.sync_absolute(joint)
        mode = self._choose_mode(node)
        lo, hi = sorted((joint.units.to_counts(joint.lower), joint.units.to_counts(joint.upper)))
        self.write(node, objects.SOFTWARE_LIMITS, 1, lo)
        self.write(node, objects.SOFTWARE_LIMITS, 2, hi)
        self.write(node, objects.PROFILE_VELOCITY, 0, joint.units.velocity_iu(min(cfg.profile_velocity, joint.max_velocity)))
        self.write(node, objects.PROFILE_ACCELERATION, 0, joint.units.acceleration_iu(cfg.profile_acceleration))
        for kind in ("tpdo", "rpdo"):
            for number in range(1, 5):
                layout = cfg.pdos.get(f"{kind}{number}")
                if layout is None:
                    self._disable_pdo(node, kind, number)
                else:
                    if mode == objects.MODE_PROFILE_POSITION and layout.name == "rpdo3":
                        # The target must land before the set-point edge, not at the next SYNC.
                        layout = Layout(layout.kind, layout.number, layout.entries, ON_CHANGE)
                    self.map_pdo(node, layout)
        if mode == objects.MODE_CSP:
            self.write(node, objects.INTERPOLATION_PERIOD, 1, max(1, round(cfg.period * 1000)))
            self.write(node, objects.INTERPOLATION_PERIOD, 2, -3)
        self.write(node, objects.MODES, 0, mode)
        self.write(node, objects.HEARTBEAT_PRODUCER, 0, cfg.heartbeat_ms)
        # The drive watches the master's heartbeat and stops by itself when it misses it (a dead
        # master or a pulled cable; CiA 301 0x1016, CiA 402 0x6007).
        self.write(node, objects.HEARTBEAT_CONSUMER, 1, cfg.master_node << 16 | cfg.drive_consumer_ms)
        self.write(node, objects.ABORT_CONNECTION, 0, objects.CONNECTION_LOSS[cfg.connection_loss])
        with self._lock:
            fb = self.feedback[node]
            fb.booted = False
            fb.heartbeat_time = time.monotonic()     # grace: the first heartbeat is one period away
            fb.heartbeat_stamp = None
        self.modes[node] = mode
        return mode

    def _counter_may_be_stale(self, node: int) -> bool:
        """False only for a drive still enabled (one that went quiet and came back without a
        reset): it kept counting, and it refuses a new counter while it holds the joint."""
        return cia402.state_of(self.read(node, objects.STATUSWORD)) is not State.OPERATION_ENABLED

    def read_absolute(self, joint: Joint) -> float:
        """The joint's angle (rad) from its absolute encoder, polled as CuiAbsolute does."""
        enc = joint.absolute
        if enc is None:
            raise ValueError(f"joint {joint.name} has no absolute encoder")
        why = "no answer"
        for _ in range(cui.RETRIES):
            with self._lock:
                self._absolute.pop(enc.can_id, None)
            self._send(enc.can_id, cui.poll_request())
            deadline = time.monotonic() + cui.TIMEOUT_S
            with self._changed:
                while enc.can_id not in self._absolute and (left := deadline - time.monotonic()) > 0:
                    self._changed.wait(left)
                reply = self._absolute.pop(enc.can_id, None)
            if reply is None:
                why = f"no answer within {cui.TIMEOUT_S:g} s"
                continue
            try:
                return math.radians(cui.parse_angle(reply, enc.reverse))
            except cui.EncoderError as exc:
                why = str(exc)
        raise DriveError(f"The absolute encoder of joint {joint.name} (CAN id {enc.can_id}) gave no position "
                         f"after {cui.RETRIES} tries ({why}): where the joint is is unknown, so the arm stays "
                         "off; check the encoder's cable and power, then call reset_fault.")

    def sync_absolute(self, joint: Joint) -> float:
        """Set the drive's position counter to the absolute encoder's angle; returns it (rad)."""
        angle = self.read_absolute(joint)
        self.write(joint.node, objects.SET_ACTUAL_POSITION, 0, joint.units.to_counts(angle))
        log.info("%s: position set from its absolute encoder: %.2f deg", self._who(joint.node), math.degrees(angle))
        return angle

    def _choose_mode(self, node: int) -> int:
        """Cyclic synchronous position when the drive has it (0x6502 bit 7), else profile position."""
        try:
            supported = self.read(node, objects.SUPPORTED_MODES)
        except DriveError:
            supported = objects.SUPPORTS_CSP | objects.SUPPORTS_PP   # not readable: try CSP, fall back below
        if supported & objects.SUPPORTS_CSP:
            try:
                self.write(node, objects.MODES, 0, objects.MODE_CSP)
                return objects.MODE_CSP
            except DriveError as exc:
                log.warning("%s; falling back to profile position", exc)
        if not supported & objects.SUPPORTS_PP:
            raise DriveError(f"{self._who(node)} supports neither cyclic synchronous nor profile position "
                             f"(0x6502 = 0x{supported:08X}): configure the drive for position control.")
        log.info("%s: using profile position (no cyclic synchronous position)", self._who(node))
        return objects.MODE_PROFILE_POSITION

    def _disable_pdo(self, node: int, kind: str, number: int) -> None:
        base = objects.TPDO_COMM if kind == "tpdo" else objects.RPDO_COMM
        cob = (0x180 if kind == "tpdo" else 0x200) + 0x100 * (number - 1) + node
        self.write(node, base + number - 1, 1, cob | PDO_INVALID)

    def map_pdo(self, node: int, layout: Layout) -> None:
        """CiA 301 mapping procedure: disable, parameters, clear map, entries, count, enable."""
        comm, mapping, cob = layout.comm_index, layout.map_index, layout.cob_id(node)
        self.write(node, comm, 1, cob | PDO_INVALID)
        self.write(node, comm, 2, layout.transmission)
        if layout.kind == "tpdo" and layout.inhibit_ms is not None:
            self.write(node, comm, 3, int(round(layout.inhibit_ms * 10)))     # units of 100 us
        if layout.kind == "tpdo" and layout.event_timer_ms is not None:
            self.write(node, comm, 5, int(layout.event_timer_ms))
        self.write(node, mapping, 0, 0)
        for sub, entry in enumerate(layout.entries, start=1):
            self.write(node, mapping, sub, entry.mapping)
        self.write(node, mapping, 0, len(layout.entries))
        self.write(node, comm, 1, cob)

    def start(self, node: int) -> None:
        """NMT start remote node: PDOs flow from now on."""
        self._send(0x000, bytes([NMT_START, node]))

    def wait_state(self, node: int, want: set[State], timeout: float) -> State:
        """Wait for a statusword (TPDO) showing one of `want`; return the last state seen."""
        deadline = time.monotonic() + timeout
        with self._changed:
            while self.feedback[node].state not in want:
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self._changed.wait(left)
            return self.feedback[node].state

    def _read_state(self, node: int) -> State:
        """The drive's state from its statusword read by SDO, not from the last TPDO.

        A drive sends its statusword when it changes (and on its event timer, if it has one). A
        change during a bus-off is lost with its TPDO, so the last word received can still say
        "operation enabled" of a drive that has since disabled itself; enabling on that word
        would end at once and leave the drive off.
        """
        sw = self.read(node, objects.STATUSWORD)
        with self._changed:
            fb = self.feedback[node]
            fb.statusword, fb.state = sw, cia402.state_of(sw)
            self._changed.notify_all()
            return fb.state

    def enable(self, node: int) -> int:
        """Walk the CiA 402 state machine to operation enabled, holding the current position.

        Returns the position (counts) the drive holds. Before enabling, 0x607A is set to the
        actual position so that the drive does not run to a stale target.
        """
        timeout = self.config.state_timeout_s
        self.wait_state(node, set(State) - {State.NOT_READY_TO_SWITCH_ON}, timeout)
        state = self._read_state(node)
        here = self.read(node, objects.POSITION_ACTUAL)
        self.write(node, objects.TARGET_POSITION, 0, here)
        if self.modes.get(node) == objects.MODE_CSP:
            self._hold(node, here)      # SYNC applies the RPDO, not the SDO: it must say the same
        self._last_target[node] = here
        with self._lock:
            self.feedback[node].position = here
            self.feedback[node].velocity = 0.0
        for _ in range(8):
            if state is State.OPERATION_ENABLED:
                return here
            cw = cia402.next_command(state)
            if cw is None:
                state = self.wait_state(node, set(State) - {state}, timeout)
                if state in (State.NOT_READY_TO_SWITCH_ON, State.FAULT_REACTION_ACTIVE):
                    break
                continue
            if cw == cia402.FAULT_RESET and self._last_cw.get(node, 0) & cia402.FAULT_RESET:
                self.controlword(node, cia402.DISABLE_VOLTAGE)     # a reset needs a rising edge
            if cw == cia402.ENABLE_OPERATION:
                if self.modes.get(node) == objects.MODE_PROFILE_POSITION:
                    cw |= cia402.CW_CHANGE_IMMEDIATELY
            previous = state
            self.controlword(node, cw)
            state = self.wait_state(node, set(State) - {previous}, timeout)
            if state is previous:
                break
        raise DriveError(f"{self._who(node)} did not reach operation enabled (it stays in '{state.value}' "
                         f"after {timeout:g} s): check its enable input and setup, then call reset_fault.")

    def quick_stop(self, node: int) -> None:
        self.controlword(node, cia402.QUICK_STOP)

    def close(self) -> None:
        self._guard_stop.set()
        self.stop_cyclic()
        try:
            self.network.disconnect()
        except Exception:   # the bus may already be gone; closing must not fail
            log.debug("network disconnect failed", exc_info=True)
