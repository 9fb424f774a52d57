"""What a heard word does: launch its task, stop everything, answer a question.

Plain logic, no bus: `Commands` is given a `Robots` (what it asks of the world: launch a task
by name, stop everything) and a speaker (anything with `say(text)`), and returns an `Outcome`
for every utterance, for the Speech tab. The voice service (`asibot.voice.service`) gives it
the bus; the tests give it doubles.

- The words come from the Task Creator's tasks (`set_tasks`): each word of a task stands for
  that task; a word of two tasks launches the first.
- `stop` (also "stop stop stop") stops at once, whatever else is going on: the pending
  question is dropped, and a command heard before the stop but not yet done is not done
  (`ticket`: the caller takes one when the utterance ends, and a stop makes older tickets
  void), so "give me the red can ... stop" never launches the task after the stop; a launch
  under way when the stop is heard is stopped again once it returns.
- With `confirm`, a task word asks "Shall I start <task>? Say yes or no." and waits up to
  `answer_seconds` for yes (launch) or no (cancel); silence cancels (`expire`, called
  periodically). Another task word replaces the question. Without `confirm`, it launches.
- yes or no with no question pending, and speech outside the grammar, do nothing: nothing
  is said either (a cough or the television must not make the robot talk).
- Spoken feedback: started, refused and the Task Creator's reason, stopped, and how a task
  ended (`on_event`, from the robot's events). A speaker that fails (no espeak-ng, no sound
  card) is logged once, never raised: feedback must not break a command.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Protocol

from asibot.errors import RpcError
from asibot.messages import Event
from asibot.voice.recognizer import Heard

log = logging.getLogger("asibot.voice")

STOP, YES, NO = "stop", "yes", "no"
#: The robot's events that are spoken (the Task Creator tells how a task ended).
SPOKEN_EVENTS = ("task_done", "task_failed")
#: Longest sentence handed to the speaker (an RPC sentence is at most 400 characters).
MAX_SAY = 300


@dataclass(frozen=True)
class Outcome:
    """What was done about one utterance (`VoiceHeard.action` and its fields)."""

    action: str
    """launch, refused, ask, cancel, stop or nothing."""
    task: str = ""
    reason: str = ""
    said: str = ""


@dataclass(frozen=True)
class Stopped:
    """What `Robots.stop` did: the robots stopped, and sentences for what could not be done."""

    robots: tuple[str, ...] = ()
    problems: tuple[str, ...] = ()


class Robots(Protocol):
    """What a heard word asks of the world (the service implements it on the bus)."""

    def launch(self, task: str) -> None:
        """Start task `task`; raise RpcError with the sentence when it is refused."""

    def stop(self) -> Stopped:
        """Stop every robot and the running task, at once."""


class Transcript:
    """A speaker that says nothing aloud: it keeps and logs the sentences (`--quiet`, tests)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._said: list[str] = []

    def say(self, text: str) -> None:
        log.info("voice says: %s", text)
        with self._lock:
            self._said.append(text)

    @property
    def said(self) -> list[str]:
        with self._lock:
            return list(self._said)


def task_words(tasks: Any) -> tuple[list[str], dict[str, str]]:
    """The words of the tasks in `keys.tasks_rpc("list")`'s reply, in order, and the task each
    stands for (the first task that has it). Malformed entries are skipped and logged."""
    words: list[str] = []
    owner: dict[str, str] = {}
    for task in tasks if isinstance(tasks, list) else []:
        name = task.get("name") if isinstance(task, dict) else None
        these = task.get("words") if isinstance(task, dict) else None
        if not isinstance(name, str) or not name or not isinstance(these, list):
            log.warning("voice: a task in the Task Creator's list is not {name, words}: %.80r", task)
            continue
        for word in these:
            if isinstance(word, str) and word.strip() and word not in owner:
                owner[word] = name
                words.append(word)
    return words, owner


class Commands:
    """Heard words to actions on `robots`, with spoken feedback through `speaker`. Thread-safe:
    `hear` may be called from several threads (a stop is not queued behind a slow launch)."""

    def __init__(self, robots: Robots, speaker: Any, *, confirm: bool = False, answer_seconds: float = 8.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.robots, self.speaker = robots, speaker
        self.confirm, self.answer_seconds, self.clock = confirm, answer_seconds, clock
        self._lock = threading.Lock()
        self._owner: dict[str, str] = {}
        self._generation = 0
        self._pending: tuple[str, float] | None = None       # (task, deadline) of the question asked
        self._speaker_failed = False
        self.counters = {"heard": 0, "nothing": 0, "launched": 0, "refused": 0, "asked": 0, "cancelled": 0,
                         "stops": 0}

    # --- the words -------------------------------------------------------------------------
    def set_tasks(self, tasks: Any) -> list[str]:
        """Take the Task Creator's tasks; returns their words, for the grammar."""
        words, owner = task_words(tasks)
        with self._lock:
            self._owner = owner
        return words

    def task_of(self, word: str) -> str | None:
        with self._lock:
            return self._owner.get(word)

    @property
    def pending(self) -> str:
        """The task a question waits about, or ''."""
        with self._lock:
            return self._pending[0] if self._pending else ""

    def ticket(self) -> int:
        """Taken when an utterance ends; a stop after it voids it (see `hear`)."""
        with self._lock:
            return self._generation

    # --- what a word does ------------------------------------------------------------------
    def hear(self, heard: Heard | None, reason: str = "", ticket: int | None = None) -> Outcome:
        """Do what `heard` asks (None: nothing of the grammar, `reason` says why)."""
        with self._lock:
            self.counters["heard"] += 1
        if heard is None:
            return self._count(Outcome("nothing", reason=reason or "Nothing of the grammar was heard."))
        if heard.word == STOP:
            return self.stop()
        with self._lock:
            outcome, say, task = self._decide(heard.word, ticket)
            generation = self._generation
        if task:
            return self._launch(task, generation)
        return self._count(dataclasses.replace(outcome, said=self._say(say) if say else ""))

    def _decide(self, word: str, ticket: int | None) -> tuple[Outcome, str, str]:
        """(outcome, sentence to say, task to launch) for a word other than stop; under the lock."""
        if ticket is not None and ticket < self._generation:
            return Outcome("cancel", reason="A stop came after it, so it was not done."), "", ""
        if word in (YES, NO):
            pending, self._pending = self._pending, None
            if pending is None or pending[1] < self.clock():
                return Outcome("nothing", reason="There was no question to answer."), "", ""
            if word == NO:
                return Outcome("cancel", pending[0]), "Cancelled.", ""
            return Outcome("launch"), "", pending[0]
        task = self._owner.get(word)
        if task is None:
            return Outcome("nothing", reason=f"{word!r} is no longer a task's word."), "", ""
        if not self.confirm:
            return Outcome("launch"), "", task
        self._pending = (task, self.clock() + self.answer_seconds)
        return Outcome("ask", task), f"Shall I start {task}? Say yes or no.", ""

    def stop(self) -> Outcome:
        """Stop every robot and the task now; older tickets are void and the question dropped."""
        with self._lock:
            self._generation += 1
            self._pending = None
        done = self.robots.stop()
        if done.robots:
            said = "Stopped. Release the emergency stop on the screen to go on."
        else:
            said = "Stopped the task; no robot is connected."
        if done.problems:
            said += " " + " ".join(done.problems)
        return self._count(Outcome("stop", reason=" ".join(done.problems), said=self._say(said)))

    def expire(self) -> Outcome | None:
        """Cancel the question if its time is up (call this periodically); the Outcome if so."""
        with self._lock:
            if self._pending is None or self._pending[1] > self.clock():
                return None
            task, self._pending = self._pending[0], None
        return self._count(Outcome("cancel", task, reason=f"No answer within {self.answer_seconds:g} s.",
                                   said=self._say(f"Cancelled: I heard no yes or no about {task}.")))

    def on_event(self, event: Event) -> str:
        """A robot's event: say how a task ended. Returns what was said ('' for nothing)."""
        if event.code in SPOKEN_EVENTS and event.text.strip():
            return self._say(event.text.strip().rstrip(".") + ".")
        return ""

    # --- helpers ---------------------------------------------------------------------------
    def _launch(self, task: str, generation: int) -> Outcome:
        try:
            self.robots.launch(task)
        except RpcError as exc:
            return self._count(Outcome("refused", task, reason=exc.message,
                                       said=self._say(f"I cannot start {task}. {exc.message}")))
        if self.ticket() != generation:     # "stop" was heard while it started: stop it too
            self.robots.stop()
            return self._count(Outcome("cancel", task, reason="A stop came while it started; it was stopped."))
        return self._count(Outcome("launch", task, said=self._say(f"Starting {task}.")))

    def _count(self, outcome: Outcome) -> Outcome:
        name = {"launch": "launched", "ask": "asked", "cancel": "cancelled", "stop": "stops"}.get(
            outcome.action, outcome.action)
        with self._lock:
            self.counters[name] += 1
        return outcome

    def _say(self, text: str) -> str:
        text = text if len(text) <= MAX_SAY else text[:MAX_SAY - 3] + "..."
        try:
            self.speaker.say(text)
        except Exception as exc:       # no espeak-ng, a broken player: feedback never breaks a command
            if not self._speaker_failed:
                log.warning("voice: cannot speak (%s); going on without spoken feedback", exc)
            self._speaker_failed = True
        return text
