"""Tasks, what the Launcher shows as buttons: `<task>.task`, 3 lines: the program (no .py), its
words (several joined by ";") and its icon's file name; ours add a 4th, the robot the task runs
on (a task taught on the kitchen arm runs there whatever the page commands: issue 54). A task
of the original ASIBOT's 3 lines runs on the robot that launches it."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

from asibot import keys
from asibot.files import fsync_dir, write_atomic
from asibot.web.userdata.errors import NotFound, UserDataError
from asibot.web.userdata.folder import Folder, decode, log
from asibot.web.userdata.names import CONTROL_RE, need_str, quote
from asibot.web.userdata.words import check_word

MAX_TASK_BYTES = 4096
ROBOT_RE = re.compile(keys.ROBOT_ID_PATTERN)


@dataclass
class Task:
    """What the Launcher shows as one button: run `program`, also on any of `words`."""

    name: str
    program: str
    words: list[str]
    icon: str
    robot: str = ""         # "" (the original's 3 lines): whichever robot launches it


def check_task_name(name: object) -> str:
    """Task names are what people read on the Launcher, so spaces are fine; the file name
    `<name>.task` must stay inside the folder and visible."""
    if isinstance(name, str):
        name = name.strip()
    name = need_str("task name", name)
    if "/" in name or "\\" in name or ".." in name or name.startswith(".") or CONTROL_RE.search(name):
        raise UserDataError(f"The task name {quote(name)} may not hold /, \\, .., control characters "
                            "or start with a dot.")
    return name


def check_task_words(words: object) -> list[str]:
    """A task's words: each a word (check_word), each once."""
    if not isinstance(words, (list, tuple)):
        raise UserDataError(f"The task's words must be a list; got {quote(words)}.")
    return list(dict.fromkeys(check_word(w) for w in words))


def parse_task(name: str, text: str) -> Task:
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if len(lines) not in (3, 4):
        raise UserDataError(f"The task file {quote(name + '.task')} must have 3 lines "
                            f"(program, words, icon) and may have a 4th (its robot); it has {len(lines)}.")
    program = lines[0].strip().removesuffix(".py")
    words = [w.strip() for w in lines[1].split(";") if w.strip()]
    robot = check_task_robot(lines[3].strip()) if len(lines) == 4 else ""
    return Task(name, program, words, lines[2].strip(), robot)


def check_task_robot(robot: object) -> str:
    """A task's robot: a robot id ("" for whichever launches it)."""
    if robot == "":
        return ""
    if not isinstance(robot, str) or not ROBOT_RE.fullmatch(robot):
        raise UserDataError(f"The task's robot {quote(robot)} is not a robot id (letters, digits, - _ .).")
    return robot


def task_text(program: str, words: list[str], icon: str, robot: str = "") -> bytes:
    return (f"{program}\n{';'.join(words)}\n{icon}\n" + (f"{robot}\n" if robot else "")).encode()


class Tasks:
    """The .task files of one folder. That a task's program, icon and words exist is checked
    by UserData, which knows them all."""

    def __init__(self, folder: Folder) -> None:
        self.folder = folder

    def path(self, name: str) -> Path:
        return self.folder.root / f"{check_task_name(name)}.task"

    def all(self) -> list[Task]:
        """The tasks, sorted by name; a broken .task file is left out (and logged)."""
        out = []
        for path in sorted(self.folder.root.glob("*.task")):
            try:
                out.append(self.get(path.stem))
            except UserDataError as e:
                log.warning("%s left out: %s", path.name, e)
        return out

    def get(self, name: str) -> Task:
        path = self.path(name)
        if not path.is_file():
            raise NotFound(f"There is no task named {quote(name)}.")
        return parse_task(path.stem, decode(path.read_bytes())[0])

    def write(self, path: Path, program: str, words: list[str], icon: str, robot: str = "") -> Task:
        """Write the task at `path` (`path(name)`: its name checked) as it is given, if the
        folder has room for it."""
        body = task_text(program, words, icon, check_task_robot(robot))
        old = path.stat().st_size if path.is_file() else None
        self.folder.room_for("task", len(body) - (old or 0), new=old is None)
        write_atomic(path, body)
        return Task(path.stem, program, words, icon, robot)

    def follow_program(self, old: str, new: str) -> None:
        """The tasks that ran program `old` run `new`, renamed from it."""
        for t in self.all():  # rewritten as they are: a task whose icon went stays as it was
            if t.program == old:
                write_atomic(self.path(t.name), task_text(new, t.words, t.icon, t.robot))

    def delete(self, name: str) -> None:
        """Move a task to the trash."""
        path = self.path(name)
        if not path.is_file():
            raise NotFound(f"There is no task named {quote(name)}.")
        os.rename(path, self.folder.trash_dir / f"{self.folder.trash_stamp()}-{path.name}")
        fsync_dir(self.folder.root)
        self.folder.purge_trash()
