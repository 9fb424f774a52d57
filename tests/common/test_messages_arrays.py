"""numpy arrays on the wire: the same bytes as before, fewer copies, the same validation."""

import tracemalloc
from pathlib import Path

import msgpack
import numpy as np
import pytest

from asibot import messages as m
from asibot.errors import MessageError
from asibot.recorder.reader import iter_messages

FIXTURES = Path(__file__).resolve().parents[2] / "recordings" / "fixtures"
#: Above messages._VIEW_MIN: a message this large is decoded with its arrays views onto the payload.
LARGE = 200_000


# ------------------------------------------------------------ the encoding before this change
def reference_default(obj):
    """messages._default as it was: tobytes() + ExtType, packed by msgpack."""
    if isinstance(obj, np.ndarray):
        arr = np.ascontiguousarray(obj)
        head = msgpack.packb([arr.dtype.str, list(arr.shape)])
        return msgpack.ExtType(m.NDARRAY_EXT, head + arr.tobytes())
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(type(obj).__name__)


def reference_pack(obj) -> bytes:
    return msgpack.packb(obj, default=reference_default, use_bin_type=True)


def reference_unpack(data: bytes):
    def hook(code, data):
        assert code == m.NDARRAY_EXT
        unpacker = msgpack.Unpacker(raw=False)
        unpacker.feed(data)
        dtype, shape = next(unpacker)
        return np.frombuffer(data, dtype=np.dtype(dtype), offset=unpacker.tell()).reshape(shape)
    return msgpack.unpackb(data, ext_hook=hook, raw=False, strict_map_key=False)


# Sizes that make msgpack pick each ext header: fixext 8 and 16, ext 8, 16 and 32 on both
# sides of their limits (a u1 vector's [dtype, shape] head takes 7 bytes up to 127 items).
U1_SIZES = [0, 1, 9, 10, 120, 248, 249, 65528, 65529, 70000]
ARRAYS = [np.arange(n, dtype=np.uint8) for n in U1_SIZES] + [
    np.array(3.5, np.float32),                                       # 0-d travels as shape (1,)
    np.arange(12, dtype=np.float32).reshape(3, 4),
    np.random.default_rng(0).random((480, 640), dtype=np.float32),  # a depth frame, 1.2 MB
    np.arange(640 * 480, dtype=np.uint16).reshape(480, 640),
    np.arange(24, dtype=">f8").reshape(2, 3, 4),                     # big-endian
    np.arange(40, dtype=np.float32)[::2],                            # not contiguous
    np.asfortranarray(np.arange(12.0).reshape(3, 4)),                # Fortran order
    np.zeros((2, 0, 3), np.int64),
    np.array([True, False]), np.array([1 + 2j]), np.array(["ab", "c"]),
    np.arange(3).astype("datetime64[ns]"),
]


@pytest.mark.parametrize("arr", ARRAYS, ids=lambda a: f"{a.dtype.str}{list(a.shape)}")
def test_arrays_encode_to_the_same_bytes_as_before_and_back(arr):
    for d in ({"depth": arr, "stamp": 7, "_type": "DepthImage"},
              {"a": 1, "arr": arr, "b": b"x" * 70_000, "c": [1.5, "s"], "d": {"e": None}},
              {f"k{i}": i for i in range(20)} | {"arr": arr},           # map 16
              {"nested": [arr, {"x": arr}]}):                            # below the top level
        data = m.pack(d)
        assert data == reference_pack(d)
        back = m.unpack(data)
        assert back.keys() == d.keys()
        got = back["nested"][0] if "nested" in d else back["arr" if "arr" in d else "depth"]
        want = np.ascontiguousarray(arr)
        assert got.dtype == want.dtype and got.shape == want.shape and got.tobytes() == want.tobytes()
        assert not got.flags.writeable
        old = reference_unpack(data)
        assert {k: v for k, v in old.items() if not isinstance(v, (np.ndarray, list))} == \
            {k: v for k, v in back.items() if not isinstance(v, (np.ndarray, list))}


def test_messages_with_arrays_or_large_bytes_encode_as_before():
    depth = np.random.default_rng(1).random((480, 640), dtype=np.float32)
    for msg in (m.DepthImage(depth=depth, stamp=5),
                m.LaserScan(angle_min=-1, angle_increment=0.01, range_min=0.1, range_max=10,
                            ranges=np.ones(200, np.float32), stamp=5),
                m.RgbImage(jpeg=bytes(range(256)) * 4096, width=640, height=480, stamp=5),
                m.Health(service="s", instance="i", uptime=1.0, pid=3, details={"a": np.ones(3)}, stamp=5)):
        assert m.encode(msg) == reference_pack(m.to_dict(msg))


def test_the_committed_recordings_decode_and_encode_to_their_own_bytes():
    files = sorted(FIXTURES.glob("*.mcap"))
    assert files
    for path in files:
        for rec in iter_messages(path):
            body = m.decode_any(rec.payload)
            cls = m.REGISTRY[body[m.TYPE_FIELD]]
            again = m.encode(m.decode(cls, rec.payload))
            if set(body) == {*cls._fields, m.TYPE_FIELD}:
                assert again == rec.payload
            else:   # recorded before a field was added (ArmCommand.controller): the recorded
                    # fields come back as they were, the new ones with their defaults
                assert {k: v for k, v in m.decode_any(again).items() if k in body} == body


def test_a_large_decoded_array_is_read_only():
    depth = np.random.default_rng(2).random((480, 640), dtype=np.float32)
    data = m.encode(m.DepthImage(depth=depth))
    msg = m.decode(m.DepthImage, data)
    assert np.array_equal(msg.depth, depth)
    with pytest.raises(ValueError):
        msg.depth[0, 0] = 1.0
    mine = msg.depth.copy()  # what a receiver does before writing
    mine[0, 0] = 1.0


def test_small_payloads_still_decode_arrays_read_only():
    msg = m.decode(m.DepthImage, m.encode(m.DepthImage(depth=np.ones((3, 4), np.float32))))
    assert msg.depth.shape == (3, 4) and not msg.depth.flags.writeable


def _peak(fn) -> int:
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_encoding_copies_an_array_once_and_decoding_not_at_all():
    depth = np.ones((1024, 1024), np.float32)  # 4 MiB
    msg = m.DepthImage(depth=depth)
    assert _peak(lambda: m.encode(msg)) < 1.2 * depth.nbytes       # was ~3x (tobytes, ext, packer)
    data = m.encode(msg)
    assert _peak(lambda: m.decode(m.DepthImage, data)) < 0.05 * depth.nbytes  # was ~3.3x, then 1x
    back = m.decode(m.DepthImage, data).depth
    while not isinstance(back, bytes):
        back = back.base
    assert back is data  # a view onto the payload, which it keeps alive


def _ext(code: int, data: bytes) -> msgpack.ExtType:
    return msgpack.ExtType(code, data)


BAD_ARRAYS = [
    (msgpack.packb(["O", [2]]) + bytes(16), "object"),
    (msgpack.packb([3, [2]]) + bytes(8), "dtype"),
    (msgpack.packb(["<zz", [2]]) + bytes(8), "dtype"),
    (msgpack.packb(["<f4", [-1]]) + bytes(8), "shape"),
    (msgpack.packb(["<f4", "2"]) + bytes(8), "shape"),
    (msgpack.packb(["<f4", [3]]) + bytes(8), "bytes"),
    (msgpack.packb(["<f4", [1]]) + bytes(8), "bytes"),
    (msgpack.packb(["<f4"]) + bytes(8), "header"),
    (b"\x92\xa3<f", "header"),
    (b"", "header"),
]


@pytest.mark.parametrize("pad", [0, LARGE], ids=["small payload", "large payload"])
@pytest.mark.parametrize("ext, problem", BAD_ARRAYS)
def test_a_malformed_array_is_a_message_error_that_says_what_is_wrong(ext, problem, pad):
    data = msgpack.packb({"depth": _ext(m.NDARRAY_EXT, ext), "pad": b"\0" * pad, "stamp": 1},
                         use_bin_type=True)
    for decode in (lambda: m.decode(m.DepthImage, data), lambda: m.decode_any(data)):
        with pytest.raises(MessageError) as err:
            decode()
        assert "not a valid array" in str(err.value) and problem in str(err.value)


@pytest.mark.parametrize("pad", [0, LARGE])
def test_truncated_or_trailing_payloads_with_arrays_are_refused(pad):
    data = m.pack({"depth": np.ones(pad // 4 + 4, np.float32), "stamp": 1})
    for bad in (data[:-1], data[:-5], data[: len(data) // 2], data + b"\x00", b"\x83" + data[1:]):
        with pytest.raises(MessageError):
            m.decode(m.DepthImage, bad)


def _every_kind() -> dict:
    """A value of every msgpack kind, small and large."""
    big = b"\x01" * 70_000
    return {
        "nil": None, "t": True, "f": False, "i": -5, "u64": 2**64 - 1, "i64": -(2**63), "x": 1.5,
        "s": "é" * 40, "s8": "a" * 200, "s16": "b" * 70_000, "bin": big, "small": b"ab",
        "list": [1, [2, {"a": [3.0, None]}], "x" * 300], "map": {"k": {"j": [1, 2]}, "1": 2},
        "ext": _ext(5, b"zz"), "ext16": _ext(7, b"q" * 300), "ts": msgpack.Timestamp(10, 5),
        "long": list(range(10_000)),
        "arr": np.arange(10, dtype=np.int32),
    }


def _decodes_like_msgpack(d: dict) -> None:
    data = m.pack(d)
    assert data == reference_pack(d)
    back = m.unpack(data)
    ref = msgpack.unpackb(data, raw=False, strict_map_key=False,
                          ext_hook=lambda c, b: msgpack.ExtType(c, b) if c != m.NDARRAY_EXT else "array")
    assert list(back) == list(ref)
    arrays = [k for k, v in d.items() if isinstance(v, np.ndarray)]
    assert {k: v for k, v in back.items() if k not in arrays} == {k: v for k, v in ref.items() if k not in arrays}
    for k in arrays:
        assert np.array_equal(back[k], d[k]) and not back[k].flags.writeable


def test_large_payloads_decode_like_msgpack_does():
    _decodes_like_msgpack(_every_kind())
    non_map = m.pack([np.ones(10_000, np.float32), "x"])
    assert non_map == reference_pack([np.ones(10_000, np.float32), "x"])
    assert np.array_equal(m.unpack(non_map)[0], np.ones(10_000, np.float32))


def test_large_messages_decode_like_msgpack_does():
    # At most 15 entries, as a message: read value by value, around an array met by hand.
    items = list(_every_kind().items())
    for i in range(0, len(items), 8):
        depth = np.arange(LARGE, dtype=np.uint8)
        d = dict(items[i:i + 4]) | {"depth": depth} | dict(items[i + 4:i + 8])
        assert len(d) <= 15 and len(m.pack(d)) > LARGE
        _decodes_like_msgpack(d)


def test_object_arrays_are_still_refused_however_large():
    with pytest.raises(TypeError):
        m.pack({"a": np.array([object()] * 10_000)})
