"""From raw SIPs to the base's state in SI units: odometry with 15-bit unwrap, sonar, bumpers.

ARCOS reports XPOS/YPOS as 15-bit counters that wrap (docs/arcos.md "SIP"). Like ARIA, the tracker
integrates the wrapped difference between consecutive SIPs instead of trusting the absolute
value (p2os's `&0xEFFF % 4096` masking is the documented bug we avoid).
"""

from __future__ import annotations

import dataclasses
import math

from asibot.base_driver.params import SONAR_MAX_RANGE_MM, RobotParams
from asibot.base_driver.sip import Sip

WRAP = 0x8000
HALF = 0x4000


def wrapped_delta(new: int, old: int) -> int:
    """Signed difference of two 15-bit counters, assuming less than half a turn of the counter."""
    d = (new - old) % WRAP
    return d - WRAP if d >= HALF else d


def signed15(raw: int) -> int:
    raw &= 0x7FFF
    return raw - WRAP if raw >= HALF else raw


def normalize_angle(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


@dataclasses.dataclass
class BaseState:
    """Everything one SIP tells about the base, in SI units."""

    x: float
    y: float
    theta: float
    vx: float
    wz: float
    volts: float
    motors_enabled: bool
    estop_pressed: bool
    stall_left: bool
    stall_right: bool
    front_bumpers: list[bool]
    rear_bumpers: list[bool]
    sonar_ranges: list[float]   # m, one per sonar, latest reading
    sonar_fresh: bool           # this SIP carried at least one sonar reading
    moving: bool


class StateTracker:
    """Keeps the unwrapped position and the latest sonar readings across SIPs."""

    def __init__(self, params: RobotParams) -> None:
        self.params = params
        self._raw: tuple[int, int] | None = None
        self._counts = [0, 0]
        self._sonar_mm = [float(SONAR_MAX_RANGE_MM)] * params.sonar_count

    def reset(self) -> None:
        """Forget the position (after a reconnect the robot may have been power-cycled)."""
        self._raw = None

    def update(self, sip: Sip) -> BaseState:
        p = self.params
        if self._raw is None:
            self._counts = [signed15(sip.xpos), signed15(sip.ypos)]
        else:
            self._counts[0] += wrapped_delta(sip.xpos, self._raw[0])
            self._counts[1] += wrapped_delta(sip.ypos, self._raw[1])
        self._raw = (sip.xpos, sip.ypos)
        for idx, rng in sip.sonars.items():
            if 0 <= idx < len(self._sonar_mm):
                self._sonar_mm[idx] = rng * p.range_conv
        left = sip.left_vel * p.vel_conv
        right = sip.right_vel * p.vel_conv
        if sip.rot_vel_x10 is not None:
            wz = math.radians(sip.rot_vel_x10 / 10.0)
        else:
            wz = (right - left) / 2.0 * p.diff_conv
        volts = sip.battery_x10 / 10.0 if sip.battery_x10 else sip.battery / 10.0
        return BaseState(
            x=self._counts[0] * p.dist_conv / 1000.0,
            y=self._counts[1] * p.dist_conv / 1000.0,
            theta=normalize_angle(sip.thpos * p.angle_conv),
            vx=(left + right) / 2.0 / 1000.0,
            wz=wz,
            volts=volts,
            motors_enabled=sip.motors_enabled,
            estop_pressed=sip.estop_pressed,
            stall_left=sip.stall_left,
            stall_right=sip.stall_right,
            front_bumpers=sip.front_bumpers,
            rear_bumpers=sip.rear_bumpers,
            sonar_ranges=[r / 1000.0 for r in self._sonar_mm],
            sonar_fresh=bool(sip.sonars),
            moving=sip.moving,
        )
