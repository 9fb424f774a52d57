"""Errors that cross the bus: an RPC refusal carries a code for programs and a sentence for people."""

from __future__ import annotations

CODES = (
    "bad_request",   # the request itself is wrong; fix the call
    "unreachable",   # the pose is outside the robot's workspace
    "joint_limit",   # the motion would pass a joint limit
    "estop",         # the emergency stop is engaged; release it first
    "busy",          # another motion is running; stop or wait first
    "timeout",       # no answer in time
    "unavailable",   # nobody serves this (service down, driver absent)
    "fault",         # the hardware reports a fault; reset it first
    "not_allowed",   # the router's access control refuses this login; use another role's
    "not_found",     # what was looked for is not there (a taught thing the cameras do not see)
    "internal",      # a bug: the server caught an unexpected exception
)


#: Longest sentence an error carries: a reply never echoes a megabyte of bad input back.
MAX_MESSAGE = 400


def quote(value: object, limit: int = 60) -> str:
    """`repr(value)`, cut to `limit` characters: how an error sentence shows bad input."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


class AsibotError(Exception):
    """Base of every error this stack raises on purpose."""


class RpcError(AsibotError):
    """An RPC refused or failed. `code` is one of CODES; `message` is a sentence for the user."""

    code: str = "internal"

    def __init__(self, *args: str) -> None:
        # Two forms: RpcError(code, message) and, for subclasses with a fixed code,
        # Unreachable(message). Both read naturally at the raise site.
        if len(args) == 2:
            code, message = args
        elif len(args) == 1:
            code, message = type(self).code, args[0]
        elif not args:
            code, message = type(self).code, ""
        else:
            raise TypeError("RpcError takes (code, message) or (message)")
        if code not in CODES:  # a typo at a raise site: fail loudly where tests see it
            raise ValueError(f"unknown RPC error code {code!r}; use one of {', '.join(CODES)}")
        self.code = code
        message = message or code.replace("_", " ")
        self.message = message if len(message) <= MAX_MESSAGE else message[:MAX_MESSAGE] + "..."
        super().__init__(self.message)

    def __str__(self) -> str:
        return self.message

    def __repr__(self) -> str:
        return f"{type(self).__name__}(code={self.code!r}, message={self.message!r})"

    def to_reply(self) -> dict:
        return {"ok": False, "error": self.code, "message": self.message}


class BadRequest(RpcError):
    code = "bad_request"


class Timeout(RpcError):
    code = "timeout"


class Unavailable(RpcError):
    code = "unavailable"


class NotAllowed(RpcError):
    code = "not_allowed"


class MessageError(AsibotError, ValueError):
    """A payload that is not a valid message of the expected type; `field` names the culprit."""

    def __init__(self, type_name: str, field: str, problem: str) -> None:
        self.type_name = type_name
        self.field = field
        self.problem = problem
        where = f"{type_name}.{field}" if field else type_name
        super().__init__(f"invalid {where}: {problem}")
