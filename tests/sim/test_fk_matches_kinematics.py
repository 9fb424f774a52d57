"""The sim's arm is the kinematics' arm: forward kinematics agree to 1e-6 for random joints.

ASIBOT: the closed-form AsibotSolver (joints in degrees; point [x, y, z, rot(y'), rot(z'')]
in metres and degrees, orientation R = Rz(atan2(y, x)) Ry(rot(y')) Rz(rot(z''))).
Katana: the Pinocchio GenericSolver on the same URDF (joints in radians).
"""

import math

import mujoco
import numpy as np
import pytest


N = 50


def rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def sim_fk(sim, q):
    sim.data.qpos[sim.scene.arm_qpos] = q
    mujoco.mj_kinematics(sim.model, sim.data)
    return sim.tool_pose()


def random_joints(spec, rng):
    lo, hi = np.array(spec.lower), np.array(spec.upper)
    lo, hi = np.maximum(lo, -math.pi), np.minimum(hi, math.pi)
    return rng.uniform(lo, hi)


def test_asibot_sim_fk_equals_the_closed_form(kitchen):
    from asibot.kinematics import AsibotSolver

    solver = AsibotSolver()
    rng = np.random.default_rng(7)
    for _ in range(N):
        q = random_joints(kitchen.robot, rng)
        pos, rot = sim_fk(kitchen, q)
        x = solver.fwd(np.degrees(q).tolist())
        assert pos == pytest.approx(x[:3], abs=1e-6)
        expected = rz(math.atan2(x[1], x[0])) @ ry(math.radians(x[3])) @ rz(math.radians(x[4]))
        assert rot == pytest.approx(expected, abs=1e-6)


def test_katana_sim_fk_equals_the_generic_solver(apartment, robot_catalog):
    from asibot.kinematics import GenericSolver

    spec = robot_catalog.get("pioneer-sim")
    solver = GenericSolver(spec.urdf_path, spec.tool_link, spec.joint_names)
    rng = np.random.default_rng(11)
    for _ in range(N):
        q = random_joints(spec, rng)
        pos, rot = sim_fk(apartment, q)
        out = solver.fwd(q)
        if isinstance(out, tuple):
            p_ref, r_ref = np.asarray(out[0]), np.asarray(out[1])
        else:
            out = np.asarray(out)
            p_ref, r_ref = out[:3, 3], out[:3, :3]
        assert pos == pytest.approx(p_ref, abs=1e-6)
        assert rot == pytest.approx(r_ref, abs=1e-6)


def test_asibot_sim_fk_equals_the_published_formula(kitchen):
    """docs/asibot-conventions.md "Kinematics": rP, hP in the arm's plane; x = rP cos q1,
    y = rP sin q1, z = hP + A0."""
    a0, a1, a2, a3 = 0.3, 0.4, 0.4, 0.3
    rng = np.random.default_rng(3)
    for _ in range(N):
        q = random_joints(kitchen.robot, rng)
        pos, rot = sim_fk(kitchen, q)
        s2, s23, s234 = q[1], q[1] + q[2], q[1] + q[2] + q[3]
        rp = a1 * math.sin(s2) + a2 * math.sin(s23) + a3 * math.sin(s234)
        hp = a1 * math.cos(s2) + a2 * math.cos(s23) + a3 * math.cos(s234)
        assert pos == pytest.approx([rp * math.cos(q[0]), rp * math.sin(q[0]), hp + a0], abs=1e-6)
        assert rot == pytest.approx(rz(q[0]) @ ry(s234) @ rz(q[4]), abs=1e-6)


@pytest.mark.parametrize("robot_id", ["asibot-sim", "pioneer-sim"])
def test_sim_fk_equals_pinocchio_on_the_same_urdf(robot_id, request, robot_catalog):
    import pinocchio as pin

    sim = request.getfixturevalue("kitchen" if robot_id == "asibot-sim" else "apartment")
    spec = robot_catalog.get(robot_id)
    model = pin.buildModelFromUrdf(str(spec.urdf_path))
    data = model.createData()
    tool = model.getFrameId(spec.tool_link)
    base = model.getFrameId(spec.base_link)
    idx = [model.idx_qs[model.getJointId(n)] for n in spec.joint_names]
    rng = np.random.default_rng(5)
    for _ in range(N):
        q = random_joints(spec, rng)
        pos, rot = sim_fk(sim, q)
        qp = pin.neutral(model)
        qp[idx] = q
        pin.framesForwardKinematics(model, data, qp)
        rel = data.oMf[base].inverse() * data.oMf[tool]
        assert pos == pytest.approx(rel.translation, abs=1e-6)
        assert rot == pytest.approx(rel.rotation, abs=1e-6)
