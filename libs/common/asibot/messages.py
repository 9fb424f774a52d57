"""Message schemas: one dataclass per message type, encoded as a MessagePack map.

Every message has `stamp` (ns, producer clock). numpy arrays travel as a msgpack ext type
(dtype, shape, raw bytes), not as lists of floats: encoding copies an array's buffer once, into
the message, and decoding a large message copies none: its arrays are read-only views onto the
payload. Decoding checks every field against the dataclass annotation and raises MessageError
naming the field, so a receiver can reject bad input, count it and keep running.
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
#   message (b"".join), instead of tobytes(), head + bytes, packb's buffer and packb's result
#   (four copies, three alive at once);
# - decoding a large message (from _VIEW_MIN) reads its map and each array's ext header by
#   hand and makes the array a read-only view (np.frombuffer) onto the payload itself; msgpack
#   reads only the small values around the arrays. msgpack-python cannot do this alone: it
#   copies every ext's data into a new bytes before its ext_hook sees it (~60-130 us per MiB).
#   Smaller messages go through msgpack.unpackb, their arrays views onto that copy.
#
# The bytes are the same either way: tests/common/test_messages_arrays.py compares them with
# msgpack.packb and an ExtType.

#: Values of a top-level map from this size are spliced into the message, not re-packed.
_SPLICE_MIN = 16 * 1024
#: Messages from this size are decoded with their arrays as views onto the payload (_unpack_map).
#: Reading a map that way costs a few us more than msgpack.unpackb (~10 with cold caches, as
#: after a large receive): about what copying 100 KB costs, so smaller messages are not worth it.
_VIEW_MIN = 128 * 1024
#: What msgpack's Unpacker is fed at a time around the arrays of a large map (it copies what it is fed).
_FEED = 4096
#: Longest [dtype, shape] head of an array (a 64-dimension shape of uint64 takes ~600 bytes).
_HEAD_MAX = 1024
#: First buffer of our Packers. msgpack.packb's starts at 256 KiB, and allocating and freeing
#: that on every call costs more than packing a small message (0.66 us vs 0.28 for a Battery),
#: ~13 us when a nested packb (an array's head) makes glibc map and unmap it each time.
_PACK_BUF = 4096

_U8, _U16, _U32 = struct.Struct(">BB"), struct.Struct(">BH"), struct.Struct(">BI")
_EXT8, _EXT16, _EXT32 = struct.Struct(">BBb"), struct.Struct(">BHb"), struct.Struct(">BIb")
_FIXEXT = {1: 0xD4, 2: 0xD5, 4: 0xD6, 8: 0xD7, 16: 0xD8}
#: The ext forms an array of more than a few bytes takes, and the bin forms, by their first byte.
_EXT_FORMS = {0xC7: _EXT8, 0xC8: _EXT16, 0xC9: _EXT32}
_BIN_FORMS = {0xC4: _U8, 0xC5: _U16, 0xC6: _U32}


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


def _contiguous(obj: np.ndarray) -> tuple[np.ndarray, bytes]:
    """The array in C order (no copy when it already is; 0-d becomes shape (1,)) and its
    [dtype, shape] head."""
    arr = np.ascontiguousarray(obj)
    if arr.dtype.hasobject:
        raise TypeError("numpy object arrays cannot travel on the bus")
    return arr, msgpack.Packer(buf_size=_HEAD_MAX).pack([arr.dtype.str, list(arr.shape)])


def _array_parts(obj: np.ndarray) -> tuple[bytes, bytes, Any]:
    """Ext header, [dtype, shape] head and a zero-copy view of the bytes of one array."""
    arr, head = _contiguous(obj)
    try:
        raw: Any = arr.reshape(-1).view(np.uint8)  # a view: b"".join copies it once
    except ValueError:  # dtypes that cannot be viewed as bytes (zero itemsize)
        raw = arr.tobytes()
    return _ext_header(NDARRAY_EXT, len(head) + arr.nbytes), head, raw


def _default(obj: Any) -> Any:
    """msgpack's fallback for arrays nested below the top level, numpy scalars and tuples."""
    if isinstance(obj, np.ndarray):
        arr, head = _contiguous(obj)  # small arrays (large ones are spliced): copies are cheap
        return msgpack.ExtType(NDARRAY_EXT, head + arr.tobytes())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, tuple):
        return list(obj)
    raise TypeError(f"cannot encode {type(obj).__name__} in a message")


_BULKY = (np.ndarray, bytes, bytearray)


def _spliced(value: Any) -> bool:
    """Whether a map value is big enough to be worth copying once by hand."""
    if isinstance(value, np.ndarray):
        return value.nbytes >= _SPLICE_MIN
    return isinstance(value, (bytes, bytearray)) and len(value) >= _SPLICE_MIN


def _pack_map_spliced(d: dict) -> bytes:
    """Pack a map piece by piece: msgpack packs the small values, each large array or bytes
    value gets a hand-written header and is copied once, by the final join."""
    packer = msgpack.Packer(default=_default, use_bin_type=True, autoreset=False, buf_size=_PACK_BUF)
    parts: list[Any] = [_map_header(len(d))]
    for key, value in d.items():
        packer.pack(key)
        if not _spliced(value):
            packer.pack(value)
            continue
        parts.append(packer.bytes())
        packer.reset()
        if isinstance(value, np.ndarray):
            parts.extend(_array_parts(value))
        else:
            parts.append(_bin_header(len(value)))
            parts.append(value)
    parts.append(packer.bytes())
    return b"".join(parts)


def _array(buf: Any, start: int, end: int) -> np.ndarray:
    """The array whose ext data is buf[start:end], as a read-only view onto `buf` (no copy;
    it may be unaligned for its dtype). Raises _BadArray."""
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
    if type(shape) is not list or any(type(n) is not int or n < 0 for n in shape):
        raise _BadArray(f"shape must be a list of sizes, got {shape!r:.60}")
    count = math.prod(shape)
    if count * dt.itemsize != end - offset:
        raise _BadArray(f"{end - offset} bytes of data do not make a {dt.str} array of shape {shape}")
    if count == 0 or dt.itemsize == 0:
        arr = np.zeros(shape, dt)
    else:
        arr = np.frombuffer(buf, dtype=dt, count=count, offset=offset).reshape(shape)
    if arr.flags.writeable:  # a view onto bytes already is read-only; onto a bytearray, not
        arr.flags.writeable = False
    return arr


def _ext_hook(code: int, data: bytes) -> Any:
    if code != NDARRAY_EXT:
        return msgpack.ExtType(code, data)
    return _array(data, 0, len(data))


def _unpacker(max_size: int) -> msgpack.Unpacker:
    """A streaming Unpacker with the options of `unpack` (limits as unpackb sets them). Its
    first buffer is small: by default it would allocate min(max_size, 1 MiB) each time."""
    return msgpack.Unpacker(ext_hook=_ext_hook, raw=False, strict_map_key=False,
                            max_buffer_size=max_size, read_size=min(_FEED, max_size))


def _bulk_at(buf: bytes, pos: int) -> tuple[bool, int, int] | None:
    """(whether it is an array, start, end of its data) when an NDARRAY_EXT or a bin starts at
    buf[pos]; None when anything else does, or when it is truncated (msgpack says what is wrong)."""
    if pos >= len(buf):
        return None
    first = buf[pos]
    form = _EXT_FORMS.get(first) or _BIN_FORMS.get(first)
    if form is None or pos + form.size > len(buf):
        return None
    fields = form.unpack_from(buf, pos)
    start, end = pos + form.size, pos + form.size + fields[1]
    is_array = first in _EXT_FORMS
    if end > len(buf) or (is_array and fields[2] != NDARRAY_EXT):
        return None
    return is_array, start, end


def _fixstr_at(buf: bytes, pos: int) -> tuple[str, int] | None:
    """(the text, its end) when a str of up to 31 bytes (a field name) starts at buf[pos]."""
    if pos >= len(buf) or not 0xA0 <= buf[pos] <= 0xBF:
        return None
    end = pos + 1 + (buf[pos] & 0x1F)
    return (buf[pos + 1:end].decode(), end) if end <= len(buf) else None


class _Reader:
    """Reads the values of `buf` one after another from `pos`. An array is made a view onto
    `buf`, and a bin is sliced out of it (one copy, as msgpack makes; fed to the Unpacker, a
    large one would be copied on each feed). Any other value is read by a msgpack Unpacker fed
    `buf` a piece at a time, so that it copies the small values around the arrays (and at most
    a piece of an array)."""

    def __init__(self, buf: bytes, pos: int) -> None:
        self.buf = buf
        self.pos = pos
        self._unpacker: msgpack.Unpacker | None = None
        self._start = self._fed = pos  # where the Unpacker's stream starts, and how far it was fed

    def next(self) -> Any:
        bulk = _bulk_at(self.buf, self.pos)
        if bulk is not None:
            is_array, start, end = bulk
            self.pos = end
            self._unpacker = None  # it may have been fed the first bytes of this: restart after it
            return _array(self.buf, start, end) if is_array else self.buf[start:end]
        unpacker = self._unpacker
        if unpacker is None:
            # A key after an array (or first in the map) needs no Unpacker: making one costs ~1 us.
            text = _fixstr_at(self.buf, self.pos)
            if text is not None:
                value, self.pos = text
                return value
            unpacker = self._unpacker = _unpacker(len(self.buf))
            self._start = self._fed = self.pos
            self._feed(unpacker)  # before the first unpack: an OutOfData costs as much as the Unpacker
        while True:
            try:
                value = unpacker.unpack()
                break
            except msgpack.OutOfData:  # the value goes on past what was fed
                if self._fed >= len(self.buf):
                    raise
                self._feed(unpacker)
        self.pos = self._start + unpacker.tell()
        return value

    def _feed(self, unpacker: msgpack.Unpacker) -> None:
        # Pieces double, so a large value that is not an array takes a few feeds, not thousands.
        piece = max(_FEED, self._fed - self._start)
        unpacker.feed(memoryview(self.buf)[self._fed:self._fed + piece])
        self._fed += piece


def _is_fixmap(first: int) -> bool:
    """A map of at most 15 entries, as every message is. A wider one is a table (an RPC reply),
    which msgpack reads faster in one go than _Reader does entry by entry."""
    return 0x80 <= first <= 0x8F


def _unpack_map(buf: bytes) -> dict:
    """msgpack.unpackb of a fixmap, except that its large arrays are read-only views onto `buf`."""
    reader = _Reader(buf, 1)
    result = {}
    left = buf[0] & 0x0F
    while left and len(buf) - reader.pos >= _VIEW_MIN:
        key = reader.next()
        result[key] = reader.next()
        left -= 1
    # The rest holds no array worth a view: msgpack reads it in one go, as a map of what is left
    # (which also raises on bytes after the message), instead of value by value.
    rest = b"".join((bytes((0x80 | left,)), memoryview(buf)[reader.pos:]))
    result.update(msgpack.unpackb(rest, ext_hook=_ext_hook, raw=False, strict_map_key=False))
    return result


def pack(obj: Any) -> bytes:
    """Encode any msgpack-able value (dicts for RPC, messages' maps) with numpy support.

    A map whose values include arrays or large bytes is assembled from pieces, each array's
    buffer copied once, into bytes equal to msgpack.packb's.
    """
    if isinstance(obj, dict):
        for v in obj.values():
            if isinstance(v, _BULKY) and _spliced(v):
                return _pack_map_spliced(obj)
    return _packer().pack(obj)


def _packer() -> msgpack.Packer:
    """What msgpack.packb(obj, default=_default, use_bin_type=True) uses, with a small buffer."""
    return msgpack.Packer(default=_default, use_bin_type=True, buf_size=_PACK_BUF)


def unpack(data: bytes) -> Any:
    """Decode bytes produced by `pack`; raises MessageError on garbage.

    Arrays come back read-only. In a message of `_VIEW_MIN` bytes or more they are views onto
    `data` itself (no copy), so any one of them keeps all of `data` alive; in anything else,
    views onto msgpack's copy of their ext data. Only bytes get views: a bytearray or
    memoryview could change under them, so it is decoded by msgpack, which copies. A view may
    be unaligned for its dtype (a DepthImage's float32 pixels start at an odd offset), which
    numpy handles, a little slower in some loops. A receiver that writes into an array, or
    wants it aligned, copies it: `arr.copy()`.
    """
    try:
        if type(data) is bytes and len(data) >= _VIEW_MIN and _is_fixmap(data[0]):
            return _unpack_map(data)
        return msgpack.unpackb(data, ext_hook=_ext_hook, raw=False, strict_map_key=False)
    except _BadArray as exc:
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
        def check_number(v: Any) -> float:
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                fail(v, "a number")
            return float(v)
        return check_number
    if tp is int:
        def check_int(v: Any) -> int:
            if isinstance(v, bool) or not isinstance(v, int):
                fail(v, "an integer")
            return v
        return check_int
    if tp is bool:
        def check_bool(v: Any) -> bool:
            if not isinstance(v, bool):
                fail(v, "true or false")
            return v
        return check_bool
    if tp is str:
        def check_str(v: Any) -> str:
            if not isinstance(v, str):
                fail(v, "a string")
            return v
        return check_str
    if tp is bytes:
        def check_bytes(v: Any) -> bytes:
            if not isinstance(v, (bytes, bytearray)):
                fail(v, "bytes")
            return bytes(v)
        return check_bytes
    if tp is np.ndarray:
        def check_array(v: Any) -> np.ndarray:
            if not isinstance(v, np.ndarray):
                fail(v, "a numpy array")
            return v
        return check_array
    if origin is list:
        (item_tp,) = typing.get_args(tp) or (Any,)
        item = _checker(item_tp, field + "[]", type_name)

        def check_list(v: Any) -> list:
            if isinstance(v, np.ndarray):
                v = v.tolist()
            if not isinstance(v, (list, tuple)):
                fail(v, "a list")
            return [item(x) for x in v]
        return check_list
    if origin is dict or tp is dict:
        def check_map(v: Any) -> dict:
            if not isinstance(v, dict):
                fail(v, "a map")
            return v
        return check_map
    if tp is Any:
        return lambda v: v
    raise TypeError(f"{type_name}.{field}: unsupported field type {tp!r}")


@typing.dataclass_transform(field_specifiers=(dataclasses.field,))
@dataclasses.dataclass
class Message:
    """Every message type derives from this: a dataclass with `stamp` (ns, producer clock; keyword
    only), registered by its class name and checked field by field when decoded."""
    stamp: int = dataclasses.field(default_factory=now_ns, kw_only=True)
    # Filled per type by __init_subclass__: field names in wire order, those without a default,
    # a check per field, and whether a field may hold a large array or bytes.
    _fields: typing.ClassVar[tuple[str, ...]]
    _required: typing.ClassVar[tuple[str, ...]]
    _checks: typing.ClassVar[dict[str, Callable[[Any], Any]]]
    _bulky: typing.ClassVar[bool]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        dataclasses.dataclass(cls)
        hints = typing.get_type_hints(cls)
        # `stamp` last, as on the wire since the first recordings (a map's order is its bytes).
        fields = sorted(dataclasses.fields(cls), key=lambda f: f.name == "stamp")
        cls._fields = tuple(f.name for f in fields)
        cls._required = tuple(
            f.name for f in fields
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        )
        cls._checks = {f.name: _checker(hints[f.name], f.name, cls.__name__) for f in fields}
        # Only messages with fields that may hold a large array or bytes look for them in encode()
        # (the bytes are the same either way; this only spares small messages the search).
        cls._bulky = any(hints[f.name] in (np.ndarray, bytes, Any) for f in fields)
        REGISTRY[cls.__name__] = cls


def to_dict(msg: Any) -> dict:
    d = {name: getattr(msg, name) for name in msg._fields}
    d[TYPE_FIELD] = type(msg).__name__
    return d


def encode(msg: Any) -> bytes:
    """Serialise a registered message to msgpack bytes (a map with `_type` for tools)."""
    if type(msg).__name__ not in REGISTRY:
        raise TypeError(f"{type(msg).__name__} is not a registered message type")
    d = to_dict(msg)
    return pack(d) if msg._bulky else _packer().pack(d)


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
class ArmState(Message):
    """Joint state of an arm; positions rad, velocities rad/s."""
    names: list[str]
    positions: list[float]
    velocities: list[float]
    mode: str = "idle"   # position | velocity | idle | fault
    fault: str = ""      # a sentence for the user, empty when healthy


#: The driver contract's command watchdog: in velocity mode a robot stops when no command
#: came for this long (drivers, the sim and the kinematics velocity stream alike).
COMMAND_WATCHDOG_S = 0.2


class ArmCommand(Message):
    """Joint reference: position (rad, optional velocity feed-forward rad/s) or velocity (rad/s).
    `controller` is the identity of the controller that sends it: a driver obeys only the one
    that holds the robot (asibot.safety.ownership), and only when that controller's key signed it
    (`seq`, `signature`: asibot.safety.identity)."""
    mode: str
    values: list[float]
    velocities: list[float] = dataclasses.field(default_factory=list)
    controller: str = ""
    seq: int = 0
    signature: bytes = b""

    def __post_init__(self) -> None:
        if self.mode not in ("position", "velocity"):
            raise MessageError("ArmCommand", "mode", f"must be 'position' or 'velocity', got {self.mode!r}")
        finite(self.values, "ArmCommand", "values")
        finite(self.velocities, "ArmCommand", "velocities")
        if self.velocities and len(self.velocities) != len(self.values):
            raise MessageError("ArmCommand", "velocities", "must be empty or as long as values")


class GripperState(Message):
    opening: float  # m between fingers
    holding: bool = False


class GripperCommand(Message):
    opening: float  # m between fingers
    controller: str = ""  # the sender's identity, signed, as in ArmCommand
    seq: int = 0
    signature: bytes = b""

    def __post_init__(self) -> None:
        finite([self.opening], "GripperCommand", "opening")


class Twist(Message):
    """Base velocity command: vx m/s forward, wz rad/s counter-clockwise. `controller` is the
    identity of the base controller that sends it (asibot.safety.ownership), signed as ArmCommand is."""
    vx: float
    wz: float
    controller: str = ""
    seq: int = 0
    signature: bytes = b""

    def __post_init__(self) -> None:
        finite([self.vx, self.wz], "Twist", "vx/wz")


class Odometry(Message):
    x: float
    y: float
    theta: float
    vx: float = 0.0
    wz: float = 0.0


class Sonar(Message):
    ranges: list[float]   # m
    angles: list[float]   # rad, robot frame


class Bumpers(Message):
    front: list[bool]
    rear: list[bool]


class Battery(Message):
    volts: float


class DepthImage(Message):
    depth: np.ndarray     # H x W float32 metres, 0 = no return


class RgbImage(Message):
    jpeg: bytes
    width: int
    height: int


class CameraInfo(Message):
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    pose: list[float]     # x, y, z, qw, qx, qy, qz in the robot base frame
    frame: str = ""


class LaserScan(Message):
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: np.ndarray


class Pose2D(Message):
    x: float
    y: float
    theta: float


class NavPose(Message):
    """Where localisation believes the robot is: map frame, m and rad. `covariance` is the 3x3
    covariance of (x, y, theta) row by row; `localised` says the filter is sure enough to drive
    on it; `particles` (N x 3 float32: x, y, theta) a sample of the filter's particles, for a map view."""
    x: float
    y: float
    theta: float
    covariance: list[float]
    localised: bool
    particles: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3), np.float32))


class NavMap(Message):
    """The map nav uses (ROS nav_msgs/OccupancyGrid): `data` int8 (height, width), row 0 at the
    origin, 0 free, 100 occupied, -1 unknown; `origin` is the pose (x, y, theta) of the lower-left
    corner of cell (0, 0); `resolution` m per cell."""
    resolution: float
    origin: list[float]
    data: np.ndarray
    name: str = ""


class NavPath(Message):
    """The planned path of the running goal (N x 2 float32, map frame, m); empty when none."""
    goal_id: int
    points: np.ndarray
    length: float = 0.0


class NavStatus(Message):
    """How navigation goes, for people: `state` is idle, active, succeeded, aborted, canceled or
    preempted (actionlib's); `text` a sentence ("driving to fridge, 3.2 m left"); `goal` x, y,
    theta or empty; `distance` m and `eta` s left; `driving` the running primitive's sentence
    ("forward, 1.00 m") or empty; `speed` and `width` the primitives' levels; `mapping` how
    the building of a new map goes ("mapping: 42.0 m² mapped from 120 scans"), empty when none."""
    goal_id: int
    state: str
    text: str
    place: str = ""
    goal: list[float] = dataclasses.field(default_factory=list)
    distance: float = 0.0
    eta: float = 0.0
    recoveries: int = 0
    driving: str = ""
    localised: bool = False
    speed: int = 0
    width: int = 0
    mapping: str = ""


class CartState(Message):
    """Cartesian controller state; pose and joints in SI (rotations and joints in rad)."""
    state: str
    pose: list[float]
    joints: list[float]


class EStop(Message):
    """The latched emergency stop of one robot; `by` says who engaged or released it (a person
    and program, `asibot.safety.estop.who()`), for the drivers' events and the logs. `signer` is the
    id whose key signed it (`seq`, `signature`: asibot.safety.identity): a release counts only signed,
    so `by` is what that key's holder said, and nobody else can say it in its name."""
    engaged: bool
    reason: str = ""
    by: str = ""
    signer: str = ""
    seq: int = 0
    signature: bytes = b""


class Event(Message):
    """A notice for the user: level info|warning|error, a stable code, a sentence."""
    level: str
    code: str
    text: str


class AudioChunk(Message):
    """A piece of a microphone's stream for the voice service, on `keys.voice_audio(source)`.
    `data`: little-endian samples, interleaved when stereo; `rate` Hz (8000 to 48000); `sample`
    "int16" or "float32" (in [-1, 1]); `channels` 1 or 2. Every chunk says its format, and a
    source keeps one (a new format is a new source); 20 to 200 ms a chunk, at most 1 s."""
    data: bytes
    rate: int
    sample: str = "int16"
    channels: int = 1


#: How long the voice service's `learn` listens to a live source for the word, s: by default,
#: and the shortest and longest a caller may ask for (a phrase said after a moment's thought).
LISTEN_SECONDS, MIN_LISTEN_SECONDS, MAX_LISTEN_SECONDS = 8.0, 1.0, 20.0


class VoiceHeard(Message):
    """One utterance the voice service cut from the audio of `source`, and what it did.

    `text` the phrase as spoken ("give me the red can"), "" when nothing of the grammar was
    heard; `word` the user's word it stands for, as written; `confidence` 0..1; `seconds` the
    utterance's length. `action`: launch (the task was started), refused (the Task Creator
    said no: `reason`), ask (a question waits for yes or no), cancel (no, no answer, or a stop
    came first), stop (every robot stopped), nothing. `task` the task concerned, `reason` a
    sentence (why nothing, why refused), `said` what the robot answered aloud ("" for nothing)."""
    source: str
    action: str
    text: str = ""
    word: str = ""
    confidence: float = 0.0
    seconds: float = 0.0
    task: str = ""
    reason: str = ""
    said: str = ""


class Health(Message):
    service: str
    instance: str
    uptime: float
    pid: int
    rejected: int = 0
    details: dict = dataclasses.field(default_factory=dict)
