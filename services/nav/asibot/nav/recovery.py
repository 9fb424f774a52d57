"""Recovery behaviours: what the robot tries when it cannot plan or cannot move.

move_base's order (docs/reference/navigation.md, 'Recovery behaviours'): clear far obstacles
(conservative reset, 3 m), turn on the spot, clear nearly everything (aggressive reset, 4 x
circumscribed radius), turn again; nav2 adds backing up 0.30 m at 0.15 m/s. Here:
conservative clear, spin, back up, aggressive clear, spin. A spin or a back-up that the
costmap says would touch something is skipped as failed (nav2's BackUp that never ends when
blocked is a known complaint, same file, 'Known complaints'), and each has a time limit.
Each behaviour is closed-loop on the map pose (odometry carried forward between AMCL
updates) and names itself in a few words for the status line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asibot.nav.costmap import INSCRIBED, Costmap
from asibot.nav.geometry import Pose, wrap
from asibot.nav.robot import P3AT, Footprint


@dataclass
class Step:
    vx: float = 0.0
    wz: float = 0.0
    done: bool = False
    failed: str = ""          # why it could not be done (then done is True too)


class Recovery:
    """One behaviour: `start` once, then `step` until it returns done."""

    name = "recovering"

    def start(self, now: float, pose: Pose, costmap: Costmap) -> None:
        self.t0 = now

    def step(self, now: float, pose: Pose, costmap: Costmap) -> Step:
        return Step(done=True)


class ClearCostmap(Recovery):
    def __init__(self, reset_distance: float, name: str) -> None:
        self.reset_distance = reset_distance
        self.name = name

    def start(self, now: float, pose: Pose, costmap: Costmap) -> None:
        super().start(now, pose, costmap)
        self._center = pose

    def step(self, now: float, pose: Pose, costmap: Costmap) -> Step:
        # the costmap is in the map frame; the pose the navigator passes here is the map pose
        costmap.clear_obstacles(self._center, self.reset_distance)
        return Step(done=True)


class Spin(Recovery):
    name = "turning on the spot to look around"

    def __init__(self, angle: float = 2 * math.pi, speed: float = 0.8, timeout: float = 15.0,
                 name: str = "") -> None:
        self.angle, self.speed, self.timeout = angle, speed, timeout
        self.name = name or self.name

    def start(self, now: float, pose: Pose, costmap: Costmap) -> None:
        super().start(now, pose, costmap)
        self._turned = 0.0
        self._last = pose.theta

    def step(self, now: float, pose: Pose, costmap: Costmap) -> Step:
        self._turned += abs(wrap(pose.theta - self._last))
        self._last = pose.theta
        left = self.angle - self._turned
        if left <= 0.05:
            return Step(done=True)
        if now - self.t0 > self.timeout:
            return Step(done=True, failed="turning on the spot took too long")
        ahead = pose.theta + np.linspace(0.0, min(0.5, left), 6)
        if (costmap.footprint_cost(pose.x, pose.y, ahead) >= INSCRIBED).any():
            return Step(done=True, failed="too close to an obstacle to turn on the spot")
        return Step(0.0, min(self.speed, max(0.3, 1.5 * left)))


class BackUp(Recovery):
    name = "backing up a little"

    def __init__(self, distance: float = 0.30, speed: float = 0.15, timeout: float = 6.0,
                 footprint: Footprint = P3AT) -> None:
        self.distance, self.speed, self.timeout, self.footprint = distance, speed, timeout, footprint

    def start(self, now: float, pose: Pose, costmap: Costmap) -> None:
        super().start(now, pose, costmap)
        self._from = pose

    def step(self, now: float, pose: Pose, costmap: Costmap) -> Step:
        gone = pose.distance(self._from)
        if gone >= self.distance - 0.01:
            return Step(done=True)
        if now - self.t0 > self.timeout:
            return Step(done=True, failed="backing up took too long")
        back = -np.linspace(0.05, self.distance - gone + 0.1, 6)
        xs = pose.x + back * math.cos(pose.theta)
        ys = pose.y + back * math.sin(pose.theta)
        if (costmap.footprint_cost(xs, ys, pose.theta) >= INSCRIBED).any():
            return Step(done=True, failed="something is behind the robot")
        return Step(-self.speed, 0.0)


def default_recoveries(footprint: Footprint = P3AT) -> list[Recovery]:
    """move_base's sequence with nav2's back-up in the middle."""
    return [ClearCostmap(3.0, "forgetting obstacles further than 1.5 m"),
            Spin(),
            BackUp(footprint=footprint),
            ClearCostmap(4 * footprint.circumscribed_radius, "forgetting nearly every obstacle seen"),
            Spin()]
