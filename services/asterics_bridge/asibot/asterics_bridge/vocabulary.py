"""The one command vocabulary of the three entries (NetConnection, text lines, HTTP).

`parse(text)` turns what a user sent into a `Command` (a canonical word and its argument), or
raises `NotUnderstood` with a sentence that proposes the nearest word ("unknown command
'forwrd'; did you mean 'forward'?"). Words are case-insensitive and spaces are folded; the
arguments of `goto`, `run`, `robot` and `token` keep their case. `WORDS` is the table that
docs/asterics.md prints: word, what it drives, what it does; the dispatcher's table of handlers
must match it word for word (`check_handlers`).
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import Collection

from asibot import driving

MAX_COMMAND_CHARS = 200

BASE, ARM, BOTH, BRIDGE, TASKS = "base", "arm", "base or arm", "bridge", "tasks"


@dataclass(frozen=True)
class Word:
    word: str
    drives: str
    does: str
    arg: str = ""            # the argument's name, for words that take one


#: Base words that are nav primitives: word -> (nav primitive name, continuous).
PRIMITIVES: dict[str, tuple[str, bool]] = {
    "forward": ("forward", True),
    "backward": ("backward", True),
    "turn left": ("turn left", True),
    "turn right": ("turn right", True),
    "curve left": ("curve forward left", True),
    "curve right": ("curve forward right", True),
    "curve back left": ("curve backward left", True),
    "curve back right": ("curve backward right", True),
    "turn around": ("turn around", False),
    "turn left 90": ("turn left 90", False),
    "turn right 90": ("turn right 90", False),
}
_NOT_NAV = sorted(name for name, _ in PRIMITIVES.values() if name not in driving.PRIMITIVES)
if _NOT_NAV:   # the bridge says only what nav can do
    raise RuntimeError(f"the bridge's base words name primitives nav does not have: {_NOT_NAV}")

#: Arm step words -> unit direction in the arm's base frame (x ahead, y left, z up).
ARM_STEPS: dict[str, tuple[int, int, int]] = {
    "arm forward": (1, 0, 0), "arm backward": (-1, 0, 0),
    "arm left": (0, 1, 0), "arm right": (0, -1, 0),
    "arm up": (0, 0, 1), "arm down": (0, 0, -1),
}

WORDS: tuple[Word, ...] = (
    Word("forward", BASE, "drive forward until stop, an obstacle or the longest time"),
    Word("backward", BASE, "drive backward until stop, an obstacle or the longest time"),
    Word("turn left", BASE, "turn left in place until stop (or the longest time)"),
    Word("turn right", BASE, "turn right in place until stop (or the longest time)"),
    Word("curve left", BASE, "drive forward on a left curve until stop (nav: curve forward left)"),
    Word("curve right", BASE, "drive forward on a right curve until stop (nav: curve forward right)"),
    Word("curve back left", BASE, "back up on a left curve until stop (nav: curve backward left)"),
    Word("curve back right", BASE, "back up on a right curve until stop (nav: curve backward right)"),
    Word("turn around", BASE, "turn 180 degrees in place"),
    Word("turn left 90", BASE, "turn 90 degrees left in place"),
    Word("turn right 90", BASE, "turn 90 degrees right in place"),
    Word("stop", BOTH, "stop the base (goal or drive), the arm, and a task started from here"),
    Word("faster", BASE, "one speed level up (1-5)"),
    Word("slower", BASE, "one speed level down"),
    Word("wider", BOTH, "after a base word: longer steps and wider curves; after an arm word: a longer arm step"),
    Word("narrower", BOTH, "the opposite of wider"),
    Word("goto", BASE, "drive to a named place", "place"),
    Word("save position", BASE, "remember where the base stands"),
    Word("recall position", BASE, "drive back to the remembered position"),
    Word("arm forward", ARM, "move the tip one step ahead (+x)"),
    Word("arm backward", ARM, "move the tip one step back (-x)"),
    Word("arm left", ARM, "move the tip one step left (+y)"),
    Word("arm right", ARM, "move the tip one step right (-y)"),
    Word("arm up", ARM, "move the tip one step up (+z)"),
    Word("arm down", ARM, "move the tip one step down (-z)"),
    Word("grab", ARM, "close the gripper"),
    Word("release", ARM, "open the gripper"),
    Word("arm save", ARM, "remember where the tip is (per robot)"),
    Word("arm recall", ARM, "move the tip back to the remembered point in a straight line"),
    Word("arm home", ARM, "move the arm to its home position"),
    Word("arm stop", ARM, "stop the arm"),
    Word("run", TASKS, "launch a task of the Task Creator on this robot", "task"),
    Word("robot", BRIDGE, "choose the robot this connection drives", "id"),
    Word("token", BRIDGE, "give the access token (a bridge serving the network asks for it first)", "secret"),
    Word("next", BRIDGE, "scanning menu: announce the next command"),
    Word("previous", BRIDGE, "scanning menu: announce the previous command"),
    Word("select", BRIDGE, "scanning menu: run the announced command"),
    Word("status", BRIDGE, "say what the robot does and where it is"),
    Word("places", BASE, "list the named places"),
    Word("tasks", TASKS, "list the tasks"),
    Word("help", BRIDGE, "list the words"),
)

_FIXED = {w.word for w in WORDS if not w.arg}
_WITH_ARG = {w.word for w in WORDS if w.arg}
#: Other spellings people type: alias -> canonical word.
ALIASES = {"go to": "goto", "backwards": "backward", "back": "backward", "open": "release",
           "close": "grab", "turn back": "turn around", "halt": "stop"}


@dataclass(frozen=True)
class Command:
    word: str
    arg: str = ""

    def __str__(self) -> str:
        return f"{self.word} {self.arg}" if self.arg else self.word


class NotUnderstood(ValueError):
    """A command that is not in the vocabulary; the message proposes the nearest word."""


def parse(text: object) -> Command:
    if not isinstance(text, str):
        raise NotUnderstood(f"A command is text such as 'forward', not {type(text).__name__}.")
    raw = " ".join(text.split())
    if not raw:
        raise NotUnderstood("The command is empty; send a word such as 'forward' or 'help'.")
    if len(raw) > MAX_COMMAND_CHARS:
        raise NotUnderstood(f"A command is at most {MAX_COMMAND_CHARS} characters; this one has {len(raw)}.")
    if not raw.isprintable():
        raise NotUnderstood("The command contains control characters; send plain words such as 'forward'.")
    low = raw.lower()
    for alias, word in ALIASES.items():
        if low == alias or low.startswith(alias + " "):
            low, raw = word + low[len(alias):], word + raw[len(alias):]
            break
    if low in _FIXED:
        return Command(low)
    head, _, rest = raw.partition(" ")
    if head.lower() in _WITH_ARG:
        if not rest:
            arg = next(w.arg for w in WORDS if w.word == head.lower())
            raise NotUnderstood(f"'{head.lower()}' needs a {arg}: '{head.lower()} <{arg}>'.")
        return Command(head.lower(), rest)
    raise NotUnderstood(_unknown(raw, low))


def is_stop(text: str) -> bool:
    """Whether `text` is a stop (any spelling): the entries obey it first, and without a token."""
    try:
        return parse(text).word == "stop"
    except NotUnderstood:
        return False


def _unknown(raw: str, low: str) -> str:
    shown = raw if len(raw) <= 40 else raw[:40] + "..."
    close = difflib.get_close_matches(low, sorted(_FIXED | set(ALIASES)), n=1, cutoff=0.6)
    if close:
        return f"unknown command '{shown}'; did you mean '{ALIASES.get(close[0], close[0])}'?"
    head, _, rest = low.partition(" ")
    close = difflib.get_close_matches(head, sorted(_WITH_ARG), n=1, cutoff=0.6)
    if close and rest:
        return f"unknown command '{shown}'; did you mean '{close[0]} {raw.partition(' ')[2]}'?"
    return f"unknown command '{shown}'; say 'help' for the list of words."


def suggest(name: str, names: list[str]) -> str:
    """' did you mean ...?' for a name among `names` (places, tasks, robots), or ''."""
    close = difflib.get_close_matches(name.lower(), [n.lower() for n in names], n=1, cutoff=0.5)
    if not close:
        return ""
    return f"; did you mean '{next(n for n in names if n.lower() == close[0])}'?"


def find(name: str, names: list[str]) -> str | None:
    """`name` as spelled in `names`, ignoring case; None when absent."""
    return next((n for n in names if n.lower() == name.lower()), None)


def check_handlers(handlers: Collection[str]) -> None:
    """ValueError unless every word of WORDS has a handler and every handler a word: the
    dispatcher checks its table with it when it is built, so a word added here without a
    handler (or a handler left after its word went) stops the bridge at start, not a user."""
    words = {w.word for w in WORDS}
    missing, extra = sorted(words - set(handlers)), sorted(set(handlers) - words)
    if missing or extra:
        raise ValueError(f"words without a handler: {missing or 'none'}; handlers without a word: {extra or 'none'}")


def help_text() -> str:
    return "words: " + ", ".join(w.word + (f" <{w.arg}>" if w.arg else "") for w in WORDS)
