"""AMCL against the tiny simulator's ground truth: tracking, kidnap, KLD, the motion model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from asibot.nav.amcl import Amcl, AmclParams, kld_limit
from asibot.nav.errors import NavError
from asibot.nav.geometry import Pose

from .tinysim import TinySim


def drive(sim: TinySim, amcl: Amcl, vx: float, wz: float, seconds: float, dt: float = 0.05) -> None:
    for k in range(int(round(seconds / dt))):
        sim.step(vx, wz, dt)
        if k % 2 == 0:                              # scans at 10 Hz
            amcl.update(sim.odom, sim.scan())


def error(sim: TinySim, amcl: Amcl) -> tuple[float, float]:
    est = amcl.pose(sim.odom)
    return sim.pose.distance(est), abs(math.remainder(sim.pose.theta - est.theta, 2 * math.pi))


@pytest.fixture
def station(world_places) -> Pose:
    return world_places.get("charging station").pose


def test_converges_from_the_charging_station_and_tracks(apartment, station):
    sim = TinySim(apartment.grid, pose=station, odom=Pose(0.0, 0.0, 0.0), seed=2)
    amcl = Amcl(apartment.grid, seed=2)
    amcl.set_pose(station)                              # the robot starts docked: pose known roughly
    assert amcl.estimate.particles == amcl.params.max_particles
    drive(sim, amcl, 0.0, 0.8, 3.0)                     # turn to look around
    drive(sim, amcl, 0.3, 0.0, 4.0)
    drive(sim, amcl, 0.2, 0.4, 4.0)
    d, a = error(sim, amcl)
    assert d < 0.1 and a < math.radians(5)
    est = amcl.estimate
    assert est.particles <= 600                         # KLD shrank the set once it converged
    assert est.std_xy < 0.2 and est.covariance.shape == (3, 3)
    assert np.allclose(est.covariance, est.covariance.T)


def test_relocalises_after_a_kidnap(apartment, station):
    sim = TinySim(apartment.grid, pose=station, odom=Pose(0.0, 0.0, 0.0), seed=5)
    amcl = Amcl(apartment.grid, seed=5)
    amcl.set_pose(station)
    drive(sim, amcl, 0.0, 0.8, 3.0)
    drive(sim, amcl, 0.3, 0.0, 3.0)
    assert error(sim, amcl)[0] < 0.1
    sim.teleport(Pose(8.0, 2.0, 0.5))                   # carried to the other room; odometry saw nothing
    assert error(sim, amcl)[0] > 5.0
    injected = 0.0
    for _ in range(10):
        drive(sim, amcl, 0.0, 0.8, 2.0)
        injected = max(injected, amcl.injection_share())
        drive(sim, amcl, 0.15, 0.0, 1.0)
        d, a = error(sim, amcl)
        if d < 0.15 and a < math.radians(10):
            break
    assert injected > 0.05                              # random particles did the finding
    assert d < 0.15 and a < math.radians(10), f"still lost: {d:.2f} m, {math.degrees(a):.0f} deg off"


def test_a_leap_to_a_place_that_looks_alike_is_not_believed(apartment, station):
    """One scan that fits a place 9 m away better (seen in CI: a box that is not on the map
    filled the camera's view, and random guesses landed where a wall stands as far): the
    estimate leaps there, the pose does not. It is the trusted one carried by odometry, still
    localised; the next scans from where the robot is bring the estimate back."""
    sim = TinySim(apartment.grid, pose=station, odom=Pose(0.0, 0.0, 0.0), seed=3)
    amcl = Amcl(apartment.grid, seed=3)
    amcl.set_pose(station)
    drive(sim, amcl, 0.0, 0.8, 3.0)
    drive(sim, amcl, 0.3, 0.0, 2.0)
    assert error(sim, amcl)[0] < 0.1 and not amcl.holding
    elsewhere = Pose(8.0, 2.0, 0.5)
    look_alike = TinySim(apartment.grid, pose=elsewhere, seed=4)
    # guesses around the other place, as injection makes them, and one scan that fits there
    amcl.poses = np.r_[amcl.poses, np.c_[elsewhere.x, elsewhere.y, elsewhere.theta] + np.random.default_rng(1).normal(0, 0.05, (500, 3))]
    amcl.weights = np.full(len(amcl.poses), 1.0 / len(amcl.poses))
    for _ in range(12):
        sim.step(0.3, 0.0, 0.1)
    assert amcl.update(sim.odom, look_alike.scan())
    assert amcl.estimate.pose.distance(elsewhere) < 0.3, "the scan did not favour the other place"
    assert amcl.holding and amcl.leaps == 1
    assert error(sim, amcl)[0] < 0.15, f"the pose leapt: {amcl.pose(sim.odom)} for {sim.pose}"
    drive(sim, amcl, 0.3, 0.0, 2.0)                     # scans from where the robot is
    assert not amcl.holding and not amcl.searching
    assert error(sim, amcl)[0] < 0.15 and amcl.estimate.pose.distance(sim.pose) < 0.15


def test_a_robot_carried_off_is_believed_once_the_hold_has_shown_the_new_place(apartment, station):
    """Carried off without the wheels turning: the trusted pose is held for half a turn, and the
    new place, steady under odometry and fitting the scans, is believed then; never a wrong one."""
    sim = TinySim(apartment.grid, pose=station, odom=Pose(0.0, 0.0, 0.0), seed=5)
    amcl = Amcl(apartment.grid, seed=5)
    amcl.set_pose(station)
    drive(sim, amcl, 0.0, 0.8, 3.0)
    drive(sim, amcl, 0.3, 0.0, 3.0)
    sim.teleport(Pose(8.0, 2.0, 0.5))
    held, wrong = False, []
    for _ in range(60):                                 # turning in place, half a second at a time
        drive(sim, amcl, 0.0, 0.8, 0.5)
        held = held or amcl.holding
        believed = not (amcl.holding or amcl.searching)
        if held and believed and error(sim, amcl)[0] > 0.5:
            wrong.append(amcl.pose(sim.odom))
        if held and believed:
            break
    assert held and wrong == []
    d, a = error(sim, amcl)
    assert d < 0.15 and a < math.radians(10), f"believed {d:.2f} m, {math.degrees(a):.0f} deg off"
    assert amcl.leaps == 1


def test_injected_random_poses_do_not_blur_a_tracked_estimate(apartment, station):
    """A moment of low likelihood (a box in front of the laser) injects random poses; they are
    guesses to be weighed by the next scan, not part of where the robot is now."""
    sim = TinySim(apartment.grid, pose=station, odom=Pose(0.0, 0.0, 0.0), seed=3)
    amcl = Amcl(apartment.grid, seed=3)
    amcl.set_pose(station)
    drive(sim, amcl, 0.0, 0.8, 3.0)
    drive(sim, amcl, 0.3, 0.0, 2.0)
    assert error(sim, amcl)[0] < 0.1 and amcl.estimate.std_xy < 0.2
    for _ in range(10):
        amcl.w_slow = 10 * amcl.w_fast                  # as after a run of poor scans: inject the cap
        drive(sim, amcl, 0.2, 0.0, 0.3)
        assert amcl.estimate.std_xy < 0.3, f"the estimate spread to {amcl.estimate.std_xy:.2f} m"
        assert error(sim, amcl)[0] < 0.15


def test_guesses_the_scan_ruled_out_stay_out_of_the_estimate(apartment, station):
    """A tight, heavy cluster where the robot is, and a thousand random guesses that carry 2 % of
    the weight between them: the estimate is the cluster, its spread is the cluster's."""
    amcl = Amcl(apartment.grid, seed=4)
    amcl.set_pose(station, cov=(0.05 ** 2, 0.05 ** 2, 0.03 ** 2))
    tracked = amcl.poses[:500].copy()
    guesses = amcl._random_poses(1000)
    amcl.poses = np.r_[tracked, guesses]
    amcl.weights = np.r_[np.full(500, 1.0), np.full(1000, 0.01)]
    amcl.weights /= amcl.weights.sum()
    est = amcl._cluster_estimate()
    assert est.pose.distance(station) < 0.05
    assert est.std_xy < 0.1, f"the guesses spread the estimate to {est.std_xy:.2f} m"


def test_global_localisation_spreads_over_free_space(apartment):
    amcl = Amcl(apartment.grid, seed=1)
    amcl.global_localization()
    xy = amcl.poses[:, :2]
    r, c = apartment.grid.info.to_cell(xy[:, 0], xy[:, 1])
    assert (apartment.grid.data[r, c] == 0).all()
    assert xy[:, 0].std() > 2.0 and not amcl.estimate.converged


def test_motion_model_is_the_diff_corrected_one(apartment):
    quiet = AmclParams(alpha1=0.0, alpha2=0.0, alpha3=0.0, alpha4=0.0)
    amcl = Amcl(apartment.grid, quiet, seed=0)
    amcl.set_pose(Pose(2.0, 2.0, 0.0), cov=(0.0, 0.0, 0.0))
    amcl.motion(Pose(0.0, 0.0, 0.0), Pose(0.3, 0.4, 1.0))       # no noise: every particle moves exactly
    assert np.allclose(amcl.poses, [2.3, 2.4, 1.0])
    amcl.set_pose(Pose(2.0, 2.0, math.pi / 2), cov=(0.0, 0.0, 0.0))
    amcl.motion(Pose(0.0, 0.0, 0.0), Pose(-0.5, 0.0, 0.0))      # backwards: no half turn
    assert np.allclose(amcl.poses, [2.0, 1.5, math.pi / 2])
    # with noise, the spread is sqrt(alpha3 * trans^2) along the motion: a standard deviation
    noisy = Amcl(apartment.grid, AmclParams(alpha1=0.0, alpha2=0.0, alpha3=0.2, alpha4=0.0), seed=0)
    noisy.set_pose(Pose(2.0, 2.0, 0.0), cov=(0.0, 0.0, 0.0))
    noisy.motion(Pose(0.0, 0.0, 0.0), Pose(1.0, 0.0, 0.0))
    assert noisy.poses[:, 0].std() == pytest.approx(math.sqrt(0.2), rel=0.1)


def test_updates_only_after_the_minimum_travel(apartment, station):
    amcl = Amcl(apartment.grid, seed=0)
    amcl.set_pose(station)
    sim = TinySim(apartment.grid, pose=station, odom=Pose(1.0, 1.0, 0.0))
    assert amcl.update(sim.odom, sim.scan())                    # the first scan always updates
    assert not amcl.update(Pose(1.1, 1.0, 0.05), sim.scan())    # 0.1 m, 0.05 rad: not yet
    assert amcl.update(Pose(1.25, 1.0, 0.0), sim.scan())        # 0.25 m on x
    moved = amcl.pose(Pose(1.35, 1.0, 0.0))                     # between updates: odometry carries it
    assert moved.distance(amcl.estimate.pose) == pytest.approx(0.1, abs=1e-6)


def test_kld_limit_is_amcls():
    def pf_resample_limit(k, err=0.05, z=0.99):
        b = 2 / (9 * (k - 1))
        return math.ceil((k - 1) / (2 * err) * (1 - b + math.sqrt(b) * z) ** 3)
    ks = np.array([2, 3, 10, 50, 200])
    want = [min(5000, max(100, pf_resample_limit(k))) for k in ks]
    assert kld_limit(ks, 0.05, 0.99, 100, 5000).tolist() == want
    assert kld_limit(np.array([1]), 0.05, 0.99, 100, 5000).tolist() == [100]


def test_bad_poses_are_sentences_and_change_nothing(apartment, station):
    amcl = Amcl(apartment.grid, seed=0)
    with pytest.raises(NavError, match="no starting point"):
        amcl.update(station, None)
    amcl.set_pose(station)
    before = amcl.poses.copy()
    with pytest.raises(NavError, match="outside the map"):
        amcl.set_pose(Pose(40.0, 1.0, 0.0))
    with pytest.raises(NavError, match="finite"):
        amcl.set_pose(Pose(math.nan, 1.0, 0.0))
    with pytest.raises(NavError, match="not finite"):
        amcl.update(Pose(math.inf, 0.0, 0.0), None)
    assert np.array_equal(amcl.poses, before)


def test_set_pose_holds_when_the_odometry_was_reset_meanwhile(apartment, station):
    """A sim reset (or a base driver that restarted) zeroes the odometry; "I am here" then must
    put the robot there, not there plus the odometry's jump."""
    sim = TinySim(apartment.grid, pose=station, odom=Pose(0.0, 0.0, 0.0), seed=4)
    amcl = Amcl(apartment.grid, seed=4)
    amcl.set_pose(station)
    drive(sim, amcl, 0.3, 0.0, 6.0)                     # odometry ~1.8 m from zero
    sim.teleport(station)
    sim.odom = Pose(0.0, 0.0, 0.0)                      # reset with the world
    amcl.set_pose(station)
    assert amcl.pose(sim.odom).distance(station) < 0.1      # the particles spread about it
    drive(sim, amcl, 0.0, 0.0, 1.0)
    d, a = error(sim, amcl)
    assert d < 0.1 and a < math.radians(5)
