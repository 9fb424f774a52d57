"""The page's microphone to the voice service, and what the voice service heard back to the page.

A page that listens sends its microphone over its WebSocket as binary frames of float32 mono
samples at its AudioContext's rate (told once in a `mic` message); each frame becomes an
`AudioChunk` on `keys.voice_audio("web-<page id>")`, so every page is its own stream for the
voice service. The voice service's `VoiceHeard` (everything it cut, from any source) and the
sentences about this page's audio (`keys.voice_events`) go back to the pages as `heard` and
`voice` messages; a page shows those of its own source.
"""

from __future__ import annotations

from typing import Any, Callable

from asibot import keys
from asibot.bus import Bus
from asibot.errors import RpcError
from asibot.messages import AudioChunk, Event, VoiceHeard

#: What the page may send: a browser's AudioContext runs at 8 to 48 kHz (usually 44.1 or 48);
#: a frame is 20 to 200 ms, and never more than a second (the voice service's own limit).
RATES = (8000, 48000)
LONGEST_S = 1.0


class MicError(ValueError):
    """A microphone frame or setting the page should not have sent; the sentence says what."""


def source_of(page_id: str) -> str:
    return f"web-{page_id}"


class VoiceRelay:
    """Publishes pages' microphone frames; passes what was heard to `send(message)` (all pages)."""

    def __init__(self, bus: Bus, send: Callable[[dict[str, Any]], None]) -> None:
        self.bus, self.send = bus, send
        self._publishers: dict[str, Any] = {}
        bus.subscribe(keys.voice_heard(), VoiceHeard, self._on_heard, maxsize=50)

    def start(self, page_id: str, rate: object) -> Any:
        """A page starts listening at `rate` Hz; returns the subscription to close when it stops."""
        if isinstance(rate, bool) or not isinstance(rate, int) or not RATES[0] <= rate <= RATES[1]:
            raise MicError(f"The microphone's rate must be a whole number of Hz from {RATES[0]} to {RATES[1]}; "
                           f"the page said {rate!r}.")
        source = source_of(page_id)
        self._publishers.setdefault(source, self.bus.publisher(keys.voice_audio(source), AudioChunk))
        return self.bus.subscribe(keys.voice_events(source), Event,
                                  lambda e: self.send({"type": "voice", "source": source, "level": e.level,
                                                       "code": e.code, "text": e.text}))

    def chunk(self, page_id: str, rate: int, data: bytes) -> None:
        """One frame of float32 mono samples from a listening page."""
        source = source_of(page_id)
        pub = self._publishers.get(source)
        if pub is None:
            raise MicError("The page sent sound before saying its microphone's rate; start listening again.")
        if not data or len(data) % 4 or len(data) // 4 > rate * LONGEST_S:
            raise MicError(f"A microphone frame must be 1 to {int(rate * LONGEST_S)} float32 samples; "
                           f"this one had {len(data)} bytes.")
        pub.put(AudioChunk(data=bytes(data), rate=rate, sample="float32", channels=1))

    def settings(self, confirm: bool | None = None) -> dict[str, Any]:
        """The voice service's settings (`confirm`: ask yes first before a task heard starts),
        changed first when `confirm` is given. RpcError unavailable when it does not run."""
        request = {} if confirm is None else {"confirm": confirm}
        try:
            return {"confirm": self.bus.call(keys.voice_rpc("settings"), request, timeout=3.0)["confirm"]}
        except RpcError as exc:
            if exc.code in ("unavailable", "timeout"):
                raise RpcError("unavailable", "The voice service is not running: `asibot up` starts it "
                                              "(service voice), and then this setting can be changed.") from None
            raise

    def _on_heard(self, heard: VoiceHeard) -> None:
        msg = {name: getattr(heard, name) for name in heard._fields if name != "stamp"}
        self.send({"type": "heard", **msg})
