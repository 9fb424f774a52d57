"""The AsTeRICS NetConnection wire protocol, both ways, with no sockets (reference: the plugin's
`ProtocolService.java`, measured against a real ARE; docs/asterics.md has the table).

A frame is a 6-byte header and a payload:

    0x40 '@'  0x4E 'N'  cmd  port  length (uint16, big-endian)  payload

cmd is `A` keepalive (port 0, no payload), `E` event (ports 1-10, no payload), `I` integer
(ports 1-5, int32 BE), `D` double (ports 1-5, IEEE-754 BE) or `S` string (ports 1-5, UTF-16BE);
lowercase letters are accepted on receive, as the plugin does. The plugin clamps strings to 300
characters and 600 bytes and refuses ports above the maximums; `encode_*` do the same.

`Decoder.feed(bytes)` takes whatever TCP delivered (half frames, several frames, frames split
anywhere, garbage) and returns what it could read: `Frame`s and `BadFrame`s (a sentence to
answer with). It resynchronises on the next `@N` after garbage or a bad header, so a broken
frame costs that frame only, and it never holds more than one frame's bytes.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

MAGIC = b"@N"
HEADER = struct.Struct(">2sBBH")
HEADER_SIZE = HEADER.size

KEEPALIVE, EVENT, INTEGER, DOUBLE, STRING = "keepalive", "event", "integer", "double", "string"
#: cmd letter -> (kind, highest port, payload size or None for strings)
COMMANDS: dict[int, tuple[str, int, int | None]] = {
    ord("A"): (KEEPALIVE, 0, 0),
    ord("E"): (EVENT, 10, 0),
    ord("I"): (INTEGER, 5, 4),
    ord("D"): (DOUBLE, 5, 8),
    ord("S"): (STRING, 5, None),
}
LETTER = {kind: letter for letter, (kind, _, _) in COMMANDS.items()}
MAX_STRING_CHARS = 300
MAX_STRING_BYTES = 600


@dataclass(frozen=True)
class Frame:
    kind: str                      # keepalive | event | integer | double | string
    port: int
    value: object = None           # int, float or str; None for events and keepalives


@dataclass(frozen=True)
class BadFrame:
    """A frame that cannot be used; `text` says why, for the answer to the client."""
    text: str


# ---------------------------------------------------------------------------- encoding
def _frame(kind: str, port: int, payload: bytes = b"") -> bytes:
    _, highest, _ = COMMANDS[LETTER[kind]]
    low = 0 if kind == KEEPALIVE else 1
    if not low <= port <= highest:
        raise ValueError(f"a {kind} frame goes on port {low} to {highest}, not {port}")
    return HEADER.pack(MAGIC, LETTER[kind], port, len(payload)) + payload


def clamp(text: str) -> str:
    """`text` cut as the plugin cuts what it sends: 300 characters, at most 600 UTF-16 bytes."""
    text = text[:MAX_STRING_CHARS]
    while len(text.encode("utf-16-be", "surrogatepass")) > MAX_STRING_BYTES:
        text = text[:-1]
    return text


def encode_string(port: int, text: str) -> bytes:
    return _frame(STRING, port, clamp(text).encode("utf-16-be", "replace"))


def encode_integer(port: int, value: int) -> bytes:
    return _frame(INTEGER, port, struct.pack(">i", value))


def encode_double(port: int, value: float) -> bytes:
    return _frame(DOUBLE, port, struct.pack(">d", value))


def encode_event(port: int) -> bytes:
    return _frame(EVENT, port)


KEEPALIVE_FRAME = _frame(KEEPALIVE, 0)


# ---------------------------------------------------------------------------- decoding
class Decoder:
    """Incremental decoder of one connection's byte stream."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.garbage = 0          # bytes skipped between frames

    def pending(self) -> int:
        """Bytes held for a frame not complete yet."""
        return len(self._buf)

    def partial(self) -> bool:
        """Whether a frame has begun (its '@' came) and not ended."""
        return bool(self._buf)

    def feed(self, data: bytes) -> list[Frame | BadFrame]:
        self._buf += data
        out: list[Frame | BadFrame] = []
        while True:
            start = self._buf.find(MAGIC)
            if start < 0:
                # keep a trailing '@': it may be the first half of the next magic
                keep = 1 if self._buf.endswith(b"@") else 0
                self.garbage += len(self._buf) - keep
                del self._buf[:len(self._buf) - keep]
                return out
            if start:
                self.garbage += start
                del self._buf[:start]
            if len(self._buf) < HEADER_SIZE:
                return out
            _, cmd, port, length = HEADER.unpack_from(self._buf)
            bad = self._check_header(cmd, port, length)
            if bad is not None:
                del self._buf[:len(MAGIC)]     # skip this '@N' and look for the next one
                out.append(bad)
                continue
            if len(self._buf) < HEADER_SIZE + length:
                return out
            payload = bytes(self._buf[HEADER_SIZE:HEADER_SIZE + length])
            del self._buf[:HEADER_SIZE + length]
            out.append(self._frame(cmd, port, payload))

    @staticmethod
    def _check_header(cmd: int, port: int, length: int) -> BadFrame | None:
        spec = COMMANDS.get(cmd & ~0x20)    # lowercase letters too
        if spec is None:
            return BadFrame(f"{chr(cmd)!r} is not a NetConnection command (A, E, I, D or S); the frame was skipped.")
        kind, highest, size = spec
        low = 0 if kind == KEEPALIVE else 1
        if not low <= port <= highest:
            return BadFrame(f"A {kind} frame goes on port {low} to {highest}, not {port}; the frame was skipped.")
        if size is None and length > MAX_STRING_BYTES:
            return BadFrame(f"A string frame of {length} bytes is longer than the {MAX_STRING_BYTES} bytes "
                            "NetConnection sends; the frame was skipped.")
        if size is not None and length != size:
            return BadFrame(f"A {kind} frame carries {size} bytes, not {length}; the frame was skipped.")
        return None

    @staticmethod
    def _frame(cmd: int, port: int, payload: bytes) -> Frame | BadFrame:
        kind = COMMANDS[cmd & ~0x20][0]
        if kind == STRING:
            try:
                if len(payload) % 2:
                    raise UnicodeDecodeError("utf-16-be", payload, len(payload) - 1, len(payload), "odd length")
                return Frame(kind, port, payload.decode("utf-16-be"))
            except UnicodeDecodeError:
                return BadFrame(f"The string on port {port} is not valid UTF-16 (big-endian); it was ignored.")
        if kind == INTEGER:
            return Frame(kind, port, struct.unpack(">i", payload)[0])
        if kind == DOUBLE:
            return Frame(kind, port, struct.unpack(">d", payload)[0])
        return Frame(kind, port)
