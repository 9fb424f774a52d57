"""The user's files for the web Task Creator: points, programs, words, tasks and icons.

Everything lives in one data folder laid out like the seed's own user folder, so an existing
ASIBOT user's folder works as it is:

    points.ini          one point a line: <name> <x> <y> <z> <rot(y')> <rot(z'')> (m, deg)
    words.ini           one word or phrase a line
    <program>.py        the user's programs
    <task>.task         3 lines: program (no .py), words (several joined by ";"), icon file name
    icons/              uploaded icons (PNG, JPEG, GIF, WebP)
    .versions/<prog>/   previous versions of each program, so a bad save can be undone
    .trash/             deleted programs and tasks

Plain Python, no web framework and no bus: the web layer maps `UserDataError` to 400,
`NotFound` to 404 and `AlreadyExists` to 409. Every write is atomic (temp file, fsync,
os.replace, fsync of the folder), so a crash mid-save leaves the old file whole; bad input
is refused with a sentence before anything is written.
"""

from __future__ import annotations

import contextlib
import functools
import io
import logging
import math
import os
import re
import stat
import threading
import time
import warnings
import zipfile
import zlib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Callable, Concatenate, ParamSpec, TypeVar

from asibot.files import data_dir, fsync_dir, remove_leftovers, write_atomic
from asibot.web import naming

log = logging.getLogger(__name__)

#: The icons that ship with the project (SVG, drawn by us, so safe to serve as images).
SHIPPED_ICONS = Path(str(resources.files("asibot.web") / "static" / "icons"))
#: The seed's launcher images (served from its figure host) and the shipped icon each became.
SEED_ICONS = {"drinkwater.jpg": "drink.svg", "pickcan.jpg": "can.svg", "washface.jpg": "face.svg",
              "brushteeth.jpg": "teeth.svg", "home.png": "home.svg"}

MAX_NAME = 64
MAX_WORD = 80
MAX_PROGRAM_BYTES = 256 * 1024
MAX_ICON_BYTES = 2 * 1024 * 1024
#: Beyond these, a points.ini or words.ini is not a hand-made list any more.
MAX_LIST_BYTES = 1024 * 1024
MAX_TASK_BYTES = 4096
VERSIONS_KEPT = 20
#: How much the folder keeps: programs, uploaded icons, and their bytes together (versions and
#: the trash are bounded by VERSIONS_KEPT and by what was once within these).
MAX_PROGRAMS = 200
MAX_ICONS = 100
MAX_STORED_BYTES = 32 * 1024 * 1024
#: Limits on an imported zip: a zip bomb is refused before it fills the disk or the memory.
MAX_ZIP_ENTRIES = 2000
MAX_ZIP_TOTAL = 64 * 1024 * 1024

_PROGRAM_RE = re.compile(r"[A-Za-z][A-Za-z0-9_-]*")
_POINT_RE = re.compile(r"[A-Za-z][A-Za-z0-9_.-]*")
_ICON_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]*\.(svg|png|jpg|gif|webp)")
_CONTROL_RE = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]")
_IMAGE_EXTENSIONS = {".png", ".jpg", ".jpeg", ".gif", ".webp", ".svg"}
_COMPILE_LOCK = threading.Lock()


class UserDataError(ValueError):
    """Bad input from the user (HTTP 400): the message is a sentence to show them."""


class NotFound(UserDataError):
    """The named point, program, version, task or icon does not exist (HTTP 404)."""


class AlreadyExists(UserDataError):
    """The name is taken (HTTP 409)."""


@dataclass
class Point:
    """A taught Cartesian point: [x, y, z, rot(y'), rot(z'')] in m and deg, base frame."""

    name: str
    values: list[float]


@dataclass
class Version:
    """A previous version of a program; `saved` is when it was replaced (Unix seconds)."""

    id: str
    saved: float
    size: int


@dataclass
class Problem:
    """Why a program does not compile, where (1-based line and column)."""

    line: int
    column: int
    message: str


@dataclass
class Task:
    """What the Launcher shows as one button: run `program`, also on any of `words`."""

    name: str
    program: str
    words: list[str]
    icon: str


@dataclass
class Icon:
    """An icon file name; shipped ones come with the project, the others were uploaded."""

    name: str
    shipped: bool


@dataclass
class Skipped:
    """One thing an import left out, and why."""

    item: str
    reason: str


@dataclass
class ImportReport:
    """What an import of a seed folder did: imported items, skipped ones, and notes."""

    imported: list[str] = field(default_factory=list)
    skipped: list[Skipped] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------------------- names

def _quote(value: object) -> str:
    """The value as the user typed it, short and with control characters visible."""
    if not isinstance(value, str):
        return f"a {type(value).__name__}"
    return repr(value[:40]) + ("..." if len(value) > 40 else "")


def _need_str(kind: str, value: object) -> str:
    if not isinstance(value, str):
        raise UserDataError(f"The {kind} must be text; got {_quote(value)}.")
    if not value:
        raise UserDataError(f"The {kind} is empty; please give one.")
    if len(value) > MAX_NAME:
        raise UserDataError(f"The {kind} {_quote(value)} is longer than {MAX_NAME} characters.")
    return value


def _plain_name(kind: str, pattern: re.Pattern, allowed: str, name: object) -> str:
    name = _need_str(kind, name)
    if not pattern.fullmatch(name):
        raise UserDataError(f"The {kind} {_quote(name)} may hold only {allowed}, and must start with a letter.")
    return name


def check_program_name(name: object) -> str:
    """A program name is also a file name and a Python module name: keep it plain."""
    return _plain_name("program name", _PROGRAM_RE, "letters, digits, _ and -", name)


def check_point_name(name: object) -> str:
    """A point name is one token of points.ini (split on spaces), so no spaces."""
    return _plain_name("point name", _POINT_RE, "letters, digits, _, - and .", name)


def check_task_name(name: object) -> str:
    """Task names are what people read on the Launcher, so spaces are fine; the file name
    `<name>.task` must stay inside the folder and visible."""
    if isinstance(name, str):
        name = name.strip()
    name = _need_str("task name", name)
    if "/" in name or "\\" in name or ".." in name or name.startswith(".") or _CONTROL_RE.search(name):
        raise UserDataError(f"The task name {_quote(name)} may not hold /, \\, .., control characters "
                            "or start with a dot.")
    return name


def check_icon_name(name: object) -> str:
    """An icon is a plain file name in one folder; anything else is refused."""
    name = _need_str("icon name", name)
    if not _ICON_RE.fullmatch(name):
        raise UserDataError(f"The icon name {_quote(name)} is not an icon file name (like drink.svg).")
    return name


def check_word(text: object) -> str:
    """A word or phrase is one line of words.ini; ';' joins several in a .task file."""
    if not isinstance(text, str):
        raise UserDataError(f"The word must be text; got {_quote(text)}.")
    text = text.strip()  # spaces around a spoken phrase mean nothing
    if not text:
        raise UserDataError("The word is empty; please type a word or a phrase.")
    if len(text) > MAX_WORD:
        raise UserDataError(f"The word {_quote(text)} is longer than {MAX_WORD} characters.")
    if _CONTROL_RE.search(text) or ";" in text:
        raise UserDataError(f"The word {_quote(text)} must be one line without ';'.")
    return text


def check_values(values: object) -> list[float]:
    """A point is exactly 5 finite numbers; anything else would break a move later."""
    if not isinstance(values, (list, tuple)) or len(values) != 5:
        got = f"{len(values)} values" if isinstance(values, (list, tuple)) else _quote(values)
        raise UserDataError(f"A point needs 5 values (x y z in m, rot(y') rot(z'') in deg); got {got}.")
    out = []
    for label, v in zip(("x", "y", "z", "rot(y')", "rot(z'')"), values):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise UserDataError(f"The point's {label} must be a finite number; got {repr(v)[:40]}.")
        out.append(float(v))
    return out


def check_program_text(text: object) -> str:
    """Program text: a str under the size limit, no NUL (it would not be a text file)."""
    if not isinstance(text, str):
        raise UserDataError(f"The program text must be text; got {_quote(text)}.")
    try:
        size = len(text.encode("utf-8"))
    except UnicodeEncodeError:
        raise UserDataError("The program text holds characters that cannot be saved as UTF-8.") from None
    if size > MAX_PROGRAM_BYTES:
        raise UserDataError(f"The program is {size // 1024} KiB; the limit is {MAX_PROGRAM_BYTES // 1024} KiB.")
    if "\x00" in text:
        raise UserDataError("The program text holds a NUL character; it would not be a text file.")
    return text


def check_program(text: str) -> list[Problem]:
    """Syntax errors (and compiler warnings) of a program, with line and column; [] if fine.

    compile() only parses and compiles, it never runs the code, so it is safe in-process;
    the seed ran `python -m py_compile` through a shell instead."""
    text = check_program_text(text)
    with _COMPILE_LOCK, warnings.catch_warnings(record=True) as caught:  # the filters are global
        warnings.simplefilter("always")
        try:
            compile(text, "<program>", "exec", dont_inherit=True)
        except SyntaxError as e:
            return [Problem(e.lineno or 1, e.offset or 1, e.msg)]
        except (ValueError, RecursionError, MemoryError) as e:  # too deep or too big to compile
            return [Problem(1, 1, f"The program cannot be compiled: {e or type(e).__name__}.")]
    return [Problem(w.lineno or 1, 1, f"Warning: {w.message}") for w in caught]


#: Where the user's files live: $ASIBOT_DATA, else the XDG data folder (asibot.files).
default_root = data_dir


def _decode(data: bytes) -> tuple[str, bool]:
    """Text of a user file; the seed's files may be Latin-1 (Spanish comments), then True."""
    try:
        return data.decode("utf-8-sig"), False
    except UnicodeDecodeError:
        return data.decode("cp1252", errors="replace"), True


def _image_kind(data: bytes) -> str | None:
    """The file extension an image really has, from its magic bytes; None if not one we take."""
    if data.startswith(b"\x89PNG\r\n\x1a\n"):
        return ".png"
    if data.startswith(b"\xff\xd8\xff"):
        return ".jpg"
    if data.startswith((b"GIF87a", b"GIF89a")):
        return ".gif"
    if len(data) >= 12 and data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return ".webp"
    return None


def _parse_point(line: str) -> Point:
    parts = line.split()
    if len(parts) != 6:
        raise UserDataError(f"A points.ini line needs a name and 5 numbers; got {len(parts)} fields.")
    try:
        values = [float(p) for p in parts[1:]]
    except ValueError:
        raise UserDataError(f"The point {_quote(parts[0])} has a value that is not a number.") from None
    return Point(check_point_name(parts[0]), check_values(values))


def _parse_task(name: str, text: str) -> Task:
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if len(lines) != 3:
        raise UserDataError(f"The task file {_quote(name + '.task')} must have 3 lines "
                            f"(program, words, icon); it has {len(lines)}.")
    program = lines[0].strip().removesuffix(".py")
    words = [w.strip() for w in lines[1].split(";") if w.strip()]
    return Task(name, program, words, lines[2].strip())


def _task_text(program: str, words: list[str], icon: str) -> bytes:
    return f"{program}\n{';'.join(words)}\n{icon}\n".encode()


P = ParamSpec("P")
R = TypeVar("R")
D = TypeVar("D", bound="UserData")


def _locked(method: Callable[Concatenate[D, P], R]) -> Callable[Concatenate[D, P], R]:
    """One lock for the whole folder: the web server calls from several threads."""
    @functools.wraps(method)
    def wrapper(self: D, *args: P.args, **kwargs: P.kwargs) -> R:
        with self._lock:
            return method(self, *args, **kwargs)
    return wrapper


class UserData:
    """The user's data folder; every method validates its input and writes atomically."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True, mode=0o700)
        self.icons_dir = self.root / "icons"
        self.versions_dir = self.root / ".versions"
        self.trash_dir = self.root / ".trash"
        self._lock = threading.RLock()  # re-entrant: save_task adds words, import saves programs
        for path in remove_leftovers(self.root):
            log.info("removed %s, left by a save that was cut short", path)

    # ------------------------------------------------------------------------------ points

    @_locked
    def points(self) -> list[Point]:
        """The taught points in file order; a hand-broken line is left out (and logged)."""
        found: dict[str, Point] = {}
        for number, line in enumerate(self._read_lines("points.ini"), 1):
            try:
                p = _parse_point(line)
            except UserDataError as e:
                log.warning("points.ini line %d left out: %s", number, e)
                continue
            found.pop(p.name, None)  # the seed appended: a later line with the same name wins
            found[p.name] = p
        return list(found.values())

    @_locked
    def point(self, name: str) -> Point:
        """One point by name."""
        name = check_point_name(name)
        for p in self.points():
            if p.name == name:
                return p
        raise NotFound(f"There is no point named {_quote(name)}.")

    @_locked
    def add_point(self, name: str, values: list[float], replace: bool = False) -> Point:
        """Store a point (a capture); refuse a taken name unless `replace`."""
        name = check_point_name(name)
        values = check_values(values)
        points = self.points()
        if any(p.name == name for p in points):
            if not replace:
                raise AlreadyExists(f"A point named {_quote(name)} already exists.")
            points = [p for p in points if p.name != name]
        points.append(Point(name, values))
        self._write_points(points)
        return points[-1]

    @_locked
    def suggest_point_name(self, here: list[float] | None = None, place: str = "") -> str:
        """What a capture at `here` (the base at nav's `place`) proposes before the user edits
        it: `naming.suggest` ("fridge-1", "above-can", "point-3")."""
        points = self.points()
        return naming.suggest((p.name for p in points), ((p.name, p.values) for p in points), here, place)

    @_locked
    def rename_point(self, old: str, new: str) -> Point:
        """Rename a point in place (programs hold its values, not its name)."""
        old, new = check_point_name(old), check_point_name(new)
        points = self.points()
        target = self.point(old)
        if old != new and any(p.name == new for p in points):
            raise AlreadyExists(f"A point named {_quote(new)} already exists.")
        for p in points:
            if p.name == old:
                p.name = new
        self._write_points(points)
        return Point(new, target.values)

    @_locked
    def delete_point(self, name: str) -> None:
        """Forget a point."""
        self.point(name)
        self._write_points([p for p in self.points() if p.name != name])

    def _write_points(self, points: list[Point]) -> None:
        # repr() is the shortest text that reads back as the same float.
        text = "".join(f"{p.name} {' '.join(repr(v) for v in p.values)}\n" for p in points)
        write_atomic(self.root / "points.ini", text.encode())

    # ---------------------------------------------------------------------------- programs

    @_locked
    def programs(self) -> list[str]:
        """The program names, sorted; files whose name is not a program name are ignored."""
        return sorted(p.stem for p in self.root.glob("*.py") if p.is_file() and _PROGRAM_RE.fullmatch(p.stem)
                      and len(p.stem) <= MAX_NAME)

    @_locked
    def read_program(self, name: str) -> str:
        """A program's text."""
        path = self._program_path(name)
        if not path.is_file():
            raise NotFound(f"There is no program named {_quote(name)}.")
        return _decode(path.read_bytes())[0]

    @_locked
    def new_program(self, name: str) -> str:
        """Start a program from the seed's template; its text is returned for the editor."""
        path = self._program_path(name)
        if path.exists():
            raise AlreadyExists(f"A program named {_quote(name)} already exists.")
        text = resources.files("asibot.examples").joinpath("template.py").read_text(encoding="utf-8")
        self._room_for("program", len(text.encode()))
        write_atomic(path, text.encode())
        return text

    @_locked
    def save_program(self, name: str, text: str) -> None:
        """Write a program (even one that does not compile yet: work in progress is kept);
        the text it replaces is kept first as a version."""
        path = self._program_path(name)
        text = check_program_text(text)
        if path.is_file():
            old = path.read_bytes()
            if old == text.encode():
                return
            self._room_for("program", len(text.encode()) - len(old), new=False)
            self._keep_version(name, old)
        else:
            self._room_for("program", len(text.encode()))
        write_atomic(path, text.encode())

    @_locked
    def versions(self, name: str) -> list[Version]:
        """The kept previous versions of a program, newest first."""
        self._program_path(name)
        folder = self.versions_dir / name
        out = [Version(p.stem, int(p.stem) / 1e9, p.stat().st_size)
               for p in folder.glob("*.py") if p.stem.isdigit()] if folder.is_dir() else []
        return sorted(out, key=lambda v: int(v.id), reverse=True)

    @_locked
    def read_version(self, name: str, id: str) -> str:
        """The text of one kept version."""
        self._program_path(name)
        if not isinstance(id, str) or not id.isdigit() or len(id) > 24:
            raise UserDataError(f"The version id {_quote(id)} is not a version id.")
        path = self.versions_dir / name / f"{id}.py"
        if not path.is_file():
            raise NotFound(f"The program {_quote(name)} has no version {_quote(id)}.")
        return _decode(path.read_bytes())[0]

    @_locked
    def restore_version(self, name: str, id: str) -> str:
        """Make a kept version current again; the text it replaces becomes a version too,
        so a restore can itself be undone."""
        text = self.read_version(name, id)
        self.save_program(name, text)
        return text

    @_locked
    def rename_program(self, old: str, new: str) -> None:
        """Rename a program with its versions; tasks that run it follow it."""
        src, dst = self._program_path(old), self._program_path(new)
        if not src.is_file():
            raise NotFound(f"There is no program named {_quote(old)}.")
        if old == new:
            return
        if dst.exists():
            raise AlreadyExists(f"A program named {_quote(new)} already exists.")
        os.rename(src, dst)
        if (self.versions_dir / old).is_dir():
            with contextlib.suppress(OSError):  # a stale versions folder of `new`: keep both
                os.rename(self.versions_dir / old, self.versions_dir / new)
        fsync_dir(self.root)
        for t in self.tasks():  # rewritten as they are: a task whose icon went stays as it was
            if t.program == old:
                write_atomic(self._task_path(t.name), _task_text(new, t.words, t.icon))

    @_locked
    def delete_program(self, name: str) -> None:
        """Move a program (and its versions) to the trash; refused while a task runs it,
        since the Launcher would show a button that cannot work."""
        path = self._program_path(name)
        if not path.is_file():
            raise NotFound(f"There is no program named {_quote(name)}.")
        users = [t.name for t in self.tasks() if t.program == name]
        if users:
            raise UserDataError(f"The program {_quote(name)} is used by the task(s) "
                                f"{', '.join(_quote(u) for u in users)}; change or delete them first.")
        stamp = self._trash_stamp()
        os.rename(path, self.trash_dir / f"{stamp}-{name}.py")
        if (self.versions_dir / name).is_dir():
            os.rename(self.versions_dir / name, self.trash_dir / f"{stamp}-{name}.versions")
        fsync_dir(self.root)

    def check_program(self, text: str) -> list[Problem]:
        """See the module function `check_program`."""
        return check_program(text)

    @_locked
    def program_file(self, name: str) -> Path:
        """The file of an existing program, for the runner (NotFound when there is none)."""
        path = self._program_path(name)
        if not path.is_file():
            raise NotFound(f"There is no program {_quote(name)}; create it on the Program page first.")
        return path

    def _program_path(self, name: str) -> Path:
        return self.root / f"{check_program_name(name)}.py"

    def _keep_version(self, name: str, data: bytes) -> None:
        folder = self.versions_dir / name
        folder.mkdir(parents=True, exist_ok=True)
        stamp = time.time_ns()
        while (folder / f"{stamp}.py").exists():  # two saves within one clock tick
            stamp += 1
        write_atomic(folder / f"{stamp}.py", data)
        for old in sorted((p for p in folder.glob("*.py") if p.stem.isdigit()),
                          key=lambda p: int(p.stem))[:-VERSIONS_KEPT]:
            old.unlink()

    def _trash_stamp(self) -> str:
        self.trash_dir.mkdir(exist_ok=True)
        return time.strftime("%Y%m%d-%H%M%S") + f"-{time.time_ns() % 1_000_000_000:09d}"

    # ------------------------------------------------------------------------------- words

    @_locked
    def words(self) -> list[str]:
        """The recorded words and phrases, in the order they were added."""
        out: list[str] = []
        seen: set[str] = set()
        for line in self._read_lines("words.ini"):
            try:
                w = check_word(line)
            except UserDataError as e:
                log.warning("words.ini line left out: %s", e)
                continue
            if w.casefold() not in seen:
                seen.add(w.casefold())
                out.append(w)
        return out

    @_locked
    def add_word(self, text: str) -> str:
        """Record a word or phrase; the same word in other capitals is the same word."""
        text = check_word(text)
        if text.casefold() in {w.casefold() for w in self.words()}:
            raise AlreadyExists(f"The word {_quote(text)} is already recorded.")
        self._write_words(self.words() + [text])
        return text

    @_locked
    def delete_word(self, text: str) -> None:
        """Forget a word (tasks keep their own copy of their words)."""
        text = check_word(text)
        words = self.words()
        kept = [w for w in words if w.casefold() != text.casefold()]
        if len(kept) == len(words):
            raise NotFound(f"The word {_quote(text)} is not recorded.")
        self._write_words(kept)

    def _add_words(self, words: list[str]) -> None:
        known = self.words()
        folded = {w.casefold() for w in known}
        new = [w for w in words if w.casefold() not in folded]
        if new:
            self._write_words(known + new)

    def _write_words(self, words: list[str]) -> None:
        write_atomic(self.root / "words.ini", "".join(w + "\n" for w in words).encode())

    # ------------------------------------------------------------------------------- tasks

    @_locked
    def tasks(self) -> list[Task]:
        """The tasks, sorted by name; a broken .task file is left out (and logged)."""
        out = []
        for path in sorted(self.root.glob("*.task")):
            try:
                out.append(self.task(path.stem))
            except UserDataError as e:
                log.warning("%s left out: %s", path.name, e)
        return out

    @_locked
    def task(self, name: str) -> Task:
        """One task by name."""
        path = self._task_path(name)
        if not path.is_file():
            raise NotFound(f"There is no task named {_quote(name)}.")
        return _parse_task(path.stem, _decode(path.read_bytes())[0])

    @_locked
    def save_task(self, name: str, program: str, words: list[str], icon: str) -> Task:
        """Create or replace a task; its program and icon must exist, and its words are
        recorded too so the Speech tab lists them."""
        path = self._task_path(name)
        if not self._program_path(program).is_file():
            raise NotFound(f"There is no program named {_quote(program)} for the task.")
        if not isinstance(words, (list, tuple)):
            raise UserDataError(f"The task's words must be a list; got {_quote(words)}.")
        words = list(dict.fromkeys(check_word(w) for w in words))
        self.icon_file(icon)
        self._add_words(words)
        write_atomic(path, _task_text(program, words, icon))
        return Task(path.stem, program, words, icon)

    @_locked
    def delete_task(self, name: str) -> None:
        """Move a task to the trash."""
        path = self._task_path(name)
        if not path.is_file():
            raise NotFound(f"There is no task named {_quote(name)}.")
        os.rename(path, self.trash_dir / f"{self._trash_stamp()}-{path.name}")
        fsync_dir(self.root)

    def _task_path(self, name: str) -> Path:
        return self.root / f"{check_task_name(name)}.task"

    # ------------------------------------------------------------------------------- icons

    @_locked
    def icons(self) -> list[Icon]:
        """The shipped icons, then the uploaded ones."""
        shipped = sorted(p.name for p in SHIPPED_ICONS.glob("*.svg"))
        uploaded = sorted(p.name for p in self.icons_dir.glob("*") if p.is_file() and _ICON_RE.fullmatch(p.name)
                          and p.suffix != ".svg") if self.icons_dir.is_dir() else []
        return [Icon(n, True) for n in shipped] + [Icon(n, False) for n in uploaded]

    @_locked
    def add_icon(self, filename: str, data: bytes) -> str:
        """Store an uploaded image and return its icon name. The type comes from the bytes,
        not the name; SVG is refused since it can carry scripts."""
        if not isinstance(data, (bytes, bytearray)):
            raise UserDataError("The icon must be an image file.")
        if len(data) > MAX_ICON_BYTES:
            raise UserDataError(f"The image is {len(data) // 1024} KiB; the limit is {MAX_ICON_BYTES // 1024} KiB.")
        ext = _image_kind(bytes(data))
        if ext is None:
            raise UserDataError(f"The file {_quote(filename)} is not a PNG, JPEG, GIF or WebP image"
                                " (SVG is not taken: it can hold scripts).")
        stem = re.split(r"[/\\]", filename if isinstance(filename, str) else "")[-1].rsplit(".", 1)[0]
        stem = re.sub(r"[^A-Za-z0-9_-]+", "-", stem).strip("-_")[:MAX_NAME - 12] or "icon"
        self.icons_dir.mkdir(exist_ok=True)
        n, name = 1, stem + ext  # never .svg, so never a shipped icon's name
        while (self.icons_dir / name).exists():
            if (self.icons_dir / name).is_file() and (self.icons_dir / name).read_bytes() == data:
                return name  # the same image uploaded again
            n += 1
            name = f"{stem}-{n}{ext}"
        self._room_for("icon", len(data))
        write_atomic(self.icons_dir / name, bytes(data))
        return name

    def _room_for(self, kind: str, grows: int, new: bool = True) -> None:
        """Refuse, with a sentence, a file that would take the folder past its limits."""
        programs = [p for p in self.root.glob("*.py") if p.is_file()]
        icons = [p for p in self.icons_dir.glob("*") if p.is_file()] if self.icons_dir.is_dir() else []
        count, most = (len(programs), MAX_PROGRAMS) if kind == "program" else (len(icons), MAX_ICONS)
        if new and count >= most:
            raise UserDataError(f"There are {count} {kind}s already, the most this folder keeps: "
                                f"delete one you no longer use first.")
        stored = sum(p.stat().st_size for p in programs + icons)
        if stored + grows > MAX_STORED_BYTES:
            raise UserDataError(f"Programs and icons take {stored / 2**20:.1f} MiB; this {kind} would take them "
                                f"past {MAX_STORED_BYTES // 2**20} MiB. Delete programs or icons you no longer use first.")

    @_locked
    def icon_file(self, name: str) -> Path:
        """The file of an icon, to serve it."""
        name = check_icon_name(name)
        # An SVG is served only if we drew it: one put in icons/ by hand could hold a script.
        path = (SHIPPED_ICONS if name.endswith(".svg") else self.icons_dir) / name
        if path.is_file():
            return path
        raise NotFound(f"There is no icon named {_quote(name)}.")

    # ------------------------------------------------------------------- seed import/export

    @_locked
    def export_zip(self) -> bytes:
        """The folder as a zip in the seed's layout, for a backup or another machine; the
        versions and the trash stay behind. Task files keep our icon names (drink.svg)."""
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
            paths = [self.root / "points.ini", self.root / "words.ini"]
            paths += [self._program_path(p) for p in self.programs()] + sorted(self.root.glob("*.task"))
            paths += [self.icons_dir / i.name for i in self.icons() if not i.shipped]
            for path in paths:
                if path.is_file():
                    z.writestr(path.relative_to(self.root).as_posix(), path.read_bytes())
        return buf.getvalue()

    @_locked
    def import_zip(self, data: bytes) -> ImportReport:
        """Load a zipped user folder (ours or the seed's). A zip with an unsafe entry
        (absolute, '..', a link) or that unpacks too big is refused whole, before any write."""
        try:
            infos = (z := zipfile.ZipFile(io.BytesIO(data))).infolist()
        except (zipfile.BadZipFile, ValueError, OSError):
            raise UserDataError("The file is not a zip archive.") from None
        if len(infos) > MAX_ZIP_ENTRIES:
            raise UserDataError(f"The zip holds {len(infos)} entries; the limit is {MAX_ZIP_ENTRIES}.")
        for info in infos:
            parts = info.filename.replace("\\", "/").split("/")
            if parts[0] == "" or ".." in parts or ":" in parts[0] or "\x00" in info.filename:
                raise UserDataError(f"The zip entry {_quote(info.filename)} points outside the folder; "
                                    "the zip is refused.")
            if stat.S_ISLNK(info.external_attr >> 16):
                raise UserDataError(f"The zip entry {_quote(info.filename)} is a link; the zip is refused.")
        infos = [i for i in infos if not i.is_dir()]
        # A zipped folder ("webInterface/points.ini"): its one top folder is dropped.
        tops = {i.filename.split("/", 1)[0] for i in infos}
        strip = len(tops) == 1 and tops != {"icons"} and all("/" in i.filename for i in infos)
        files: dict[str, bytes | None] = {}
        total = 0
        for info in infos:
            name = info.filename.split("/", 1)[1] if strip else info.filename
            limit = _import_limit(name)
            if limit is None or info.file_size > limit:
                files[name] = None  # not a user file, or too big: skipped unread
                continue
            try:
                with z.open(info) as f:  # the declared size may lie: never read past the limit
                    body = f.read(limit + 1)
            except (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError, RuntimeError):
                # zipfile stops at the declared size, so a lying entry fails its CRC here;
                # encrypted or exotic entries land here too.
                raise UserDataError(f"The zip entry {_quote(info.filename)} cannot be read "
                                    "(damaged, encrypted or not what it declares); the zip is refused.") from None
            total += len(body)
            if len(body) > limit or total > MAX_ZIP_TOTAL:
                raise UserDataError("The zip unpacks to more than its entries declare or to more than "
                                    f"{MAX_ZIP_TOTAL // 2**20} MiB; it is refused.")
            files[name] = body
        return self._import(files)

    @_locked
    def import_folder(self, path: Path) -> ImportReport:
        """Load an existing ASIBOT user folder (the seed's webInterface context folder).
        Links are not followed, so the import reads only what is in the folder."""
        path = Path(path)
        if not path.is_dir():
            raise NotFound(f"There is no folder {_quote(str(path))}.")
        entries = list(path.iterdir())
        if (path / "icons").is_dir() and not (path / "icons").is_symlink():
            entries += list((path / "icons").iterdir())
        if len(entries) > MAX_ZIP_ENTRIES:
            raise UserDataError(f"The folder holds {len(entries)} files; the limit is {MAX_ZIP_ENTRIES}. "
                                "Is it the user folder?")
        files: dict[str, bytes | None] = {}
        for p in entries:
            if p.is_file() and not p.is_symlink():
                limit = _import_limit(p.relative_to(path).as_posix())
                files[p.relative_to(path).as_posix()] = (
                    None if limit is None or p.stat().st_size > limit else p.read_bytes())
        return self._import(files)

    def _import(self, files: dict[str, bytes | None]) -> ImportReport:
        """Import a user folder's files (None: unread, not ours or too big): points, words,
        programs, icons, then the tasks that need them. Each item is checked on its own: a
        bad one is skipped with its reason and the rest still load."""
        report = ImportReport()

        def text_of(name: str) -> str:
            text, latin = _decode(files.pop(name) or b"")
            if latin:
                report.notes.append(f"{name} was not UTF-8; it was read as Latin-1.")
            return text

        for name in sorted(n for n, body in files.items() if body is None):
            del files[name]
            why = "it is too big for its kind" if _import_limit(name) else \
                "it is not a user file (points.ini, words.ini, *.py, *.task, images)"
            report.skipped.append(Skipped(name, why))

        if "points.ini" in files:
            points = {p.name: p for p in self.points()}
            for number, line in enumerate(text_of("points.ini").splitlines(), 1):
                try:
                    if line.strip():
                        p = _parse_point(line)
                        points.pop(p.name, None)  # a later line of the same name wins, as on the seed
                        points[p.name] = p
                        report.imported.append(f"point {p.name}")
                except UserDataError as e:
                    report.skipped.append(Skipped(f"points.ini line {number}", str(e)))
            self._write_points(list(points.values()))

        if "words.ini" in files:
            words = []
            for number, line in enumerate(text_of("words.ini").splitlines(), 1):
                try:
                    if line.strip():
                        words.append(check_word(line))
                        report.imported.append(f"word {words[-1]}")
                except UserDataError as e:
                    report.skipped.append(Skipped(f"words.ini line {number}", str(e)))
            self._add_words(words)

        for name in sorted(n for n in files if n.endswith(".py") and "/" not in n):
            try:
                program = check_program_name(name[:-3])
                text = text_of(name)
                existed = self._program_path(program).is_file()
                self.save_program(program, text)
                report.imported.append(f"program {program}" + (" (replaced; the old text is kept as a version)"
                                                               if existed else ""))
                errors = [p for p in check_program(text) if not p.message.startswith("Warning:")]
                if errors:
                    report.notes.append(f"The program {program} does not compile in Python 3 (line {errors[0].line}: "
                                        f"{errors[0].message}); fix it in the Program tab.")
            except UserDataError as e:
                report.skipped.append(Skipped(name, str(e)))

        icon_names: dict[str, str] = {}  # an image's name in the imported folder -> its icon name here
        for name in sorted(n for n in files if Path(n).suffix.lower() in _IMAGE_EXTENSIONS
                           and n.count("/") == n.startswith("icons/")):
            base, body = name.rsplit("/", 1)[-1], files.pop(name) or b""
            if base.lower() in SEED_ICONS:  # the seed's own launcher image: our icon stands in
                report.skipped.append(Skipped(name, f"the shipped {SEED_ICONS[base.lower()]} stands in for it"))
                continue
            try:
                icon_names[base] = self.add_icon(base, body)
                report.imported.append(f"icon {icon_names[base]}")
            except UserDataError as e:
                report.skipped.append(Skipped(name, str(e)))

        for name in sorted(n for n in files if n.endswith(".task") and "/" not in n):
            try:
                t = _parse_task(check_task_name(name[:-5]), text_of(name))
                icon = SEED_ICONS.get(t.icon.lower()) or icon_names.get(t.icon) or t.icon
                self.save_task(t.name, t.program, t.words, icon)
                report.imported.append(f"task {t.name}")
                if icon != t.icon:
                    report.notes.append(f"The task {t.name} shows {icon} for the seed's {t.icon}.")
            except UserDataError as e:
                report.skipped.append(Skipped(name, str(e)))

        for name in sorted(files):  # left over: a user file's name at the wrong place
            report.skipped.append(Skipped(name, "it is not a user file (points.ini, words.ini, *.py, *.task, images)"))
        return report

    # ----------------------------------------------------------------------------- helpers

    def _read_lines(self, name: str) -> list[str]:
        path = self.root / name
        if not path.is_file():
            return []
        return [line for line in _decode(path.read_bytes())[0].splitlines() if line.strip()]


def _import_limit(name: str) -> int | None:
    """The largest file of this kind an import reads; None for a file it does not take."""
    suffix = Path(name).suffix.lower()
    if name in ("points.ini", "words.ini"):
        return MAX_LIST_BYTES
    if suffix in (".py", ".task") and "/" not in name:
        return MAX_PROGRAM_BYTES if suffix == ".py" else MAX_TASK_BYTES
    if suffix in _IMAGE_EXTENSIONS and name.count("/") == name.startswith("icons/"):
        return MAX_ICON_BYTES
    return None
