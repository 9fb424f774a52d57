"""Closed-form ASIBOT solver: published conventions, round trips, errors, Jacobian, batch."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st

from asibot.errors import RpcError
from asibot.kinematics import AsibotSolver, JointLimit, Unreachable

S = AsibotSolver()
ang = lambda lim: st.floats(-lim, lim, allow_nan=False)
joints = st.tuples(ang(180), ang(135), ang(135), ang(135), ang(180)).map(list)


def same_point(a, b, tol=1e-9, tol_deg=None):
    """Positions within tol [m], angles within tol_deg [deg] (modulo 360)."""
    d = np.subtract(a, b)
    d[3:] = (d[3:] + 180) % 360 - 180
    return np.abs(d[:3]).max() < tol and np.abs(d[3:]).max() < (tol if tol_deg is None else tol_deg)


def test_home_is_straight_up():
    assert S.fwd([0, 0, 0, 0, 0]) == pytest.approx([0, 0, 1.4, 0, 0])


def test_published_fk_for_forward_lean():
    p = S.fwd([90, 30, 0, 0, 20])
    assert p == pytest.approx([0, 0.3 + 0.4 * 0.5 * 2 + 0.0 - 0.3 + 0.3 * 0.5, 0.3 + 1.1 * math.cos(math.radians(30)), 30, 20])


def test_orientation_fixed_behind_the_azimuth():
    # docs/asibot-conventions.md, "Kinematics": q = (0, -45, 0, 0, 0) is Ry(-45), i.e. azimuth 180, rot(y') 45, rot(z'') 180.
    p = S.fwd([0, -45, 0, 0, 0])
    assert p[0] < 0 and p[3] == pytest.approx(45) and abs(p[4]) == pytest.approx(180)


@settings(max_examples=300, deadline=None)
@given(joints)
def test_round_trip_returns_same_point(q):
    p = S.fwd(q)
    q2 = S.inv(p, q)
    # Compare the flange transforms: the 5-tuple jumps where the tip crosses the q1 axis.
    # Near the stretched elbow, q3 is ill-conditioned (sqrt(1 - c3^2)): 1e-7 is the float limit.
    assert np.allclose(S.flange_transform(q2), S.flange_transform(q), atol=1e-7)


@settings(max_examples=200, deadline=None)
@given(joints)
def test_round_trip_from_own_joints_gives_them_back(q):
    p = S.fwd(q)
    # azimuth or elbow undefined: several joint sets are equally close
    assume(math.hypot(p[0], p[1]) > 1e-6 and abs(q[2]) > 1e-2 and abs(abs(q[2]) - 180) > 1e-2)
    q2 = S.inv(p, q)
    d = (np.subtract(q2, q) + 180) % 360 - 180
    assert np.abs(d).max() < 1e-6


@pytest.mark.parametrize("config", ["FU", "FD", "RU", "RD"])
def test_every_configuration_is_selected_from_a_nearby_guess(config):
    base = [30, 20, 40, 30, 10]
    p = S.fwd(base)
    fd = S.configurations(p, base, p)
    names = ["FU", "FD", "RU", "RD"]
    target = fd[names.index(config)]
    got = S.inv(p, target)
    assert np.allclose(got, target, atol=1e-9)
    assert same_point(S.fwd(got), p, 1e-9)


def test_unreachable_says_how_far():
    with pytest.raises(Unreachable) as e:
        S.inv([1.2, 0, 0.4, 0, 0], [0] * 5)
    assert e.value.code == "unreachable" and isinstance(e.value, RpcError)
    assert "[1.2, 0, 0.4, 0, 0]" in str(e.value) and "m beyond the arm's reach" in str(e.value)


def test_unreachable_with_that_tilt():
    with pytest.raises(Unreachable, match="tilt"):
        S.inv([1.09, 0, 0.3, 180, 0], [0] * 5)


def test_joint_limit_names_the_joint():
    # Reachable only with the elbow folded beyond 135 deg.
    with pytest.raises(JointLimit) as e:
        S.inv([0.05, 0, 0.35, 0, 0], [0] * 5)
    assert e.value.code == "joint_limit" and "q" in str(e.value) and "limits" in str(e.value)


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="5 finite numbers"):
        S.inv([0, 0, float("nan"), 0, 0], [0] * 5)
    with pytest.raises(ValueError):
        S.fwd([0, 0, 0])


def test_circular_joints_use_the_turn_nearest_the_guess():
    p = S.fwd([170, 20, 30, 40, 0])
    q = S.inv(p, [350, 20, 30, 40, 0])
    assert q[0] == pytest.approx(170)
    q = S.inv(S.fwd([-170, 20, 30, 40, 0]), [185, 20, 30, 40, 0])
    assert q[0] == pytest.approx(190)


def test_tie_prefers_elbow_up():
    # Straight up with guess at home: FU and FD coincide (q3 = 0), UP wins.
    q = S.inv([0, 0, 1.4, 0, 0], [0] * 5)
    assert q == pytest.approx([0, 0, 0, 0, 0], abs=1e-5) and q[2] >= 0  # UP has q3 >= 0
    p = S.fwd([0, 30, 40, 20, 0])
    fu, fd = S.configurations(p, [0] * 5, p)[:2]
    mid = list((np.array(fu) + np.array(fd)) / 2)  # equidistant from FU and FD
    assert S.inv(p, mid) == pytest.approx(fu)


SEED_LIMITS = [(-180, 180), (-135, 135), (-135, 135), (-135, 135), (-180, 180)]


@pytest.mark.parametrize("limits", [None, SEED_LIMITS], ids=["ours", "seed-test-limits"])
@pytest.mark.parametrize("point, elbow_down", [
    # roboticslab-uc3m/kinematics-dynamics tests/testAsibotSolverFromFile.cpp, AsibotSolverInvKin3
    # and InvKin4 (FORWARD cases), guess [0, 45, 0, 0, 0]: FU [az, 0, 45, 0, 0] and FD
    # [az, 45, -45, 45, 0] are both 220 deg away; "selects elbow-down on
    # LeastOverallAngularDisplacement strategy", by the smaller |dq2|.
    ([-0.318163634, 0.379172654, 1.194974747, 45.0, 0.0], [130, 45, -45, 45, 0]),
    ([-0.379172654, 0.318163634, 1.194974747, 45.0, 0.0], [140, 45, -45, 45, 0]),
])
def test_exact_tie_is_decided_by_dq2_like_the_seed(limits, point, elbow_down):
    s = AsibotSolver() if limits is None else AsibotSolver(limits=limits)
    guess = [0, 45, 0, 0, 0]
    fu, fd = s.configurations(point, guess, point)[:2]
    assert sum(abs(np.subtract(fu, guess))) == pytest.approx(sum(abs(np.subtract(fd, guess))), abs=1e-9)
    assert s.inv(point, guess) == pytest.approx(elbow_down, abs=1e-3)
    q, ok = s.inv_batch(np.array([point]), guess)
    assert ok[0] and q[0] == pytest.approx(elbow_down, abs=1e-3)


@settings(max_examples=100, deadline=None)
@given(joints)
def test_jacobian_matches_numeric_differentiation(q):
    j = S.jacobian(q)
    h = 1e-6
    num = np.zeros((3, 5))
    for k in range(5):
        dq = np.zeros(5)
        dq[k] = math.degrees(h)
        num[:, k] = (np.array(S.flange(list(np.add(q, dq)))[:3]) - np.array(S.flange(list(np.subtract(q, dq)))[:3])) / (2 * h)
    assert np.allclose(j[:3], num, atol=1e-6)
    # angular part: rotation axis of each joint
    for k in range(5):
        dq = np.zeros(5)
        dq[k] = math.degrees(h)
        r1 = S.flange_transform(list(np.add(q, dq)))[:3, :3]
        r0 = S.flange_transform(list(np.subtract(q, dq)))[:3, :3]
        w = r1 @ r0.T
        num_w = np.array([w[2, 1] - w[1, 2], w[0, 2] - w[2, 0], w[1, 0] - w[0, 1]]) / 2 / (2 * h)
        assert np.allclose(j[3:, k], num_w, atol=1e-5)


def test_tool_frame_moves_the_point_and_inverts():
    s = AsibotSolver()
    s.set_tool([0, 0, 0.1, 0, 0, 0])
    assert s.fwd([0] * 5) == pytest.approx([0, 0, 1.5, 0, 0])
    q = [20, 30, 40, 20, 10]
    assert np.allclose(s.fwd(s.inv(s.fwd(q), q)), s.fwd(q), atol=1e-9)
    s.set_tool([0] * 6)
    assert s.fwd([0] * 5) == pytest.approx([0, 0, 1.4, 0, 0])
    with pytest.raises(ValueError):
        s.set_tool([1, 2])


def test_batch_equals_single_calls():
    rng = np.random.default_rng(3)
    q = rng.uniform(-1, 1, (500, 5)) * [180, 135, 135, 135, 180]
    x = S.fwd_batch(q)
    assert np.allclose(x, [S.fwd(list(r)) for r in q], atol=1e-12)
    x[:50, 2] += 3.0  # some unreachable
    guess = [10, 0, 20, 0, 0]
    qb, ok = S.inv_batch(x, guess)
    for i in range(len(x)):
        try:
            qs = S.inv(list(x[i]), guess)
        except (Unreachable, JointLimit):
            assert not ok[i] and np.isnan(qb[i]).all()
            continue
        assert ok[i] and np.allclose(qs, qb[i], atol=1e-9)
    assert (~ok[:50]).all() and ok[50:].any()


@pytest.mark.parametrize("tool", [[0, 0, 0.1, 0, 0, 0], [0.02, -0.01, 0.12, 0.1, 0.2, -0.3]])
def test_batch_applies_the_tool_frame_like_single_calls(tool):
    s = AsibotSolver()
    s.set_tool(tool)
    q = np.random.default_rng(3).uniform([-180, -120, -120, -120, -180], [180, 120, 120, 120, 180], (300, 5))
    single = np.array([s.fwd(list(v)) for v in q])
    diff = s.fwd_batch(q) - single
    diff[:, 3:] = (diff[:, 3:] + 180) % 360 - 180
    assert np.abs(diff).max() < 1e-9
    joints, ok = s.inv_batch(single, q)
    for x, g, j, good in zip(single, q, joints, ok):
        try:
            expected = s.inv(list(x), list(g))
        except (Unreachable, JointLimit):
            assert not good
            continue
        assert good and np.allclose(j, expected, atol=1e-9)
