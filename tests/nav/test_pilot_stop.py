"""A stop says so to the base: the pilot's next command is a zero, not silence.

Silence stops the base only at its watchdog (200 ms in the sim), later than asked and with a
warning event ("No drive command for 200 ms") that a one-switch user hears as an alarm after
each ordinary stop: seen with the real AsTeRICS ARE driving the sim through the bridge.
"""

from __future__ import annotations

import math

from asibot.nav.geometry import Pose
from asibot.nav.pilot import Pilot

from .test_mapping import feed
from .tinysim import TinySim

START = Pose(1.0, 1.5, 0.0)


def drive_a_while(pilot: Pilot, sim: TinySim, now: float, cycles: int = 10) -> float:
    for _ in range(cycles):
        feed(pilot, sim, now)
        cmd = pilot.tick(now)
        sim.step(cmd.vx if cmd else 0.0, cmd.wz if cmd else 0.0, 0.1)
        now += 0.1
    return now


def test_stopping_a_primitive_sends_one_zero_then_nothing(apartment, world_places):
    sim = TinySim(apartment.grid, pose=START, beams=90, seed=3)
    sim.odom = START
    pilot = Pilot(apartment.grid, world_places, START, seed=1)
    now = drive_a_while(pilot, sim, 0.0, 3)
    for stop in (lambda t: pilot.drive(t, "stop"), lambda t: pilot.stop(t)):
        pilot.drive(now, "forward", continuous=True)
        now = drive_a_while(pilot, sim, now)
        assert math.hypot(sim.vx, sim.wz) > 0.05, "the primitive never drove"
        stop(now)
        feed(pilot, sim, now)
        cmd = pilot.tick(now)
        assert cmd is not None and (cmd.vx, cmd.wz) == (0.0, 0.0)
        feed(pilot, sim, now + 0.1)
        assert pilot.tick(now + 0.1) is None      # then nothing: another program may drive it
        now = drive_a_while(pilot, sim, now + 0.2, 5)


def test_a_stop_with_nothing_driving_sends_nothing(apartment, world_places):
    sim = TinySim(apartment.grid, pose=START, beams=90, seed=3)
    sim.odom = START
    pilot = Pilot(apartment.grid, world_places, START, seed=1)
    now = drive_a_while(pilot, sim, 0.0, 3)
    pilot.stop(now)
    feed(pilot, sim, now)
    assert pilot.tick(now) is None
