"""Kinematic failures as RPC errors, so the server can send the sentence straight to the user."""

from asibot.errors import RpcError


class Unreachable(RpcError):
    """The target pose is outside the arm's workspace."""

    code = "unreachable"


class JointLimit(RpcError):
    """The target pose is reachable only by passing a joint limit."""

    code = "joint_limit"
