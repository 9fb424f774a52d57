"""The steps of a program made without Python: `<program>.steps.json` beside `<program>.py`,
with the SHA-256 of the Python they last generated, so whether the two still agree is known
("in sync"): a program edited as Python afterwards no longer matches its steps, and the page
says so and keeps both. Saving steps again writes the .py from them (once the person confirmed
that it replaces the edited Python; the old .py is kept as a version, as every save keeps one).
Previous steps are kept too, in .versions/<program>/<stamp>.steps.json, bounded with the
program's Python (folder.py), and counted with it against the folder's cap.

The file: {"format": 1, "steps": [...], "python_sha256": "<hex>"}. The steps are the models of
asibot.web.steps; the generator is there too.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from asibot.files import fsync_dir, write_atomic
from asibot.web import steps as steplib
from asibot.web.userdata.errors import AlreadyExists, NotFound, UserDataError
from asibot.web.userdata.folder import Folder, decode
from asibot.web.userdata.names import quote
from asibot.web.userdata.points import Points
from asibot.web.userdata.programs import Programs, check_program_name

FORMAT = 1
SUFFIX = ".steps.json"


def digest(text: str | bytes) -> str:
    return hashlib.sha256(text.encode() if isinstance(text, str) else text).hexdigest()


@dataclass
class Saved:
    """A program's saved steps, and whether its .py is still the one they generated."""

    steps: list[steplib.Step]
    in_sync: bool


@dataclass
class Made:
    """What saving steps made: the program's Python text."""

    steps: list[steplib.Step]
    text: str


class ProgramSteps:
    """The steps files of one folder, joined with its points and programs (a save checks the
    points the steps name and writes the program). Every method takes the folder's lock."""

    def __init__(self, folder: Folder, points: Points, programs: Programs) -> None:
        self.folder, self.points, self.programs = folder, points, programs

    def path(self, name: str) -> Path:
        return self.folder.root / f"{check_program_name(name)}{SUFFIX}"

    def point_values(self) -> dict[str, list[float]]:
        return {p.name: p.values for p in self.points.all()}

    def read(self, name: str) -> Saved | None:
        """The program's steps and whether they are in sync; None for a program without steps."""
        with self.folder.lock:
            py = self.programs.path(name)
            if not py.is_file():
                raise NotFound(f"There is no program named {quote(name)}.")
            data = self._load(name)
            if data is None:
                return None
            steps = steplib.parse(data.get("steps"))
            return Saved(steps, data.get("python_sha256") == digest(py.read_bytes()))

    def points_changed(self, name: str, saved: Saved) -> bool:
        """In sync, but the points the steps use were captured again (or renamed) since: saving
        the steps again would change the program."""
        with self.folder.lock:
            if not saved.in_sync:
                return False
            try:
                text = steplib.generate(name, saved.steps, self.point_values())
            except UserDataError:
                return True     # a point they use is gone: a save would say which
            return digest(text) != digest(self.programs.path(name).read_bytes())

    def preview(self, name: str, steps: Sequence[steplib.Step]) -> str:
        """The Python the steps would make now (nothing is written)."""
        with self.folder.lock:
            check_program_name(name)
            return steplib.generate(name, steps, self.point_values())

    def save(self, name: str, steps: Sequence[steplib.Step], replace: bool = False, new: bool = False) -> Made:
        """Save the steps and write the program they make. A program whose Python no longer
        matches its steps (or that has no steps yet) is replaced only with `replace`, the person's
        confirmation; `new` makes a new program (refused when the name is taken)."""
        with self.folder.lock:
            py = self.programs.path(name)
            if new and py.exists():
                raise AlreadyExists(f"A program named {quote(name)} already exists.")
            if not new and not py.is_file():
                raise NotFound(f"There is no program named {quote(name)}.")
            steplib.check_shape(steps)
            text = steplib.generate(name, steps, self.point_values())
            if not new and not replace:
                saved = self._load(name)
                if saved is None:
                    raise UserDataError(f"The program {quote(name)} is written in Python, not in steps; saving "
                                        "steps replaces its Python (kept as a previous version). Confirm to go on.")
                if saved.get("python_sha256") != digest(py.read_bytes()):
                    raise UserDataError(f"The Python of {quote(name)} was edited after its steps made it; saving the "
                                        "steps replaces that Python (kept as a previous version). Confirm to go on.")
            body = json.dumps({"format": FORMAT, "steps": steplib.dump(steps), "python_sha256": digest(text)},
                              indent=1, ensure_ascii=False).encode() + b"\n"
            path = self.path(name)
            old = path.read_bytes() if path.is_file() else None
            # the versions they replace are kept; the folder's room is checked for all of it at once
            self.programs.save(name, text, also_bytes=len(body) - len(old or b""),
                               also_versions=[(SUFFIX, len(old))] if old is not None and old != body else [])
            if old is not None and old != body:
                self.folder.keep_version(name, SUFFIX, old)
            if old != body:
                write_atomic(path, body)
            return Made(list(steps), text)

    def rename(self, old: str, new: str) -> None:
        """The steps follow their program (called after the program was renamed)."""
        with self.folder.lock:
            src, dst = self.path(old), self.path(new)
            if old != new and src.is_file():
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(dst)      # steps of a program that no longer exists
                os.rename(src, dst)
                fsync_dir(self.folder.root)

    def delete(self, name: str) -> None:
        """The steps go to the trash with their program (called after it went)."""
        with self.folder.lock:
            src = self.path(name)
            if src.is_file():
                os.rename(src, self.folder.trash_dir / f"{self.folder.trash_stamp()}-{name}{SUFFIX}")
                fsync_dir(self.folder.root)
                self.folder.purge_trash()

    def _load(self, name: str) -> dict | None:
        path = self.path(name)
        if not path.is_file():
            return None
        try:
            data = json.loads(decode(path.read_bytes())[0])
        except ValueError:
            raise UserDataError(f"The steps file of {quote(name)} is not JSON; fix or delete "
                                f"{path.name} in the data folder.") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise UserDataError(f"The steps file of {quote(name)} is not one this page reads (format {FORMAT}).")
        return data
