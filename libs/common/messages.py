"""Message schemas: one dataclass per message type, encoded as a MessagePack map.

Every message has `stamp` (ns, producer clock). numpy arrays travel as a msgpack ext type
(dtype, shape, raw bytes) so a depth image costs one copy, not a list of floats. Decoding
checks every field against the dataclass annotation and raises MessageError naming the field,
so a receiver can reject bad input, count it and keep running.
"""

from __future__ import annotations

import dataclasses
import math
import time
import typing
from typing import Any, Callable, TypeVar

import msgpack
import numpy as np

from asibot.errors import MessageError

NDARRAY_EXT = 1
TYPE_FIELD = "_type"

T = TypeVar("T")
REGISTRY: dict[str, type] = {}


def now_ns() -> int:
    return time.time_ns()


# ---------------------------------------------------------------- msgpack with numpy
def _default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        arr = np.ascontiguousarray(obj)
        if arr.dtype.hasobject:
            raise TypeError("numpy object arrays cannot travel on the bus")
        head = msgpack.packb([arr.dtype.str, list(arr.shape)])
        return msgpack.ExtType(NDARRAY_EXT, head + arr.tobytes())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, tuple):
        return list(obj)
    raise TypeError(f"cannot encode {type(obj).__name__} in a message")


def _ext_hook(code: int, data: bytes) -> Any:
    if code != NDARRAY_EXT:
        return msgpack.ExtType(code, data)
    unpacker = msgpack.Unpacker(raw=False)
    unpacker.feed(data)
    dtype, shape = next(unpacker)
    offset = unpacker.tell()
    dt = np.dtype(dtype)
    if dt.hasobject:
        raise ValueError("object arrays are not allowed")
    arr = np.frombuffer(data, dtype=dt, offset=offset)
    return arr.reshape(shape)


def pack(obj: Any) -> bytes:
    """Encode any msgpack-able value (dicts for RPC, messages' maps) with numpy support."""
    return msgpack.packb(obj, default=_default, use_bin_type=True)


def unpack(data: bytes) -> Any:
    """Decode bytes produced by `pack`; raises MessageError on garbage."""
    try:
        return msgpack.unpackb(data, ext_hook=_ext_hook, raw=False, strict_map_key=False)
    except Exception as exc:  # msgpack raises several unrelated types
        raise MessageError("payload", "", f"not valid MessagePack ({type(exc).__name__}: {exc})") from None


# ---------------------------------------------------------------- schema checking
def _checker(tp: Any, field: str, type_name: str) -> Callable[[Any], Any]:
    """Build a function that validates (and lightly normalises) one field's value."""

    def fail(v: Any, want: str) -> typing.NoReturn:
        raise MessageError(type_name, field, f"expected {want}, got {type(v).__name__} {v!r:.60}")

    origin = typing.get_origin(tp)
    if tp is float:
        def check(v: Any) -> float:
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                fail(v, "a number")
            return float(v)
        return check
    if tp is int:
        def check(v: Any) -> int:
            if isinstance(v, bool) or not isinstance(v, int):
                fail(v, "an integer")
            return v
        return check
    if tp is bool:
        def check(v: Any) -> bool:
            if not isinstance(v, bool):
                fail(v, "true or false")
            return v
        return check
    if tp is str:
        def check(v: Any) -> str:
            if not isinstance(v, str):
                fail(v, "a string")
            return v
        return check
    if tp is bytes:
        def check(v: Any) -> bytes:
            if not isinstance(v, (bytes, bytearray)):
                fail(v, "bytes")
            return bytes(v)
        return check
    if tp is np.ndarray:
        def check(v: Any) -> np.ndarray:
            if not isinstance(v, np.ndarray):
                fail(v, "a numpy array")
            return v
        return check
    if origin is list:
        (item_tp,) = typing.get_args(tp) or (Any,)
        item = _checker(item_tp, field + "[]", type_name)

        def check(v: Any) -> list:
            if isinstance(v, np.ndarray):
                v = v.tolist()
            if not isinstance(v, (list, tuple)):
                fail(v, "a list")
            return [item(x) for x in v]
        return check
    if origin is dict or tp is dict:
        def check(v: Any) -> dict:
            if not isinstance(v, dict):
                fail(v, "a map")
            return v
        return check
    if tp is Any:
        return lambda v: v
    raise TypeError(f"{type_name}.{field}: unsupported field type {tp!r}")


def message(cls: type[T]) -> type[T]:
    """Class decorator: make `cls` a dataclass message with a `stamp` and register it."""
    if "stamp" not in cls.__dict__.get("__annotations__", {}):
        cls.__annotations__["stamp"] = int
        cls.stamp = dataclasses.field(default_factory=now_ns)  # type: ignore[attr-defined]
    cls = dataclasses.dataclass(cls)
    hints = typing.get_type_hints(cls)
    fields = dataclasses.fields(cls)
    cls._fields = tuple(f.name for f in fields)  # type: ignore[attr-defined]
    cls._required = tuple(  # type: ignore[attr-defined]
        f.name for f in fields
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    )
    cls._checks = {f.name: _checker(hints[f.name], f.name, cls.__name__) for f in fields}  # type: ignore[attr-defined]
    REGISTRY[cls.__name__] = cls
    return cls


def to_dict(msg: Any) -> dict:
    d = {name: getattr(msg, name) for name in msg._fields}
    d[TYPE_FIELD] = type(msg).__name__
    return d


def encode(msg: Any) -> bytes:
    """Serialise a registered message to msgpack bytes (a map with `_type` for tools)."""
    if type(msg).__name__ not in REGISTRY:
        raise TypeError(f"{type(msg).__name__} is not a registered message type")
    return pack(to_dict(msg))


def from_dict(cls: type[T], d: Any) -> T:
    """Validate a decoded map against `cls`; raises MessageError naming the first bad field."""
    name = cls.__name__
    if not isinstance(d, dict):
        raise MessageError(name, "", f"expected a map, got {type(d).__name__}")
    tag = d.get(TYPE_FIELD)
    if tag is not None and tag != name:
        raise MessageError(name, TYPE_FIELD, f"this is a {tag}, not a {name}")
    for req in cls._required:  # type: ignore[attr-defined]
        if req not in d:
            raise MessageError(name, req, "missing")
    kwargs = {}
    checks = cls._checks  # type: ignore[attr-defined]
    for key, value in d.items():
        check = checks.get(key)
        if check is not None:  # unknown fields are ignored: newer producers, older consumers
            kwargs[key] = check(value)
    return cls(**kwargs)


def decode(cls: type[T], data: bytes) -> T:
    return from_dict(cls, unpack(data))


def decode_any(data: bytes) -> Any:
    """Decode without a schema (recorder, replay, export); typed messages come back as dicts."""
    return unpack(data)


def finite(values: list[float], type_name: str, field: str) -> list[float]:
    """Reject NaN/inf where a value would move a robot."""
    for v in values:
        if not math.isfinite(v):
            raise MessageError(type_name, field, "contains a value that is not finite")
    return values


# ---------------------------------------------------------------- the catalogue
@message
class ArmState:
    """Joint state of an arm; positions rad, velocities rad/s."""
    names: list[str]
    positions: list[float]
    velocities: list[float]
    mode: str = "idle"   # position | velocity | idle | fault
    fault: str = ""      # a sentence for the user, empty when healthy


@message
class ArmCommand:
    """Joint reference: position (rad, optional velocity feed-forward rad/s) or velocity (rad/s)."""
    mode: str
    values: list[float]
    velocities: list[float] = dataclasses.field(default_factory=list)

    def __post_init__(self) -> None:
        if self.mode not in ("position", "velocity"):
            raise MessageError("ArmCommand", "mode", f"must be 'position' or 'velocity', got {self.mode!r}")
        finite(self.values, "ArmCommand", "values")
        finite(self.velocities, "ArmCommand", "velocities")
        if self.velocities and len(self.velocities) != len(self.values):
            raise MessageError("ArmCommand", "velocities", "must be empty or as long as values")


@message
class GripperState:
    opening: float  # m between fingers
    holding: bool = False


@message
class GripperCommand:
    opening: float  # m between fingers

    def __post_init__(self) -> None:
        finite([self.opening], "GripperCommand", "opening")


@message
class Twist:
    """Base velocity command: vx m/s forward, wz rad/s counter-clockwise."""
    vx: float
    wz: float

    def __post_init__(self) -> None:
        finite([self.vx, self.wz], "Twist", "vx/wz")


@message
class Odometry:
    x: float
    y: float
    theta: float
    vx: float = 0.0
    wz: float = 0.0


@message
class Sonar:
    ranges: list[float]   # m
    angles: list[float]   # rad, robot frame


@message
class Bumpers:
    front: list[bool]
    rear: list[bool]


@message
class Battery:
    volts: float


@message
class DepthImage:
    depth: np.ndarray     # H x W float32 metres, 0 = no return


@message
class RgbImage:
    jpeg: bytes
    width: int
    height: int


@message
class CameraInfo:
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    pose: list[float]     # x, y, z, qw, qx, qy, qz in the robot base frame
    frame: str = ""


@message
class LaserScan:
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: np.ndarray


@message
class Pose2D:
    x: float
    y: float
    theta: float


@message
class CartState:
    """Cartesian controller state; pose and joints in SI (rotations and joints in rad)."""
    state: str
    pose: list[float]
    joints: list[float]


@message
class EStop:
    engaged: bool
    reason: str = ""


@message
class Event:
    """A notice for the user: level info|warning|error, a stable code, a sentence."""
    level: str
    code: str
    text: str


@message
class Health:
    service: str
    instance: str
    uptime: float
    pid: int
    rejected: int = 0
    details: dict = dataclasses.field(default_factory=dict)
