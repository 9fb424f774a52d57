"""URDFs, catalog, Pinocchio solver and the SI adapter the controller uses."""

import math
import os

import numpy as np
import pytest

from asibot import robots
from asibot.kinematics import AsibotSolver, GenericSolver, JointLimit, Unreachable, solver_for

ASI = robots.get("asibot")
KAT = robots.get("pioneer")
# Each test draws from a generator of its own: the same samples whichever tests ran before it in
# its process (under xdist a shared one gave each worker other samples, and one failed).


def test_catalog_has_every_robot_with_consistent_lists():
    assert robots.ids() == ["asibot", "asibot-sim", "pioneer", "pioneer-sim"]
    for rid in robots.ids():
        s = robots.get(rid)
        assert s.urdf_path.exists()
        n = len(s.joint_names)
        assert n == 5 and len(s.lower) == len(s.upper) == len(s.max_velocity) == len(s.home) == n
        assert all(lo <= h <= hi for lo, h, hi in zip(s.lower, s.home, s.upper))
    assert ASI.joint_names == ["q1", "q2", "q3", "q4", "q5"]
    assert ASI.upper[1] == pytest.approx(math.radians(135)) and ASI.max_velocity[0] == pytest.approx(math.radians(25))
    with pytest.raises(KeyError, match="choose one of"):
        robots.get("nao")


@pytest.mark.parametrize("spec", [ASI, KAT], ids=["asibot", "katana"])
def test_urdf_loads_in_mujoco_and_pinocchio(spec):
    os.environ.setdefault("MUJOCO_GL", "osmesa")
    import mujoco
    m = mujoco.MjModel.from_xml_path(str(spec.urdf_path))
    names = {m.joint(i).name for i in range(m.njnt)}
    assert set(spec.joint_names) <= names
    g = GenericSolver(spec.urdf_path, spec.tool_link, spec.joint_names)
    assert np.allclose(g.lower, spec.lower) and np.allclose(g.upper, spec.upper)


def test_urdf_fk_equals_closed_form():
    g = GenericSolver(ASI.urdf_path, ASI.tool_link, ASI.joint_names)
    for q in np.random.default_rng(7).uniform(ASI.lower, ASI.upper, (200, 5)):
        assert np.allclose(g.fwd(q), AsibotSolver().flange_transform(list(np.degrees(q))), atol=1e-9)


def test_generic_ik_agrees_with_closed_form_on_the_asibot():
    g = GenericSolver(ASI.urdf_path, ASI.tool_link, ASI.joint_names)
    a = AsibotSolver()
    for q in np.random.default_rng(8).uniform(-1, 1, (30, 5)) * np.radians([170, 120, 120, 120, 170]):
        guess = q + 0.05
        qc = np.radians(a.inv(a.fwd(list(np.degrees(q))), list(np.degrees(guess))))
        qg = g.inv(g.fwd(q), guess)
        assert np.allclose(g.fwd(qg), g.fwd(q), atol=1e-7)
        assert np.allclose(qg, qc, atol=1e-5)  # near the guess both find the same configuration


@pytest.mark.parametrize("rid", ["asibot-sim", "pioneer-sim"])
def test_adapter_round_trips_in_si(rid):
    spec = robots.get(rid)
    m = solver_for(spec)
    assert m.pose_size == 5
    for q in np.random.default_rng(9).uniform(spec.lower, spec.upper, (40, 5)):
        p = m.fwd(q)
        q2 = m.inv(p, spec.home)
        assert np.all(q2 >= np.array(spec.lower) - 1e-9) and np.all(q2 <= np.array(spec.upper) + 1e-9)
        p2 = m.fwd(q2)
        d = p2 - p
        d[3:] = (d[3:] + np.pi) % (2 * np.pi) - np.pi
        assert np.abs(d).max() < 1e-6
        assert np.allclose(m.from_user_point(m.to_user_point(p)), p)


def test_adapter_units_and_home():
    m = solver_for(ASI)
    assert m.to_user_point(m.fwd(np.zeros(5))) == pytest.approx([0, 0, 1.4, 0, 0])
    assert m.to_user_point([0, 0, 1, math.pi / 2, 0]) == pytest.approx([0, 0, 1, 90, 0])
    with pytest.raises(ValueError):
        m.from_user_point([0, 0, 1])


@pytest.mark.parametrize("rid", ["asibot", "pioneer"])
def test_adapter_errors_are_rpc_errors(rid):
    spec = robots.get(rid)
    m = solver_for(spec)
    with pytest.raises(Unreachable) as e:
        m.inv(np.array([3.0, 0, 0.5, 0, 0]), spec.home)
    assert e.value.code == "unreachable" and "[3, 0, 0.5, 0, 0]" in str(e.value)


def test_katana_limit_case():
    m = solver_for(KAT)
    q = np.array(KAT.home)
    q[0] = 3.0  # past motor1's upper limit 2.891 rad
    with pytest.raises(JointLimit, match="joint limit"):
        m.inv(m.fwd(q), KAT.home)


def test_jacobians_agree_between_solvers():
    g = solver_for(robots.get("asibot"))
    p = GenericSolver(ASI.urdf_path, ASI.tool_link, ASI.joint_names)
    for q in np.random.default_rng(10).uniform(ASI.lower, ASI.upper, (20, 5)):
        assert np.allclose(g.jacobian(q), p.jacobian(q), atol=1e-9)


def test_asibot_tool_through_adapter():
    m = solver_for(ASI)
    m.set_tool([0, 0, 0.1, 0, 0, 0])
    assert m.fwd(np.zeros(5))[2] == pytest.approx(1.5)


def test_katana_tool_frame_extends_the_approach_and_inverts():
    m = solver_for(KAT)
    q = np.array(KAT.home) + 0.1
    bare = m.fwd(q)
    m.set_tool([0, 0, 0.05, 0, 0, 0])
    longer = m.fwd(q)
    # 5 cm further along the approach: Rz(az) Ry(rot(y')) z, with az from the position
    az, pitch = math.atan2(bare[1], bare[0]), bare[3]
    along = np.array([math.cos(az) * math.sin(pitch), math.sin(az) * math.sin(pitch), math.cos(pitch)])
    assert np.allclose(longer[:3] - bare[:3], 0.05 * along, atol=1e-6)
    assert np.allclose(longer[3:], bare[3:], atol=1e-6)
    assert np.allclose(m.fwd(m.inv(longer, KAT.home)), longer, atol=1e-5)
    m.set_tool(None)
    assert np.allclose(m.fwd(q), bare)
    with pytest.raises(ValueError, match="6 finite numbers"):
        m.set_tool([0, 0, math.nan, 0, 0, 0])


@pytest.mark.parametrize("rid", ["asibot-sim", "pioneer-sim"])
def test_inv_path_solves_each_sample_from_the_previous_like_inv(rid):
    spec = robots.get(rid)
    m = solver_for(spec)
    q0 = np.asarray(spec.home, float) * 0.5 + 0.2
    p0, p1 = m.fwd(q0), m.fwd(q0 + 0.1)
    poses = p0 + (p1 - p0) * np.linspace(0, 1, 6)[:, None]
    qs, failure = m.inv_path(poses, q0)
    assert failure is None and qs.shape == (6, 5)
    q = q0
    for pose, got in zip(poses, qs):
        q = m.inv(pose, q)
        assert np.allclose(got, q, atol=1e-9)
    far = np.vstack([poses, [5.0, 0, 0, 0, 0]])  # the last one out of reach
    qs, failure = m.inv_path(far, q0)
    assert isinstance(failure, Unreachable) and len(qs) == 6
