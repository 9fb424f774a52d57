"""One emulated CiA 402 drive, frames in -> frames out, no bus and no threads.

It behaves like the iPOS drives of the ASIBOT as far as the master can see: NMT, an expedited
SDO server over its object dictionary, PDOs mapped at run time, SYNC-cyclic and event-driven
TPDOs with inhibit and event timers, heartbeats, a heartbeat consumer (0x1016) that acts on a
lost master by its abort connection option code (0x6007), the CiA 402 state machine, cyclic
synchronous position and profile position, software position limits, and injectable faults. It has no
dynamics: the joint follows its set-point at up to `max_speed` (torque actual reads 0).
"""

from __future__ import annotations

import math
import struct
from collections import deque
from dataclasses import dataclass, field

from asibot.arm_driver import cia402, objects
from asibot.arm_driver.cia402 import State
from asibot.arm_driver.emcy import Emcy
from asibot.arm_driver.pdo import PDO_INVALID, RPDO_BASE, TPDO_BASE, Entry

Frame = tuple[int, bytes]

NMT_BOOTUP, NMT_STOPPED, NMT_OPERATIONAL, NMT_PRE_OPERATIONAL = 0x00, 0x04, 0x05, 0x7F
SDO_RX, SDO_TX, EMCY_BASE, HEARTBEAT_BASE = 0x600, 0x580, 0x080, 0x700

# SDO abort codes (CiA 301 table 22; docs/canopen.md, "SDO abort codes").
ABORT_COMMAND = 0x05040001
ABORT_READ_ONLY = 0x06010002
ABORT_NO_OBJECT = 0x06020000
ABORT_NOT_MAPPABLE = 0x06040041
ABORT_PDO_TOO_LONG = 0x06040042
ABORT_LENGTH = 0x06070010
ABORT_NO_SUBINDEX = 0x06090011
ABORT_VALUE_RANGE = 0x06090030
ABORT_DEVICE_STATE = 0x08000022

READ_ONLY = {objects.DEVICE_TYPE, objects.ERROR_REGISTER, objects.MANUFACTURER_STATUS,
             objects.MOTION_ERROR, objects.DETAILED_ERROR, objects.STATUSWORD, objects.MODES_DISPLAY,
             objects.POSITION_INTERNAL, objects.POSITION_ACTUAL, objects.VELOCITY_ACTUAL,
             objects.TORQUE_ACTUAL, objects.SUPPORTED_MODES}
MAPPABLE_TX = {objects.MANUFACTURER_STATUS, objects.STATUSWORD, objects.MODES_DISPLAY,
               objects.MOTION_ERROR, objects.DETAILED_ERROR, objects.POSITION_INTERNAL,
               objects.POSITION_ACTUAL, objects.VELOCITY_ACTUAL, objects.TORQUE_ACTUAL}
MAPPABLE_RX = {objects.CONTROLWORD, objects.TARGET_POSITION, objects.MODES}

MER_OVER_CURRENT = 1 << 8     # Motion Error Register 0x2000 bit 8 (docs/canopen.md, "Error registers")
MSR_FAULT = 1 << 15           # Manufacturer Status Register bit 15


@dataclass
class _Pdo:
    cob_id: int
    transmission: int = 255
    inhibit_100us: int = 0
    event_timer_ms: int = 0
    entries: list[Entry] = field(default_factory=list)
    count: int = 0
    last_data: bytes | None = None
    last_sent: float = -1e9
    pending: bytes | None = None      # sync RPDO data waiting for the next SYNC
    sync_counter: int = 0

    @property
    def valid(self) -> bool:
        return not self.cob_id & PDO_INVALID


class EmulatedDrive:
    """One node. `handle`, `on_sync` and `poll` return the frames the drive sends."""

    def __init__(self, node: int, *, supports_csp: bool = True, max_speed: float = math.radians(30),
                 counts_per_rad: float = 160 * 4096 / (2 * math.pi), position: float = 0.0) -> None:
        if not 1 <= node <= 127:
            raise ValueError(f"node id {node} is outside 1..127")
        self.node = node
        self.supports_csp = supports_csp
        self.max_speed_counts = abs(max_speed * counts_per_rad)   # counts/s; OpenRAVE maxveldeg 30
        self.counts_per_rad = counts_per_rad
        self._initial_position = position * counts_per_rad
        # The incremental counter reads `position`; the joint itself is at position + zero.
        # They differ after a power cycle, which restarts the counter where the joint stands.
        self.zero = 0.0
        self.heartbeat_lost = False
        self._power_on()

    # ------------------------------------------------------------ life cycle
    def _power_on(self) -> None:
        self.nmt = NMT_BOOTUP
        self.state = State.SWITCH_ON_DISABLED
        self.controlword = 0
        self.mer = 0
        self.der = 0
        self.position = getattr(self, "position", self._initial_position)  # the joint does not move on reset
        self.velocity = 0.0
        self.goal = self.position
        self.profile_speed = 0.0
        self.setpoint_ack = False
        self._last_motion: float | None = None
        self._last_sync: float | None = None
        # Each SYNC's set-point step while enabled in CSP (counts): a real drive follows each
        # within one period, so a test reads here whether the master ever outran a joint.
        self.steps: deque[int] = deque(maxlen=100_000)
        self._applied: int | None = None
        self._last_heartbeat = -1e9
        # CiA 301: consumer monitoring starts with the first heartbeat heard, and stops after
        # one timeout event until the producer is heard again.
        self._master_heard: float | None = None
        self.connection_losses = 0
        self._limit_hit = False
        self.od: dict[tuple[int, int], int] = {
            (objects.DEVICE_TYPE, 0): 0x00020192,      # CiA 402, servo drive
            (objects.HEARTBEAT_PRODUCER, 0): 0,
            (objects.HEARTBEAT_CONSUMER, 0): 1,        # one consumer entry
            (objects.HEARTBEAT_CONSUMER, 1): 0,        # off until the master configures it
            (objects.ABORT_CONNECTION, 0): 1,          # fault signal until configured
            (objects.MODES, 0): 0,
            (objects.TARGET_POSITION, 0): 0,
            (objects.SOFTWARE_LIMITS, 0): 2,
            (objects.SOFTWARE_LIMITS, 1): -(1 << 31),
            (objects.SOFTWARE_LIMITS, 2): (1 << 31) - 1,
            (objects.PROFILE_VELOCITY, 0): 0,
            (objects.PROFILE_ACCELERATION, 0): 0,
            (objects.INTERPOLATION_PERIOD, 1): 1,
            (objects.INTERPOLATION_PERIOD, 2): -3,
            (objects.SUPPORTED_MODES, 0): objects.SUPPORTS_PP | (objects.SUPPORTS_CSP if self.supports_csp else 0),
            (objects.CONTROLWORD, 0): 0,
            (objects.SET_ACTUAL_POSITION, 0): 0,
        }
        # Every PDO starts disabled and empty: the master must map what it wants.
        self.tpdos = {n: _Pdo(TPDO_BASE[n] + self.node | PDO_INVALID) for n in range(1, 5)}
        self.rpdos = {n: _Pdo(RPDO_BASE[n] + self.node | PDO_INVALID) for n in range(1, 5)}
        self._outbox: list[Frame] = [(HEARTBEAT_BASE + self.node, b"\x00")]   # boot-up
        self.nmt = NMT_PRE_OPERATIONAL

    def reboot(self) -> None:
        """Reset (NMT or a supply blip that keeps the counter): object dictionary back to
        defaults, boot-up message, state switch on disabled."""
        self._power_on()

    def power_cycle(self) -> None:
        """Switched off and on: as reboot(), and the position counter restarts at 0."""
        self.zero += self.position
        self.position = 0.0
        self._power_on()

    @property
    def joint_angle(self) -> float:
        """Where the joint really is, rad (what an absolute encoder on it measures)."""
        return (self.position + self.zero) / self.counts_per_rad

    # ------------------------------------------------------------ observed values
    @property
    def statusword(self) -> int:
        sw = cia402.STATUSWORD[self.state] | cia402.SW_REMOTE
        if self.state not in (State.NOT_READY_TO_SWITCH_ON, State.SWITCH_ON_DISABLED, State.FAULT):
            sw |= cia402.SW_VOLTAGE_ENABLED
        if self.state is State.OPERATION_ENABLED:
            if abs(self.goal - self.position) < 0.5 and self.velocity == 0.0:
                sw |= cia402.SW_TARGET_REACHED
            if self.mode == objects.MODE_CSP or self.setpoint_ack:
                sw |= cia402.SW_FOLLOWING
        if self._limit_hit:
            sw |= cia402.SW_INTERNAL_LIMIT
        return sw

    @property
    def mode(self) -> int:
        return self.od[(objects.MODES, 0)]

    @property
    def position_counts(self) -> int:
        return int(round(self.position))

    def value(self, index: int, sub: int = 0) -> int:
        """Current value of an object (dynamic ones computed)."""
        dynamic = {
            objects.STATUSWORD: lambda: self.statusword,
            objects.MANUFACTURER_STATUS: lambda: ((MSR_FAULT if self.state is State.FAULT else 0) << 16)
            | self.statusword,
            objects.MODES_DISPLAY: lambda: self.mode,
            objects.POSITION_INTERNAL: lambda: self.position_counts,
            objects.POSITION_ACTUAL: lambda: self.position_counts,
            objects.VELOCITY_ACTUAL: lambda: int(round(self.velocity)),
            objects.TORQUE_ACTUAL: lambda: 0,
            objects.MOTION_ERROR: lambda: self.mer,
            objects.DETAILED_ERROR: lambda: self.der,
            objects.ERROR_REGISTER: lambda: 0x03 if self.mer & MER_OVER_CURRENT else (0x01 if self.mer else 0),
        }
        if index in dynamic and sub == 0:
            return dynamic[index]()
        pdo = self._pdo_for(index)
        if pdo is not None:
            return self._pdo_read(pdo, index, sub)
        return self.od[(index, sub)]

    # ------------------------------------------------------------ frames in
    def handle(self, cob_id: int, data: bytes, now: float) -> list[Frame]:
        """One received frame (already known to concern this node or everybody)."""
        if cob_id == 0x000:
            self._nmt(data)
        elif cob_id == SDO_RX + self.node and self.nmt != NMT_STOPPED:
            self._outbox.append((SDO_TX + self.node, self._sdo(data)))
        elif self.nmt == NMT_OPERATIONAL:
            for pdo in self.rpdos.values():
                if pdo.valid and pdo.cob_id & 0x7FF == cob_id:
                    if pdo.transmission <= 240:
                        pdo.pending = bytes(data)
                    else:
                        self._apply_rpdo(pdo, bytes(data), now)
        return self._flush()

    def on_sync(self, now: float) -> list[Frame]:
        """SYNC: apply synchronous RPDOs, move (CSP), then send SYNC-cyclic TPDOs."""
        if self.nmt != NMT_OPERATIONAL:
            return self._flush()
        for pdo in self.rpdos.values():
            if pdo.valid and pdo.pending is not None:
                data, pdo.pending = pdo.pending, None
                self._apply_rpdo(pdo, data, now)
        if self.state is State.OPERATION_ENABLED and self.mode == objects.MODE_CSP:
            target = self.od[(objects.TARGET_POSITION, 0)]
            if self._applied is not None:
                self.steps.append(target - self._applied)
            self._applied = target
            last = self._last_sync if self._last_sync is not None else now
            self._move_towards(self._limited(self.od[(objects.TARGET_POSITION, 0)]), min(now - last, 0.05),
                               self.max_speed_counts)
        self._last_sync = now
        for pdo in self.tpdos.values():
            if pdo.valid and 1 <= pdo.transmission <= 240:
                pdo.sync_counter += 1
                if pdo.sync_counter >= pdo.transmission:
                    pdo.sync_counter = 0
                    self._send_tpdo(pdo, now)
        return self._flush()

    def heard_heartbeat(self, producer: int, now: float) -> list[Frame]:
        """A heartbeat of node `producer` was on the bus."""
        watched, time_ms = self._consumer()
        if time_ms and producer == watched:
            self._master_heard = now
        return self._flush()

    def _consumer(self) -> tuple[int, int]:
        entry = self.od[(objects.HEARTBEAT_CONSUMER, 1)]
        return (entry >> 16) & 0xFF, entry & 0xFFFF

    def _watch_master(self, now: float) -> None:
        watched, time_ms = self._consumer()
        if not time_ms or self._master_heard is None or now - self._master_heard <= time_ms / 1000.0:
            return
        self._master_heard = None
        self.connection_losses += 1
        # EMCY 0x8130 heartbeat error, error register: generic + communication (CiA 301).
        self._outbox.append((EMCY_BASE + self.node, Emcy(0x8130, 0x11, b"").encode()))
        option = self.od[(objects.ABORT_CONNECTION, 0)]
        if option == objects.CONNECTION_LOSS["fault"]:
            self._enter(State.FAULT)
        elif option == objects.CONNECTION_LOSS["disable_voltage"]:
            self._enter(cia402.transition(self.state, cia402.DISABLE_VOLTAGE, self.controlword))
        elif option == objects.CONNECTION_LOSS["quick_stop"]:
            self._enter(cia402.transition(self.state, cia402.QUICK_STOP, self.controlword))

    def poll(self, now: float) -> list[Frame]:
        """Time passes: heartbeat, the master's heartbeat watched, profile-position motion, event-driven TPDOs."""
        self._watch_master(now)
        period = self.od[(objects.HEARTBEAT_PRODUCER, 0)] / 1000.0
        if period > 0 and not self.heartbeat_lost and now - self._last_heartbeat >= period:
            self._last_heartbeat = now
            self._outbox.append((HEARTBEAT_BASE + self.node, bytes([self.nmt])))
        if self.state is State.OPERATION_ENABLED and self.mode == objects.MODE_PROFILE_POSITION:
            self._profile_step(now)
        elif self.state is not State.OPERATION_ENABLED or self.mode != objects.MODE_CSP or (
                self._last_sync is not None and now - self._last_sync > 0.05):
            # Not moving, or CSP without SYNC: the drive holds its last set-point.
            self.velocity = 0.0
            self._last_motion = now
        if self.nmt == NMT_OPERATIONAL:
            for pdo in self.tpdos.values():
                if pdo.valid and pdo.transmission >= 254:
                    data = self._tpdo_data(pdo)
                    since = now - pdo.last_sent
                    changed = data != pdo.last_data and since >= pdo.inhibit_100us / 10000.0
                    timer = pdo.event_timer_ms and since >= pdo.event_timer_ms / 1000.0
                    if changed or timer:
                        self._send_tpdo(pdo, now)
        return self._flush()

    # ------------------------------------------------------------ faults
    def inject_over_current(self) -> list[Frame]:
        """A continuous over-current trips the drive: FAULT, MER bit 8, EMCY 0x2310."""
        self.mer |= MER_OVER_CURRENT
        self._enter(State.FAULT)
        self._outbox.append((EMCY_BASE + self.node, Emcy(0x2310, 0x03, b"").encode()))
        return self._flush()

    # ------------------------------------------------------------ internals
    def _flush(self) -> list[Frame]:
        out, self._outbox = self._outbox, []
        return out

    def _nmt(self, data: bytes) -> None:
        if len(data) != 2 or data[1] not in (0, self.node):
            return
        command = data[0]
        if command == 0x01:
            self.nmt = NMT_OPERATIONAL
        elif command == 0x02:
            self.nmt = NMT_STOPPED
        elif command == 0x80:
            self.nmt = NMT_PRE_OPERATIONAL
        elif command in (0x81, 0x82):
            self._power_on()

    def _enter(self, state: State) -> None:
        if state is not self.state:
            # Like a real drive, CSP then follows 0x607A as it is: the master must write the
            # actual position there before enabling, or the joint runs to the stale target.
            self.velocity = 0.0
            self.goal = self.position
            self.state = state
            self._applied = None        # a new enable starts a new stream of set-points

    def _controlword(self, cw: int, now: float) -> None:
        previous, self.controlword = self.controlword, cw
        self.od[(objects.CONTROLWORD, 0)] = cw
        new = cia402.transition(self.state, cw, previous)
        if self.state is State.FAULT and new is State.SWITCH_ON_DISABLED:
            self.mer = self.der = 0
            self._outbox.append((EMCY_BASE + self.node, Emcy(0x0000, 0x00, b"").encode()))
        if new is State.OPERATION_ENABLED and self.mode not in (objects.MODE_CSP, objects.MODE_PROFILE_POSITION):
            self._outbox.append((EMCY_BASE + self.node, Emcy(0xFF04, 0x01, b"").encode()))
            return
        self._enter(new)
        if self.state is State.OPERATION_ENABLED and self.mode == objects.MODE_PROFILE_POSITION:
            if cw & cia402.CW_HALT:
                self.goal = self.position
            elif cw & cia402.CW_NEW_SETPOINT and not previous & cia402.CW_NEW_SETPOINT:
                target = self.od[(objects.TARGET_POSITION, 0)]
                self.goal = self._limited(self.goal + target if cw & cia402.CW_RELATIVE else target)
                self.setpoint_ack = True
            elif not cw & cia402.CW_NEW_SETPOINT:
                self.setpoint_ack = False

    def _apply_rpdo(self, pdo: _Pdo, data: bytes, now: float) -> None:
        entries = pdo.entries[: pdo.count]
        size = sum(e.bits for e in entries) // 8
        if len(data) < size:
            self._outbox.append((EMCY_BASE + self.node, Emcy(0x8210, 0x11, b"").encode()))  # PDO length error
            return
        offset = 0
        for e in entries:
            t = objects.type_of(e.index, e.subindex)
            v = t.decode(data[offset: offset + t.size])
            offset += t.size
            if e.index == objects.CONTROLWORD:
                self._controlword(v, now)
            else:
                self.od[(e.index, e.subindex)] = v

    def _limited(self, counts: float) -> float:
        lo, hi = self.od[(objects.SOFTWARE_LIMITS, 1)], self.od[(objects.SOFTWARE_LIMITS, 2)]
        self._limit_hit = not lo <= counts <= hi
        return min(max(counts, lo), hi)

    def _move_towards(self, goal: float, dt: float, speed: float) -> None:
        self.goal = goal
        step = max(-speed * dt, min(speed * dt, goal - self.position))
        self.position += step
        self.velocity = step / dt if dt > 0 else 0.0

    def _profile_step(self, now: float) -> None:
        last = self._last_motion if self._last_motion is not None else now
        dt, self._last_motion = min(now - last, 0.05), now
        if dt <= 0:
            return
        vmax = self.od[(objects.PROFILE_VELOCITY, 0)] / 65536.0 * 1000.0 or self.max_speed_counts
        vmax = min(vmax, self.max_speed_counts)
        acc = self.od[(objects.PROFILE_ACCELERATION, 0)] / 65536.0 * 1e6 or 10 * vmax
        remaining = self.goal - self.position
        # Trapezoid: accelerate, cruise, and brake in time to stop at the goal.
        v_stop = math.sqrt(2 * acc * abs(remaining))
        want = math.copysign(min(vmax, v_stop), remaining)
        v = self.velocity + max(-acc * dt, min(acc * dt, want - self.velocity))
        if abs(remaining) <= abs(v) * dt or abs(remaining) < 0.5:
            self.position, v = self.goal, 0.0
        else:
            self.position += v * dt
        self.velocity = v

    # SDO server: expedited transfers only (every object here fits in 4 bytes).
    def _sdo(self, data: bytes) -> bytes:
        if len(data) != 8:
            return self._abort(0, 0, ABORT_COMMAND)
        command = data[0] >> 5
        index, sub = struct.unpack_from("<HB", data, 1)
        if command == 1:
            if not data[0] & 0x02:
                return self._abort(index, sub, ABORT_COMMAND)   # segmented download: not needed here
            size = 4 - ((data[0] >> 2) & 0x3) if data[0] & 0x01 else 4
            code = self._write(index, sub, bytes(data[4: 4 + size]))
            if code:
                return self._abort(index, sub, code)
            return bytes([0x60]) + data[1:4] + b"\0\0\0\0"
        if command == 2:
            try:
                t = objects.type_of(index, sub)
                value = self.value(index, sub)
            except KeyError:
                return self._abort(index, sub, ABORT_NO_OBJECT if not objects.known(index) else ABORT_NO_SUBINDEX)
            raw = t.encode(value if t.signed or value >= 0 else value & ((1 << t.bits) - 1))
            return bytes([0x43 | ((4 - t.size) << 2)]) + data[1:4] + raw.ljust(4, b"\0")
        if command == 4:
            return b""   # client abort: nothing to answer
        return self._abort(index, sub, ABORT_COMMAND)

    @staticmethod
    def _abort(index: int, sub: int, code: int) -> bytes:
        return struct.pack("<BHBI", 0x80, index, sub, code)

    def _write(self, index: int, sub: int, raw: bytes) -> int:
        if not objects.known(index, sub):
            return ABORT_NO_OBJECT
        if index in READ_ONLY:
            return ABORT_READ_ONLY
        t = objects.type_of(index, sub)
        if len(raw) != t.size:
            return ABORT_LENGTH
        value = t.decode(raw)
        pdo = self._pdo_for(index)
        if pdo is not None:
            return self._pdo_write(pdo, index, sub, value)
        if (index, sub) not in self.od:
            return ABORT_NO_SUBINDEX
        if (index, sub) == (objects.HEARTBEAT_CONSUMER, 0):
            return ABORT_READ_ONLY              # the number of entries is fixed
        if index == objects.MODES:
            if value not in (0, objects.MODE_PROFILE_POSITION) and not (value == objects.MODE_CSP and self.supports_csp):
                return ABORT_VALUE_RANGE
        if index == objects.CONTROLWORD:
            self._controlword(value, 0.0)
            return 0
        if index == objects.SET_ACTUAL_POSITION:
            if self.state is State.OPERATION_ENABLED:
                return ABORT_DEVICE_STATE       # not while it holds or moves the joint
            self.zero += self.position - value
            self.position = self.goal = float(value)
        self.od[(index, sub)] = value
        return 0

    def _pdo_for(self, index: int) -> _Pdo | None:
        for base, table in ((objects.RPDO_COMM, self.rpdos), (objects.RPDO_MAP, self.rpdos),
                            (objects.TPDO_COMM, self.tpdos), (objects.TPDO_MAP, self.tpdos)):
            if base <= index < base + 4:
                return table[index - base + 1]
        return None

    def _pdo_read(self, pdo: _Pdo, index: int, sub: int) -> int:
        if index & 0x0200:        # 0x16xx / 0x1Axx: mapping
            if sub == 0:
                return pdo.count
            return pdo.entries[sub - 1].mapping if sub <= len(pdo.entries) else 0
        return {1: pdo.cob_id, 2: pdo.transmission, 3: pdo.inhibit_100us, 5: pdo.event_timer_ms}[sub]

    def _pdo_write(self, pdo: _Pdo, index: int, sub: int, value: int) -> int:
        tx = pdo in self.tpdos.values()
        if index & 0x0200:
            if sub == 0:
                if value > 8:
                    return ABORT_PDO_TOO_LONG
                if pdo.valid:
                    return ABORT_DEVICE_STATE
                entries = pdo.entries[:value]
                if value > len(entries) or sum(e.bits for e in entries) > 64:
                    return ABORT_PDO_TOO_LONG
                pdo.count = value
                return 0
            if pdo.valid or pdo.count != 0:
                return ABORT_DEVICE_STATE      # CiA 301: disable the PDO and zero sub0 first
            entry = Entry.from_mapping(value)
            allowed = MAPPABLE_TX if tx else MAPPABLE_RX
            if entry.index not in allowed or objects.type_of(entry.index, entry.subindex).bits != entry.bits:
                return ABORT_NOT_MAPPABLE
            while len(pdo.entries) < sub:
                pdo.entries.append(Entry(0, 0, 0))
            pdo.entries[sub - 1] = entry
            del pdo.entries[sub:]
            return 0
        if sub == 1:
            if pdo.valid and not value & PDO_INVALID and value & 0x7FF != pdo.cob_id & 0x7FF:
                return ABORT_VALUE_RANGE       # change the COB-ID only while the PDO is disabled
            pdo.cob_id = value
            pdo.last_data = None
            return 0
        if sub == 2:
            pdo.transmission = value
        elif sub == 3 and tx:
            pdo.inhibit_100us = value
        elif sub == 5 and tx:
            pdo.event_timer_ms = value
        else:
            return ABORT_NO_SUBINDEX
        return 0

    def _tpdo_data(self, pdo: _Pdo) -> bytes:
        out = bytearray()
        for e in pdo.entries[: pdo.count]:
            t = objects.type_of(e.index, e.subindex)
            v = self.value(e.index, e.subindex)
            out += t.encode(v if t.signed else v & ((1 << t.bits) - 1))
        return bytes(out)

    def _send_tpdo(self, pdo: _Pdo, now: float) -> None:
        data = self._tpdo_data(pdo)
        pdo.last_data, pdo.last_sent = data, now
        self._outbox.append((pdo.cob_id & 0x7FF, data))
