"""What every RPC verb of the kinematics server accepts, checked in one place.

`verbs(n_joints)` is the table: verb -> `Verb` (its fields, each a `Field` with a validator,
and whether it needs a live driver). The server serves exactly the verbs of this table and
hands each handler the checked arguments (`Verb.parse`), so a verb cannot be served
unchecked. Any wrong type, size or value becomes `bad_request` with a sentence that names
the field, says what it must be (with the allowed range) and quotes at most a short prefix
of what came (`asibot.errors.quote`): a megabyte of bad input never comes back in a reply.

Ranges are wide enough for every arm of the catalog and narrow enough that the arithmetic
after them stays finite and small: a point farther than `MAX_DISTANCE` is not a typo of a
reachable one but a unit mistake, and a movl to a distant point that passes these checks is
refused by the planner's reach check of its end point, before any path is sampled.

Units are the user's (m and deg), as in the client and the seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any, Mapping, TypeGuard

import numpy as np

from asibot import jog
from asibot.errors import RpcError, quote

#: Largest coordinate of a point, m: far beyond any arm, small enough to square.
MAX_DISTANCE = 1e6
#: Largest angle of a point (rot(y'), rot(z'')), deg: one turn either way.
MAX_POINT_ANGLE = 360.0
#: Largest joint value or joint step (fwd, movj joints, relj, jog), deg: two turns either way.
#: A jog step of x, y or z takes the same number in m: far beyond any arm, refused by the reach
#: check of the step's end point.
MAX_JOINT = 720.0
#: Longest movement a request may ask for, s.
MAX_DURATION = 600.0
#: movj/relj/home speed: a fraction of each joint's maximum speed.
MIN_JOINT_SPEED, MAX_JOINT_SPEED = 0.01, 1.0
#: movl speed, m/s.
MIN_LINEAR_SPEED, MAX_LINEAR_SPEED = 0.001, 1.0
#: movv: largest linear (m/s) and angular (deg/s) velocity.
MAX_VELOCITY, MAX_ANGULAR_VELOCITY = 2.0, 360.0
#: tool frame: largest offset (m) and rotation-vector component (deg).
MAX_TOOL_OFFSET, MAX_TOOL_ANGLE = 5.0, 360.0
#: Longest `wait` a request may ask for, s (the server waits at most MAX_WAIT per call anyway).
MAX_WAIT_REQUEST = 3600.0
#: pointer: the device's yaw rate (deg/s) and pitch (deg), and the speed along the tool (m/s).
MAX_POINTER_YAW, MAX_POINTER_PITCH = 360.0, 180.0
POINTER_SPEED, MAX_POINTER_SPEED = 0.05, 0.1
POINTER_DIRECTIONS = ("forward", "hold", "backward")
#: Longest a single `wait` RPC blocks, s (its default timeout); the client loops for longer waits.
MAX_WAIT = 10.0


class Invalid(Exception):
    """A validator's refusal: `detail` says what exactly is wrong (or "")."""

    def __init__(self, detail: str = "") -> None:
        super().__init__(detail)
        self.detail = detail


#: Longer lists, strings and bytes are shown from a prefix (no megabyte repr to cut).
_LONG = 64


def shown(value: object) -> str:
    """`errors.quote(value)`, safe and cheap for anything a request can carry: a long list,
    string or bytes is shown from its first elements with its length, and a list nested a
    thousand deep (which has no repr) by its type."""
    try:
        if isinstance(value, (list, tuple, str, bytes)) and len(value) > _LONG:
            unit = "characters" if isinstance(value, str) else "bytes" if isinstance(value, bytes) else "elements"
            return f"{quote(value[:_LONG])[:60]}... ({len(value)} {unit})"
        return quote(value)
    except RecursionError:
        return f"a {type(value).__name__} nested too deep to show"


def _real(value: object) -> TypeGuard[int | float]:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _g(x: float) -> str:
    return f"{x:g}"


@dataclass(frozen=True)
class Number:
    """A finite real number in [lo, hi] (or (lo, hi] with `open_low`), `unit` for the sentence."""

    lo: float
    hi: float
    unit: str = ""
    open_low: bool = False

    def range(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        return f"{'(' if self.open_low else '['}{_g(self.lo)}, {_g(self.hi)}]{unit}"

    def describe(self) -> str:
        return f"a number in {self.range()}"

    def __call__(self, value: object) -> float:
        # Compare before converting: an int of any size compares exactly with a float.
        if not _real(value) or (isinstance(value, float) and not math.isfinite(value)):
            raise Invalid()
        if not (self.lo < value if self.open_low else self.lo <= value) or not value <= self.hi:
            raise Invalid()
        return float(value)


@dataclass(frozen=True)
class Numbers:
    """A list (or 1-D numeric array) of len(names) numbers, element i checked by parts[i]."""

    names: tuple[str, ...]
    parts: tuple[Number, ...]

    def describe(self) -> str:
        groups: list[tuple[list[str], Number]] = []
        for name, part in zip(self.names, self.parts):
            if groups and groups[-1][1] == part:
                groups[-1][0].append(name)
            else:
                groups.append(([name], part))
        ranges = "; ".join(f"{', '.join(names)} in {part.range()}" for names, part in groups)
        return f"[{', '.join(self.names)}], {len(self.names)} finite numbers ({ranges})"

    def __call__(self, value: object) -> np.ndarray:
        if isinstance(value, np.ndarray):
            if value.ndim != 1 or value.dtype.kind not in "iuf":
                raise Invalid()
            if len(value) != len(self.names):
                raise Invalid(f"it has {len(value)} elements")
            value = value.tolist()
        if not isinstance(value, (list, tuple)):
            raise Invalid()
        if len(value) != len(self.names):  # before looking inside: a long list costs nothing
            raise Invalid(f"it has {len(value)} elements")
        out = np.empty(len(value))
        for i, (name, part, v) in enumerate(zip(self.names, self.parts, value)):
            try:
                out[i] = part(v)
            except Invalid:
                what = f"outside {part.range()}" if _real(v) and not (isinstance(v, float) and math.isnan(v)) \
                    else "not a finite number"
                raise Invalid(f"{name} = {shown(v)} is {what}") from None
        return out


@dataclass(frozen=True)
class OneOf:
    """One of a few words."""

    choices: tuple[str, ...]

    def describe(self) -> str:
        return " or ".join(self.choices)

    def __call__(self, value: object) -> str:
        if not isinstance(value, str) or value not in self.choices:
            raise Invalid()
        return value


@dataclass(frozen=True)
class Flag:
    def describe(self) -> str:
        return "true or false"

    def __call__(self, value: object) -> bool:
        if not isinstance(value, bool):
            raise Invalid()
        return value


@dataclass(frozen=True)
class Whole:
    """A whole number in [lo, hi]: an int, not a float (a level is counted, not measured) nor a
    bool (JSON's `true` is not the number 1 here)."""

    lo: int
    hi: int

    def describe(self) -> str:
        return f"a whole number from {self.lo} to {self.hi}"

    def __call__(self, value: object) -> int:
        if not isinstance(value, int) or isinstance(value, bool) or not self.lo <= value <= self.hi:
            raise Invalid()
        return value


Validator = Number | Numbers | OneOf | Flag | Whole


@dataclass(frozen=True)
class Field:
    """One named argument. Absent and null are the same: `default` (None unless given), or
    a refusal when `required`."""

    check: Validator
    required: bool = False
    default: Any = None
    #: Said after what the value must be, e.g. "or null to remove it".
    also: str = ""

    def describe(self) -> str:
        return self.check.describe() + (f", {self.also}" if self.also else "")


@dataclass(frozen=True)
class Verb:
    """The arguments of one verb. `strict`: an unknown field is refused (a typo such as
    'sped' must not move the arm at the default speed); `stop` is not strict, because a stop
    always stops. `needs_driver`: the server waits a moment for the arm driver before it
    answers (just after start-up its first state may be behind the first request)."""

    fields: Mapping[str, Field] = field(default_factory=dict)
    strict: bool = True
    needs_driver: bool = False

    def parse(self, verb: str, request: Mapping[Any, Any]) -> SimpleNamespace:
        """The checked arguments (every field of the table, absent ones at their default),
        or RpcError("bad_request", sentence)."""
        if self.strict:
            unknown = [k for k in request if k not in self.fields]
            if unknown:
                takes = ", ".join(self.fields) if self.fields else "no arguments"
                raise RpcError("bad_request", f"{verb} takes {takes}; {shown(unknown[0])} is not one of them.")
        out = {}
        for name, f in self.fields.items():
            value = request.get(name)
            if value is None:
                if f.required:
                    raise RpcError("bad_request", f"{verb} needs '{name}': {f.describe()}.")
                out[name] = f.default
                continue
            try:
                out[name] = f.check(value)
            except Invalid as exc:
                why = f" ({exc.detail})" if exc.detail else ""
                raise RpcError("bad_request", f"'{name}' must be {f.describe()}; got {shown(value)}{why}.") \
                    from None
        return SimpleNamespace(**out)


def point(names: tuple[str, ...] = ("x", "y", "z", "rot(y')", "rot(z'')")) -> Numbers:
    """A user point [x, y, z, rot(y'), rot(z'')] in m and deg."""
    distance, angle = Number(-MAX_DISTANCE, MAX_DISTANCE, "m"), Number(-MAX_POINT_ANGLE, MAX_POINT_ANGLE, "deg")
    return Numbers(names, (distance,) * 3 + (angle,) * (len(names) - 3))


def joints(n: int) -> Numbers:
    """n joint values (or steps) in deg."""
    return Numbers(tuple(f"q{i + 1}" for i in range(n)), (Number(-MAX_JOINT, MAX_JOINT, "deg"),) * n)


DURATION = Field(Number(0.0, MAX_DURATION, "s", open_low=True))
JOINT_SPEED = Field(Number(MIN_JOINT_SPEED, MAX_JOINT_SPEED, "of the maximum joint speed"))

#: The pointer verb's fields (asibot.kinematics.pointer.PointerInput is built from them).
POINTER = Verb({
    "deadman": Field(Flag(), required=True),
    "direction": Field(OneOf(POINTER_DIRECTIONS), default="hold"),
    "yaw": Field(Number(-MAX_POINTER_YAW, MAX_POINTER_YAW, "deg/s"), default=0.0),
    "pitch": Field(Number(-MAX_POINTER_PITCH, MAX_POINTER_PITCH, "deg")),
    "speed": Field(Number(0.0, MAX_POINTER_SPEED, "m/s", open_low=True), default=POINTER_SPEED),
}, needs_driver=True)


def verbs(n_joints: int) -> dict[str, Verb]:
    """Every verb of cart/rpc/<verb> and what it accepts, for an arm of `n_joints` joints."""
    p, q = point(), joints(n_joints)
    velocity = Numbers(("vx", "vy", "vz", "w rot(y')", "w rot(z'')"),
                       (Number(-MAX_VELOCITY, MAX_VELOCITY, "m/s"),) * 3
                       + (Number(-MAX_ANGULAR_VELOCITY, MAX_ANGULAR_VELOCITY, "deg/s"),) * 2)
    joint_velocity = Numbers(tuple(f"w q{i + 1}" for i in range(n_joints)),
                             (Number(-MAX_ANGULAR_VELOCITY, MAX_ANGULAR_VELOCITY, "deg/s"),) * n_joints)
    tool = Numbers(("x", "y", "z", "rx", "ry", "rz"),
                   (Number(-MAX_TOOL_OFFSET, MAX_TOOL_OFFSET, "m"),) * 3
                   + (Number(-MAX_TOOL_ANGLE, MAX_TOOL_ANGLE, "deg"),) * 3)
    return {
        "stat": Verb(needs_driver=True),
        "inv": Verb({"point": Field(p, required=True)}),
        "fwd": Verb({"joints": Field(q, required=True)}),
        "movj": Verb({"point": Field(p), "joints": Field(q), "duration": DURATION, "speed": JOINT_SPEED},
                     needs_driver=True),
        "movl": Verb({"point": Field(p, required=True), "duration": DURATION,
                      "speed": Field(Number(MIN_LINEAR_SPEED, MAX_LINEAR_SPEED, "m/s"))}, needs_driver=True),
        "movv": Verb({"velocity": Field(velocity, required=True)}, needs_driver=True),
        "movjv": Verb({"velocity": Field(joint_velocity, required=True)}, needs_driver=True),
        "relj": Verb({"joints": Field(q, required=True), "duration": DURATION, "speed": JOINT_SPEED},
                     needs_driver=True),
        "home": Verb({"duration": DURATION, "speed": JOINT_SPEED}, needs_driver=True),
        "stop": Verb(strict=False),
        "wait": Verb({"timeout": Field(Number(0.0, MAX_WAIT_REQUEST, "s", open_low=True), default=MAX_WAIT)}),
        "tool": Verb({"tool": Field(tool, also="or null to remove it")}),
        "act": Verb({"action": Field(OneOf(("open", "close")), required=True)}),
        "pointer": POINTER,
        # One step of one axis (the page's step buttons): a joint (movj) or a coordinate of the
        # point (movl) by a signed step, at one of the page's speed levels.
        "jog": Verb({"axis": Field(OneOf(jog.axes(n_joints)), required=True),
                     "step": Field(Number(-MAX_JOINT, MAX_JOINT, "deg (m for x, y, z)"), required=True),
                     "level": Field(Whole(1, len(jog.SPEED_LEVELS)), required=True)}, needs_driver=True),
    }
