"""How a program's Python error reaches the page: one sentence with the user's line, and the
traceback behind it without the machine's paths.

A run that ends in an exception leaves its traceback as the last lines of its stderr. The page
shows one sentence, `Line 7: The straight line passes a singularity ...; use movj for this move
or pick an intermediate point.` (an asibot error's message is already a sentence for people, so
its class is left out; Python's own errors keep theirs: `Line 3: NameError: name 'x' is not
defined.`), and under "Details" the traceback: the user's files by their name in the program's
folder, a library by its module (`asibot.client`) where the user's call entered it and no deeper,
and never a path of the machine. Output lines get the same names (`Files.line`).
"""

from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from asibot.web import reference

HEADER = "Traceback (most recent call last):"
#: What Python writes between the tracebacks of a chain of exceptions.
CHAINED = ("During handling of the above exception, another exception occurred:",
           "The above exception was the direct cause of the following exception:")
_FRAME = re.compile(r'^(?P<indent>\s*)File "(?P<file>.+)", line (?P<line>\d+)(?P<rest>.*)$')
_NO_ATTRIBUTE = re.compile(r"^AttributeError: '(?P<cls>\w+)' object has no attribute '(?P<name>\w+)'")
#: Where a frame's file is: the program itself, another file of its folder, an importable module
#: (its dotted name) or somewhere else.
OWN, USER, MODULE, OTHER = "own", "user", "module", "other"


@dataclass(frozen=True)
class PythonError:
    """The exception a run ended with."""

    line: int | None
    """The user's line: in the deepest frame of the program's own file (None: none is)."""
    message: str
    """Its words: an asibot error's sentence, or Python's `NameError: name 'x' is not defined`."""
    details: list[str]
    """The traceback as the page shows it (`Files`)."""
    taken: int
    """How many of the last stderr lines are that traceback (the page shows them as details)."""

    @property
    def sentence(self) -> str:
        """`Line 7: <message>.`, with one full stop."""
        text = full_stop(self.message)
        return text if self.line is None else f"Line {self.line}: {text}"

    @property
    def reason(self) -> str:
        """The runner's words for how the run ended (`<program>: <reason>.`: no stop of its own)."""
        where = "" if self.line is None else f" on line {self.line}"
        return f"failed with an error{where}: {without_stop(self.message)}"


class Files:
    """Names the files of a traceback as the page shows them, never by the machine's paths."""

    def __init__(self, program: Path | str, roots: Iterable[str] | None = None) -> None:
        self.given = os.path.abspath(program)
        self.program = os.path.realpath(program)
        self.folders = sorted({os.path.dirname(self.given), os.path.dirname(self.program)}, key=len, reverse=True)
        # The module search path: the longest root that holds a file names its module.
        self.roots = sorted({os.path.realpath(r) for r in (sys.path if roots is None else roots)
                             if r and os.path.isabs(r)}, key=len, reverse=True)

    def where(self, file: str) -> tuple[str, str]:
        """(OWN, USER, MODULE or OTHER, the name shown): `prog.py`, `helper.py`, `asibot.client`."""
        if file.startswith("<"):           # <frozen runpy>, <string>
            return OTHER, file
        real = os.path.realpath(file)
        if real == self.program:
            return OWN, os.path.basename(self.given)
        folder = os.path.dirname(self.program)
        if real.startswith(folder + os.sep):
            return USER, os.path.relpath(real, folder)
        module = self.module(real)
        return (MODULE, module) if module else (OTHER, os.path.basename(real))

    def module(self, real: str) -> str | None:
        for root in self.roots:
            if real.startswith(root + os.sep):
                stem, ext = os.path.splitext(real[len(root) + 1:])
                parts = stem.split(os.sep)
                if parts[-1] == "__init__":
                    parts.pop()
                if ext == ".py" and parts and all(p.isidentifier() for p in parts):
                    return ".".join(parts)
        return None

    def line(self, line: str) -> str:
        """One stderr line for the page: a frame names its file as `where` does; the program's
        folder is left out of any path."""
        m = _FRAME.match(line)
        if m:
            return f'{m["indent"]}File "{self.where(m["file"])[1]}", line {m["line"]}{m["rest"]}'
        return self.hide(line)

    def hide(self, text: str) -> str:
        for folder in self.folders:
            text = text.replace(folder + os.sep, "")
        return text


def read_error(lines: list[str], files: Files) -> PythonError | None:
    """The exception at the end of a run's stderr `lines`, or None when they end otherwise.

    Its line is the user's own in the deepest frame that is theirs: an error inside a library
    points at the user's line that called it. A syntax error of the program itself has no
    "Traceback" header, only its `File "...", line N` frame.
    """
    starts = [i for i, line in enumerate(lines) if line.startswith(HEADER)]
    if starts:
        last = first = starts[-1]
        while True:     # the whole chain of exceptions goes to the details
            before = first - 1
            while before >= 0 and not lines[before].strip():
                before -= 1
            earlier = [s for s in starts if s < before]
            if before < 0 or lines[before] not in CHAINED or not earlier:
                break
            first = earlier[-1]
    else:
        own = [i for i, line in enumerate(lines) if (m := _FRAME.match(line)) and files.where(m["file"])[0] == OWN]
        if not own:
            return None
        last = first = own[0]
    line_no = None
    for line in lines[last:]:
        m = _FRAME.match(line)
        if m and files.where(m["file"])[0] == OWN:
            line_no = int(m["line"])
    messages = [line for line in lines[last:] if line.strip() and not line[0].isspace() and not line.startswith(HEADER)]
    if not messages:
        return None
    return PythonError(line_no, _message(messages[-1].strip(), files), details(lines[first:], files), len(lines) - first)


def details(lines: list[str], files: Files) -> list[str]:
    """The traceback for people: the frames of the user's files with their source lines, the
    frame where a call of theirs entered a library by its module name, and nothing deeper."""
    shown: list[str] = []
    caller = False      # the frame before is the user's
    source = False      # the lines under this frame (its source, its ^^^ marks) are shown
    for line in lines:
        m = _FRAME.match(line)
        if m:
            kind, name = files.where(m["file"])
            if kind in (OWN, USER) or (caller and kind == MODULE):
                shown.append(f'{m["indent"]}File "{name}", line {m["line"]}{m["rest"]}')
            caller = source = kind in (OWN, USER)
        elif line[:1].isspace():
            if source:
                shown.append(line)
        else:           # the header, the exception, the words between chained ones, a blank line
            shown.append(files.hide(line))
            caller = source = False
    return shown


def full_stop(text: str) -> str:
    text = text.rstrip()
    return text if text.endswith((".", "!", "?")) else f"{text}."


def without_stop(text: str) -> str:
    """The text as a clause: its own final full stop left out (another sentence goes on from it)."""
    text = text.rstrip()
    return text[:-1] if text.endswith(".") and not text.endswith("..") else text


def _message(text: str, files: Files) -> str:
    kind, colon, words = text.partition(": ")
    if colon and kind.startswith("asibot.") and all(p.isidentifier() for p in kind.split(".")):
        text = words            # asibot.errors.RpcError: <a sentence for people>
    m = _NO_ATTRIBUTE.match(text)
    clients = {cls.__name__ for cls in reference.CLIENTS}
    if m and m["cls"] in clients:
        python = re.search(r"Did you mean: '(\w+)'\?", text)
        guesses = reference.guess(m["cls"], m["name"]) or ([python[1]] if python else [])
        guess = f" Did you mean {' or '.join(guesses)}?" if guesses else ""
        text = (f"{m['cls']} has no method {m['name']} (AttributeError).{guess} "
                "The Python reference on the Program tab lists its methods.")
    return files.hide(text)
