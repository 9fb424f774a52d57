"""The data folder itself: where each kind of file lives, one lock for all of them, the previous
versions, the trash, and how much the folder keeps.

Everything the program store keeps on disk counts against one cap, MAX_STORED_BYTES: the
programs with their steps, the tasks, the uploaded icons, the previous versions (.versions/)
and the trash (.trash/). The versions are a bounded history, as an editor keeps: per program at
most VERSIONS_KEPT of its Python (and as many of its steps) and VERSION_BYTES_KEPT in all, the
oldest dropped first. The trash forgets what was deleted more than TRASH_DAYS ago, and the
oldest first while it holds more than MAX_TRASH_BYTES or MAX_TRASH_ITEMS; `empty_trash` empties
it. A write the cap has no room for is refused with a sentence that says how much is used, of
what, and how to free it, and nothing is written."""

from __future__ import annotations

import logging
import os
import shutil
import stat
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from asibot.files import remove_leftovers, write_atomic
from asibot.web.userdata.errors import UserDataError

log = logging.getLogger("asibot.web.userdata")

#: How much the folder keeps: programs, tasks and uploaded icons (each counted), and the bytes
#: of everything the program store keeps (live files, versions and trash together).
MAX_PROGRAMS = 200
MAX_TASKS = 200
MAX_ICONS = 100
MAX_STORED_BYTES = 32 * 1024 * 1024
#: Previous versions of one program: the newest VERSIONS_KEPT of its Python (and as many of its
#: steps), VERSION_BYTES_KEPT of both together; the oldest go first, the newest always stays.
VERSIONS_KEPT = 20
VERSION_BYTES_KEPT = 1024 * 1024
#: The trash: an entry deleted more than TRASH_DAYS ago is purged, and the oldest go first
#: while it holds more than MAX_TRASH_BYTES or MAX_TRASH_ITEMS entries.
TRASH_DAYS = 30
MAX_TRASH_BYTES = 8 * 1024 * 1024
MAX_TRASH_ITEMS = 500

#: The live files of the program store, at the top of the folder: programs, their steps, tasks.
LIVE_SUFFIXES = (".py", ".steps.json", ".task")
#: What a kept version's file name ends in: a program's Python, its steps.
VERSION_SUFFIXES = (".py", ".steps.json")
#: Where to free room, as the refusals say it.
HOW_TO_FREE = ("Delete programs you no longer use (their versions go with them), then empty the trash "
               "(Program tab, below the list of programs)")


def decode(data: bytes) -> tuple[str, bool]:
    """Text of a user file; the seed's files may be Latin-1 (Spanish comments), then True."""
    try:
        return data.decode("utf-8-sig"), False
    except UnicodeDecodeError:
        return data.decode("cp1252", errors="replace"), True


def size_text(n: float) -> str:
    """Bytes as people read them: 512 bytes, 12 KiB, 31.8 MiB (32 MiB, not 32.0)."""
    if n < 1024:
        return f"{int(n)} bytes"
    if n < 1024 * 1024:
        return f"{n / 1024:.0f} KiB"
    return f"{n / 2**20:.1f}".removesuffix(".0") + " MiB"


def tree_bytes(path: Path | str) -> int:
    """The bytes of the files in `path` (a file or a folder), links not followed."""
    try:
        st = os.lstat(path)
    except OSError:
        return 0
    if not stat.S_ISDIR(st.st_mode):
        return st.st_size
    total = 0
    try:
        with os.scandir(path) as entries:
            for e in entries:
                total += tree_bytes(e.path) if e.is_dir(follow_symlinks=False) else e.stat(follow_symlinks=False).st_size
    except OSError:
        pass
    return total


def _files(folder: Path, suffixes: tuple[str, ...] | None = None) -> list[int]:
    """The sizes of the files (links followed, as `Path.is_file`) in `folder`, those ending in
    one of `suffixes` if given; [] when there is no such folder."""
    out = []
    try:
        with os.scandir(folder) as entries:
            for e in entries:
                if (suffixes is None or e.name.endswith(suffixes)) and e.is_file():
                    out.append(e.stat(follow_symlinks=False).st_size)
    except (FileNotFoundError, NotADirectoryError):
        pass
    return out


def remove_tree(path: Path) -> None:
    """Remove a file, a link or a folder (never what a link points to)."""
    try:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()
    except FileNotFoundError:
        pass


def version_stamp(path: Path) -> int | None:
    """The stamp (ns) of a kept version, `<stamp>.py` or `<stamp>.steps.json`; None for another file."""
    head = path.name.split(".", 1)[0]
    return int(head) if head.isdigit() and len(head) <= 24 else None


@dataclass
class Usage:
    """The bytes the program store keeps: live programs, steps and tasks; icons; versions; trash."""

    programs: int
    icons: int
    versions: int
    trash: int
    trash_items: int

    @property
    def total(self) -> int:
        return self.programs + self.icons + self.versions + self.trash

    def as_json(self) -> dict:
        return {"used": self.total, "limit": MAX_STORED_BYTES, "programs": self.programs, "icons": self.icons,
                "versions": self.versions, "trash": self.trash, "trash_items": self.trash_items}

    def sentence(self) -> str:
        """"Your programs use 31.8 MiB of 32 MiB (versions 20.1 MiB, trash 5 MiB, icons 12 KiB)"."""
        return (f"Your programs use {size_text(self.total)} of {size_text(MAX_STORED_BYTES)} (versions "
                f"{size_text(self.versions)}, trash {size_text(self.trash)}, icons {size_text(self.icons)})")


@dataclass
class Emptied:
    """What emptying the trash removed."""

    items: int
    bytes: int


class Folder:
    """The user's data folder, made 0700 when it is new."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True, mode=0o700)
        self.icons_dir = self.root / "icons"
        self.versions_dir = self.root / ".versions"
        self.trash_dir = self.root / ".trash"
        self.lock = threading.RLock()  # re-entrant: save_task adds words, import saves programs
        for path in remove_leftovers(self.root):
            log.info("removed %s, left by a save that was cut short", path)
        self.prune_versions()
        self.purge_trash()

    def read_lines(self, name: str) -> list[str]:
        """The lines of a list file (points.ini, words.ini) that hold something."""
        path = self.root / name
        if not path.is_file():
            return []
        return [line for line in decode(path.read_bytes())[0].splitlines() if line.strip()]

    # --------------------------------------------------------------------------- how much

    def usage(self) -> Usage:
        """How much the program store keeps now."""
        trash = list(self.trash_dir.iterdir()) if self.trash_dir.is_dir() else []
        return Usage(programs=sum(_files(self.root, LIVE_SUFFIXES)), icons=sum(_files(self.icons_dir)),
                     versions=tree_bytes(self.versions_dir), trash=sum(tree_bytes(p) for p in trash),
                     # a deleted program's versions go with it: one item, as the user deleted it
                     trash_items=sum(not p.name.endswith(".versions") for p in trash))

    def room_for(self, kind: str, grows: int, new: bool = True) -> None:
        """Refuse, with a sentence, a file that would take the folder past its limits: `grows`
        is every byte the write adds (the file's growth and the version it keeps, less the
        versions that go to make room), `new` that it adds a file of its `kind`."""
        self.purge_trash()
        if new:
            if kind == "program":
                count, most = len(_files(self.root, (".py",))), MAX_PROGRAMS
            elif kind == "task":
                count, most = len(_files(self.root, (".task",))), MAX_TASKS
            else:
                count, most = len(_files(self.icons_dir)), MAX_ICONS
            if count >= most:
                raise UserDataError(f"There are {count} {kind}s already, the most this folder keeps: "
                                    f"delete one you no longer use first.")
        usage = self.usage()
        if grows > 0 and usage.total + grows > MAX_STORED_BYTES:
            raise UserDataError(f"{usage.sentence()}; this {kind} needs {size_text(grows)} more, so nothing was "
                                f"saved. {HOW_TO_FREE}.")

    # --------------------------------------------------------------------------- versions

    def version_files(self, name: str) -> list[Path]:
        """The kept versions of program `name` (Python and steps), oldest first."""
        folder = self.versions_dir / name
        if not folder.is_dir():
            return []
        found = [(stamp, p) for p in folder.iterdir() if (stamp := version_stamp(p)) is not None and p.is_file()]
        return [p for _, p in sorted(found)]

    def versions_dropped(self, name: str, new: Sequence[tuple[str, int]] = ()) -> list[Path]:
        """The versions of `name` that go when the `new` ones (suffix, bytes) are kept too: past
        VERSIONS_KEPT of one kind, then the oldest while all are over VERSION_BYTES_KEPT. The
        newest always stays (the new ones, or the newest kept one when none is new)."""
        files = self.version_files(name)
        drop: list[Path] = []
        for suffix in VERSION_SUFFIXES:
            same = [p for p in files if p.name == f"{version_stamp(p)}{suffix}"]
            drop += same[:max(0, len(same) + sum(s == suffix for s, _ in new) - VERSIONS_KEPT)]
        kept = [p for p in files if p not in drop]
        sizes = {p: tree_bytes(p) for p in kept}
        total = sum(size for _, size in new) + sum(sizes.values())
        for p in kept if new else kept[:-1]:       # oldest first
            if total <= VERSION_BYTES_KEPT:
                break
            drop.append(p)
            total -= sizes[p]
        return drop

    def version_growth(self, name: str, new: Sequence[tuple[str, int]]) -> int:
        """The bytes keeping the `new` versions adds, once those they push out are gone."""
        return sum(size for _, size in new) - sum(tree_bytes(p) for p in self.versions_dropped(name, new))

    def prune_versions(self) -> None:
        """Every program's versions within the bounds (a folder kept by an older release may
        hold more)."""
        if self.versions_dir.is_dir():
            for folder in self.versions_dir.iterdir():
                if folder.is_dir() and not folder.is_symlink():
                    for old in self.versions_dropped(folder.name):
                        remove_tree(old)

    def keep_version(self, name: str, suffix: str, data: bytes) -> None:
        """Keep `data` as the newest version of `name` (`<stamp><suffix>`), then drop the
        versions past the bounds (`versions_dropped`)."""
        drop = self.versions_dropped(name, [(suffix, len(data))])
        folder = self.versions_dir / name
        folder.mkdir(parents=True, exist_ok=True)
        stamp = time.time_ns()
        while (folder / f"{stamp}{suffix}").exists():  # two saves within one clock tick
            stamp += 1
        write_atomic(folder / f"{stamp}{suffix}", data)
        for old in drop:
            remove_tree(old)

    # ------------------------------------------------------------------------------ trash

    def trash_stamp(self) -> str:
        self.trash_dir.mkdir(exist_ok=True)
        return time.strftime("%Y%m%d-%H%M%S") + f"-{time.time_ns() % 1_000_000_000:09d}"

    def trash_entries(self) -> list[tuple[float, Path]]:
        """The trash's entries with when each was deleted (its stamp, else its change time), oldest first."""
        if not self.trash_dir.is_dir():
            return []
        out = []
        for p in self.trash_dir.iterdir():
            try:
                when = time.mktime(time.strptime(p.name[:15], "%Y%m%d-%H%M%S"))
            except ValueError:
                try:
                    when = p.lstat().st_mtime
                except OSError:
                    continue
            out.append((when, p))
        return sorted(out, key=lambda e: (e[0], e[1].name))

    def purge_trash(self, now: float | None = None) -> None:
        """Forget what was deleted more than TRASH_DAYS ago, then the oldest while the trash holds
        more than MAX_TRASH_BYTES or MAX_TRASH_ITEMS entries."""
        entries = self.trash_entries()
        if not entries:
            return
        cutoff = (time.time() if now is None else now) - TRASH_DAYS * 86400
        sizes = [tree_bytes(p) for _, p in entries]
        total, count = sum(sizes), len(entries)
        for (when, path), size in zip(entries, sizes):
            if when >= cutoff and total <= MAX_TRASH_BYTES and count <= MAX_TRASH_ITEMS:
                break
            try:
                remove_tree(path)
            except OSError as exc:
                log.warning("could not purge %s from the trash: %s", path, exc)
                continue
            log.info("purged %s from the trash (%s)", path.name,
                     f"older than {TRASH_DAYS} days" if when < cutoff else "the trash was full")
            total, count = total - size, count - 1

    def empty_trash(self) -> Emptied:
        """Remove everything in the trash; what was there is gone for good."""
        entries = self.trash_entries()
        freed = 0
        for _, path in entries:
            size = tree_bytes(path)
            remove_tree(path)
            freed += size
        return Emptied(sum(not path.name.endswith(".versions") for _, path in entries), freed)
