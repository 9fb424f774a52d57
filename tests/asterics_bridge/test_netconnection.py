"""The NetConnection codec against the bytes measured from a real ARE (docs/asterics.md,
reference section 1.1), and every kind of bad input."""

import random
import struct

import pytest

from asibot.asterics_bridge import netconnection as nc
from asibot.asterics_bridge.netconnection import BadFrame, Decoder, Frame

#: ARE -> server: "forward" on stringInputPort1, as measured.
FORWARD = bytes.fromhex("40 4e 53 01 00 0e 00 66 00 6f 00 72 00 77 00 61 00 72 00 64")
EVENT_1 = bytes.fromhex("40 4e 45 01 00 00")
KEEPALIVE = bytes.fromhex("40 4e 41 00 00 00")
#: server -> ARE: "obstacle ahead" on port 1, then the port-1 event.
OBSTACLE = bytes.fromhex("40 4e 53 01 00 1c") + "obstacle ahead".encode("utf-16-be")


def test_the_measured_frames_both_ways():
    assert Decoder().feed(FORWARD + EVENT_1) == [Frame("string", 1, "forward"), Frame("event", 1)]
    assert nc.encode_string(1, "forward") == FORWARD
    assert nc.encode_event(1) == EVENT_1
    assert nc.encode_string(1, "obstacle ahead") + nc.encode_event(1) == OBSTACLE + EVENT_1
    assert Decoder().feed(OBSTACLE) == [Frame("string", 1, "obstacle ahead")]
    assert nc.KEEPALIVE_FRAME == KEEPALIVE
    assert Decoder().feed(KEEPALIVE) == [Frame("keepalive", 0)]


def test_integers_doubles_and_lowercase_commands():
    assert nc.encode_integer(3, -2) == b"@NI\x03\x00\x04" + struct.pack(">i", -2)
    assert nc.encode_double(5, 1.5) == b"@ND\x05\x00\x08" + struct.pack(">d", 1.5)
    frames = Decoder().feed(nc.encode_integer(3, -2) + nc.encode_double(5, 1.5) + b"@Ns\x02\x00\x02\x00A")
    assert frames == [Frame("integer", 3, -2), Frame("double", 5, 1.5), Frame("string", 2, "A")]


def test_frames_split_at_every_byte_arrive_whole():
    stream = FORWARD + EVENT_1 + KEEPALIVE + OBSTACLE
    whole = Decoder().feed(stream)
    for cut in range(1, len(stream)):
        d = Decoder()
        assert d.feed(stream[:cut]) + d.feed(stream[cut:]) == whole, cut
    d = Decoder()
    assert [f for b in stream for f in d.feed(bytes([b]))] == whole
    assert d.pending() == 0


def test_half_frames_wait_for_their_rest():
    d = Decoder()
    assert d.feed(FORWARD[:3]) == [] and d.feed(FORWARD[3:9]) == []
    assert d.pending() == 9
    assert d.feed(FORWARD[9:]) == [Frame("string", 1, "forward")]


def test_garbage_between_frames_is_skipped():
    d = Decoder()
    assert d.feed(b"hello" + FORWARD + b"\x00\xff@@x" + EVENT_1 + b"@") == [Frame("string", 1, "forward"),
                                                                           Frame("event", 1)]
    assert d.garbage == 5 + 5
    assert d.feed(FORWARD[1:]) == [Frame("string", 1, "forward")]   # the trailing '@' was kept


def test_oversized_lengths_are_refused_and_the_stream_resynchronises():
    d = Decoder()
    out = d.feed(b"@NS\x01\xff\xff" + b"\x00x" * 10 + FORWARD)
    assert isinstance(out[0], BadFrame) and "65535 bytes" in out[0].text
    assert out[1:] == [Frame("string", 1, "forward")]
    out = d.feed(b"@NS\x01\x02\x5a" + FORWARD)       # 602 > 600: the plugin never sends it
    assert isinstance(out[0], BadFrame) and out[-1] == Frame("string", 1, "forward")


@pytest.mark.parametrize("frame, words", [
    (b"@NS\x01\x00\x03\x00f\x00", "not valid UTF-16"),          # odd length
    (b"@NS\x01\x00\x02\xd8\x00", "not valid UTF-16"),           # a lone high surrogate
    (b"@NS\x01\x00\x02\xdc\x00", "not valid UTF-16"),           # a lone low surrogate
    (b"@NS\x06\x00\x02\x00f", "port 1 to 5, not 6"),
    (b"@NS\x00\x00\x02\x00f", "port 1 to 5, not 0"),
    (b"@NE\x0b\x00\x00", "port 1 to 10, not 11"),
    (b"@NA\x01\x00\x00", "port 0 to 0, not 1"),
    (b"@NI\x01\x00\x02\x00\x01", "carries 4 bytes, not 2"),
    (b"@ND\x01\x00\x04\x00\x00\x00\x01", "carries 8 bytes, not 4"),
    (b"@NE\x01\x00\x04", "carries 0 bytes, not 4"),
    (b"@NX\x01\x00\x00", "not a NetConnection command"),
])
def test_bad_frames_are_answered_and_the_next_frame_is_read(frame, words):
    out = Decoder().feed(frame + FORWARD)
    assert isinstance(out[0], BadFrame) and words in out[0].text, out
    assert out[-1] == Frame("string", 1, "forward")


def test_what_is_held_stays_bounded():
    d = Decoder()
    d.feed(bytes(random.Random(1).randrange(256) for _ in range(200_000)).replace(b"@N", b"xx"))
    assert d.pending() <= 1
    d.feed(b"@NS\x01\x02\x58")                   # a 600-byte string announced, not sent
    assert d.pending() == nc.HEADER_SIZE


def test_random_bytes_never_raise():
    rng = random.Random(7)
    d = Decoder()
    for _ in range(2000):
        chunk = bytes(rng.choice(b"@NSEIDA\x00\x01\x02\x05\xff") for _ in range(rng.randrange(1, 40)))
        for item in d.feed(chunk):
            assert isinstance(item, (Frame, BadFrame))
    assert d.pending() < nc.HEADER_SIZE + nc.MAX_STRING_BYTES


def test_sent_strings_are_clamped_as_the_plugin_clamps_them():
    assert Decoder().feed(nc.encode_string(1, "x" * 500))[0].value == "x" * 300
    emoji = "\U0001F600" * 200                        # 2 UTF-16 units each
    sent = Decoder().feed(nc.encode_string(1, emoji))[0].value
    assert sent == emoji[:150] and len(sent.encode("utf-16-be")) == 600
    with pytest.raises(ValueError):
        nc.encode_string(6, "x")
    with pytest.raises(ValueError):
        nc.encode_event(11)
