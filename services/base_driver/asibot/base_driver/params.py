"""P3-AT parameter sets, chosen by the subclass the controller names in its SYNC2 reply.

Values from docs/arcos.md, "P3-AT parameters" (ARIA `params/p3at.p`, `p3at-sh.p`,
p2os `robot_params.cpp`): "p3at" is the old H8/AROS controller whose positions count in
0.465 mm units, "p3at-sh" the SH/ARCOS controller already counting in mm.
"""

from __future__ import annotations

import dataclasses
import math

#: Sonar poses (x mm, y mm, heading deg) of the 8+8 ring, ARIA p3at-sh.p (docs/arcos.md "P3-AT parameters").
SONAR_POSES: tuple[tuple[int, int, int], ...] = (
    (147, 136, 90), (193, 119, 50), (227, 79, 30), (245, 27, 10),
    (245, -27, -10), (227, -79, -30), (193, -119, -50), (147, -136, -90),
    (-144, -136, -90), (-189, -119, -130), (-223, -79, -150), (-241, -27, -170),
    (-241, 27, 170), (-223, 79, 150), (-189, 119, 130), (-144, 136, 90),
)

#: Sonar board default maximum range (docs/arcos.md "P3-AT parameters").
SONAR_MAX_RANGE_MM = 4335

#: p2os battery diagnostics (docs/arcos.md "P3-AT parameters"): WARN below 11.75 V, ERROR below 11.0 V.
BATTERY_WARN_V = 11.75
BATTERY_ERROR_V = 11.0


@dataclasses.dataclass(frozen=True)
class RobotParams:
    """Firmware-unit conversions and limits of one controller family."""

    subclass: str
    dist_conv: float = 1.0          # position units -> mm
    angle_conv: float = 2 * math.pi / 4096   # 0.001534 rad per THPOS unit
    vel_conv: float = 1.0           # wheel velocity units -> mm/s
    range_conv: float = 1.0         # sonar units -> mm
    diff_conv: float = 0.0034       # (R - L)/2 mm/s -> rad/s; 2/0.0034 = 588 mm effective track
    vel2_divisor: int = 20
    max_velocity_mm_s: int = 1200   # MaxVelocity (absolute)
    max_rot_velocity_deg_s: int = 300
    sonar_count: int = 16

    @property
    def track_mm(self) -> float:
        """Effective (slip-inflated) track implied by DiffConvFactor (docs/arcos.md "SIP")."""
        return 2.0 / self.diff_conv

    def sonar_angles(self) -> list[float]:
        return [math.radians(h) for _, _, h in SONAR_POSES[: self.sonar_count]]


P3AT = RobotParams(subclass="p3at", dist_conv=0.465)
P3AT_SH = RobotParams(subclass="p3at-sh", dist_conv=1.0)

KNOWN = {p.subclass: p for p in (P3AT, P3AT_SH)}


def for_subclass(subclass: str) -> RobotParams:
    """Pick the parameter set named by the SYNC2 subclass (e.g. "p3at" or "p3at-sh").

    Any other "*-sh" controller shares the SH unit conventions (DistConvFactor 1.0), so it
    gets the p3at-sh set; anything else is refused rather than driven with wrong units.
    """
    key = subclass.strip().lower()
    if key in KNOWN:
        return KNOWN[key]
    if key.endswith("-sh"):
        return dataclasses.replace(P3AT_SH, subclass=key)
    raise ValueError(
        f"the robot reports subclass {subclass!r}; this driver knows {sorted(KNOWN)}. "
        "Start it with --params p3at or --params p3at-sh to force a parameter set."
    )
