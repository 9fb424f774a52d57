"""Audio sources in, recognised utterances out, on one worker thread, in bounded memory.

Plain logic, no bus: `Streams.put(source, data, rate, sample, channels)` takes a chunk of any
source (a web page's microphone, the robot's own) from any thread and returns at once; a
worker thread feeds each source's own `Listener` (resampler, VAD, the shared recogniser) and
calls `on_result(source, result)` for every utterance that ends. Problems are told with
`on_notice(source, level, code, sentence)`; none of them stops another source.

- A chunk is checked whole where it arrives (`asibot.voice.audio.decode`: format, rate, whole
  frames, empty, NaN or infinity, longer than `max_chunk` s): a bad one is refused with a
  sentence (`bad_audio`) and changes nothing for its source.
- A source keeps the format of its first chunk; a chunk in another format is refused
  (`format_changed`): a new format is a new stream, under a new source name or after the
  source was forgotten.
- At most `max_sources` sources at once (`too_many_sources`), each with at most `max_queued`
  s of audio waiting: audio that arrives faster than it is heard (a flood, an endless burst)
  is dropped with what was waiting, the phrase under way with it (`audio_overflow`, told once
  until the source catches up). Memory is bounded by sources x queue x the VAD's 5 s.
- A source that sent nothing for `forget_after` s is forgotten, its unfinished phrase dropped
  (`source_forgotten`): a tab closed, a microphone unplugged or stuck.
- Sources are served in turn, one chunk at a time, so one cannot starve the others.
- `capture(source, on_utterance)` hands a source's next utterance to `on_utterance` instead of
  the recogniser (`uncapture` gives up): the word a user says to teach it
  (asibot.voice.learning) starts no task.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

from asibot.voice.audio import AudioFormat, decode
from asibot.voice.errors import BadAudio
from asibot.voice.recognizer import Listener, Recognizer, Result
from asibot.voice.vad import Utterance, VadConfig

log = logging.getLogger("asibot.voice")

MAX_CHUNK = 1.0
"""s of audio in one chunk at most: a browser sends 20 to 100 ms, sounddevice a block."""
MAX_QUEUED = 5.0
"""s of audio of one source waiting at most; the worker hears about 50 s of audio a second."""
FORGET_AFTER = 2.0
MAX_SOURCES = 8

OnResult = Callable[[str, Result], None]
OnNotice = Callable[[str, str, str, str], None]


def describe(fmt: AudioFormat) -> str:
    return f"{fmt.rate} Hz {fmt.sample} {'mono' if fmt.channels == 1 else 'stereo'}"


@dataclass
class _Source:
    listener: Listener
    format: AudioFormat
    last: float
    chunks: collections.deque = field(default_factory=collections.deque)
    queued: int = 0              # frames waiting
    fresh: bool = False          # the listener must start afresh (audio was dropped)
    overflowing: bool = False    # told about an overflow, not caught up yet


class Streams:
    """Per-source listeners fed by one worker thread (see the module's docstring)."""

    def __init__(self, recognizer: Recognizer, on_result: OnResult, on_notice: OnNotice, *,
                 vad: VadConfig | None = None, forget_after: float = FORGET_AFTER, max_sources: int = MAX_SOURCES,
                 max_queued: float = MAX_QUEUED, max_chunk: float = MAX_CHUNK,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.recognizer, self.vad = recognizer, vad
        self.on_result, self.on_notice = on_result, on_notice
        self.forget_after, self.max_sources = forget_after, max_sources
        self.max_queued, self.max_chunk, self.clock = max_queued, max_chunk, clock
        self.counters = {"chunks": 0, "refused": 0, "dropped": 0, "utterances": 0, "forgotten": 0}
        self._cond = threading.Condition()
        self._sources: dict[str, _Source] = {}
        self._ready: collections.deque[str] = collections.deque()    # sources with chunks waiting, in turn
        self._captures: dict[str, Callable[[Utterance], None]] = {}
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="voice-streams", daemon=True)
        self._thread.start()

    # --- in: any thread ----------------------------------------------------------------------
    def put(self, source: str, data: bytes, rate: int, sample: str = "int16", channels: int = 1) -> bool:
        """Queue one chunk of `source`; False (and a notice) when it is refused."""
        try:
            fmt = AudioFormat.parse(rate, sample, channels)
            decode(data, fmt, max_seconds=self.max_chunk)   # every check, before anything is kept
        except BadAudio as exc:
            return self._refuse(source, "warning", "bad_audio", str(exc))
        frames = len(data) // fmt.frame_bytes
        problem: tuple[str, str, str] | None = None
        with self._cond:
            if self._closed:
                return False
            s = self._sources.get(source)
            if s is None:
                if len(self._sources) >= self.max_sources:
                    problem = ("error", "too_many_sources",
                               f"There are already {self.max_sources} audio sources; the audio of {source!r} is "
                               "ignored until one of them stops sending for "
                               f"{self.forget_after:g} s.")
                else:
                    s = self._sources[source] = _Source(Listener(self.recognizer, fmt, self.vad), fmt, self.clock())
            if s is not None and s.format != fmt:
                problem = ("warning", "format_changed",
                           f"The audio of {source!r} is {describe(s.format)}, but a chunk said {describe(fmt)}; "
                           f"keep one format per stream (a new format needs a new source name, or a pause of "
                           f"{self.forget_after:g} s).")
                s = None
            if s is not None:
                s.last = self.clock()
                if s.queued + frames > self.max_queued * fmt.rate:
                    problem = self._overflow_locked(source, s)
                    s = None
                else:
                    s.chunks.append(bytes(data))
                    s.queued += frames
                    if len(s.chunks) == 1:
                        self._ready.append(source)
                    self.counters["chunks"] += 1
                    self._cond.notify()
                    return True
        if problem is None:
            return False
        return self._refuse(source, *problem)

    def _overflow_locked(self, source: str, s: _Source) -> tuple[str, str, str] | None:
        self.counters["dropped"] += len(s.chunks) + 1
        s.chunks.clear()
        s.queued = 0
        s.fresh = True
        if s.overflowing:
            return None
        s.overflowing = True
        return ("warning", "audio_overflow",
                f"The audio of {source!r} arrives faster than it can be heard (more than {self.max_queued:g} s "
                "waiting); what was waiting was dropped, with the phrase under way. Send audio in real time.")

    def _refuse(self, source: str, level: str, code: str, text: str) -> bool:
        with self._cond:
            self.counters["refused"] += 1
        self._notice(source, level, code, text)
        return False

    def _notice(self, source: str, level: str, code: str, text: str) -> None:
        try:
            self.on_notice(source, level, code, text)
        except Exception:
            log.exception("voice: telling about %s failed", source)

    def capture(self, source: str, on_utterance: Callable[[Utterance], None]) -> None:
        """Hand the next utterance of `source` (one that ends from now on) to `on_utterance`, on the
        worker, instead of recognising it."""
        with self._cond:
            self._captures[source] = on_utterance

    def uncapture(self, source: str, on_utterance: Callable[[Utterance], None]) -> None:
        """The caller gave up waiting: recognise `source` again, unless another capture replaced this one."""
        with self._cond:
            if self._captures.get(source) is on_utterance:
                del self._captures[source]
            s = self._sources.get(source)
            if s is not None and s.listener.capture is on_utterance:
                s.listener.capture = None

    # --- state ----------------------------------------------------------------------------
    def sources(self) -> dict[str, str]:
        """The live sources and their formats."""
        with self._cond:
            return {name: describe(s.format) for name, s in self._sources.items()}

    def capturing(self) -> list[str]:
        """The sources whose next utterance is waited for, not recognised."""
        with self._cond:
            return sorted(set(self._captures) | {name for name, s in self._sources.items() if s.listener.capture})

    def queued(self) -> float:
        """s of audio waiting, all sources."""
        with self._cond:
            return sum(s.queued / s.format.rate for s in self._sources.values())

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(2.0)

    # --- the worker -----------------------------------------------------------------------
    def _run(self) -> None:
        while True:
            with self._cond:
                forgotten = self._forget_locked()
                item = self._next_locked()
                if item is None and not forgotten and not self._closed:
                    self._cond.wait(min(0.1, self.forget_after / 4))
                if self._closed:
                    return
            for source, text in forgotten:
                self._notice(source, "info", "source_forgotten", text)
            if item is not None:
                self._feed(*item)

    def _next_locked(self) -> tuple[str, _Source, bytes, bool] | None:
        while self._ready:
            source = self._ready.popleft()
            s = self._sources.get(source)
            if s is None or not s.chunks:
                continue               # dropped by an overflow: nothing to hear
            data = s.chunks.popleft()
            s.queued -= len(data) // s.format.frame_bytes
            if s.chunks:
                self._ready.append(source)
            else:
                s.overflowing = False
            fresh, s.fresh = s.fresh, False
            if source in self._captures:          # on the worker, between two feeds of this listener
                s.listener.arm(self._captures.pop(source))
            return source, s, data, fresh
        return None

    def _forget_locked(self) -> list[tuple[str, str]]:
        now = self.clock()
        out = []
        for source, s in list(self._sources.items()):
            if not s.chunks and now - s.last > self.forget_after:
                del self._sources[source]
                self.counters["forgotten"] += 1
                dropped = " and its unfinished phrase dropped" if s.listener.in_speech else ""
                out.append((source, f"No audio from {source!r} for {self.forget_after:g} s: it is forgotten"
                                    f"{dropped}."))
        return out

    def _feed(self, source: str, s: _Source, data: bytes, fresh: bool) -> None:
        if fresh:
            capture = s.listener.capture
            s.listener = Listener(self.recognizer, s.format, self.vad)
            if capture is not None:
                s.listener.arm(capture)
        try:
            results = s.listener.feed(data)
        except BadAudio as exc:        # checked in put already; a sentence all the same
            self._notice(source, "warning", "bad_audio", str(exc))
            return
        except Exception:
            log.exception("voice: hearing the audio of %s failed", source)
            return
        for result in results:
            with self._cond:
                self.counters["utterances"] += 1
            try:
                self.on_result(source, result)
            except Exception:
                log.exception("voice: acting on what %s said failed", source)
