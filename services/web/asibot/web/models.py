"""The request types every route module shares: one strict base and the robot, speed and number fields.

Each body model forbids fields it does not know, so a misspelt field is a sentence, not a
silently ignored setting; the types are the API's description at /docs.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import Path
from pydantic import BaseModel, ConfigDict, Field, StrictFloat, StrictInt

from asibot.jog import SPEED_LEVELS

RobotId = Annotated[str, Path(pattern=r"^[A-Za-z0-9_][A-Za-z0-9_.\-]{0,63}$",
                              description="a robot id as the Connection Manager lists it")]
Level = Annotated[StrictInt, Field(ge=1, le=len(SPEED_LEVELS), description="speed level, 1 (slowest) to 5")]
# JSON's `true` is not the number 1 here.
Number = StrictFloat | StrictInt


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")
