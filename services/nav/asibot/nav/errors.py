"""The errors navigation raises: each carries an RPC code for programs and a sentence for people.

They are `asibot.errors.RpcError`s, so the future nav service can answer any of them as it is
(`err.to_reply()`), and a sentence written here reaches the user unchanged.
"""

from __future__ import annotations

from asibot.errors import RpcError


class NavError(RpcError):
    """Bad input to navigation (a NaN goal, a pose off the map, a bad place name): fix the call."""

    code = "bad_request"


class MapError(NavError):
    """A map file that cannot be read or written: the sentence names the file and the problem."""


class Unreachable(RpcError):
    """A goal the robot cannot reach (inside a wall, no path, blocked): the sentence says why."""

    code = "unreachable"
