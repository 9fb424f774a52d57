import math

import numpy as np
import pytest

from asibot.errors import RpcError
from asibot.kinematics import trajectory as tr

from .robot_under_test import asibot_model, asibot_spec


@pytest.mark.parametrize("cls", [tr.OrderOneTraj, tr.OrderThreeTraj])
def test_generators_hit_both_ends_and_hold_after(cls):
    g = cls(np.array([1.0, -2.0]), np.array([3.0, 4.0]), 2.0)
    assert np.allclose(g.get(0.0), [1.0, -2.0])
    assert np.allclose(g.get(2.0), [3.0, 4.0])
    assert np.allclose(g.get(5.0), [3.0, 4.0])
    assert np.allclose(g.getdot(5.0), 0.0)


def test_order_three_has_null_end_velocities_and_monotonic_progress():
    g = tr.OrderThreeTraj(np.array([0.0]), np.array([1.0]), 3.0)
    assert g.getdot(0.0)[0] == 0.0
    assert abs(g.getdot(3.0 - 1e-9)[0]) < 1e-6
    xs = [g.get(t)[0] for t in np.linspace(0, 3, 301)]
    assert all(b >= a for a, b in zip(xs, xs[1:]))
    assert g.getdot(1.5)[0] == pytest.approx(1.5 / 3.0)  # peak = 1.5 x mean


def test_order_one_is_constant_velocity():
    g = tr.OrderOneTraj(np.array([0.0]), np.array([2.0]), 4.0)
    assert g.getdot(0.0)[0] == g.getdot(3.9)[0] == 0.5
    assert g.get(1.0)[0] == pytest.approx(0.5)


def test_movj_is_isochronous_and_respects_max_velocity():
    vmax = np.radians([25.0] * 5)
    q1 = np.radians([90.0, 10.0, 0.0, 0.0, 0.0])
    plan = tr.plan_movj(np.zeros(5), q1, vmax, duration=0.1)  # too fast: stretched
    assert plan.duration == pytest.approx(1.5 * math.radians(90) / vmax[0])
    for t in np.linspace(0, plan.duration, 50):
        assert np.all(np.abs(plan.qdot_at(t)) <= vmax + 1e-9)
    assert np.allclose(plan.q_at(plan.duration), q1)
    mid = plan.q_at(plan.duration / 2)
    assert np.allclose(mid, q1 / 2)  # all joints at the same fraction: they end together


def test_movj_rejects_bad_speed():
    with pytest.raises(RpcError) as err:
        tr.plan_movj(np.zeros(5), np.ones(5), np.ones(5), speed=3.0)
    assert err.value.code == "bad_request"


def _line(p0, p1, **kw):
    spec, model = asibot_spec(), asibot_model()
    q0 = model.inv(p0, np.array([0, 0.1, 0.5, 0.5, 0]))
    return model, q0, tr.plan_movl(model, q0, p0, p1, spec.lower, spec.upper, spec.max_velocity, **kw)


def test_movl_follows_a_straight_line():
    p0, p1 = np.array([0.5, 0.2, 0.7, 1.5, 0.0]), np.array([0.6, -0.2, 0.9, 1.5, 0.3])
    model, q0, plan = _line(p0, p1, speed=0.1)
    assert plan.duration >= np.linalg.norm(p1[:3] - p0[:3]) / 0.1 - 1e-9
    for t in np.linspace(0, plan.duration, 40):
        p = model.fwd(plan.q_at(t))
        s = np.dot(p[:3] - p0[:3], p1[:3] - p0[:3]) / np.dot(p1[:3] - p0[:3], p1[:3] - p0[:3])
        assert np.linalg.norm(p[:3] - (p0[:3] + s * (p1[:3] - p0[:3]))) < 1e-3
    assert np.allclose(model.fwd(plan.q_at(plan.duration)), p1, atol=1e-6)
    assert np.allclose(plan.qdot_at(0.0), 0.0)


class CountingModel:
    """The real model, counting the poses its path checks solve."""

    def __init__(self, fail_after: int | None = None) -> None:
        self.model, self.solved, self.fail_after = asibot_model(), 0, fail_after

    def __getattr__(self, name):
        return getattr(self.model, name)

    def inv_path(self, poses, q0):
        self.solved += len(poses)
        qs, failure = self.model.inv_path(poses, q0)
        if self.fail_after is not None and len(poses) > self.fail_after:  # an IK failure midway
            return qs[:self.fail_after], RpcError("unreachable", "no solution here")
        return qs, failure


def test_movl_to_an_unreachable_end_is_refused_before_sampling_the_path():
    # the end point's wrist is beyond reach: one IK says so, no path of samples is solved
    spec, model = asibot_spec(), CountingModel()
    p0, p1 = np.array([0.9, 0.0, 0.3, math.pi / 2, 0.0]), np.array([0.85, 0.0, 0.9, 0.0, 0.0])
    q0 = model.inv(p0, np.array([0, 0.1, 0.5, 0.5, 0]))
    for end in (p1, np.array([1e5, 0.0, 1.0, 0.0, 0.0])):
        with pytest.raises(RpcError) as err:
            tr.plan_movl(model, q0, p0, end, spec.lower, spec.upper, spec.max_velocity)
        assert err.value.code == "unreachable" and "beyond" in err.value.message
    assert model.solved == 2


def test_movl_through_a_singularity_says_where_before_moving():
    # both ends reachable; the straight line crosses the base axis, where the azimuth flips
    with pytest.raises(RpcError) as err:
        _line(np.array([0.5, 0.0, 1.2, 0.0, 0.0]), np.array([-0.5, 0.001, 1.2, 0.0, 0.0]))
    assert err.value.code == "unreachable" and "at 50 % of the path" in err.value.message


def test_movl_unreachable_midway_says_where_before_moving():
    spec, model = asibot_spec(), CountingModel(fail_after=60)
    p0, p1 = np.array([0.5, 0.2, 0.7, 1.5, 0.0]), np.array([0.6, -0.2, 0.9, 1.5, 0.3])
    q0 = model.inv(p0, np.array([0, 0.1, 0.5, 0.5, 0]))
    with pytest.raises(RpcError) as err:
        tr.plan_movl(model, q0, p0, p1, spec.lower, spec.upper, spec.max_velocity)
    assert err.value.code == "unreachable"
    assert "The point is unreachable at " in err.value.message and "% of the path" in err.value.message
    pct = int(err.value.message.split("at ")[1].split(" %")[0])
    assert 0 < pct < 100


def test_a_line_too_long_to_check_is_refused():
    # ten turns of the tool about its axis: reachable at both ends, 7,200 steps of 0.5 deg
    spec, model = asibot_spec(), CountingModel()
    p0 = np.array([0.5, 0.2, 0.7, 1.5, 0.0])
    q0 = model.inv(p0, np.array([0, 0.1, 0.5, 0.5, 0]))
    with pytest.raises(RpcError) as err:
        tr.plan_movl(model, q0, p0, p0 + [0, 0, 0, 0, 20 * math.pi], spec.lower, spec.upper, spec.max_velocity)
    assert err.value.code == "bad_request" and "too long" in err.value.message
    assert model.solved == 1


def test_movl_into_the_stretched_home_pose_takes_seconds_within_joint_speeds():
    # From holding the red can (gripper down) straight up to home, the seed's template move:
    # dq/ds grows without bound at home, but only where the law slows down.
    spec, model = asibot_spec(), asibot_model()
    q0 = np.radians([90.0, 21.3, 96.2, 62.8, 0.0])
    p0, p1 = model.fwd(q0), np.array([0.0, 0.0, 1.4, 0.0, 0.0])
    plan = tr.plan_movl(model, q0, p0, p1, spec.lower, spec.upper, spec.max_velocity)
    assert plan.duration < 2 * np.linalg.norm(p1[:3] - p0[:3]) / tr.DEFAULT_LINEAR_SPEED
    ts = np.linspace(0.0, plan.duration, 3000)
    peak = np.max([np.abs(plan.qdot_at(t)) for t in ts], axis=0)
    assert np.all(peak <= np.asarray(spec.max_velocity) * 1.001)
    assert np.allclose(model.fwd(plan.q_at(plan.duration)), p1, atol=1e-6)
