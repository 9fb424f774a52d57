"""The request types every route module shares: one strict base and the robot, speed and number fields.

Each body model forbids fields it does not know, so a misspelt field is a sentence, not a
silently ignored setting; the types are the API's description at /docs. JSON's `true` and
`false` are never numbers here: every number field is strict (StrictInt, StrictFloat) or, for a
jog's `Direction`, checked by `whole`, as the WebSocket's messages (page_messages) are too.
"""

from __future__ import annotations

from typing import Annotated, Literal, TypeGuard

from fastapi import Path
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, StrictFloat, StrictInt
from pydantic_core import PydanticCustomError

from asibot import keys
from asibot.jog import SPEED_LEVELS

RobotId = Annotated[str, Path(pattern=f"^{keys.ROBOT_ID_PATTERN}$",
                              description="a robot id as the Connection Manager lists it")]
Level = Annotated[StrictInt, Field(ge=1, le=len(SPEED_LEVELS), description="speed level, 1 (slowest) to 5")]
# JSON's `true` is not the number 1 here.
Number = StrictFloat | StrictInt

#: The ways a jog goes along its axis: a step (api_robots) and a held button (page_messages).
DIRECTIONS = (-1, 1)
DIRECTION_RULE = "The direction must be -1 or 1"


def whole(value: object) -> TypeGuard[int]:
    """An int that is not a bool (JSON's `true` is not the number 1 here, nor is 1.0 a whole number)."""
    return isinstance(value, int) and not isinstance(value, bool)


def is_direction(value: object) -> TypeGuard[int]:
    """-1 or 1, and not `true` (a bool is an int in Python, and `True == 1`)."""
    return whole(value) and value in DIRECTIONS


def _direction(value: object) -> object:
    if not is_direction(value):
        raise PydanticCustomError("bad_request", DIRECTION_RULE)
    return value


# The Literal is the description at /docs; the check is `is_direction`, before it, because a
# Literal of ints takes `true` as 1 (and 1.0), and Field(strict=True) cannot go on a Literal.
Direction = Annotated[Literal[-1, 1], BeforeValidator(_direction)]


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")
