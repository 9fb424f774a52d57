"""The Pioneer base driver: the driver contract's base side, without knowing about Zenoh.

One I/O thread owns the line: it connects (and reconnects every second after the cable is
pulled), reads SIPs, refreshes the setpoint and runs the cmd_vel watchdog. cmd_vel, estop and
reset_fault arrive from other threads and write at once (lowest latency). The rules every base
keeps (a cmd_vel beyond --max-vx / --max-wz refused whole, the estop, the watchdog, re-arming
after a recovery, a change of controller) are `asibot.safety.guarded_base`'s; this driver adds
the line's own: a lost connection zeroes the setpoint, so a reconnect never resumes an old
velocity, and a reconnect is a recovery too. The service obeys only the controller that holds
the base (asibot.safety.ownership).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from typing import Callable

from asibot.base_driver import arcos, codec
from asibot.base_driver.arcos import ArcosClient, ArcosError, Identity
from asibot.base_driver.link import Link, LinkError, open_link
from asibot.base_driver.notices import EventSink, Notices
from asibot.base_driver.params import RobotParams
from asibot.base_driver.sip import is_sip, parse_sip
from asibot.base_driver.state import BaseState, StateTracker
from asibot.errors import RpcError
from asibot.messages import COMMAND_WATCHDOG_S
from asibot.safety.guarded_base import GuardedBase

log = logging.getLogger(__name__)

#: ARCOS sends a SIP every 100 ms (docs/arcos.md "SIP"); five missing ones mean the line is dead.
SIP_TIMEOUT = 0.5
RECONNECT_PERIOD = 1.0
#: p2os defaults MOTOR_DEF_MAX_SPEED 0.5 m/s and MOTOR_DEF_MAX_TURNSPEED 100 deg/s
#: (docs/arcos.md "Motion and watchdog").
DEFAULT_MAX_VX = 0.5
DEFAULT_MAX_WZ = math.radians(100)
StateSink = Callable[[BaseState], None]


class BaseDriver(GuardedBase):
    """ARCOS base behind the driver contract: cmd_vel in, BaseState and events out."""

    limits = "the driver's"
    hints = {"vx": " (--max-vx)", "wz": " (--max-wz)"}

    def __init__(self, port: str, *, on_state: StateSink, on_event: EventSink,
                 baud: int = 9600, params: RobotParams | None = None,
                 max_vx: float = DEFAULT_MAX_VX, max_wz: float = DEFAULT_MAX_WZ,
                 watchdog: float = COMMAND_WATCHDOG_S,
                 link_factory: Callable[[str, int], Link] = open_link,
                 on_write: Callable[[bytes], None] | None = None) -> None:
        super().__init__(max_vx, max_wz, on_event, watchdog=watchdog)
        self.port = port
        self.baud = baud
        self.forced_params = params
        self._on_state = on_state
        self._link_factory = link_factory
        self._on_write = on_write
        self._client: ArcosClient | None = None
        self._tracker: StateTracker | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._last_sip = 0.0
        self._reported_unreachable = False
        self._notices = Notices(on_event)
        self.last_state: BaseState | None = None
        self.counters.update({"sips": 0, "reconnects": 0, "bad_checksums": 0, "dropped_bytes": 0})

    # ------------------------------------------------------------ lifecycle
    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="arcos-io", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread:
            self._thread.join(timeout=2.0)
        with self._lock:
            if self._client:
                self._client.close()
                self._client = None

    @property
    def connected(self) -> bool:
        return self._client is not None

    @property
    def params(self) -> RobotParams | None:
        client = self._client
        return client.params if client else None

    @property
    def identity(self) -> Identity | None:
        client = self._client
        return client.identity if client else None

    # ------------------------------------------------------------ GuardedBase
    def cmd_vel(self, vx: float, wz: float, controller: str = "") -> bool:
        """Obey a velocity command (m/s, rad/s) of `controller`: `GuardedBase.command`. Returns
        False when it is ignored (the estop, the Pioneer not connected)."""
        return self.command(vx, wz, controller)

    def _drive(self, vx: float, wz: float) -> bool:
        client = self._client
        if client is None:
            return False
        return self._guarded(lambda: client.set_velocity(*arcos.to_firmware(vx, wz)))

    def _halt(self) -> None:
        client = self._client
        if client is not None:
            self._guarded(client.emergency_stop)

    def _moving(self) -> bool:
        client = self._client
        return client is not None and client.desired != (0, 0)

    def reset_fault(self) -> dict:
        """Re-enable the motors (after a stall cut their power or the motor button was off)."""
        with self._lock:
            client = self._client
            if client is None:
                raise RpcError("unavailable", f"The Pioneer on {self.port} is not connected; check the cable.")
            if self.estop:
                raise RpcError("estop", "The emergency stop is engaged; release it before resetting faults.")
            self._guarded(lambda: client.enable_motors(True))
            self.recovered("its motors were re-enabled")
        return {"motors_enabled_requested": True}

    # ------------------------------------------------------------ state
    def fault(self) -> str:
        if self._client is None:
            return f"The Pioneer on {self.port} is not connected."
        s = self.last_state
        if s is not None and s.estop_pressed:
            return "The Pioneer's own emergency stop button is pressed."
        if s is not None and (s.stall_left or s.stall_right):
            return "A wheel stalled and its motor power was cut; clear the obstacle and reset the fault."
        if s is not None and not s.motors_enabled:
            return "The motors are disabled; press the motors button or reset the fault."
        return ""

    def mode(self) -> str:
        if self.fault():
            return "fault"
        return "velocity" if self._moving() else "idle"

    def status(self) -> dict:
        ident = self.identity
        params = self.params
        return {
            "port": self.port, "connected": self.connected,
            "robot_name": ident.name if ident else "", "robot_class": ident.klass if ident else "",
            "subclass": ident.subclass if ident else "",
            "params": params.subclass if params else "",
            "names": [], "lower": [], "upper": [], "max_velocity": [],
            "max_vx": self.max_vx, "max_wz": self.max_wz,
            "mode": self.mode(), "fault": self.fault(), "estop": self.estop,
            "counters": dict(self.counters),
        }

    # ------------------------------------------------------------ the I/O thread
    def _run(self) -> None:
        while not self._stop.is_set():
            if self._client is None:
                if not self._connect():
                    self._stop.wait(RECONNECT_PERIOD)
                continue
            try:
                self._service_line()
            except (*LinkError, ArcosError) as exc:
                self._lost(str(exc) or type(exc).__name__)

    def _connect(self) -> bool:
        try:
            link = self._link_factory(self.port, self.baud)
        except LinkError as exc:
            self._unreachable(str(exc))
            return False
        client = ArcosClient(link, self.forced_params, on_write=self._on_write)
        try:
            ident = client.connect()
            params = client.params
            if params is None:      # connect() sets them: the forced ones, or those of the SYNC2 reply
                raise ArcosError("the handshake left the robot's parameters unknown")
        except (*LinkError, ArcosError) as exc:
            try:
                link.close()
            except Exception:
                pass
            self._unreachable(str(exc))
            return False
        with self._lock:
            self._client = client
            self._tracker = StateTracker(params)
            self._last_sip = time.monotonic()
            self.watchdog.last = -math.inf      # nothing heard on this line yet
            self._notices.reset()
            self._reported_unreachable = False
            if self.estop:
                self._halt()
            # The line is (back) up: a stream sent while it was down must not drive on.
            self.arming.disarm(f"the Pioneer {'re' if self.counters['reconnects'] else ''}connected on {self.port}")
        log.info("connected to %s (%s %s) on %s, params %s", ident.name, ident.klass,
                 ident.subclass, self.port, params.subclass)
        self.on_event("info", "connected",
                      f"Connected to the Pioneer {ident.name!r} ({ident.subclass}) on {self.port}.")
        self.on_event("info", "ready", self.arming.ready_text("The base"))
        return True

    def _unreachable(self, reason: str) -> None:
        if not self._reported_unreachable:
            self._reported_unreachable = True
            log.warning("cannot reach the Pioneer on %s: %s", self.port, reason)
            self.on_event("error", "disconnected",
                          f"Cannot reach the Pioneer on {self.port} ({reason}); check the cable and "
                          f"the port; retrying every {RECONNECT_PERIOD:g} s.")

    def _lost(self, reason: str) -> None:
        with self._lock:
            client, self._client = self._client, None
        if client is not None:
            client.close()
            self.counters["reconnects"] += 1
        self._reported_unreachable = True
        log.warning("lost the Pioneer on %s: %s", self.port, reason)
        self.on_event("error", "disconnected",
                      f"Lost the Pioneer on {self.port} ({reason}). Its own watchdog stops it; "
                      "reconnecting, and it will not resume the old velocity.")

    def _service_line(self) -> None:
        client = self._client
        assert client is not None
        for payload in client.read_payloads():
            if is_sip(payload):
                self._on_sip(payload)
        self.counters["bad_checksums"] = client.deframer.bad_checksums
        self.counters["dropped_bytes"] = client.deframer.dropped_bytes
        now = time.monotonic()
        if now - self._last_sip > SIP_TIMEOUT:
            raise ArcosError(f"no SIP for {SIP_TIMEOUT:g} s")
        self.watch(now)
        with self._lock:
            client.refresh()

    def _on_sip(self, payload: bytes) -> None:
        try:
            sip = parse_sip(payload)
        except codec.PacketError as exc:
            log.warning("skipping a malformed SIP: %s", exc)
            return
        assert self._tracker is not None
        state = self._tracker.update(sip)
        self._last_sip = time.monotonic()
        self.counters["sips"] += 1
        self._notices.update(state)
        self.last_state = state
        self._on_state(state)

    def _guarded(self, action: Callable[[], None]) -> bool:
        """Run a write; a dead line becomes a disconnect handled by the I/O thread."""
        try:
            action()
            return True
        except LinkError as exc:
            log.warning("write to %s failed: %s", self.port, exc)
            return False
