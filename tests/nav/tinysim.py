"""A tiny 2-D world for the nav tests: a unicycle with the base's acceleration ramp, noisy
odometry, and a laser scan ray-cast against an occupancy grid (the map plus boxes that are
not on the map). Ground truth stays here: tests compare against it, never against nav's
own estimate."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from asibot.messages import LaserScan
from asibot.nav.geometry import Pose, wrap
from asibot.nav.grid import OccupancyGrid
from asibot.nav.robot import HW_ACC_WZ, HW_ACC_X, P3AT


@dataclass
class TinySim:
    grid: OccupancyGrid
    pose: Pose = Pose(0.0, 0.0, 0.0)
    odom_noise: tuple[float, float] = (0.02, 0.03)   # relative noise on v and w
    range_noise: float = 0.01
    beams: int = 180
    range_max: float = 6.0
    seed: int = 1
    vx: float = 0.0
    wz: float = 0.0
    odom: Pose = Pose(0.0, 0.0, 0.0)
    collided: bool = False
    time: float = 0.0
    rng: np.random.Generator = field(init=False)

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)
        self.world = self.grid.occupied.copy()

    def add_box(self, x0: float, y0: float, x1: float, y1: float) -> None:
        """An obstacle in the world that the map does not know."""
        xs, ys = np.meshgrid(np.arange(x0, x1, 0.01), np.arange(y0, y1, 0.01))
        r, c = self.grid.info.to_cell(xs, ys)
        ok = self.grid.info.inside(r, c)
        self.world[r[ok], c[ok]] = True

    def teleport(self, pose: Pose) -> None:
        self.pose = pose
        self.vx = self.wz = 0.0

    def step(self, cmd_vx: float, cmd_wz: float, dt: float) -> None:
        """Ramp toward the command (the base's limits), move, integrate noisy odometry."""
        self.vx += float(np.clip(cmd_vx - self.vx, -HW_ACC_X * dt, HW_ACC_X * dt))
        self.wz += float(np.clip(cmd_wz - self.wz, -HW_ACC_WZ * dt, HW_ACC_WZ * dt))
        p = self.pose
        mid = p.theta + 0.5 * self.wz * dt
        self.pose = Pose(p.x + self.vx * dt * math.cos(mid), p.y + self.vx * dt * math.sin(mid),
                         wrap(p.theta + self.wz * dt))
        ov = self.vx * (1 + self.rng.normal(0, self.odom_noise[0]))
        ow = self.wz * (1 + self.rng.normal(0, self.odom_noise[1]))
        o = self.odom
        mid = o.theta + 0.5 * ow * dt
        self.odom = Pose(o.x + ov * dt * math.cos(mid), o.y + ov * dt * math.sin(mid), wrap(o.theta + ow * dt))
        self.time += dt
        if self.touching():
            self.collided = True

    def touching(self) -> bool:
        hx, hy = P3AT.length / 2, P3AT.width / 2
        gx, gy = np.meshgrid(np.linspace(-hx, hx, 14), np.linspace(-hy, hy, 12))
        c, s = math.cos(self.pose.theta), math.sin(self.pose.theta)
        r, col = self.grid.info.to_cell(self.pose.x + c * gx - s * gy, self.pose.y + s * gx + c * gy)
        ok = self.grid.info.inside(r, col)
        return bool(self.world[r[ok], col[ok]].any())

    def scan(self) -> LaserScan:
        """A 360-degree scan in the base frame from the true pose (ray marching, 1.5 cm steps)."""
        inc = 2 * math.pi / self.beams
        a = -math.pi + inc * np.arange(self.beams)
        t = np.arange(0.05, self.range_max, 0.015)
        th = self.pose.theta + a
        x = self.pose.x + np.cos(th)[:, None] * t[None, :]
        y = self.pose.y + np.sin(th)[:, None] * t[None, :]
        r, c = self.grid.info.to_cell(x, y)
        ok = self.grid.info.inside(r, c)
        hit = np.zeros(x.shape, bool)
        hit[ok] = self.world[r[ok], c[ok]]
        first = np.where(hit.any(axis=1), hit.argmax(axis=1), -1)
        ranges = np.where(first >= 0, t[np.maximum(first, 0)], np.inf)
        ranges = ranges + self.rng.normal(0, self.range_noise, self.beams) * np.isfinite(ranges)
        return LaserScan(angle_min=-math.pi, angle_increment=inc, range_min=0.05, range_max=self.range_max,
                         ranges=ranges.astype(np.float32))


@dataclass
class OdomReading:
    x: float
    y: float
    theta: float
    vx: float
    wz: float


def odometry(sim: TinySim) -> OdomReading:
    o = sim.odom
    return OdomReading(o.x, o.y, o.theta, sim.vx, sim.wz)


class Harness:
    """The future service's loop, at 10 Hz: scan -> AMCL -> navigator -> base, in sim time."""

    def __init__(self, sim: TinySim, amcl, navigator, dt: float = 0.1) -> None:
        self.sim, self.amcl, self.nav, self.dt = sim, amcl, navigator, dt
        self.now = 0.0
        self.commands: list[tuple[float, float]] = []
        #: what the loop tells the navigator about the filter (a test makes it lose track)
        self.localised: Callable[[], bool] = lambda: True

    def pose(self) -> Pose:
        return self.amcl.pose(self.sim.odom)

    def localise(self) -> Pose:
        self.amcl.update(self.sim.odom, self.sim.scan())
        return self.pose()

    def step(self) -> None:
        scan = self.sim.scan()
        self.amcl.update(self.sim.odom, scan)
        cmd = self.nav.step(self.now, self.pose(), scan, odometry(self.sim), localised=self.localised())
        vx, wz = (cmd.vx, cmd.wz) if cmd is not None else (0.0, 0.0)
        self.commands.append((vx, wz))
        for _ in range(2):
            self.sim.step(vx, wz, self.dt / 2)
        self.now += self.dt

    def run(self, until, limit: float) -> None:
        """Step until `until()` is true or `limit` seconds of sim time passed."""
        end = self.now + limit
        while not until() and self.now < end:
            self.step()
