"""The user's files for the web Task Creator: points, programs, words, tasks and icons.

Everything lives in one data folder laid out like the seed's own user folder, so an existing
ASIBOT user's folder works as it is:

    points.ini          one point a line: <name> <x> <y> <z> <rot(y')> <rot(z'')> (m, deg)
    words.ini           one word or phrase a line
    <program>.py        the user's programs
    <program>.steps.json  the steps of a program made without Python (steps.py), beside it
    <task>.task         3 lines: program (no .py), words (several joined by ";"), icon file name
    favourites.json     how often each task and place was used, and the carer's order of them
    icons/              uploaded icons (PNG, JPEG, GIF, WebP)
    .versions/<prog>/   previous versions of each program, so a bad save can be undone (a bounded
                        history, as an editor keeps)
    .trash/             deleted programs and tasks, purged after a time or past a size; it can be emptied

Programs, steps, tasks, icons, versions and trash count against one cap together (folder.py
says how much each part keeps and what a refusal says).

One module a kind of file (points, words, programs, tasks, icons, and the seed's folder in and
out: seed); `UserData` is the folder as the routes see it, and joins the kinds where one needs
another (a task's program, icon and words; a program's tasks).

Plain Python, no web framework and no bus: the web layer maps `UserDataError` to 400,
`NotFound` to 404 and `AlreadyExists` to 409. Every write is atomic (temp file, fsync,
os.replace, fsync of the folder), so a crash mid-save leaves the old file whole; bad input
is refused with a sentence before anything is written.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Callable, Concatenate, ParamSpec, TypeVar

from asibot.files import data_dir
from asibot.web.userdata import seed
from asibot.web.userdata.errors import AlreadyExists, NotFound, UserDataError
from asibot.web.userdata.favourites import Favourites
from asibot.web.userdata.folder import VERSIONS_KEPT, Emptied, Folder, Usage
from asibot.web.userdata.icons import MAX_ICON_BYTES, SHIPPED_ICONS, Icon, Icons, check_icon_name
from asibot.web.userdata.names import MAX_NAME, quote
from asibot.web.userdata.points import Point, Points, check_point_name, check_values
from asibot.web.userdata.programs import (MAX_PROGRAM_BYTES, Problem, Programs, Version, check_program,
                                          check_program_name, check_program_text)
from asibot.web.userdata.seed import SEED_ICONS, ImportReport, Skipped
from asibot.web.userdata.steps import Made, ProgramSteps, Saved
from asibot.web.userdata.tasks import Task, Tasks, check_task_name, check_task_words
from asibot.web.userdata.words import MAX_WORD, Words, check_word

__all__ = ["AlreadyExists", "NotFound", "UserDataError", "UserData", "default_root",
           "Point", "Version", "Problem", "Task", "Icon", "Skipped", "ImportReport", "Made", "Saved", "Usage", "Emptied",
           "check_point_name", "check_values", "check_program_name", "check_program_text", "check_program",
           "check_task_name", "check_icon_name", "check_word",
           "SHIPPED_ICONS", "SEED_ICONS", "MAX_NAME", "MAX_WORD", "MAX_PROGRAM_BYTES", "MAX_ICON_BYTES",
           "VERSIONS_KEPT"]
# The folder's limits are read where they are kept (folder.MAX_PROGRAMS, seed.MAX_ZIP_ENTRIES, ...):
# they are not repeated here, where changing one would change nothing.

#: Where the user's files live: $ASIBOT_DATA, else the XDG data folder (asibot.files).
default_root = data_dir

P = ParamSpec("P")
R = TypeVar("R")
D = TypeVar("D", bound="UserData")


def _locked(method: Callable[Concatenate[D, P], R]) -> Callable[Concatenate[D, P], R]:
    """One lock for the whole folder: the web server calls from several threads."""
    @functools.wraps(method)
    def wrapper(self: D, *args: P.args, **kwargs: P.kwargs) -> R:
        with self.folder.lock:
            return method(self, *args, **kwargs)
    return wrapper


class UserData:
    """The user's data folder; every method validates its input and writes atomically."""

    def __init__(self, root: Path) -> None:
        self.folder = Folder(root)
        self.root = self.folder.root
        self.point_file = Points(self.folder)
        self.word_file = Words(self.folder)
        self.program_files = Programs(self.folder)
        self.task_files = Tasks(self.folder)
        self.favourites = Favourites(self.folder)
        self.icon_files = Icons(self.folder)
        #: The steps of programs made without Python; its methods take the folder's lock.
        self.steps = ProgramSteps(self.folder, self.point_file, self.program_files)

    # ------------------------------------------------------------------------------ points

    @_locked
    def points(self) -> list[Point]:
        """The taught points in file order; a hand-broken line is left out (and logged)."""
        return self.point_file.all()

    @_locked
    def point(self, name: str) -> Point:
        return self.point_file.get(name)

    @_locked
    def add_point(self, name: str, values: list[float], replace: bool = False) -> Point:
        """Store a point (a capture); refuse a taken name unless `replace`."""
        return self.point_file.add(name, values, replace)

    @_locked
    def suggest_point_name(self, here: list[float] | None = None, place: str = "") -> str:
        return self.point_file.suggest_name(here, place)

    @_locked
    def rename_point(self, old: str, new: str) -> Point:
        return self.point_file.rename(old, new)

    @_locked
    def delete_point(self, name: str) -> None:
        self.point_file.delete(name)

    # ---------------------------------------------------------------------------- programs

    @_locked
    def programs(self) -> list[str]:
        return self.program_files.names()

    @_locked
    def read_program(self, name: str) -> str:
        return self.program_files.read(name)

    @_locked
    def new_program(self, name: str) -> str:
        return self.program_files.new(name)

    @_locked
    def save_program(self, name: str, text: str) -> None:
        self.program_files.save(name, text)

    @_locked
    def versions(self, name: str) -> list[Version]:
        return self.program_files.versions(name)

    @_locked
    def read_version(self, name: str, id: str) -> str:
        return self.program_files.read_version(name, id)

    @_locked
    def restore_version(self, name: str, id: str) -> str:
        return self.program_files.restore_version(name, id)

    @_locked
    def rename_program(self, old: str, new: str) -> None:
        """Rename a program with its versions; tasks that run it follow it."""
        self.program_files.rename(old, new)
        if old != new:
            self.steps.rename(old, new)
            self.task_files.follow_program(old, new)

    @_locked
    def delete_program(self, name: str) -> None:
        """Move a program (and its versions) to the trash; refused while a task runs it."""
        self.program_files.delete(name, [t.name for t in self.task_files.all() if t.program == name])
        self.steps.delete(name)

    @_locked
    def usage(self) -> Usage:
        """How much the program store keeps: programs, icons, versions and trash (reading it
        changes nothing: the trash is purged at start and by writes)."""
        return self.folder.usage()

    @_locked
    def empty_trash(self) -> Emptied:
        """Remove the deleted programs, steps and tasks for good; what is live stays."""
        return self.folder.empty_trash()

    def check_program(self, text: str) -> list[Problem]:
        """See the module function `check_program`."""
        return check_program(text)

    @_locked
    def program_file(self, name: str) -> Path:
        """The file of an existing program, for the runner (NotFound when there is none)."""
        return self.program_files.file(name)

    # ------------------------------------------------------------------------------- words

    @_locked
    def words(self) -> list[str]:
        """The recorded words and phrases, in the order they were added."""
        return self.word_file.all()

    @_locked
    def add_word(self, text: str) -> str:
        """Record a word or phrase; the same word in other capitals is the same word."""
        return self.word_file.add(text)

    @_locked
    def delete_word(self, text: str) -> None:
        """Forget a word (tasks keep their own copy of their words)."""
        self.word_file.delete(text)

    # ------------------------------------------------------------------------------- tasks

    @_locked
    def tasks(self) -> list[Task]:
        return self.task_files.all()

    @_locked
    def task(self, name: str) -> Task:
        return self.task_files.get(name)

    @_locked
    def save_task(self, name: str, program: str, words: list[str], icon: str, robot: str = "") -> Task:
        """Create or replace a task; its program and icon must exist, and its words are
        recorded too so the Speech tab lists them. `robot`: the robot it runs on, "" for
        whichever launches it."""
        path = self.task_files.path(name)
        if not self.program_files.path(program).is_file():
            raise NotFound(f"There is no program named {quote(program)} for the task.")
        words = check_task_words(words)
        self.icon_files.file(icon)
        self.word_file.add_new(words)
        return self.task_files.write(path, program, words, icon, robot)

    @_locked
    def delete_task(self, name: str) -> None:
        """Move a task to the trash."""
        self.task_files.delete(name)

    # ------------------------------------------------------------------------------- icons

    @_locked
    def icons(self) -> list[Icon]:
        return self.icon_files.all()

    @_locked
    def add_icon(self, filename: str, data: bytes) -> str:
        return self.icon_files.add(filename, data)

    @_locked
    def icon_file(self, name: str) -> Path:
        return self.icon_files.file(name)

    # ------------------------------------------------------------------- seed import/export

    @_locked
    def export_zip(self) -> bytes:
        return seed.export_zip(self)

    @_locked
    def import_zip(self, data: bytes) -> ImportReport:
        return seed.import_zip(self, data)

    @_locked
    def import_folder(self, path: Path) -> ImportReport:
        return seed.import_folder(self, path)
