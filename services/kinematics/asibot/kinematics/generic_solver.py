"""A generic solver on Pinocchio from a URDF (the seed's KdlBot): FK, Jacobian, DLS IK.

Joints in rad, poses as 4x4 homogeneous transforms of `tool_link` in the URDF root frame.
Joints of the URDF that are not in `joint_names` (e.g. gripper fingers) stay at 0.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import pinocchio as pin

from .errors import JointLimit, Unreachable


class GenericSolver:
    """FK/Jacobian/IK of one serial chain of a URDF."""

    def __init__(self, urdf_path: str | Path, tool_link: str, joint_names: Sequence[str],
                 max_iter: int = 200, tol: float = 1e-10) -> None:
        self.model = pin.buildModelFromUrdf(str(urdf_path))
        self.data = self.model.createData()
        if not self.model.existFrame(tool_link):
            raise ValueError(f"{urdf_path} has no link {tool_link!r}; check the robot catalog")
        self.frame = self.model.getFrameId(tool_link)
        self.idx_q, self.idx_v = [], []
        for n in joint_names:
            if not self.model.existJointName(n):
                raise ValueError(f"{urdf_path} has no joint {n!r}; check the robot catalog")
            j = self.model.joints[self.model.getJointId(n)]
            self.idx_q.append(j.idx_q)
            self.idx_v.append(j.idx_v)
        self.lower = self.model.lowerPositionLimit[self.idx_q].copy()
        self.upper = self.model.upperPositionLimit[self.idx_q].copy()
        self.max_iter, self.tol = max_iter, tol
        self._q = pin.neutral(self.model)
        # Fixed restart seeds, so that a failing solve is reproducible.
        self._seeds = list(np.random.default_rng(0).uniform(self.lower, self.upper, (24, len(self.idx_q))))

    def _full(self, q: Sequence[float] | np.ndarray) -> np.ndarray:
        qq = self._q.copy()
        qq[self.idx_q] = q
        return qq

    def fwd(self, q: Sequence[float] | np.ndarray) -> np.ndarray:
        """4x4 transform of the tool link for joints q [rad]."""
        pin.framesForwardKinematics(self.model, self.data, self._full(q))
        return self.data.oMf[self.frame].homogeneous.copy()

    def jacobian(self, q: Sequence[float] | np.ndarray) -> np.ndarray:
        """6x5 Jacobian [v; w] of the tool origin in base-aligned axes (same as AsibotSolver.jacobian)."""
        qq = self._full(q)
        pin.computeJointJacobians(self.model, self.data, qq)
        pin.updateFramePlacements(self.model, self.data)
        j = pin.getFrameJacobian(self.model, self.data, self.frame, pin.LOCAL_WORLD_ALIGNED)
        return j[:, self.idx_v].copy()

    def _solve(self, target: pin.SE3, q0: np.ndarray, clamp: bool) -> tuple[np.ndarray, float]:
        q = q0.copy()
        err = np.inf
        for _ in range(self.max_iter):
            pin.framesForwardKinematics(self.model, self.data, self._full(q))
            e = pin.log6(self.data.oMf[self.frame].actInv(target)).vector
            err = float(e @ e)
            if err < self.tol ** 2:
                break
            pin.computeJointJacobians(self.model, self.data)
            j = pin.getFrameJacobian(self.model, self.data, self.frame, pin.LOCAL)[:, self.idx_v]
            lam = 1e-6 + 1e-2 * min(err, 1.0)
            dq = j.T @ np.linalg.solve(j @ j.T + lam * np.eye(6), e)
            q = q + dq
            if clamp:
                q = np.clip(q, self.lower, self.upper)
        return q, float(np.sqrt(err))

    def inv(self, target: np.ndarray, q_guess: Sequence[float] | np.ndarray,
            what: str | Callable[[], str] = "The pose") -> np.ndarray:
        """Joints [rad] within limits reaching the 4x4 `target`, starting from q_guess.

        Damped least squares (6D error log6, damping grows with the error) from the guess,
        then from the limits' centre and fixed seeds spread over the joint space. Raises JointLimit if only an
        unclamped solution exists, Unreachable otherwise; their sentences start with `what` (or
        what(), only built on failure)."""
        t = pin.SE3(np.asarray(target, float))
        g = np.clip(np.asarray(q_guess, float), self.lower, self.upper)
        mid = (self.lower + self.upper) / 2
        seeds = [g, mid, mid + 0.3 * (self.upper - mid), mid + 0.3 * (self.lower - mid),
                 np.where(np.arange(len(g)) % 2 == 0, mid + 0.5 * (self.upper - mid), mid + 0.5 * (self.lower - mid))]
        for s in seeds + self._seeds:
            q, err = self._solve(t, s, clamp=True)
            if err < 1e-7:
                return q
        for s in seeds[:2]:
            q, err = self._solve(t, s, clamp=False)
            if err < 1e-7:
                what = what() if callable(what) else what
                raise JointLimit(f"{what} is reachable only past a joint limit; choose a point closer to the "
                                 "middle of the workspace.")
        what = what() if callable(what) else what
        raise Unreachable(f"{what} is out of the arm's reach (no joint solution found); choose a closer "
                          "point or another orientation.")
