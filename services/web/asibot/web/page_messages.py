"""What a page may send over its WebSocket, checked once as it arrives.

`hold` beats while a jog button is held and `point` reports of a handheld pointer
(asibot.web.pointer), `release` when either ends; `mic` starts or stops the page's microphone.
`read` turns one text message into one of these, or refuses it with the sentence the page shows.
The robot is checked first, as the REST routes do, so a page commanding a robot that went away
hears that before anything about its fields. Motion (motion.py) takes these typed values as
they are: this is the one check of what a page sends.
"""

from __future__ import annotations

import json
from typing import Annotated, Any, Callable, Collection, Literal

from pydantic import (BaseModel, ConfigDict, Field, InstanceOf, TypeAdapter, ValidationError, ValidationInfo,
                      field_validator, model_validator)
from pydantic_core import PydanticCustomError

from asibot import robots
from asibot.errors import CODES, RpcError
from asibot.jog import speed_fraction
from asibot.poses import POINT_AXES
from asibot.web.models import DIRECTION_RULE, Direction, is_direction, whole
from asibot.web.pointer import DeviceReading
from asibot.web.voice_relay import MicError, check_rate

#: Largest text message, characters (a pointer report is about 200).
PAGE_MESSAGE_LIMIT = 16 * 1024
NOT_UNDERSTOOD = "The page sent a message the server does not understand."
#: A reading with the dead-man off: the pointer stream ends at once (Motion.point).
STILL = DeviceReading("phone", 0.0, 0.0, deadman=False)
#: The error type of a refusal the page gets without a code (the microphone's, as before).
_NO_CODE = "refused"


class Refused(Exception):
    """A message the page is told about: `code` as an RpcError's (None: no code); `kind` is the
    message's type when it had one, `robot` the connected robot it was for, and `moving` whether
    the refusal is of a pointer reading, which must end the pointer's stream."""

    def __init__(self, text: str, code: str | None = None, kind: str | None = None,
                 robot: str | None = None, moving: bool = False) -> None:
        super().__init__(text)
        self.text, self.code, self.kind, self.robot, self.moving = text, code, kind, robot, moving

    def json(self) -> str:
        code = {} if self.code is None else {"code": self.code}
        robot = {} if self.robot is None else {"robot": self.robot}   # the page names it
        return json.dumps({"type": "refused", **code, **robot, "text": self.text})


def _refuse(code: str, sentence: str) -> PydanticCustomError:
    # Braces in a quoted value would be read as the template's fields: they are its context.
    return PydanticCustomError(code, "{sentence}", {"sentence": sentence})


def check_level(level: int) -> int:
    """A speed level, 1 (slowest) to 5, else a bad_request with the jog's own sentence."""
    try:
        speed_fraction(level)
    except ValueError as exc:
        raise RpcError("bad_request", str(exc)) from None
    return level


def check_direction(direction: int) -> int:
    """-1 or 1, as the REST step's `Direction` checks it (models.is_direction: not `true`), else a
    bad_request with the sentence the page shows."""
    if not is_direction(direction):
        raise RpcError("bad_request", f"{DIRECTION_RULE}; got {direction!r}.")
    return direction


def _checked(check: Callable[[Any], object], value: object) -> object:
    """`value`, once `check` (and its sentence) accepts it."""
    try:
        check(value)
    except RpcError as exc:
        raise _refuse(exc.code, exc.message) from None
    return value


class _Message(BaseModel):
    # Fields the page adds that the server does not use are let pass, as they always were.
    model_config = ConfigDict(extra="ignore", frozen=True)


class _ToRobot(_Message):
    # Fields default to None and are checked all the same, so a missing field's sentence is its
    # own ("got None"), as the page has always heard it.
    robot: str = Field(None, validate_default=True)

    @field_validator("robot", mode="before")
    @classmethod
    def _connected(cls, robot: object, info: ValidationInfo) -> str:
        if not isinstance(robot, str) or robot not in (info.context or {}).get("live", ()):
            raise _refuse("unavailable", f"Robot {robot!r} is not connected.")
        if robot not in robots.ids():
            raise _refuse("bad_request", f"There is no robot {robot!r}; choose one of {', '.join(robots.ids())}.")
        return robot


class Mic(_Message):
    """The page starts listening (`rate`: its AudioContext's Hz) or stops (`rate`: null)."""
    type: Literal["mic"]
    rate: int | None = None

    @field_validator("rate", mode="before")
    @classmethod
    def _rate(cls, rate: object) -> int | None:
        try:
            return None if rate is None else check_rate(rate)
        except MicError as exc:
            raise _refuse(_NO_CODE, str(exc)) from None


class Hold(_ToRobot):
    """One beat of a held jog button: one joint or point axis, one way, at a speed level."""
    type: Literal["hold"]
    space: Literal["joint", "cartesian"] = Field(None, validate_default=True)
    axis: int = Field(None, validate_default=True)
    direction: Direction = Field(None, validate_default=True)
    level: int = Field(None, validate_default=True)

    @field_validator("space", mode="before")
    @classmethod
    def _space(cls, space: object) -> object:
        if space not in ("joint", "cartesian"):
            raise _refuse("bad_request", f"The space must be 'joint' or 'cartesian'; got {space!r}.")
        return space

    @field_validator("axis", mode="before")
    @classmethod
    def _axis(cls, axis: object, info: ValidationInfo) -> object:
        robot, space = info.data.get("robot"), info.data.get("space")
        if robot is None or space is None:
            return axis     # the robot or the space was refused: that is the sentence
        size = len(robots.get(robot).joint_names) if space == "joint" else len(POINT_AXES)
        if not whole(axis) or not 0 <= axis < size:
            raise _refuse("bad_request", f"The axis must be 0 to {size - 1}; got {axis!r}.")
        return axis

    @field_validator("direction", mode="before")
    @classmethod
    def _direction(cls, direction: object) -> object:
        return _checked(check_direction, direction)

    @field_validator("level", mode="before")
    @classmethod
    def _level(cls, level: object) -> object:
        return _checked(check_level, level)


class Point(_ToRobot):
    """One report of a handheld pointer: the device's reading, as it is (asibot.web.pointer)."""
    type: Literal["point"]
    reading: InstanceOf[DeviceReading]

    @model_validator(mode="before")
    @classmethod
    def _gather(cls, message: Any) -> Any:
        # The reading's fields sit beside `type` and `robot` in the message.
        return {**message, "reading": message} if isinstance(message, dict) else message

    @field_validator("reading", mode="before")
    @classmethod
    def _reading(cls, message: object) -> DeviceReading:
        try:
            return DeviceReading.from_message(message)   # type: ignore[arg-type]  # _gather: a dict
        except RpcError as exc:
            raise _refuse(exc.code, exc.message) from None


class Release(_Message):
    """The held button or the pointer's dead-man was let go: stop what this page moves."""
    type: Literal["release"]


PageMessage = Annotated[Mic | Hold | Point | Release, Field(discriminator="type")]
_MESSAGE: TypeAdapter[Mic | Hold | Point | Release] = TypeAdapter(PageMessage)


def read(text: str, live: Collection[str]) -> Mic | Hold | Point | Release | None:
    """One message of the page, checked; `live`: the connected robots. None for a type this
    server does not know: it is let pass, as it always was. Refused with the sentence otherwise."""
    try:
        if len(text) > PAGE_MESSAGE_LIMIT:
            raise ValueError("too long")
        raw = json.loads(text)
    except (ValueError, RecursionError):   # RecursionError: JSON nested too deep
        raise Refused(NOT_UNDERSTOOD) from None
    try:
        return _MESSAGE.validate_python(raw, context={"live": live})
    except ValidationError as exc:
        first = exc.errors()[0]
    if first["type"] == "union_tag_invalid":
        return None
    if len(first["loc"]) < 2 or first["type"] not in (_NO_CODE, *CODES):
        raise Refused(NOT_UNDERSTOOD)
    kind, field = str(first["loc"][0]), first["loc"][1]
    robot = raw.get("robot")
    connected = isinstance(robot, str) and robot in live and kind in ("hold", "point")
    raise Refused(first["msg"], None if first["type"] == _NO_CODE else first["type"], kind,
                  robot if connected else None, moving=kind == "point" and field == "reading")
