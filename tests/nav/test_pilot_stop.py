"""A stop says so to the base: the pilot's next command is a zero, not silence.

Silence stops the base only at its watchdog (200 ms in the sim), later than asked and with a
warning event ("No drive command for 200 ms") that a one-switch user hears as an alarm after
each ordinary stop: seen with the real AsTeRICS ARE driving the sim through the bridge.
"""

from __future__ import annotations

import math

from asibot import messages as m
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


def test_a_goal_stands_still_while_no_scan_comes_and_gives_up_after_blind_timeout(apartment, world_places):
    """move_base's rule: a costmap that is not current commands no motion. Scans that stop
    (perception starved or gone) stop the robot with a sentence; it drives on when they come
    back; without them for `blind_timeout` the goal ends saying why."""
    sim = TinySim(apartment.grid, pose=START, beams=90, seed=3)
    sim.odom = START
    told: list[str] = []
    pilot = Pilot(apartment.grid, world_places, START, seed=1, on_event=lambda level, code, text: told.append(text))
    now = drive_a_while(pilot, sim, 0.0, 3)
    gid = pilot.goto(now, place="fridge")["goal_id"]
    now = drive_a_while(pilot, sim, now, 20)
    assert sim.vx > 0.05, "the goal never drove"

    def blind(now: float, seconds: float) -> tuple[float, list]:
        """Odometry only, for `seconds`; the commands sent."""
        sent = []
        for _ in range(int(round(seconds / 0.1))):
            pilot.odometry(now, m.Odometry(x=sim.odom.x, y=sim.odom.y, theta=sim.odom.theta, vx=sim.vx,
                                           wz=sim.wz, stamp=int(now * 1e9)))
            cmd = pilot.tick(now)
            sent.append(cmd)
            sim.step(cmd.vx if cmd else 0.0, cmd.wz if cmd else 0.0, 0.1)
            now += 0.1
        return now, sent

    now, sent = blind(now, 2.0)
    # the last scan counts for input_timeout (0.5 s): then every command is a zero
    assert all(c is not None and (c.vx, c.wz) == (0.0, 0.0) for c in sent[6:]), sent
    assert pilot.status().text == "waiting: I cannot see obstacles (no scan) on the way to fridge"
    assert pilot.status().state == "active"
    now = drive_a_while(pilot, sim, now, 20)
    assert sim.vx > 0.05, "the goal did not drive on once scans came back"
    now, sent = blind(now, 11.0)
    assert pilot.status().state == "aborted"
    assert pilot.status().text == ("could not reach fridge: I could not see obstacles for 10 s "
                                   "(no scan: is the perception service running?)")
    assert pilot.result(gid)["state"] == "aborted" and told[-1].startswith("could not reach fridge")
