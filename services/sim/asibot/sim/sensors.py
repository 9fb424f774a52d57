"""The Pioneer's sonar ring, bumpers and battery, read from the MuJoCo state.

Sonar: each of the 16 transducers (ARIA p3at-sh.p poses, docs/arcos.md "P3-AT parameters") is a cone;
we cast three rays across +-10 deg of its axis and keep the nearest echo, up to the sonar
board's 4.335 m maximum, which is also what a transducer reports without an echo.
Battery: a 12 V lead-acid pack; p2os warns below 11.75 V and errors below 11.0 V (same section).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from asibot.sim.scene import ROBOT_GROUP, Base

SONAR_MAX_RANGE = 4.335
SONAR_CONE = (-math.radians(10), 0.0, math.radians(10))
SONAR_HEADINGS_DEG = (90, 50, 30, 10, -10, -30, -50, -90, -90, -130, -150, -170, 170, 150, 130, 90)

BATTERY_FULL_V = 12.9
BATTERY_EMPTY_V = 11.0
DRAIN_V_PER_S = 0.5 / 3600      # idle electronics
DRIVE_DRAIN_V_PER_S = 1.0 / 3600  # extra at full drive effort
CHARGE_V_PER_S = 2.0 / 3600

_GROUPS = np.ones(6, np.uint8)
_GROUPS[ROBOT_GROUP] = 0


def sonar_ranges(model: mujoco.MjModel, data: mujoco.MjData, base: Base) -> list[float]:
    """Nearest echo per transducer in metres (max range when nothing answers)."""
    out = []
    geomid = np.zeros(1, np.int32)
    for site in base.sonar_sites:
        origin = data.site_xpos[site]
        axes = data.site_xmat[site].reshape(3, 3)
        best = SONAR_MAX_RANGE
        for a in SONAR_CONE:
            direction = math.cos(a) * axes[:, 0] + math.sin(a) * axes[:, 1]
            d = mujoco.mj_ray(model, data, origin, direction, _GROUPS, 1, -1, geomid)
            if 0 <= d < best:
                best = d
        out.append(float(best))
    return out


def sonar_angles() -> list[float]:
    return [math.radians(h) for h in SONAR_HEADINGS_DEG]


def bumpers(model: mujoco.MjModel, data: mujoco.MjData, base: Base, robot_bodies: set[int]
            ) -> tuple[list[bool], list[bool]]:
    """Which bumper segments touch something that is not the robot itself."""
    front = {g: False for g in base.bumpers_front}
    rear = {g: False for g in base.bumpers_rear}
    for c in data.contact[: data.ncon]:
        for mine, other in ((c.geom1, c.geom2), (c.geom2, c.geom1)):
            if int(model.geom_bodyid[other]) in robot_bodies:
                continue
            if mine in front:
                front[mine] = True
            elif mine in rear:
                rear[mine] = True
    return list(front.values()), list(rear.values())


class Battery:
    """Slow discharge with use, recharge while parked at the charging station."""

    def __init__(self, volts: float = BATTERY_FULL_V) -> None:
        self.volts = volts

    def update(self, dt: float, effort: float, charging: bool) -> float:
        """effort: 0..1 share of full drive speed."""
        if charging:
            self.volts = min(BATTERY_FULL_V, self.volts + CHARGE_V_PER_S * dt)
        else:
            drain = DRAIN_V_PER_S + DRIVE_DRAIN_V_PER_S * min(max(effort, 0.0), 1.0)
            self.volts = max(BATTERY_EMPTY_V, self.volts - drain * dt)
        return self.volts
