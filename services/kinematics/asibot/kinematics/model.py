"""One kinematic interface for the controller, whatever the solver (SI units).

Joints are rad. A pose is the 5-vector [x, y, z, rot(y'), rot(z'')] in m and rad, with the
ASIBOT convention (docs/asibot-conventions.md, "Kinematics") for every arm: orientation
Rz(atan2(y, x)) Ry(rot(y')) Rz(rot(z'')) of the tool's approach frame. For the Katana, whose
lift joints are parallel and whose wrist rolls about the approach, this is the natural 5-DOF pose too:
rot(y') is the approach's tilt from vertical, rot(z'') the roll. The approach frame is the
tool frame turned so that its z axis points out of the wrist (Katana: the tool's x axis).
Users see the same 5-vector with angles in degrees (to_user_point / from_user_point).
A path (movl) is solved by inv_path, which converts units once for the whole path.
"""

from __future__ import annotations

import math
from typing import Protocol, Sequence

import numpy as np

from asibot.errors import RpcError
from asibot import poses
from asibot.poses import point_rotation

from .asibot_solver import AsibotSolver, tool_frame, transform_point
from .generic_solver import GenericSolver

POSE_SIZE = 5
#: Joints or a pose: the controller and the server pass numpy arrays, tests and the catalog lists.
Vector = Sequence[float] | np.ndarray


class KinematicModel(Protocol):
    pose_size: int

    def fwd(self, q: Vector) -> np.ndarray: ...
    def inv(self, pose: Vector, q_guess: Vector) -> np.ndarray: ...
    def inv_path(self, poses: np.ndarray, q0: Vector) -> tuple[np.ndarray, RpcError | None]: ...
    def jacobian(self, q: Vector) -> np.ndarray: ...
    def set_tool(self, tool: Sequence[float] | None) -> None: ...
    def to_user_point(self, pose: Vector) -> list[float]: ...
    def from_user_point(self, point: Vector) -> np.ndarray: ...


_user = poses.user_point


def _si(point: Vector) -> np.ndarray:
    if len(point) != POSE_SIZE or not all(math.isfinite(float(v)) for v in point):
        raise ValueError(f"A point is {POSE_SIZE} finite numbers [x, y, z, rot(y'), rot(z'')], got {list(point)!r}.")
    return np.array(poses.si_pose(point))


class AsibotModel:
    """The closed-form AsibotSolver behind the SI interface."""

    pose_size = POSE_SIZE

    def __init__(self, solver: AsibotSolver | None = None) -> None:
        self.solver = solver or AsibotSolver()

    def fwd(self, q: Vector) -> np.ndarray:
        return _si(self.solver.fwd([math.degrees(v) for v in q]))

    def inv(self, pose: Vector, q_guess: Vector) -> np.ndarray:
        q = self.solver.inv(self.to_user_point(pose), [math.degrees(v) for v in q_guess])
        return np.radians(q)

    def inv_path(self, poses: np.ndarray, q0: Vector) -> tuple[np.ndarray, RpcError | None]:
        """IK along a path: each row of the N x 5 SI `poses` solved from the previous solution,
        the first from q0 (rad). Degrees and radians are converted once for the whole path,
        not per sample. Returns (N x 5 joints in rad, None), or at the first row that fails
        (the joints of the rows before it, its RpcError)."""
        points = np.array(poses, float)
        points[:, 3:] = np.degrees(points[:, 3:])
        out = np.empty((len(points), 5))
        q = np.degrees(np.asarray(q0, float)).tolist()
        inv = self.solver.inv
        for i, x in enumerate(points.tolist()):
            try:
                q = inv(x, q)
            except RpcError as exc:
                return np.radians(out[:i]), exc
            out[i] = q
        return np.radians(out), None

    def jacobian(self, q: Vector) -> np.ndarray:
        """6x5 [v; w] per rad, see AsibotSolver.jacobian."""
        return self.solver.jacobian([math.degrees(v) for v in q])

    def set_tool(self, tool: Sequence[float] | None) -> None:
        """Tool frame [x, y, z, rx, ry, rz] (m, axis-angle rad) on the flange; None or zeros removes it."""
        self.solver.set_tool(tool)

    to_user_point = staticmethod(_user)
    from_user_point = staticmethod(_si)


def _approach_correction(s: GenericSolver, q: Vector) -> np.ndarray:
    """Rotation C (in tool axes) whose z is the approach direction: out of the last joint."""
    h = s.fwd(q)
    s.fwd(q)
    last = s.model.joints[max(s.model.getJointId(n) for n in s.model.names[1:]
                              if s.model.joints[s.model.getJointId(n)].idx_q in s.idx_q)]
    wrist = s.data.oMi[last.id]
    d = h[:3, 3] - wrist.translation
    a = h[:3, :3].T @ (d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-9 else wrist.rotation[:, 2])
    z = np.array([0.0, 0.0, 1.0])
    v, c = np.cross(z, a), float(z @ a)
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1 + c)


class PinocchioModel:
    """GenericSolver behind the SI interface, for any arm of the catalog."""

    pose_size = POSE_SIZE

    def __init__(self, solver: GenericSolver, home: Sequence[float]) -> None:
        self.solver = solver
        self.c = _approach_correction(solver, home)
        self._tool: np.ndarray | None = None

    def set_tool(self, tool: Sequence[float] | None) -> None:
        """Tool frame [x, y, z, rx, ry, rz] (m, axis-angle rad) in the approach frame; None or
        zeros removes it. An offset along the approach (z) keeps every 5-DOF pose reachable."""
        self._tool = tool_frame(tool)

    def fwd(self, q: Vector) -> np.ndarray:
        h = self.solver.fwd(q)
        h[:3, :3] = h[:3, :3] @ self.c
        if self._tool is not None:
            h = h @ self._tool
        return _si(transform_point(h, math.degrees(q[0])))

    def inv(self, pose: Vector, q_guess: Vector) -> np.ndarray:
        p = [float(v) for v in pose]
        h = np.eye(4)
        h[:3, :3] = point_rotation(p[0], p[1], p[3], p[4])
        h[:3, 3] = p[:3]
        if self._tool is not None:
            h = h @ np.linalg.inv(self._tool)
        h[:3, :3] = h[:3, :3] @ self.c.T
        shown = lambda: "The point [" + ", ".join(f"{v:.3g}" for v in self.to_user_point(p)) + "]"
        return self.solver.inv(h, q_guess, what=shown)

    def inv_path(self, poses: np.ndarray, q0: Vector) -> tuple[np.ndarray, RpcError | None]:
        """IK along a path, as AsibotModel.inv_path (SI throughout: nothing to convert)."""
        out = np.empty((len(poses), len(q0)))
        q = np.asarray(q0, float)
        for i, pose in enumerate(np.asarray(poses, float)):
            try:
                q = self.inv(pose, q)
            except RpcError as exc:
                return out[:i], exc
            out[i] = q
        return out, None

    def jacobian(self, q: Vector) -> np.ndarray:
        return self.solver.jacobian(q)

    to_user_point = staticmethod(_user)
    from_user_point = staticmethod(_si)


def solver_for(spec) -> KinematicModel:
    """The kinematic model the catalog entry `spec` (asibot.robots.RobotSpec) asks for."""
    if spec.solver == "asibot":
        d = 180 / math.pi
        return AsibotModel(AsibotSolver(limits=[(lo * d, hi * d) for lo, hi in zip(spec.lower, spec.upper)]))
    if spec.solver == "pinocchio":
        return PinocchioModel(GenericSolver(spec.urdf_path, spec.tool_link, spec.joint_names), spec.home)
    raise ValueError(f"robot {spec.robot_id} asks for solver {spec.solver!r}; use 'asibot' or 'pinocchio'")
