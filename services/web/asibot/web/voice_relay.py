"""The page's microphone to the voice service, and what the voice service heard back to the page.

A page that listens sends its microphone over its WebSocket as binary frames of float32 mono
samples at its AudioContext's rate (told once in a `mic` message); each frame becomes an
`AudioChunk` on `keys.voice_audio("web-<page id>")`, so every page is its own stream for the
voice service. The voice service's `VoiceHeard` (everything it cut, from any source) and the
sentences about this page's audio (`keys.voice_events`) go back to the pages as `heard` and
`voice` messages; a page shows those of its own source. `learn` asks the voice service to take
the next thing a page's microphone hears as the user's own way of saying a word.
"""

from __future__ import annotations

import contextlib
from typing import Any, Callable, Iterator

from asibot import keys
from asibot.bus import Bus
from asibot.client import VoiceClient
from asibot.errors import RpcError, Timeout, Unavailable
from asibot.messages import AudioChunk, Event, VoiceHeard

#: What the page may send: a browser's AudioContext runs at 8 to 48 kHz (usually 44.1 or 48);
#: a frame is 20 to 200 ms, and never more than a second (the voice service's own limit).
RATES = (8000, 48000)
LONGEST_S = 1.0
#: The voice service answers at once, except `learn`, which waits for the word to be said.
CALL_TIMEOUT = 3.0


class MicError(ValueError):
    """A microphone frame or setting the page should not have sent; the sentence says what."""


def check_rate(rate: object) -> int:
    """A microphone's rate as the page said it; MicError with the sentence when it is not one."""
    if isinstance(rate, bool) or not isinstance(rate, int) or not RATES[0] <= rate <= RATES[1]:
        raise MicError(f"The microphone's rate must be a whole number of Hz from {RATES[0]} to {RATES[1]}; "
                       f"the page said {rate!r}.")
    return rate


def source_of(page_id: str) -> str:
    return f"web-{page_id}"


class VoiceRelay:
    """Publishes pages' microphone frames; passes what was heard to `send(message)` (all pages)."""

    def __init__(self, bus: Bus, send: Callable[[dict[str, Any]], None]) -> None:
        self.bus, self.send = bus, send
        self.voice = VoiceClient.on(bus, timeout=CALL_TIMEOUT)
        self._publishers: dict[str, Any] = {}
        bus.subscribe(keys.voice_heard(), VoiceHeard, self._on_heard, maxsize=50)

    def start(self, page_id: str, rate: int) -> Any:
        """A page starts listening at `rate` Hz (`check_rate`: the page's message was checked with
        it); returns the subscription to close when it stops."""
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
        with _running("this setting can be changed"):
            return {"confirm": self.voice.settings(confirm)}

    def learn(self, word: str, page_id: str, seconds: float) -> dict[str, Any]:
        """Learn how the user says `word` from the next thing this page's microphone hears, within
        `seconds` (the page listens already): the phones, the sayings kept, whether it matched."""
        with _running("words can be learned"):
            return self.voice.learn(word, source=source_of(page_id), seconds=seconds)

    def forget(self, word: str) -> dict[str, Any]:
        """Forget the user's own pronunciations of `word`."""
        with _running("words can be forgotten"):
            return self.voice.forget(word)

    def learned(self, words: list[str]) -> dict[str, Any]:
        """{"words": {phrase: [phones, ...]}, "phrases": {word: phrase}}: the words learned by
        saying them, and the phrase each of the user's `words` is learned under."""
        with _running("the words learned can be shown"):
            return self.voice.learned(words)

    def _on_heard(self, heard: VoiceHeard) -> None:
        msg = {name: getattr(heard, name) for name in heard._fields if name != "stamp"}
        self.send({"type": "heard", **msg})


@contextlib.contextmanager
def _running(then: str) -> Iterator[None]:
    """A call of the voice service, whose absence the page's user is told how to mend."""
    try:
        yield
    except (Unavailable, Timeout):
        raise RpcError("unavailable", "The voice service is not running: `asibot up` starts it "
                                      f"(service voice), and then {then}.") from None
