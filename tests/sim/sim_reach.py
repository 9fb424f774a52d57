"""Test helper: put the gripper around a point, pointing down, by damped least squares on the
sim's own model (no dependency on the kinematics service, so it also checks the sim alone)."""

from __future__ import annotations

import mujoco
import numpy as np

from asibot.sim.simulation import Simulation


def grasp_offset(sim: Simulation) -> np.ndarray:
    """Midpoint between the fingertips' geoms, in the tool frame."""
    d, s = sim.data, sim.scene
    rt, pt = d.xmat[s.tool_body].reshape(3, 3), d.xpos[s.tool_body]
    pts = [d.geom_xpos[g] for geoms in s.gripper.geoms for g in geoms]
    return rt.T @ (np.mean(pts, axis=0) - pt)


def solve_down(sim: Simulation, target: np.ndarray, q0: np.ndarray, iters: int = 300) -> np.ndarray:
    """Joint vector putting the grasp point at `target` (world) with the tool z axis down."""
    model, s = sim.model, sim.scene
    data = mujoco.MjData(model)
    data.qpos[:] = sim.data.qpos
    off = grasp_offset(sim)
    q = np.array(q0, float)
    base = sim.data.xpos[s.arm_base_body]
    rb = sim.data.xmat[s.arm_base_body].reshape(3, 3)
    local = rb.T @ (np.asarray(target) - base)
    q[0] = np.arctan2(local[1], local[0])  # face the target: both arms start with a yaw joint
    jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    for _ in range(iters):
        data.qpos[s.arm_qpos] = q
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        rt = data.xmat[s.tool_body].reshape(3, 3)
        p = data.xpos[s.tool_body] + rt @ off
        e_pos = target - p
        e_rot = np.cross(rt[:, 2], np.array([0.0, 0.0, -1.0]))
        if np.linalg.norm(e_pos) < 1e-5 and np.linalg.norm(e_rot) < 1e-5 and rt[2, 2] < 0:
            break
        mujoco.mj_jac(model, data, jacp, jacr, p, s.tool_body)
        j = np.vstack([jacp[:, s.arm_dof], jacr[:, s.arm_dof]])
        e = np.concatenate([e_pos, e_rot])
        dq = j.T @ np.linalg.solve(j @ j.T + 1e-4 * np.eye(6), e)
        q = np.clip(q + dq, sim.limits.lower, sim.limits.upper)
    else:
        raise AssertionError(f"no joint solution puts the gripper at {target} pointing down")
    return q


def move_to(sim: Simulation, q: np.ndarray, settle_s: float = 0.5, timeout_s: float = 20.0) -> None:
    """Command a joint position and step until it is reached (plus settling time)."""
    from asibot.messages import ArmCommand
    sim.command_arm(ArmCommand(mode="position", values=[float(v) for v in q]))
    steps = int(0.1 / sim.dt)
    t_end = sim.time + timeout_s
    while sim.time < t_end and np.max(np.abs(sim.arm.q_ref - q)) > 1e-9:
        sim.step(steps)
    sim.step(int(settle_s / sim.dt))
