"""The user's programs: `<program>.py`, with the previous versions of each in .versions/<program>/,
so a bad save can be undone, and deleted ones in .trash/. How many versions are kept, how long
the trash keeps what was deleted and how much all of it may take: folder.py."""

from __future__ import annotations

import contextlib
import os
import re
import threading
import warnings
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Sequence

from asibot.files import fsync_dir, write_atomic
from asibot.web.userdata.errors import AlreadyExists, NotFound, UserDataError
from asibot.web.userdata.folder import Folder, decode
from asibot.web.userdata.names import MAX_NAME, plain_name, quote

MAX_PROGRAM_BYTES = 256 * 1024

PROGRAM_RE = re.compile(r"[A-Za-z][A-Za-z0-9_-]*")
_COMPILE_LOCK = threading.Lock()


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


def check_program_name(name: object) -> str:
    """A program name is also a file name and a Python module name: keep it plain."""
    return plain_name("program name", PROGRAM_RE, "letters, digits, _ and -", name)


def check_program_text(text: object) -> str:
    """Program text: a str under the size limit, no NUL (it would not be a text file)."""
    if not isinstance(text, str):
        raise UserDataError(f"The program text must be text; got {quote(text)}.")
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


class Programs:
    """The programs of one folder and their versions. Which tasks run a program is the tasks'
    business (UserData joins the two)."""

    def __init__(self, folder: Folder) -> None:
        self.folder = folder

    def names(self) -> list[str]:
        """The program names, sorted; files whose name is not a program name are ignored."""
        return sorted(p.stem for p in self.folder.root.glob("*.py") if p.is_file() and PROGRAM_RE.fullmatch(p.stem)
                      and len(p.stem) <= MAX_NAME)

    def path(self, name: str) -> Path:
        return self.folder.root / f"{check_program_name(name)}.py"

    def read(self, name: str) -> str:
        path = self.path(name)
        if not path.is_file():
            raise NotFound(f"There is no program named {quote(name)}.")
        return decode(path.read_bytes())[0]

    def new(self, name: str) -> str:
        """Start a program from the seed's template; its text is returned for the editor."""
        path = self.path(name)
        if path.exists():
            raise AlreadyExists(f"A program named {quote(name)} already exists.")
        text = resources.files("asibot.examples").joinpath("template.py").read_text(encoding="utf-8")
        self.folder.room_for("program", len(text.encode()))
        write_atomic(path, text.encode())
        return text

    def save(self, name: str, text: str, also_bytes: int = 0, also_versions: Sequence[tuple[str, int]] = ()) -> None:
        """Write a program (even one that does not compile yet: work in progress is kept);
        the text it replaces is kept first as a version. Refused, nothing written, when the
        folder has no room for it (folder.room_for); `also_bytes` and `also_versions` (suffix,
        bytes) are what the caller writes with it (a program's steps), counted in the same check."""
        path = self.path(name)
        body = check_program_text(text).encode()
        old = path.read_bytes() if path.is_file() else None
        versions = [*also_versions, *([(".py", len(old))] if old is not None and old != body else [])]
        grows = len(body) - len(old or b"") + also_bytes + self.folder.version_growth(name, versions)
        if old == body:
            if grows > 0:
                self.folder.room_for("program", grows, new=False)
            return
        self.folder.room_for("program", grows, new=old is None)
        if old is not None:
            self.folder.keep_version(name, ".py", old)
        write_atomic(path, body)

    def versions(self, name: str) -> list[Version]:
        """The kept previous versions of a program, newest first."""
        self.path(name)
        folder = self.folder.versions_dir / name
        out = [Version(p.stem, int(p.stem) / 1e9, p.stat().st_size)
               for p in folder.glob("*.py") if p.stem.isdigit()] if folder.is_dir() else []
        return sorted(out, key=lambda v: int(v.id), reverse=True)

    def read_version(self, name: str, id: str) -> str:
        self.path(name)
        if not isinstance(id, str) or not id.isdigit() or len(id) > 24:
            raise UserDataError(f"The version id {quote(id)} is not a version id.")
        path = self.folder.versions_dir / name / f"{id}.py"
        if not path.is_file():
            raise NotFound(f"The program {quote(name)} has no version {quote(id)}.")
        return decode(path.read_bytes())[0]

    def restore_version(self, name: str, id: str) -> str:
        """Make a kept version current again; the text it replaces becomes a version too,
        so a restore can itself be undone."""
        text = self.read_version(name, id)
        self.save(name, text)
        return text

    def rename(self, old: str, new: str) -> None:
        """Rename a program with its versions."""
        src, dst = self.path(old), self.path(new)
        if not src.is_file():
            raise NotFound(f"There is no program named {quote(old)}.")
        if old == new:
            return
        if dst.exists():
            raise AlreadyExists(f"A program named {quote(new)} already exists.")
        os.rename(src, dst)
        if (self.folder.versions_dir / old).is_dir():
            with contextlib.suppress(OSError):  # a stale versions folder of `new`: keep both
                os.rename(self.folder.versions_dir / old, self.folder.versions_dir / new)
        fsync_dir(self.folder.root)

    def delete(self, name: str, used_by: list[str]) -> None:
        """Move a program (and its versions) to the trash; refused while tasks (`used_by`) run
        it, since the Launcher would show a button that cannot work."""
        path = self.path(name)
        if not path.is_file():
            raise NotFound(f"There is no program named {quote(name)}.")
        if used_by:
            raise UserDataError(f"The program {quote(name)} is used by the task(s) "
                                f"{', '.join(quote(u) for u in used_by)}; change or delete them first.")
        stamp = self.folder.trash_stamp()
        os.rename(path, self.folder.trash_dir / f"{stamp}-{name}.py")
        if (self.folder.versions_dir / name).is_dir():
            os.rename(self.folder.versions_dir / name, self.folder.trash_dir / f"{stamp}-{name}.versions")
        fsync_dir(self.folder.root)
        self.folder.purge_trash()

    def file(self, name: str) -> Path:
        """The file of an existing program, for the runner (NotFound when there is none)."""
        path = self.path(name)
        if not path.is_file():
            raise NotFound(f"There is no program {quote(name)}; create it on the Program page first.")
        return path
