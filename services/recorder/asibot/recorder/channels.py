"""The Foxglove channels of one sink: an MCAP file (the export) or a WebSocket server (the
live view). Each sink has a foxglove.Context of its own, so an export running beside a live
view (or a test beside another) never writes into the other's channels.

A channel is made on its topic's first message and typed by it: the SDK's channel of a
well-known message (protobuf, the schema Foxglove knows), or a JSON channel with our schema.
"""

from __future__ import annotations

import logging
import threading
from typing import Any, Protocol

import foxglove
from foxglove import channels as fc

from asibot.recorder.conversions import Message
from asibot.recorder.jsonable import Json

log = logging.getLogger("asibot.recorder.channels")


class _Channel(Protocol):
    """What a channel of the SDK does here, typed or JSON."""

    def log(self, msg: Any, *, log_time: int | None = None) -> None: ...


def schema_name(message: Message) -> str:
    return message.schema_name if isinstance(message, Json) else f"foxglove.{type(message).__name__}"


class Channels:
    """Logs (topic, message) pairs on `context`, one channel a topic; thread-safe."""

    def __init__(self, context: foxglove.Context) -> None:
        self.context = context
        self.schemas: dict[str, str] = {}        # topic -> schema name
        self._channels: dict[str, _Channel] = {}
        self._refused: set[tuple[str, str]] = set()
        self._lock = threading.Lock()

    def _channel(self, topic: str, message: Message) -> _Channel | None:
        """The topic's channel, made on its first message; None when the topic already
        carries another schema (a channel has one: the other type's messages are left out)."""
        name = schema_name(message)
        with self._lock:
            known = self.schemas.get(topic)
            if known is None:
                if isinstance(message, Json):
                    channel: _Channel = foxglove.Channel(topic, schema=message.schema, context=self.context)
                else:
                    channel = getattr(fc, f"{type(message).__name__}Channel")(topic, context=self.context)
                self._channels[topic], self.schemas[topic] = channel, name
                return channel
            if known == name:
                return self._channels[topic]
            first = (topic, name) not in self._refused
            self._refused.add((topic, name))
        if first:
            log.warning("%s carries %s: its %s messages are left out", topic, known, name)
        return None

    def log(self, topic: str, message: Message, log_time: int) -> bool:
        """Log one message at `log_time` (ns); False when its topic carries another schema."""
        channel = self._channel(topic, message)
        if channel is None:
            return False
        channel.log(message.encode() if isinstance(message, Json) else message, log_time=log_time)
        return True
