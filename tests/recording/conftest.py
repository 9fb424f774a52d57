"""Helpers shared by the recording tests."""

from __future__ import annotations

import contextlib
import json
import struct
import time
from typing import Any, Callable, Iterator

import pytest
from websockets.sync.client import ClientConnection, connect
from websockets.typing import Subprotocol


@pytest.fixture
def calls(monkeypatch) -> Callable[[Any, str], list[tuple]]:
    """`calls(module, "name")` wraps that function for the test and returns the list of the
    arguments of every call to it, to tell how much a piece of code did (or how far it got)."""

    def watch(owner: Any, name: str) -> list[tuple]:
        seen: list[tuple] = []
        real = getattr(owner, name)

        def counting(*args: Any) -> Any:
            seen.append(args)
            return real(*args)

        monkeypatch.setattr(owner, name, counting)
        return seen

    return watch


# ---------------------------------------------------------------- reading what Foxglove reads
# Foxglove's well-known messages are protobuf, each channel carrying its schema as a
# FileDescriptorSet. These helpers read them by field name from that schema alone, with no
# protobuf library and not with the SDK that wrote them: an independent check of what the
# Foxglove app will decode.

def _varint(buf: bytes, i: int) -> tuple[int, int]:
    shift = value = 0
    while True:
        b = buf[i]
        i += 1
        value |= (b & 0x7F) << shift
        if not b & 0x80:
            return value, i
        shift += 7


def _records(buf: bytes):
    """(field number, wire type, raw value) of each field of one protobuf message."""
    i = 0
    while i < len(buf):
        tag, i = _varint(buf, i)
        wire = tag & 7
        if wire == 0:
            value, i = _varint(buf, i)
        elif wire == 1:
            value, i = buf[i:i + 8], i + 8
        elif wire == 2:
            n, i = _varint(buf, i)
            value, i = buf[i:i + n], i + n
        elif wire == 5:
            value, i = buf[i:i + 4], i + 4
        else:
            raise ValueError(f"unexpected wire type {wire}")
        yield tag >> 3, wire, value


# descriptor.proto's scalar types: struct format of fixed-size ones, else how a varint reads.
_FIXED = {1: "<d", 2: "<f", 6: "<Q", 7: "<I", 15: "<i", 16: "<q"}
_DEFAULTS = {8: False, 9: "", 12: b""}


def _scalar(kind: int, wire: int, value: Any) -> Any:
    if kind in _FIXED:
        return struct.unpack(_FIXED[kind], value)[0]
    if kind == 9:
        return value.decode()
    if kind == 12:
        return bytes(value)
    if kind == 8:
        return bool(value)
    if kind in (17, 18):                      # sint: zigzag
        return (value >> 1) ^ -(value & 1)
    return value - (1 << 64) if kind in (3, 5) and value >= 1 << 63 else value


class Protobuf:
    """The message types of one FileDescriptorSet, and `decode(type, data)` by field name.

    A field absent from the data reads as proto3's default (0, "", b"", [], False); an
    absent message field is absent from the result."""

    def __init__(self, descriptor_set: bytes) -> None:
        self.types: dict[str, dict[int, tuple[str, int, bool, str]]] = {}
        for number, _, file in _records(descriptor_set):
            if number == 1:
                fields = {n: v for n, _, v in _records(file) if n == 2}
                package = fields.get(2, b"").decode()
                for n, _, message in _records(file):
                    if n == 4:
                        self._add(f".{package}" if package else "", message)

    def _add(self, scope: str, message: bytes) -> None:
        name = next(v.decode() for n, _, v in _records(message) if n == 1)
        fields = {}
        for n, _, value in _records(message):
            if n == 2:
                f = {k: v for k, _, v in _records(value)}
                fields[f[3]] = (f[1].decode(), f[5], f.get(4) == 3, f.get(6, b"").decode())
            elif n == 3:
                self._add(f"{scope}.{name}", value)
        self.types[f"{scope}.{name}"] = fields

    def decode(self, type_name: str, data: bytes) -> dict:
        fields = self.types[type_name if type_name.startswith(".") else f".{type_name}"]
        out: dict[str, Any] = {name: [] for name, _, repeated, _ in fields.values() if repeated}
        out.update({name: _DEFAULTS.get(kind, 0) for name, kind, repeated, _ in fields.values()
                    if not repeated and kind != 11})
        for number, wire, value in _records(data):
            name, kind, repeated, sub = fields[number]
            if kind == 11:
                item: Any = self.decode(sub, value)
            elif wire == 2 and kind not in (9, 12):          # packed repeated numbers
                if kind in _FIXED:
                    size = struct.calcsize(_FIXED[kind])
                    out[name] += [_scalar(kind, 1, value[i:i + size]) for i in range(0, len(value), size)]
                else:
                    i = 0
                    while i < len(value):
                        v, i = _varint(value, i)
                        out[name].append(_scalar(kind, 0, v))
                continue
            else:
                item = _scalar(kind, wire, value)
            if repeated:
                out[name].append(item)
            else:
                out[name] = item
        return out


@pytest.fixture
def protobuf() -> type[Protobuf]:
    """`protobuf(schema.data).decode("foxglove.RawImage", message.data)`: see Protobuf."""
    return Protobuf


class FoxgloveClient:
    """A client of a Foxglove WebSocket server, as the Foxglove app speaks to it: the SDK's
    protocol `foxglove.sdk.v1` (foxglove.websocket.v1 renamed, the same messages)."""

    def __init__(self, ws: ClientConnection) -> None:
        self.ws = ws
        self.info = json.loads(ws.recv(10))
        self.channels: dict[str, dict] = {}        # topic -> the advertised channel
        self.received: dict[int, list[tuple[int, bytes]]] = {}   # subscription -> (log time, payload)

    def pump(self, timeout: float = 0.05) -> None:
        """Read what the server sent within `timeout`: advertisements and messages."""
        try:
            frame = self.ws.recv(timeout)
        except TimeoutError:
            return
        if isinstance(frame, str):
            op = json.loads(frame)
            if op["op"] == "advertise":
                self.channels.update({c["topic"]: c for c in op["channels"]})
        elif frame[0] == 1:                     # message data: subscription id, log time, payload
            sub, log_time = struct.unpack_from("<IQ", frame, 1)
            self.received.setdefault(sub, []).append((log_time, frame[13:]))

    def wait(self, condition: Callable[[], Any], timeout: float, message: str,
             poke: Callable[[], None] = lambda: None) -> Any:
        """Pump until condition() is truthy, calling poke() between reads (to publish again)."""
        deadline = time.monotonic() + timeout
        while not (value := condition()):
            assert time.monotonic() < deadline, f"{message}; advertised: {sorted(self.channels)}"
            poke()
            self.pump()
        return value

    def subscribe(self, topic: str) -> int:
        """Subscribe to an advertised topic; the subscription's id is its channel's."""
        channel = self.channels[topic]["id"]
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": channel, "channelId": channel}]}))
        return channel


@pytest.fixture
def foxglove_client() -> Iterator[Callable[[str], FoxgloveClient]]:
    """`foxglove_client(url)` connects a FoxgloveClient; every one is closed at the end."""
    with contextlib.ExitStack() as connections:
        yield lambda url: FoxgloveClient(connections.enter_context(
            connect(url, subprotocols=[Subprotocol("foxglove.sdk.v1")], open_timeout=10)))
