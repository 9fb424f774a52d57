"""What every name of a user file shares: text, not empty, not too long, shown back short."""

from __future__ import annotations

import re

from asibot.web.userdata.errors import UserDataError

MAX_NAME = 64
#: Control characters and the line separators a browser may type: never in a name or a word.
CONTROL_RE = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]")


def quote(value: object) -> str:
    """The value as the user typed it, short and with control characters visible."""
    if not isinstance(value, str):
        return f"a {type(value).__name__}"
    return repr(value[:40]) + ("..." if len(value) > 40 else "")


def need_str(kind: str, value: object) -> str:
    if not isinstance(value, str):
        raise UserDataError(f"The {kind} must be text; got {quote(value)}.")
    if not value:
        raise UserDataError(f"The {kind} is empty; please give one.")
    if len(value) > MAX_NAME:
        raise UserDataError(f"The {kind} {quote(value)} is longer than {MAX_NAME} characters.")
    return value


def plain_name(kind: str, pattern: re.Pattern, allowed: str, name: object) -> str:
    name = need_str(kind, name)
    if not pattern.fullmatch(name):
        raise UserDataError(f"The {kind} {quote(name)} may hold only {allowed}, and must start with a letter.")
    return name
