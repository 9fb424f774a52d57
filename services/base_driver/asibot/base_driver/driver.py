"""The Pioneer base driver: the driver contract's base side, without knowing about Zenoh.

One I/O thread owns the line: it connects (and reconnects every second after the cable is
pulled), reads SIPs, refreshes the setpoint and runs the cmd_vel watchdog (asibot.safety.watchdog). cmd_vel,
estop and reset_fault arrive from other threads and write at once (lowest latency).
Safety rules: a lost connection zeroes the setpoint, so a reconnect never resumes an old
velocity; while the estop is engaged every motion command is ignored; a cmd_vel beyond
--max-vx / --max-wz (or not finite) is refused whole with a CommandRefused, never clamped and
obeyed: the base keeps its previous command, which the watchdog ends a period later. The
service obeys only the controller that holds the base (asibot.safety.ownership); after a reconnect,
an estop release, a motor reset or a change of controller, a cmd_vel stream still running
from before moves nothing until it pauses for a watchdog period (asibot.safety.arming).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from typing import Callable

from asibot.base_driver import arcos, codec
from asibot.safety.arming import Arming
from asibot.base_driver.arcos import ArcosClient, ArcosError, Identity
from asibot.base_driver.link import Link, LinkError, open_link
from asibot.base_driver.notices import EventSink, Notices
from asibot.base_driver.params import RobotParams
from asibot.base_driver.sip import is_sip, parse_sip
from asibot.base_driver.state import BaseState, StateTracker
from asibot.errors import RpcError
from asibot.safety.events import CommandRefused, quantity
from asibot.messages import COMMAND_WATCHDOG_S
from asibot.safety.watchdog import Watchdog

log = logging.getLogger(__name__)

#: ARCOS sends a SIP every 100 ms (docs/arcos.md "SIP"); five missing ones mean the line is dead.
SIP_TIMEOUT = 0.5
RECONNECT_PERIOD = 1.0
#: p2os defaults MOTOR_DEF_MAX_SPEED 0.5 m/s and MOTOR_DEF_MAX_TURNSPEED 100 deg/s
#: (docs/arcos.md "Motion and watchdog").
DEFAULT_MAX_VX = 0.5
DEFAULT_MAX_WZ = math.radians(100)
#: A cmd_vel this fraction over a limit is numerical noise: clamped to the limit, not refused.
SPEED_TOLERANCE = 1e-3
StateSink = Callable[[BaseState], None]


class BaseDriver:
    """ARCOS base behind the driver contract: cmd_vel in, BaseState and events out."""

    def __init__(self, port: str, *, on_state: StateSink, on_event: EventSink,
                 baud: int = 9600, params: RobotParams | None = None,
                 max_vx: float = DEFAULT_MAX_VX, max_wz: float = DEFAULT_MAX_WZ,
                 watchdog: float = COMMAND_WATCHDOG_S,
                 link_factory: Callable[[str, int], Link] = open_link,
                 on_write: Callable[[bytes], None] | None = None) -> None:
        if not (max_vx > 0 and max_wz > 0 and math.isfinite(max_vx) and math.isfinite(max_wz)):
            raise ValueError("max_vx and max_wz must be positive, finite limits (m/s, rad/s)")
        self.port = port
        self.baud = baud
        self.forced_params = params
        self.max_vx = max_vx
        self.max_wz = max_wz
        self.watchdog = Watchdog(watchdog)
        self._on_state = on_state
        self._on_event = on_event
        self._link_factory = link_factory
        self._on_write = on_write
        self._lock = threading.RLock()
        self._client: ArcosClient | None = None
        self._tracker: StateTracker | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.arming = Arming()          # a driver starts armed (asibot.safety.arming says why)
        self._estop = False
        self._estop_reason = ""
        self._last_sip = 0.0
        self._reported_unreachable = False
        self._notices = Notices(on_event)
        self.last_state: BaseState | None = None
        self.counters = {"sips": 0, "cmd_vel": 0, "ignored_estop": 0, "refused": 0, "not_ready": 0,
                         "watchdog_stops": 0, "reconnects": 0, "bad_checksums": 0,
                         "dropped_bytes": 0}

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

    # ------------------------------------------------------------ commands
    def cmd_vel(self, vx: float, wz: float, controller: str = "") -> bool:
        """Obey a velocity command (m/s, rad/s) of `controller` (the holder: the service checked).
        Returns False when it is ignored (estop, offline).

        Raises CommandRefused, and changes nothing, when vx or wz is not finite or beyond the
        driver's limits (more than SPEED_TOLERANCE over): refused, not clamped; and
        arming.NotReady when it continues a stream from before the last recovery.
        """
        try:
            self._check(vx, wz)
        except CommandRefused:
            with self._lock:
                self.counters["refused"] += 1
            raise
        with self._lock:
            self.counters["cmd_vel"] += 1
            may_move = self.arming.admit(controller, time.monotonic())   # noted even when ignored
            if self._estop:
                self.counters["ignored_estop"] += 1
                return False
            if not may_move:
                self.counters["not_ready"] += 1
                raise self.arming.refusal("the base")
            # Only the tolerated noise is clamped here.
            cvx = max(-self.max_vx, min(self.max_vx, vx))
            cwz = max(-self.max_wz, min(self.max_wz, wz))
            self.watchdog.feed(time.monotonic())
            client = self._client
            if client is None:
                return False
            return self._guarded(lambda: client.set_velocity(*arcos.to_firmware(cvx, cwz)))

    def _check(self, vx: float, wz: float) -> None:
        for name, v in (("vx", vx), ("wz", wz)):
            if not math.isfinite(v):
                raise CommandRefused("not_finite", f"{name} is {quantity(v)}, not a finite number")
        for name, v, limit, unit, flag in (("vx", vx, self.max_vx, "m/s", "--max-vx"),
                                           ("wz", wz, self.max_wz, "rad/s", "--max-wz")):
            if abs(v) > limit * (1.0 + SPEED_TOLERANCE):
                raise CommandRefused("speed_limit", f"{name} {quantity(v, unit, limit)} is beyond the driver's "
                                                    f"limit {quantity(limit, unit, abs(v))} ({flag})")

    def heard(self, controller: str) -> None:
        """A cmd_vel of a controller that does not hold the base (refused by the service):
        noted, so that its stream does not move the base the moment it takes over."""
        with self._lock:
            self.arming.heard(controller, time.monotonic())

    def set_estop(self, engaged: bool, reason: str = "", by: str = "") -> None:
        """Latched estop: engaging sends E_STOP at once; only a release re-enables motion."""
        with self._lock:
            if engaged == self._estop:
                return
            self._estop = engaged
            self._estop_reason = reason
            client = self._client
            who = f" by {by}" if by else ""
            why = f" ({reason})" if reason else ""
            if engaged:
                if client is not None:
                    self._guarded(client.emergency_stop)
                self._on_event("error", "estop",
                               f"Emergency stop engaged{who}{why}: the base is stopped and ignores "
                               "motion commands until the stop is released.")
            else:
                self._on_event("info", "estop_released", f"Emergency stop released{who}{why}.")
                self._recovered(f"the emergency stop was released{who}")

    def set_controller(self, holder: str | None) -> None:
        """The controller that holds the base changed (asibot.safety.ownership): stop the base if it
        was moving, and re-arm for the new holder, if any."""
        with self._lock:
            client = self._client
            if client is not None and client.desired != (0, 0):
                self._guarded(lambda: client.set_velocity(0, 0))
                self._on_event("warning", "controller_lost",
                               "The controller of the base changed or disappeared while the base was moving: "
                               "the base stopped.")
            if holder is None:
                self.arming.disarm("its controller disappeared")
            else:
                self._recovered(f"controller {holder!r} took hold of it")

    def _recovered(self, why: str) -> None:
        """Under the lock: after a recovery only a new stream moves the base; say it is ready."""
        self.arming.disarm(why)
        self._on_event("info", "ready", self.arming.ready_text("The base"))

    def reset_fault(self) -> dict:
        """Re-enable the motors (after a stall cut their power or the motor button was off)."""
        with self._lock:
            client = self._client
            if client is None:
                raise RpcError("unavailable", f"The Pioneer on {self.port} is not connected; check the cable.")
            if self._estop:
                raise RpcError("estop", "The emergency stop is engaged; release it before resetting faults.")
            self._guarded(lambda: client.enable_motors(True))
            self._recovered("its motors were re-enabled")
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
        client = self._client
        return "velocity" if client is not None and client.desired != (0, 0) else "idle"

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
            "mode": self.mode(), "fault": self.fault(), "estop": self._estop,
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
            if self._estop:
                self._guarded(client.emergency_stop)
            # The line is (back) up: a stream sent while it was down must not drive on.
            self.arming.disarm(f"the Pioneer {'re' if self.counters['reconnects'] else ''}connected on {self.port}")
        log.info("connected to %s (%s %s) on %s, params %s", ident.name, ident.klass,
                 ident.subclass, self.port, params.subclass)
        self._on_event("info", "connected",
                       f"Connected to the Pioneer {ident.name!r} ({ident.subclass}) on {self.port}.")
        self._on_event("info", "ready", self.arming.ready_text("The base"))
        return True

    def _unreachable(self, reason: str) -> None:
        if not self._reported_unreachable:
            self._reported_unreachable = True
            log.warning("cannot reach the Pioneer on %s: %s", self.port, reason)
            self._on_event("error", "disconnected",
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
        self._on_event("error", "disconnected",
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
        with self._lock:
            if self.watchdog.fires(now, client.desired != (0, 0)):
                self.counters["watchdog_stops"] += 1
                client.set_velocity(0, 0)
                self._on_event("warning", "watchdog", self.watchdog.says("cmd_vel", "the base stopped"))
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
