"""The thesis's driving primitives, closed-loop on odometry, stopping before obstacles.

For a user driving with one switch or a head tracker, each primitive is one command, named
as in `asibot.driving.PRIMITIVES` (the names nav, the web and the bridge share): forward,
backward, turn left, turn right, turn left 90, turn right 90, turn around, curve forward
left/right, curve backward left/right, stop. Two settings shape them, raised and lowered by
the user one level at a time (1..5):

- speed (faster / slower): the linear and turning speeds;
- width (wider / narrower): how far a step goes, how much a turn step turns, and how wide a
  curve is.

A step ends where it should, closed-loop on odometry: it decelerates so it stops on the
target (within 1 cm / 1 deg by odometry), holding its heading on straight steps. A
"continuous" primitive goes on until `stop`, an obstacle, or `longest_s`. Before every
command the footprint is swept along the motion for the braking distance plus `margin`
against the scan points (base frame); anything there stops the robot with a sentence
("stopped: obstacle ahead, 0.4 m"). Without a scan the robot does not move: it cannot see.
It stands still and waits for one, as a goal does, for `blind_timeout`, then the primitive
ends with a sentence: a scan late by a moment (a busy computer, a camera frame dropped) only
pauses a turn, a perception service that is gone ends it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asibot import driving
from asibot.messages import LaserScan
from asibot.errors import quote
from asibot.nav.errors import NavError
from asibot.nav.geometry import Pose, wrap
from asibot.nav.robot import P3AT, P3AT_LIMITS, Footprint, Limits

LEVELS = 5
SPEEDS = (0.10, 0.20, 0.30, 0.40, 0.50)          # m/s, by speed level
TURN_SPEEDS = (0.30, 0.50, 0.70, 0.90, 1.10)     # rad/s, by speed level
STEPS = (0.25, 0.50, 1.00, 1.50, 2.00)           # m, by width level
TURN_STEPS = (15.0, 30.0, 45.0, 60.0, 90.0)      # deg, by width level
RADII = (0.40, 0.60, 0.80, 1.20, 1.60)           # m, curve radius by width level
MAX_STEP = 10.0                                 # m, the longest drive(distance) at once
MAX_TURN = 2 * math.pi                          # rad, the most turn(angle) turns at once

#: name -> (direction of travel, turn side, kind): kind is straight, turn or curve; a fixed
#: angle (deg) for the exact turns.
PRIMITIVES: dict[str, tuple[int, int, str, float | None]] = {
    "forward": (1, 0, "straight", None),
    "backward": (-1, 0, "straight", None),
    "turn left": (0, 1, "turn", None),
    "turn right": (0, -1, "turn", None),
    "turn left 90": (0, 1, "turn", 90.0),
    "turn right 90": (0, -1, "turn", 90.0),
    "turn around": (0, 1, "turn", 180.0),
    "curve forward left": (1, 1, "curve", None),
    "curve forward right": (1, -1, "curve", None),
    "curve backward left": (-1, 1, "curve", None),
    "curve backward right": (-1, -1, "curve", None),
    "stop": (0, 0, "stop", None),
}
if tuple(PRIMITIVES) != driving.PRIMITIVES:
    # The web draws, and the bridge sends, the names of asibot.driving: nav must drive those.
    raise RuntimeError(f"asibot.nav.primitives drives {list(PRIMITIVES)}, "
                       f"but asibot.driving names {list(driving.PRIMITIVES)}")


@dataclass
class Settings:
    speed: int = 2
    width: int = 3
    longest_s: float = 30.0
    margin: float = 0.12          # m kept free around the swept footprint
    require_scan: bool = True
    # s standing still without a scan before the primitive ends: shorter than a goal's 10 s
    # (NavParams.blind_timeout), as a person who pressed once for a step is waiting on it
    blind_timeout: float = 2.0


@dataclass
class Motion:
    """Speeds for now; once `active` is False the primitive has ended, `done` says whether it
    went the whole way (else `text` says why it stopped)."""
    vx: float
    wz: float
    active: bool
    text: str = ""
    done: bool = False


class Primitives:
    def __init__(self, settings: Settings | None = None, limits: Limits = P3AT_LIMITS,
                 footprint: Footprint = P3AT) -> None:
        self.settings = settings or Settings()
        self.limits = limits
        self.footprint = footprint
        self._name: str | None = None
        self.last_text = "stopped"

    # ---------------------------------------------------------------------- settings

    def _level(self, which: str, delta: int) -> str:
        old = getattr(self.settings, which)
        new = min(LEVELS, max(1, old + delta))
        setattr(self.settings, which, new)
        edge = "" if new != old else (" (already the highest)" if delta > 0 else " (already the lowest)")
        if which == "speed":
            return f"speed {new} of {LEVELS}: {SPEEDS[new - 1]:.1f} m/s{edge}"
        return (f"width {new} of {LEVELS}: steps of {STEPS[new - 1]:.2f} m and {TURN_STEPS[new - 1]:.0f} deg, "
                f"curves {RADII[new - 1]:.1f} m wide{edge}")

    def faster(self) -> str:
        return self._level("speed", 1)

    def slower(self) -> str:
        return self._level("speed", -1)

    def wider(self) -> str:
        return self._level("width", 1)

    def narrower(self) -> str:
        return self._level("width", -1)

    # ---------------------------------------------------------------------- commands

    @property
    def active(self) -> bool:
        return self._name is not None

    def start(self, now: float, name: object, odom: Pose, continuous: bool = False,
              amount: float | None = None) -> str:
        """Begin a primitive from the odometry pose `odom`; a sentence saying what it does.
        `amount` replaces the width level's step: metres for a straight or curved step, radians
        for a turn (`drive(0.7)`, `turn(35)` of a program)."""
        if not isinstance(name, str) or driving.normalise(name) not in PRIMITIVES:
            raise NavError(f"{quote(name, 30)} is not a driving primitive; use one of {', '.join(PRIMITIVES)}.")
        if not all(math.isfinite(v) for v in odom):
            raise NavError("The odometry pose is not finite; the robot does not move.")
        name = driving.normalise(name)
        if name == "stop":
            return self.stop()
        direction, side, kind, fixed = PRIMITIVES[name]
        s = self.settings
        if amount is not None:
            longest = MAX_TURN if kind == "turn" else MAX_STEP
            if isinstance(amount, bool) or not isinstance(amount, (int, float)) or not 0 < amount <= longest:
                unit = f"{math.degrees(longest):.0f} deg" if kind == "turn" else f"{longest:g} m"
                raise NavError(f"How far to {name} must be a number above 0 and at most {unit}; got {quote(amount, 20)}.")
            fixed, continuous = (math.degrees(amount) if kind == "turn" else None), False
        if fixed is not None:
            continuous = False
        self._name, self._kind, self._dir, self._side = name, kind, direction, side
        self._continuous = continuous
        self._t0, self._start = now, odom
        self._blind_since: float | None = None
        self._last_theta, self._turned, self._travelled, self._last_xy = odom.theta, 0.0, 0.0, (odom.x, odom.y)
        self._v = SPEEDS[s.speed - 1]
        self._w = TURN_SPEEDS[s.speed - 1]
        if kind == "straight":
            self._target = math.inf if continuous else (amount or STEPS[s.width - 1])
            what = f"{self._target:.2f} m" if not continuous else "until you say stop"
        elif kind == "turn":
            self._target = math.inf if continuous else math.radians(fixed if fixed is not None else TURN_STEPS[s.width - 1])
            what = f"{math.degrees(self._target):.0f} deg" if not continuous else "until you say stop"
        else:
            radius = RADII[s.width - 1]
            self._w = min(self._w, self._v / radius)
            self._v = self._w * radius
            self._target = math.inf if continuous else (amount or STEPS[s.width - 1])
            what = f"{self._target:.2f} m on a {radius:.1f} m curve" if not continuous else "until you say stop"
        self.last_text = self._what = f"{name}, {what}"
        return self.last_text

    def stop(self, text: str = "stopped") -> str:
        self._name = None
        self.last_text = text
        return text

    def _end(self, text: str, done: bool = False) -> Motion:
        self.stop(text)
        return Motion(0.0, 0.0, False, text, done)

    def step(self, now: float, odom: Pose, scan: LaserScan | None) -> Motion:
        """Speeds for now; `active` False (and zero speeds) once the primitive has ended."""
        if self._name is None:
            return Motion(0.0, 0.0, False, self.last_text)
        if not all(math.isfinite(v) for v in odom):
            return self._end("stopped: the odometry is not finite")
        lim = self.limits
        self._turned += wrap(odom.theta - self._last_theta) * (self._side or 1)
        self._last_theta = odom.theta
        self._travelled += math.hypot(odom.x - self._last_xy[0], odom.y - self._last_xy[1])
        self._last_xy = (odom.x, odom.y)
        if now - self._t0 > self.settings.longest_s:
            return self._end(f"stopped: {self.settings.longest_s:.0f} s is the longest a motion lasts")
        decel = 0.6
        if self._kind == "straight":
            d = Pose(odom.x - self._start.x, odom.y - self._start.y, 0.0)
            along = (d.x * math.cos(self._start.theta) + d.y * math.sin(self._start.theta)) * self._dir
            left = self._target - along
            if left <= 0.005:
                return self._end(f"{self._name}: done", done=True)
            v = min(self._v, math.sqrt(2 * lim.acc_x * decel * left), max(0.03, 1.5 * left))
            vx = self._dir * v
            wz = float(np.clip(2.0 * wrap(self._start.theta - odom.theta), -0.3, 0.3))
        elif self._kind == "turn":
            left = self._target - self._turned
            if left <= math.radians(0.5):
                return self._end(f"{self._name}: done", done=True)
            w = min(self._w, math.sqrt(2 * lim.acc_wz * decel * left), max(0.08, 2.0 * left))
            vx, wz = 0.0, self._side * w
        else:
            left = self._target - self._travelled
            if left <= 0.005:
                return self._end(f"{self._name}: done", done=True)
            scale = min(1.0, math.sqrt(2 * lim.acc_x * decel * left) / self._v, max(0.03, 1.5 * left) / self._v)
            # backward left ends behind and to the left, as a car backing with the wheel turned left
            vx, wz = self._dir * self._v * scale, self._dir * self._side * self._w * scale
        if scan is None and self.settings.require_scan:
            return self._wait_to_see(now)
        self._blind_since, self.last_text = None, self._what
        blocked = self._obstacle(vx, wz, scan)
        if blocked:
            return self._end(blocked)
        return Motion(vx, wz, True, self.last_text)

    def _wait_to_see(self, now: float) -> Motion:
        """No scan: stand still for `blind_timeout` (the odometry still counts the way gone),
        then end."""
        self._blind_since = now if self._blind_since is None else self._blind_since
        if now - self._blind_since >= self.settings.blind_timeout:
            return self._end("stopped: I cannot see obstacles (no scan)")
        self.last_text = "waiting: I cannot see obstacles (no scan)"
        return Motion(0.0, 0.0, True, self.last_text)

    def _obstacle(self, vx: float, wz: float, scan: LaserScan | None) -> str:
        """A sentence when the swept footprint ahead meets a scan point, else ""."""
        if scan is None:
            return ""
        r = np.asarray(scan.ranges, np.float64)
        a = scan.angle_min + scan.angle_increment * np.arange(len(r))
        ok = np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max)
        px, py = r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])
        fp, lim = self.footprint, self.limits
        own = fp.contains(px, py, 0.02)        # the robot's own body, or noise at the sensor
        px, py = px[~own], py[~own]
        if px.size == 0:
            return ""
        margin = self.settings.margin
        brake = max(vx * vx / (2 * lim.acc_x), 0.0)
        turn_brake = wz * wz / (2 * lim.acc_wz)
        horizon = max(0.3, (brake + margin) / max(abs(vx), 1e-3) if abs(vx) > 1e-3 else (turn_brake + 0.2) / max(abs(wz), 1e-3))
        horizon = min(horizon, 3.0)
        t = np.linspace(0.0, horizon, 16)
        if abs(wz) < 1e-6:
            xs, ys, th = vx * t, np.zeros_like(t), np.zeros_like(t)
        else:
            th = wz * t
            xs, ys = vx / wz * np.sin(th), vx / wz * (1 - np.cos(th))
        c, s = np.cos(th)[:, None], np.sin(th)[:, None]
        lx = c * (px - xs[:, None]) + s * (py - ys[:, None])
        ly = -s * (px - xs[:, None]) + c * (py - ys[:, None])
        grow = margin if abs(vx) > 1e-3 else 0.05
        hit = fp.contains(lx, ly, grow).any(axis=0)
        if not hit.any():
            return ""
        gap = float(np.hypot(px[hit], py[hit]).min())
        where = "ahead" if vx > 1e-3 else "behind" if vx < -1e-3 else "beside the robot"
        clearance = max(0.0, gap - (fp.length / 2 if abs(vx) > 1e-3 else fp.circumscribed_radius))
        return f"stopped: obstacle {where}, {clearance:.1f} m"
