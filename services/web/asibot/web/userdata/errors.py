"""How the user's files refuse bad input: a sentence to show, and the kind of refusal."""

from __future__ import annotations


class UserDataError(ValueError):
    """Bad input from the user (HTTP 400): the message is a sentence to show them."""


class NotFound(UserDataError):
    """The named point, program, version, task or icon does not exist (HTTP 404)."""


class AlreadyExists(UserDataError):
    """The name is taken (HTTP 409)."""
