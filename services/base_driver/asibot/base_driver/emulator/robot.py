"""An emulated P3-AT controller: ARCOS protocol and motion, without sockets or threads.

Bytes in (`receive`), bytes out (`receive`'s echoes and `step`'s SIPs); time is passed in,
so tests can drive it deterministically and the emulator server can run it in real time.
Behaviour from docs/arcos.md: sync echoes and the SYNC2 strings ("Connection"), a SIP every
100 ms ("SIP"), VEL/RVEL/VEL2/E_STOP ("Commands", "Motion and watchdog"), the 2 s watchdog
after which motion resumes toward the last setpoints when commands return ("Motion and
watchdog"), 15-bit positions ("SIP"), p3at-sh units, sonar ring poses and 4335 mm range
("P3-AT parameters").
"""

from __future__ import annotations

import dataclasses
import math

from asibot.base_driver import codec
from asibot.base_driver.codec import Cmd
from asibot.base_driver.emulator.gridmap import GridMap, room
from asibot.base_driver.params import P3AT_SH, SONAR_MAX_RANGE_MM, SONAR_POSES, RobotParams
from asibot.base_driver.sip import FLAG_MOTORS_ENABLED, STALL_LEFT, STALL_RIGHT, Sip, encode_sip, encode_sync2

#: ARCOS default SIP cycle (docs/arcos.md "SIP").
SIP_PERIOD = 0.1
#: ARCOS watchdog, nominally two seconds (docs/arcos.md "Motion and watchdog").
WATCHDOG = 2.0
#: Acceleration limits of the emulator. The sources give no P3-AT firmware defaults
#: (SETA/SETRA change them at run time), so these are the emulator's own choice
#: (docs/arcos.md "Motion and watchdog").
TRANS_ACCEL = 1000.0   # mm/s^2
ROT_ACCEL = 300.0      # deg/s^2
#: How long a stall cuts motor power (ARCOS StallCount; the firmware value is not in the sources).
STALL_TIME = 1.0
#: Half of RobotLength 626 mm (docs/arcos.md "P3-AT parameters"): the disc used for collisions.
BODY_RADIUS = 0.313


@dataclasses.dataclass
class Pose:
    x: float = 0.0      # m, world (map) frame
    y: float = 0.0
    theta: float = 0.0  # rad


class EmulatedP3at:
    """One P3-AT controller. Not thread-safe: the server serialises calls."""

    def __init__(self, world: GridMap | None = None, start: Pose | None = None,
                 params: RobotParams = P3AT_SH, name: str = "emulated-p3at",
                 battery_volts: float = 12.8, watchdog: float = WATCHDOG) -> None:
        self.world = world or room()
        self.params = params
        self.name = name
        self.battery_volts = battery_volts
        self.watchdog = watchdog
        self.start = start or Pose()
        if self.world.disc_hits(self.start.x, self.start.y, BODY_RADIUS):
            raise ValueError(f"the start pose ({self.start.x:.2f}, {self.start.y:.2f}) is inside an "
                             "obstacle of the map; choose a free start pose (--start X,Y,THETA)")
        self.pose = dataclasses.replace(self.start)
        self.deframer = codec.Deframer()
        self.received: list[tuple[float, int, int | None]] = []   # (time, command, argument)
        self._sync_stage = 0
        self.is_open = False
        self.motors_enabled = False
        self.sonar_on = True
        self.target_vel = 0.0     # mm/s setpoint
        self.target_rot = 0.0     # deg/s setpoint
        self.vel = 0.0            # actual mm/s
        self.rot = 0.0            # actual deg/s
        self.trans_accel = TRANS_ACCEL
        self.rot_accel = ROT_ACCEL
        self.max_vel = float(params.max_velocity_mm_s)
        self.max_rot = float(params.max_rot_velocity_deg_s)
        self.odom_x = 0.0         # mm since power-on / SETO
        self.odom_y = 0.0
        self.odom_th = 0.0        # rad
        self.stalled = False
        self._stall_until = 0.0
        self.bumped_front = False
        self.bumped_rear = False
        self.watchdog_tripped = False
        self._last_command = 0.0
        self._last_step: float | None = None
        self._next_sip = 0.0

    # ------------------------------------------------------------ the line
    def receive(self, data: bytes, now: float) -> bytes:
        """Consume bytes from the client; return what the controller answers at once."""
        out = bytearray()
        for payload in self.deframer.feed(data):
            out += self._handle(payload, now)
        return bytes(out)

    def step(self, now: float) -> bytes:
        """Advance the motion to `now`; returns a SIP packet when one is due, else b""."""
        self._integrate(now)
        if not self.is_open or now < self._next_sip:
            return b""
        self._next_sip = max(self._next_sip + SIP_PERIOD, now)
        return codec.frame(encode_sip(self.sip()))

    def disconnect(self) -> None:
        """The cable was pulled: partial packets are lost; the controller itself keeps its state."""
        self.deframer.clear()
        if not self.is_open:
            self._sync_stage = 0

    # ------------------------------------------------------------ commands
    def _handle(self, payload: bytes, now: float) -> bytes:
        cmd = payload[0]
        arg = _int_arg(payload)
        self.received.append((now, cmd, arg))
        if not self.is_open:
            return self._handle_sync(cmd, payload, now)
        self._last_command = now
        if self.watchdog_tripped:
            # Motion resumes toward the last setpoints (docs/arcos.md "Motion and watchdog").
            self.watchdog_tripped = False
        if cmd == Cmd.CLOSE:
            self._close()
        elif cmd == Cmd.ENABLE and arg is not None:
            self.motors_enabled = arg != 0
            if self.motors_enabled:
                self.stalled = self.bumped_front = self.bumped_rear = False
        elif cmd == Cmd.VEL and arg is not None:
            self.target_vel = _clamp(arg, self.max_vel)
        elif cmd in (Cmd.RVEL, Cmd.ROTATE) and arg is not None:
            self.target_rot = _clamp(arg, self.max_rot)
        elif cmd == Cmd.VEL2 and arg is not None:
            self._vel2(arg)
        elif cmd == Cmd.STOP:
            self.target_vel = self.target_rot = 0.0
        elif cmd == Cmd.E_STOP:
            self.target_vel = self.target_rot = 0.0
            self.vel = self.rot = 0.0         # overrides the deceleration limits
        elif cmd == Cmd.SETO:
            self.odom_x = self.odom_y = self.odom_th = 0.0
        elif cmd == Cmd.SETA and arg:
            self.trans_accel = float(abs(arg))
        elif cmd == Cmd.SETRA and arg:
            self.rot_accel = float(abs(arg))
        elif cmd == Cmd.SETV and arg:
            self.max_vel = min(float(abs(arg)), self.params.max_velocity_mm_s)
        elif cmd == Cmd.SETRV and arg:
            self.max_rot = min(float(abs(arg)), self.params.max_rot_velocity_deg_s)
        elif cmd == Cmd.SONAR and arg is not None:
            self.sonar_on = arg != 0
        return b""

    def _handle_sync(self, cmd: int, payload: bytes, now: float) -> bytes:
        if len(payload) == 1 and cmd == 0:
            self._sync_stage = 1
            return codec.command(0)
        if len(payload) == 1 and cmd == 1 and self._sync_stage == 1:
            self._sync_stage = 2
            return codec.command(1)
        if len(payload) == 1 and cmd == 2 and self._sync_stage == 2:
            self._sync_stage = 3
            return codec.frame(encode_sync2(self.name, "Pioneer", self.params.subclass))
        if cmd == Cmd.OPEN and self._sync_stage == 3:
            self.is_open = True
            self._sync_stage = 0
            self._last_command = now
            self._next_sip = now
            self._last_step = now
            return b""
        self._sync_stage = 0
        return b""

    def _close(self) -> None:
        """CLOSE ends the session: stop, motors off, back to waiting for a sync."""
        self.is_open = False
        self.motors_enabled = False
        self.target_vel = self.target_rot = 0.0
        self.watchdog_tripped = False

    def _vel2(self, arg: int) -> None:
        word = arg & 0xFFFF
        left = _s8(word >> 8) * self.params.vel2_divisor
        right = _s8(word & 0xFF) * self.params.vel2_divisor
        self.target_vel = _clamp((left + right) / 2.0, self.max_vel)
        self.target_rot = _clamp(math.degrees((right - left) / 2.0 * self.params.diff_conv), self.max_rot)

    # ------------------------------------------------------------ motion
    def _integrate(self, now: float) -> None:
        if self._last_step is None:
            self._last_step = now
            return
        dt = max(0.0, min(now - self._last_step, 0.5))
        self._last_step = now
        if self.is_open and now - self._last_command > self.watchdog:
            self.watchdog_tripped = True
        if self.stalled and now >= self._stall_until:
            self.stalled = self.bumped_front = self.bumped_rear = False
        driving = self.is_open and self.motors_enabled and not self.watchdog_tripped and not self.stalled
        want_v = self.target_vel if driving else 0.0
        want_w = self.target_rot if driving else 0.0
        self.vel = _approach(self.vel, want_v, self.trans_accel * dt)
        self.rot = _approach(self.rot, want_w, self.rot_accel * dt)
        if dt == 0.0 or (self.vel == 0.0 and self.rot == 0.0):
            return
        d = self.vel / 1000.0 * dt
        dth = math.radians(self.rot) * dt
        mid = self.pose.theta + dth / 2.0
        nx, ny = self.pose.x + d * math.cos(mid), self.pose.y + d * math.sin(mid)
        if d != 0.0 and self.world.disc_hits(nx, ny, BODY_RADIUS):
            self.bumped_front, self.bumped_rear = d > 0, d < 0
            self.stalled = True             # wheels blocked: ARCOS cuts motor power ("Motion and watchdog")
            self._stall_until = now + STALL_TIME
            self.vel = self.rot = 0.0
            return
        self.pose = Pose(nx, ny, self.pose.theta + dth)
        omid = self.odom_th + dth / 2.0
        self.odom_x += d * 1000.0 * math.cos(omid)
        self.odom_y += d * 1000.0 * math.sin(omid)
        self.odom_th += dth

    # ------------------------------------------------------------ the SIP
    def sip(self) -> Sip:
        p = self.params
        half_track = p.track_mm / 2.0
        w_mm = math.radians(self.rot) * half_track
        sb = 0
        if self.stalled:
            sb |= STALL_LEFT | STALL_RIGHT
        if self.bumped_front:
            sb |= 0b11111 << 1
        if self.bumped_rear:
            sb |= 0b11111 << 9
        th_units = int(round(_wrap_angle(self.odom_th) / p.angle_conv))
        volts10 = int(round(self.battery_volts * 10))
        return Sip(
            moving=self.vel != 0.0 or self.rot != 0.0,
            xpos=int(round(self.odom_x / p.dist_conv)) & 0x7FFF,
            ypos=int(round(self.odom_y / p.dist_conv)) & 0x7FFF,
            thpos=th_units,
            left_vel=int(round((self.vel - w_mm) / p.vel_conv)),
            right_vel=int(round((self.vel + w_mm) / p.vel_conv)),
            battery=volts10, stall_bumpers=sb, control=th_units,
            flags=FLAG_MOTORS_ENABLED if self.motors_enabled else 0,
            compass=0, sonars=self.sonar_ranges() if self.sonar_on else {},
            battery_x10=volts10, rot_vel_x10=int(round(self.rot * 10)),
        )

    def sonar_ranges(self) -> dict[int, int]:
        """Range of every sonar in firmware units, from the sonar pose on the robot into the map."""
        c, s = math.cos(self.pose.theta), math.sin(self.pose.theta)
        rays = [(self.pose.x + (c * sx - s * sy) / 1000.0, self.pose.y + (s * sx + c * sy) / 1000.0,
                 self.pose.theta + math.radians(heading))
                for sx, sy, heading in SONAR_POSES[: self.params.sonar_count]]
        ranges = self.world.raycast_many(rays, SONAR_MAX_RANGE_MM / 1000.0)
        return {i: int(round(r * 1000.0 / self.params.range_conv)) for i, r in enumerate(ranges)}


def _int_arg(payload: bytes) -> int | None:
    if len(payload) >= 4 and payload[1] in (codec.ARGINT, codec.ARGNINT):
        v = payload[2] | (payload[3] << 8)
        return -v if payload[1] == codec.ARGNINT else v
    return None


def _clamp(v: float, limit: float) -> float:
    return max(-limit, min(limit, float(v)))


def _approach(current: float, target: float, step: float) -> float:
    if abs(target - current) <= step:
        return target
    return current + math.copysign(step, target - current)


def _s8(b: int) -> int:
    return b - 256 if b >= 128 else b


def _wrap_angle(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))
