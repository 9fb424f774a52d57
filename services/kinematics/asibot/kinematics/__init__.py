"""Kinematics: closed-form and generic solvers, trajectories and the Cartesian control server."""

from .asibot_solver import AsibotSolver
from .errors import JointLimit, Unreachable
from .generic_solver import GenericSolver
from .model import KinematicModel, solver_for

__all__ = ["AsibotSolver", "GenericSolver", "JointLimit", "KinematicModel", "Unreachable", "solver_for"]
