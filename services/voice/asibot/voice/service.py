"""The voice service: `python -m asibot.voice --robot asibot-sim [--confirm] [--local-mic]`.

In: microphone audio on `keys.voice_audio(<source>)` (`AudioChunk`; a web page publishes its
microphone there as `web-<page id>`) and, with `--local-mic`, the robot's own microphone; the
Task Creator's tasks (`keys.tasks_rpc("list")`, every `--refresh` s: their words are the
grammar, with stop, yes and no); the robot's events (how a task ended); which robots have a
live driver (`keys.ALL_DRIVERS`).
Out: `keys.tasks_rpc("launch")` for a task word, and for "stop" the latched emergency stop of
every robot with a live driver and `keys.tasks_rpc("stop")`; `keys.voice_heard()` for every
utterance (what was heard, what was done); `keys.voice_events(<source>)` when a source's audio
is refused; spoken feedback with espeak-ng (`--quiet`: logged instead).
Learning: `keys.voice_rpc("learn")` learns the user's own pronunciation of a word from a
recording or from the next thing said on a live source (asibot.voice.learning), kept in
`<data>/voice/pronunciations.json`; `forget` drops them, `learned` lists them.

Threads: chunks are checked and queued on the bus's thread (`streams.Streams`), heard on the
streams' worker, and acted on by a commands thread, except "stop", which is done at once on
the worker, so it never waits behind a slow launch. docs/voice.md, "The service".
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import queue
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from asibot.safety import estop
from asibot import keys, messages, runtime, verbs
from asibot.files import data_dir, private_dir, write_atomic
from asibot.bus import Bus
from asibot.client import TasksClient
from asibot.errors import RpcError, Unavailable
from asibot.safety.estop import who
from asibot.safety.identity import Identity
from asibot.messages import (AudioChunk, Event, LISTEN_SECONDS, MAX_LISTEN_SECONDS, MIN_LISTEN_SECONDS,
                             VoiceHeard)
from asibot.verbs import Blob, Field, Flag, Number, OneOf, Text, Texts, Verb, Whole
from asibot.voice.audio import MAX_RATE, MIN_RATE, SAMPLE_TYPES, AudioFormat, decode, to_16k
from asibot.voice.commands import STOP, Commands, Outcome, Stopped, Transcript
from asibot.voice.errors import GrammarError
from asibot.voice.grammar import FIXED_WORDS, MAX_PHRASES, Grammar
from asibot.voice.learning import Learned, Learner
from asibot.voice.pronunciations import Pronunciations
from asibot.voice.recognizer import Recognizer, Result
from asibot.voice.speaker import Speaker
from asibot.voice.streams import FORGET_AFTER, Streams

if TYPE_CHECKING:   # main() imports the microphone only for --local-mic
    from asibot.voice.mic import LocalMic

NAME = "voice"
DEFAULT_ROBOT = "asibot-sim"
#: Timeout of a launch or stop call, and of the list of tasks, s.
CALL_TIMEOUT, LIST_TIMEOUT = 3.0, 1.0
#: After start, how long a Task Creator that does not answer yet is waited for without a
#: warning (`asibot up` starts the web and voice together; the web takes a few seconds), s.
STARTUP_GRACE_S = 30.0
WAITING_FOR_TASKS = "Waiting for the Task Creator (the web service) to list the tasks."
#: Utterances waiting to be acted on at most (each is a phrase someone said: a handful).
MAX_WAITING = 16
#: A recording sent to learn a word from, s at most (the word, with quiet around it).
MAX_RECORDING = 10.0
#: Longest word or phrase a request may name, characters (a phrase has at most 12 words).
MAX_WORD_CHARS = 200

_WORD = Field(Text("a word or phrase", longest=MAX_WORD_CHARS), required=True)

#: The verbs of `keys.voice_rpc`. Whether a word can be learned (its words, how many) and
#: whether audio can be heard (whole frames, its length) are the learner's and the decoder's
#: checks, whose sentences say what to do.
VERBS = {
    "status": Verb(doc="the words listened for, the sources heard, the settings and the words learned"),
    "settings": Verb({"confirm": Field(Flag(), also="or absent to just read it")},
                     doc="ask yes first before a task heard starts (kept in the user's data folder)"),
    "learn": Verb({
        "word": _WORD,
        # At most MAX_RECORDING s at the highest rate, in stereo float32.
        "data": Field(Blob("a recording", largest=int(MAX_RECORDING * MAX_RATE * 2 * 4)),
                      also="or absent to listen to a source"),
        "rate": Field(Whole(MIN_RATE, MAX_RATE), also="in Hz"),
        "sample": Field(OneOf(tuple(SAMPLE_TYPES)), default="int16"),
        "channels": Field(Whole(1, 2), default=1),
        "source": Field(Text("an audio source name"), also="or absent to learn from a recording"),
        "seconds": Field(Number(MIN_LISTEN_SECONDS, MAX_LISTEN_SECONDS, "s"), default=LISTEN_SECONDS),
    }, doc="learn how the user says a word, from a recording or from the next thing said on a live source"),
    "forget": Verb({"word": _WORD}, doc="forget the user's own pronunciations of a word (the dictionary's stay)"),
    "learned": Verb({"words": Field(Texts(Text("a word as written", longest=MAX_WORD_CHARS), most=MAX_PHRASES),
                                    default=())},
                    doc="every phrase learned and its sayings, and the phrase each of `words` is learned under"),
}

log = logging.getLogger("asibot.voice")


class BusRobots:
    """`commands.Robots` on the bus: launch on `robot` through the Task Creator; stop by engaging
    the latched emergency stop of every robot whose driver is alive (what the page's red button
    does: the drivers stop at once, whatever moves the robot) and stopping the running task."""

    def __init__(self, bus: Bus, robot: str, timeout: float = CALL_TIMEOUT) -> None:
        self.bus, self.robot, self.timeout = bus, robot, timeout
        self._tasks = TasksClient.on(bus, robot, timeout)       # the web's tasks, as a program calls them
        self._listing = TasksClient.on(bus, robot, LIST_TIMEOUT)
        self.me = Identity("voice")     # signs its estops (asibot.safety.estop)
        self._lock = threading.Lock()
        self._live: set[str] = set()
        bus.watch(keys.ALL_DRIVERS, self._on_driver)

    def _on_driver(self, key: str, alive: bool) -> None:
        robot = keys.robot_of(key)
        if robot:
            with self._lock:
                (self._live.add if alive else self._live.discard)(robot)

    def live(self) -> list[str]:
        with self._lock:
            return sorted(self._live)

    def launch(self, task: str) -> None:
        try:
            self._tasks.launch(task)
        except Unavailable:
            raise Unavailable("The Task Creator is not running, so no task can start.") from None

    def stop(self) -> Stopped:
        robots = self.live()
        for robot in robots:
            estop.latch(self.bus, robot, self.me, True, '"stop" said to the voice service', who("voice"))
        problems = []
        try:
            self._tasks.stop()
        except Unavailable:
            pass                                     # no Task Creator: no task of its runs
        except RpcError as exc:
            problems.append(f"The task could not be stopped: {exc.message}")
        return Stopped(tuple(robots), tuple(problems))

    def tasks(self) -> list:
        return self._listing.tasks()


class VoiceService(runtime.Service):
    def __init__(self, bus: Bus, robot: str, speaker: object, *, confirm: bool = False, answer_seconds: float = 8.0,
                 refresh: float = 2.0, source_timeout: float = FORGET_AFTER,
                 recognizer: Recognizer | None = None, settings_file: Path | None = None,
                 pronunciations_file: Path | None = None) -> None:
        self.bus, self.robot, self.speaker, self.refresh_period = bus, robot, speaker, refresh
        self.recognizer = recognizer or Recognizer()
        self.grammar = self.recognizer.grammar
        self.tasks_problem = "The Task Creator was not asked yet."
        self._started, self._never_listed = time.monotonic(), True
        self.robots = BusRobots(bus, robot)
        self.settings_file = settings_file or data_dir() / "voice" / "settings.json"
        confirm = _saved_confirm(self.settings_file, default=confirm)
        self.commands = Commands(self.robots, speaker, confirm=confirm, answer_seconds=answer_seconds)
        self.pronunciations = Pronunciations(pronunciations_file or data_dir() / "voice" / "pronunciations.json")
        self.learner = Learner(self.recognizer, self.pronunciations, self.words)
        self._task_words: list[str] = []
        self._grammar_lock = threading.Lock()    # a refresh and a word learned rebuild the grammar one at a time
        self._relisten()                         # a learned "stop" counts before the Task Creator answers
        self.mic: LocalMic | None = None
        self._asked_by = ""
        self._stop = threading.Event()
        self._waiting: queue.Queue = queue.Queue(MAX_WAITING)
        self._heard = bus.publisher(keys.voice_heard(), VoiceHeard)
        self.streams = Streams(self.recognizer, self._on_result, self._on_notice, forget_after=source_timeout)
        bus.subscribe(keys.ALL_VOICE_AUDIO, AudioChunk, self._on_chunk, with_key=True, on_reject=self._on_bad_chunk)
        bus.subscribe(keys.events(robot), Event, self.commands.on_event)
        verbs.serve(bus, keys.voice_rpc, VERBS, {"status": self._status, "settings": self._settings,
                                                 "learn": self._learn, "forget": self._forget,
                                                 "learned": self._learned})
        self._threads = [threading.Thread(target=fn, name=name, daemon=True)
                         for fn, name in ((self._act, "voice-commands"), (self._housekeeping, "voice-tasks"))]
        for t in self._threads:
            t.start()

    # --- audio in ---------------------------------------------------------------------------
    def _on_chunk(self, key: str, chunk: AudioChunk) -> None:
        source = keys.voice_source_of(key)
        if source:
            self.streams.put(source, chunk.data, chunk.rate, chunk.sample, chunk.channels)

    def _on_bad_chunk(self, key: str, error: Exception) -> None:
        source = keys.voice_source_of(key)
        if source:
            self._on_notice(source, "warning", "bad_audio", f"The audio chunk was refused: {error}.")

    def _on_notice(self, source: str, level: str, code: str, text: str) -> None:
        (log.info if level == "info" else log.warning)("voice: %s: %s", source, text)
        self.bus.put_raw(keys.voice_events(source), messages.encode(Event(level=level, code=code, text=text)))

    # --- what was heard ---------------------------------------------------------------------
    def _on_result(self, source: str, result: Result) -> None:
        """On the streams' worker: "stop" at once, the rest in order on the commands thread."""
        if result.heard is not None and result.heard.word == STOP:
            self._publish(source, result, self.commands.hear(result.heard))
            return
        try:
            self._waiting.put_nowait((source, result, self.commands.ticket()))
        except queue.Full:
            self._publish(source, result, Outcome("nothing", reason="Still busy with what was said before; "
                                                                    "say it again."))

    def _act(self) -> None:
        while not self._stop.is_set():
            try:
                source, result, ticket = self._waiting.get(timeout=0.2)
            except queue.Empty:
                continue
            self._publish(source, result, self.commands.hear(result.heard, result.reason, ticket))

    def _publish(self, source: str, result: Result | None, outcome: Outcome) -> None:
        heard = result.heard if result is not None else None
        if outcome.action == "ask":
            self._asked_by = source
        msg = VoiceHeard(source=source, action=outcome.action, text=heard.text if heard else "",
                         word=heard.word if heard else "", confidence=heard.confidence if heard else 0.0,
                         seconds=result.seconds if result is not None else 0.0, task=outcome.task,
                         reason=outcome.reason, said=outcome.said)
        log.info("voice: %s: heard %r -> %s %s%s", source or "-", msg.text, msg.action, msg.task,
                 f" ({msg.reason})" if msg.reason else "")
        self._heard.put(msg)

    # --- the words, the question's time -----------------------------------------------------
    def _housekeeping(self) -> None:
        next_refresh = time.monotonic()
        while not self._stop.is_set():
            if time.monotonic() >= next_refresh:
                self.refresh()
                next_refresh = time.monotonic() + self.refresh_period
            expired = self.commands.expire()
            if expired is not None:
                self._publish(self._asked_by, None, expired)
            self._stop.wait(0.1)

    def refresh(self) -> None:
        """Ask the Task Creator for the tasks; listen for their words if they changed."""
        try:
            words = self.commands.set_tasks(self.robots.tasks())
            with self._grammar_lock:
                self._task_words = words
                grammar = self._listen()
        except Unavailable as exc:
            # At start-up the Task Creator may not be up yet (services start in any order):
            # that is waiting, not a problem, until it has answered once or the grace is over.
            if self._never_listed and time.monotonic() - self._started < STARTUP_GRACE_S:
                if self.tasks_problem != WAITING_FOR_TASKS:
                    log.info("voice: %s", WAITING_FOR_TASKS)
                self.tasks_problem = WAITING_FOR_TASKS
                return
            self._cannot_update(exc)
            return
        except (RpcError, GrammarError) as exc:
            self._cannot_update(exc)
            return
        self._never_listed = False
        if grammar.key != self.grammar.key or self.tasks_problem:
            listed = ", ".join(repr(w) for w in grammar.phrases.values() if w not in FIXED_WORDS)
            log.info("voice: listening for %s and %s", listed or "no task words", ", ".join(FIXED_WORDS))
            for word, why in grammar.refused.items():
                log.warning("voice: the word %r is left out: %s", word, why)
        self.grammar, self.tasks_problem = grammar, ""

    def _cannot_update(self, exc: Exception) -> None:
        problem = f"{exc} Keeping the {len(self.grammar.phrases) - len(FIXED_WORDS)} words heard before."
        if problem != self.tasks_problem:
            log.warning("voice: cannot update the words: %s", problem)
        self.tasks_problem = problem

    def _listen(self) -> Grammar:
        """The tasks' words and the user's own pronunciations as the grammar (under _grammar_lock)."""
        return self.recognizer.set_words(self._task_words, skip_unknown=True, learned=self.pronunciations.all())

    def _relisten(self) -> None:
        """A pronunciation was learned or forgotten: listen with it from the next phrase on."""
        with self._grammar_lock:
            self.grammar = self._listen()

    def words(self) -> list[str]:
        """The tasks' words listened for, as written."""
        return [w for w in self.grammar.phrases.values() if w not in FIXED_WORDS]

    # --- the verbs of VERBS: each takes its checked arguments -------------------------------
    def _status(self, a: Any) -> dict:
        return {"robot": self.robot, "words": self.words(), "fixed": list(FIXED_WORDS),
                "refused": dict(self.grammar.refused), "tasks": self.tasks_problem or "ok",
                "sources": self.streams.sources(), "confirm": self.commands.confirm, "pending": self.commands.pending,
                "live_robots": self.robots.live(), "learned": sorted(self.pronunciations.all()),
                "learning_from": self.streams.capturing()}

    def _settings(self, a: Any) -> dict:
        """`confirm`: ask "Shall I start ...? Say yes or no." before a task heard starts (the
        page's setting, kept in the user's data folder); absent: just read it."""
        if a.confirm is not None:
            private_dir(self.settings_file.parent)
            write_atomic(self.settings_file, json.dumps({"confirm": a.confirm}).encode())
            self.commands.confirm = a.confirm
        return {"confirm": self.commands.confirm}

    def _learn(self, a: Any) -> dict:
        """Learn how the user says `word` from a recording (`data`, `rate`, `sample`, `channels`:
        the AudioChunk fields; up to MAX_RECORDING s, quiet around the word), or from the next
        thing said on the live `source` (a page's microphone) within `seconds`. Answers the
        phones learned and whether the recogniser would already have heard the word in this
        saying (`matched`)."""
        try:
            self.learner.phrase(a.word)                 # a bad word is refused before any listening
            if (a.data is None) == (a.source is None):
                raise RpcError("bad_request", "learn needs either a recording (data, rate, sample, channels) or "
                                              "a live source to listen to (source), not both and not neither.")
            if a.data is not None:
                fmt = AudioFormat.parse(a.rate, a.sample, a.channels)    # the rate a recording needs
                decode(a.data, fmt, max_seconds=MAX_RECORDING)          # every check, before the work
                learned = self.learner.learn_recording(a.word, to_16k(a.data, fmt))
            else:
                learned = self.learner.learn(a.word, self._next_utterance(a.source, a.seconds))
        except ValueError as exc:                            # BadAudio, GrammarError, a bad source name
            raise RpcError("bad_request", f"{exc} Nothing was learned.") from None
        self._relisten()
        log.info("voice: learned %r as %s (%s)", learned.phrase, " ".join(learned.phones),
                 {True: "it matched", False: f"heard {learned.heard!r}", None: "new"}[learned.matched])
        return _learned_reply(learned)

    def _next_utterance(self, source: str, seconds: float) -> np.ndarray:
        """The next utterance said on live `source`, which then launches nothing; RpcError timeout."""
        keys.voice_audio(source)                                   # ValueError naming a bad source
        got: queue.Queue = queue.Queue()
        hand_over = got.put                  # one bound method: uncapture compares by identity
        self.streams.capture(source, hand_over)
        try:
            utterance = got.get(timeout=seconds)
        except queue.Empty:
            raise RpcError("timeout", f"Nothing was said into {source!r} within {seconds:g} s (is its microphone "
                                      "on?); start again and say the word. Nothing was learned.") from None
        finally:
            self.streams.uncapture(source, hand_over)
        if utterance.cut:
            raise RpcError("bad_request", f"The speech went on for more than {utterance.seconds:.0f} s without a "
                                          "pause; say only the word or phrase. Nothing was learned.")
        return utterance.samples

    def _forget(self, a: Any) -> dict:
        """Forget the user's own pronunciations of `word` (the dictionary's stays)."""
        try:
            phrase, count = self.learner.forget(a.word)
        except ValueError as exc:
            raise RpcError("bad_request", f"{exc} Nothing was forgotten.") from None
        if count:
            self._relisten()
            log.info("voice: forgot the %d learned pronunciation(s) of %r", count, phrase)
        return {"phrase": phrase, "forgotten": count}

    def _learned(self, a: Any) -> dict:
        """Every learned phrase and its pronunciations (phones joined by spaces); with `words`
        (the user's words as written), also the phrase each is learned under (`phrases`), so a
        page can show "Give me the red can!" with the sayings of "give me the red can"."""
        phrases = {}
        for word in a.words:
            try:
                phrases[word] = self.learner.phrase(word)
            except ValueError:
                continue                 # not a phrase at all (no words, too many): nothing can be learned for it
        learned = self.pronunciations.all().items()
        return {"words": {phrase: [" ".join(s) for s in sayings] for phrase, sayings in learned}, "phrases": phrases}

    # --- runtime.Service --------------------------------------------------------------------
    def health(self) -> dict:
        return {"robot": self.robot, "words": len(self.words()), "refused": len(self.grammar.refused),
                "tasks": self.tasks_problem or "ok", "sources": len(self.streams.sources()),
                "queued_s": round(self.streams.queued(), 2), "pending": self.commands.pending,
                **self.commands.counters, **{f"audio_{k}": v for k, v in self.streams.counters.items()},
                **(self.mic.health() if self.mic is not None else {})}

    def close(self) -> None:
        self._stop.set()
        if self.mic is not None:
            self.mic.close()
        self.streams.close()
        self.learner.reader.close()
        for t in self._threads:
            t.join(1.0)


def _learned_reply(learned: Learned) -> dict:
    return {"phrase": learned.phrase, "phones": " ".join(learned.phones),
            "sayings": [" ".join(s) for s in learned.sayings], "matched": learned.matched, "heard": learned.heard,
            "dropped": learned.dropped, "seconds": round(learned.seconds, 2)}


def _saved_confirm(path: Path, default: bool) -> bool:
    """The page's "ask yes first" setting if one was saved, else `default` (--confirm). A file
    that cannot be read is left alone, with a warning: the setting is the default until saved."""
    try:
        value = json.loads(path.read_text()).get("confirm")
    except FileNotFoundError:
        return default
    except (OSError, ValueError, AttributeError) as exc:
        log.warning("voice: %s is not a settings file (%s); asking yes first: %s", path, exc, default)
        return default
    return value if isinstance(value, bool) else default


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--confirm", action="store_true",
                   help="ask 'Shall I start <task>? Say yes or no.' before launching a task heard (unless "
                        "the page's setting, kept in <data>/voice/settings.json, says otherwise)")
    p.add_argument("--answer-seconds", type=float, default=8.0, help="s to wait for yes or no (default 8)")
    p.add_argument("--refresh", type=float, default=2.0, help="s between two looks at the tasks' words (default 2)")
    p.add_argument("--source-timeout", type=float, default=FORGET_AFTER,
                   help=f"s without audio after which a source is forgotten (default {FORGET_AFTER:g})")
    p.add_argument("--quiet", action="store_true", help="log the spoken feedback instead of speaking it")
    p.add_argument("--voice", default="en-us", help="espeak-ng voice (default en-us)")
    p.add_argument("--speed", type=int, default=150, help="espeak-ng words per minute (default 150)")
    p.add_argument("--local-mic", action="store_true", default=os.environ.get("ASIBOT_VOICE_LOCAL_MIC") == "1",
                   help="also listen to this machine's microphone (sounddevice; needs the PortAudio library: "
                        "`sudo apt-get install libportaudio2`); default off, or ASIBOT_VOICE_LOCAL_MIC=1")
    p.add_argument("--mic-device", default=None,
                   help="the input device for --local-mic, by number or name (`python -m sounddevice` lists them)")


def build(bus: Bus, args: argparse.Namespace) -> VoiceService:
    robot = runtime.robot_id(args, DEFAULT_ROBOT)
    for name, value, low, high in (("--answer-seconds", args.answer_seconds, 1.0, 60.0),
                                   ("--refresh", args.refresh, 0.05, 60.0),
                                   ("--source-timeout", args.source_timeout, 0.2, 60.0)):
        if not low <= value <= high:
            raise ValueError(f"{name} must be between {low:g} and {high:g} s, not {value:g}")
    try:
        speaker: object = Transcript() if args.quiet else Speaker(voice=args.voice, speed=args.speed)
    except ValueError as exc:
        raise ValueError(f"--voice / --speed: {exc}") from None
    if isinstance(speaker, Speaker) and not speaker.available:
        log.warning("voice: espeak-ng is not installed (`sudo apt-get install espeak-ng`); the feedback is only logged")
        speaker = Transcript()
    if args.local_mic:
        from asibot.voice.mic import LocalMic, sounddevice_module
        sounddevice_module()                  # refused before anything starts when PortAudio is missing
    service = VoiceService(bus, robot, speaker, confirm=args.confirm, answer_seconds=args.answer_seconds,
                           refresh=args.refresh, source_timeout=args.source_timeout)
    if args.local_mic:
        device = int(args.mic_device) if args.mic_device and args.mic_device.isdigit() else args.mic_device
        try:
            service.mic = LocalMic(service.streams.put, device)
        except ValueError:
            service.close()
            raise
    return service
