"""The running stack, live in Foxglove: every key on the bus served on a Foxglove WebSocket
server (foxglove-sdk), as `asibot foxglove` runs it.

Messages are converted as the export converts a recording (`asibot.recorder.conversions`), so
a layout made for a recording shows the live stack too. The server speaks the SDK's WebSocket
protocol (`foxglove.sdk.v1`, foxglove.websocket.v1 renamed): Foxglove connects with "Open
connection > Foxglove WebSocket"; a Lichtblick too old to know the new name is refused.
The server offers no capability (no client publishing, services or parameters): a viewer
watches, it never commands.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable

import foxglove
from foxglove.websocket import ChannelView, Client, ServerListener

from asibot import keys, messages
from asibot.bus import Bus, Closable
from asibot.errors import MessageError
from asibot.messages import EStop, NavMap
from asibot.recorder.channels import Channels
from asibot.recorder.conversions import Message, Out, convert

log = logging.getLogger("asibot.recorder.live_view")

#: Foxglove's own default, which its "Open connection" dialog proposes.
DEFAULT_PORT = 8765
#: Loopback: the cameras and the map of someone's home are seen from this machine only,
#: unless the user names another address.
DEFAULT_HOST = "127.0.0.1"

#: Keys whose value is latched on the bus (published once, then served to whoever asks):
#: the view asks for them when it starts, and sends their newest value again to each client
#: that subscribes, since a client that connects later would otherwise never see them.
LATCHED: tuple[tuple[Callable[[str], str], type], ...] = ((keys.nav_map, NavMap), (keys.estop, EStop))


def _latched(key: str) -> bool:
    robot = keys.robot_of(key)
    return robot is not None and any(key == key_of(robot) for key_of, _ in LATCHED)


class _Resend(ServerListener):
    """Tells the view when a client subscribes, so it can send the latched values again."""

    def __init__(self, on_subscribe: Callable[[str], None]) -> None:
        self._on_subscribe = on_subscribe

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self._on_subscribe(channel.topic)


class LiveView:
    """Serves what `bus` carries on a Foxglove WebSocket server at host:port until closed.

    `port=0` takes any free port (`port` says which). Raises RuntimeError when the server
    cannot listen there (the port is taken, the host is not an address of this machine).
    """

    def __init__(self, bus: Bus, *, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT) -> None:
        self.host = host
        self.messages = 0          # messages sent to the server (each client subscribed gets them)
        self.skipped = 0           # payloads that were not a valid message
        self._latest: dict[str, tuple[str, Message]] = {}     # topic -> newest latched message
        self._lock = threading.Lock()
        self.channels = Channels(foxglove.Context())       # this view's channels only
        self.server = foxglove.start_server(name="asibot", host=host, port=port,
                                            context=self.channels.context,
                                            server_listener=_Resend(self._resend))
        self._subscriptions: list[Closable] = []
        try:
            self._subscriptions.append(bus.subscribe_raw(keys.EVERYTHING, self._on_sample))
            for key_of, cls in LATCHED:
                self._subscriptions.append(bus.subscribe(keys.every_robot(key_of), cls, self._on_latched,
                                                         latest=True, with_key=True))
        except BaseException:
            self.close()
            raise

    @property
    def port(self) -> int:
        return self.server.port

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"

    def _on_sample(self, key: str, payload: bytes, t_ns: int) -> None:
        if _latched(key):              # comes through its own subscription, and is kept
            return
        try:
            out = convert(key, messages.decode_any(payload))
        except MessageError:
            with self._lock:
                self.skipped += 1
            return
        self._log(out, t_ns)

    def _on_latched(self, key: str, msg: Any) -> None:
        out = convert(key, messages.to_dict(msg))
        with self._lock:
            self._latest.update({topic: (topic, message) for topic, message in out})
        self._log(out, time.time_ns())

    def _resend(self, topic: str) -> None:
        with self._lock:
            latest = self._latest.get(topic)
        if latest is not None:
            self._log([latest], time.time_ns())

    def _log(self, out: Out, t_ns: int) -> None:
        logged = sum(self.channels.log(topic, message, t_ns) for topic, message in out)
        with self._lock:
            self.messages += logged
            self.skipped += len(out) - logged

    def close(self) -> None:
        for sub in self._subscriptions:
            sub.close()
        self._subscriptions.clear()
        self.server.stop()

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
