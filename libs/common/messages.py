"""Message schemas: one dataclass per message type, encoded as a MessagePack map.

Every message has `stamp` (ns, producer clock). numpy arrays travel as a msgpack ext type
(dtype, shape, raw bytes) so a depth image costs one copy, not a list of floats. Decoding
checks every field against the dataclass annotation and raises MessageError naming the field,
so a receiver can reject bad input, count it and keep running.
"""

from __future__ import annotations

import dataclasses
import math
import struct
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
#
# An array travels as msgpack ext type NDARRAY_EXT whose data is packb([dtype.str, shape])
# followed by the array's bytes in C order. That format is fixed (recordings and other msgpack
# implementations read it); only how we produce and read it is tuned here, because camera
# frames (a 640x480 depth image is 1.2 MB) cross the bus at 10-30 Hz:
#
# - encoding builds a map that holds arrays (or large bytes) from small msgpack-packed pieces
#   and hand-written ext/bin headers, and copies each array's buffer once, straight into the
#   message (b"".join), instead of tobytes() + ExtType + packb (three copies of the array);
# - decoding a large map walks its top level by hand and makes each array a view onto the
#   payload (np.frombuffer), instead of letting msgpack copy the ext data and then feeding
#   it to an Unpacker (two copies). Small payloads take msgpack's C path, which is faster.
#
# The bytes are the same either way: tests/common/test_messages_arrays.py compares them with
# msgpack.packb and an ExtType.

#: Values of a top-level map from this size are spliced into the message, not re-packed.
_SPLICE_MIN = 16 * 1024
#: Payloads from this size are decoded by the top-level walker, arrays as views.
_ZERO_COPY_MIN = 16 * 1024
#: Objects the walker skips by hand before it leaves the payload to msgpack (long lists).
_SKIP_BUDGET = 4096
#: Longest [dtype, shape] head of an array (a 64-dimension shape of uint64 takes ~600 bytes).
_HEAD_MAX = 1024

_U8, _U16, _U32 = struct.Struct(">BB"), struct.Struct(">BH"), struct.Struct(">BI")
_EXT8, _EXT16, _EXT32 = struct.Struct(">BBb"), struct.Struct(">BHb"), struct.Struct(">BIb")
_FIXEXT = {1: 0xD4, 2: 0xD5, 4: 0xD6, 8: 0xD7, 16: 0xD8}


class _BadArray(ValueError):
    """An NDARRAY_EXT whose data is not a valid array."""


def _map_header(n: int) -> bytes:
    if n < 16:
        return bytes((0x80 | n,))
    return _U16.pack(0xDE, n) if n < 0x10000 else _U32.pack(0xDF, n)


def _bin_header(n: int) -> bytes:
    if n < 0x100:
        return _U8.pack(0xC4, n)
    return _U16.pack(0xC5, n) if n < 0x10000 else _U32.pack(0xC6, n)


def _ext_header(code: int, n: int) -> bytes:
    """The header msgpack writes before `n` bytes of ext data (it picks the same form)."""
    if n in _FIXEXT:
        return bytes((_FIXEXT[n], code & 0xFF))
    if n < 0x100:
        return _EXT8.pack(0xC7, n, code)
    if n < 0x10000:
        return _EXT16.pack(0xC8, n, code)
    if n <= 0xFFFFFFFF:
        return _EXT32.pack(0xC9, n, code)
    raise ValueError("an array of 4 GiB or more cannot travel in one message")


def _array_parts(obj: np.ndarray) -> tuple[bytes, bytes, Any]:
    """Ext header, [dtype, shape] head and a zero-copy view of the bytes of one array."""
    arr = np.ascontiguousarray(obj)  # no copy when already C-contiguous; 0-d becomes shape (1,)
    if arr.dtype.hasobject:
        raise TypeError("numpy object arrays cannot travel on the bus")
    head = msgpack.packb([arr.dtype.str, list(arr.shape)])
    try:
        raw: Any = arr.reshape(-1).view(np.uint8)  # a view: b"".join copies it once
    except ValueError:  # dtypes that cannot be viewed as bytes (zero itemsize)
        raw = arr.tobytes()
    return _ext_header(NDARRAY_EXT, len(head) + arr.nbytes), head, raw


def _default(obj: Any) -> Any:
    """msgpack's fallback for arrays nested below the top level, numpy scalars and tuples."""
    if isinstance(obj, np.ndarray):
        header, head, raw = _array_parts(obj)
        return msgpack.ExtType(NDARRAY_EXT, head + bytes(raw))
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, tuple):
        return list(obj)
    raise TypeError(f"cannot encode {type(obj).__name__} in a message")


def _spliced(value: Any) -> bool:
    return isinstance(value, np.ndarray) or (
        isinstance(value, (bytes, bytearray)) and len(value) >= _SPLICE_MIN)


def _pack_map_spliced(d: dict) -> bytes:
    """Pack a map piece by piece; arrays and large bytes are copied once, by the final join."""
    parts: list[Any] = [_map_header(len(d))]
    for key, value in d.items():
        parts.append(msgpack.packb(key, default=_default, use_bin_type=True))
        if isinstance(value, np.ndarray):
            parts.extend(_array_parts(value))
        elif isinstance(value, (bytes, bytearray)) and len(value) >= _SPLICE_MIN:
            parts.append(_bin_header(len(value)))
            parts.append(value)
        else:
            parts.append(msgpack.packb(value, default=_default, use_bin_type=True))
    return b"".join(parts)


def _array(buf: Any, start: int, end: int) -> np.ndarray:
    """The array whose ext data is buf[start:end]: a read-only view onto `buf` when the data
    is aligned for its dtype, else a read-only aligned copy. Raises _BadArray."""
    unpacker = msgpack.Unpacker(raw=False, max_buffer_size=_HEAD_MAX)
    try:
        unpacker.feed(buf[start:min(end, start + _HEAD_MAX)])
        dtype, shape = unpacker.unpack()
    except Exception as exc:  # truncated, not msgpack, not a pair
        raise _BadArray(f"not a valid array header ({type(exc).__name__}: {exc})") from None
    offset = start + unpacker.tell()
    if not isinstance(dtype, str):
        raise _BadArray(f"dtype must be a string, got {dtype!r:.60}")
    try:
        dt = np.dtype(dtype)
    except Exception:
        raise _BadArray(f"unknown dtype {dtype!r:.60}") from None
    if dt.hasobject:
        raise _BadArray("object arrays are not allowed")
    if not isinstance(shape, list) or not all(
            isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape):
        raise _BadArray(f"shape must be a list of sizes, got {shape!r:.60}")
    count = math.prod(shape)
    if count * dt.itemsize != end - offset:
        raise _BadArray(f"{end - offset} bytes of data do not make a {dt.str} array of shape {shape}")
    if count == 0 or dt.itemsize == 0:
        arr = np.zeros(shape, dt)
    else:
        arr = np.frombuffer(buf, dtype=dt, count=count, offset=offset).reshape(shape)
        if not arr.flags.aligned:
            arr = arr.copy()  # unaligned data makes many numpy loops slower (count_nonzero 6x)
    arr.flags.writeable = False
    return arr


def _ext_hook(code: int, data: bytes) -> Any:
    if code != NDARRAY_EXT:
        return msgpack.ExtType(code, data)
    return _array(data, 0, len(data))


class _NotHere(Exception):
    """The walker leaves this payload to msgpack (not a map, odd keys, garbage, long lists)."""


# For a type byte 0xc0-0xdf: (header size, length bytes, ext type byte, children per count).
# A length-prefixed object is header + length; a container adds count * children objects.
_FORMS: dict[int, tuple[int, int, int, int]] = {
    0xC0: (1, 0, 0, 0), 0xC2: (1, 0, 0, 0), 0xC3: (1, 0, 0, 0),
    0xC4: (2, 1, 0, 0), 0xC5: (3, 2, 0, 0), 0xC6: (5, 4, 0, 0),           # bin
    0xC7: (3, 1, 1, 0), 0xC8: (4, 2, 1, 0), 0xC9: (6, 4, 1, 0),           # ext
    0xCA: (5, 0, 0, 0), 0xCB: (9, 0, 0, 0),                               # float
    0xCC: (2, 0, 0, 0), 0xCD: (3, 0, 0, 0), 0xCE: (5, 0, 0, 0), 0xCF: (9, 0, 0, 0),
    0xD0: (2, 0, 0, 0), 0xD1: (3, 0, 0, 0), 0xD2: (5, 0, 0, 0), 0xD3: (9, 0, 0, 0),
    0xD4: (3, 0, 0, 0), 0xD5: (4, 0, 0, 0), 0xD6: (6, 0, 0, 0), 0xD7: (10, 0, 0, 0),
    0xD8: (18, 0, 0, 0),                                                  # fixext
    0xD9: (2, 1, 0, 0), 0xDA: (3, 2, 0, 0), 0xDB: (5, 4, 0, 0),           # str
    0xDC: (3, 2, 0, 1), 0xDD: (5, 4, 0, 1), 0xDE: (3, 2, 0, 2), 0xDF: (5, 4, 0, 2),
}


def _length(buf: Any, pos: int, size: int) -> int:
    if size == 1:
        return buf[pos]
    return int.from_bytes(buf[pos:pos + size], "big")


def _skip(buf: Any, pos: int, budget: list[int]) -> int:
    """Offset just past the msgpack object at `pos`, stepping over its children."""
    todo = 1
    while todo:
        todo -= 1
        budget[0] -= 1
        if budget[0] < 0:
            raise _NotHere
        b = buf[pos]
        if b < 0x80 or b >= 0xE0:       # fixint
            pos += 1
        elif b < 0x90:                   # fixmap
            todo += 2 * (b & 0x0F)
            pos += 1
        elif b < 0xA0:                   # fixarray
            todo += b & 0x0F
            pos += 1
        elif b < 0xC0:                   # fixstr
            pos += 1 + (b & 0x1F)
        else:
            form = _FORMS.get(b)
            if form is None:
                raise _NotHere
            size, lsize, _, children = form
            if children:
                todo += children * _length(buf, pos + 1, lsize)
                pos += size
            elif lsize:
                pos += size + _length(buf, pos + 1, lsize)
            else:
                pos += size
    if pos > len(buf):
        raise _NotHere
    return pos


def _ext_at(buf: Any, pos: int) -> tuple[int, int, int] | None:
    """(code, data start, data end) when the object at `pos` is an ext, else None."""
    b = buf[pos]
    if 0xD4 <= b <= 0xD8:
        size = 1 << (b - 0xD4)
        start = pos + 2
    elif 0xC7 <= b <= 0xC9:
        lsize = 1 << (b - 0xC7)
        size = _length(buf, pos + 1, lsize)
        start = pos + 2 + lsize
    else:
        return None
    code = buf[start - 1]
    end = start + size
    if end > len(buf):
        raise _NotHere
    return (code - 256 if code > 127 else code), start, end


def _unpack_map(data: Any, budget: int | None = _SKIP_BUDGET) -> dict | None:
    """Decode a top-level map by hand, its arrays as views onto `data` (no copy).

    None when the payload is not for this walker (msgpack then decodes it, or says what is
    wrong with it); MessageError naming the key when a value holds a bad array.
    """
    buf = memoryview(data).cast("B") if not isinstance(data, (bytes, bytearray)) else memoryview(data)
    left = [budget if budget is not None else len(buf) + 1]
    try:
        b = buf[0]
        if 0x80 <= b <= 0x8F:
            n, pos = b & 0x0F, 1
        elif b in (0xDE, 0xDF):
            lsize = 2 if b == 0xDE else 4
            n, pos = _length(buf, 1, lsize), 1 + lsize
        else:
            return None
        out: dict = {}
        for _ in range(n):
            b = buf[pos]
            if 0xA0 <= b <= 0xBF:
                start, end = pos + 1, pos + 1 + (b & 0x1F)
            elif 0xD9 <= b <= 0xDB:
                lsize = 1 << (b - 0xD9)
                start = pos + 1 + lsize
                end = start + _length(buf, pos + 1, lsize)
            else:
                return None  # keys that are not strings: msgpack's rules apply
            if end > len(buf):
                return None
            key = str(buf[start:end], "utf-8")
            pos = end
            try:
                ext = _ext_at(buf, pos)
                if ext is not None:
                    code, start, pos = ext
                    out[key] = _array(buf, start, pos) if code == NDARRAY_EXT else \
                        msgpack.ExtType(code, bytes(buf[start:pos]))
                    continue
                end = _skip(buf, pos, left)
                out[key] = msgpack.unpackb(buf[pos:end], ext_hook=_ext_hook, raw=False,
                                           strict_map_key=False)
                pos = end
            except _BadArray as exc:
                raise MessageError("payload", key, f"not a valid array: {exc}") from None
        return out if pos == len(buf) else None
    except MessageError:
        raise
    except Exception:  # truncated, invalid bytes, too many objects to skip by hand
        return None


def pack(obj: Any) -> bytes:
    """Encode any msgpack-able value (dicts for RPC, messages' maps) with numpy support.

    A map whose values include arrays or large bytes is assembled from pieces, each array's
    buffer copied once, into bytes equal to msgpack.packb's.
    """
    if isinstance(obj, dict) and any(_spliced(v) for v in obj.values()):
        return _pack_map_spliced(obj)
    return msgpack.packb(obj, default=_default, use_bin_type=True)


def unpack(data: bytes) -> Any:
    """Decode bytes produced by `pack`; raises MessageError on garbage.

    Arrays come back read-only. In a large payload (>= 16 KiB) a top-level array is a view
    onto `data` (it keeps `data` alive; no copy) unless its bytes are misaligned for its
    dtype, in which case it is one aligned copy. Copy (`arr.copy()`) before writing into one.
    """
    if len(data) >= _ZERO_COPY_MIN:
        found = _unpack_map(data)
        if found is not None:
            return found
    try:
        return msgpack.unpackb(data, ext_hook=_ext_hook, raw=False, strict_map_key=False)
    except _BadArray as exc:
        _unpack_map(data, budget=None)  # names the field when the array is in a top-level value
        raise MessageError("payload", "", f"not a valid array: {exc}") from None
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
    """Decode and validate a `cls`; its arrays are read-only (see `unpack`)."""
    try:
        d = unpack(data)
    except MessageError as exc:
        if not exc.field:
            raise
        raise MessageError(cls.__name__, exc.field, exc.problem) from None
    return from_dict(cls, d)


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


#: The driver contract's command watchdog: in velocity mode a robot stops when no command
#: came for this long (drivers, the sim and the kinematics velocity stream alike).
COMMAND_WATCHDOG_S = 0.2


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
