"""The data folder itself: where each kind of file lives, one lock for all of them, the trash,
and how much the folder keeps."""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path

from asibot.files import remove_leftovers
from asibot.web.userdata.errors import UserDataError

log = logging.getLogger("asibot.web.userdata")

#: How much the folder keeps: programs, uploaded icons, and their bytes together (versions and
#: the trash are bounded by VERSIONS_KEPT and by what was once within these).
MAX_PROGRAMS = 200
MAX_ICONS = 100
MAX_STORED_BYTES = 32 * 1024 * 1024


def decode(data: bytes) -> tuple[str, bool]:
    """Text of a user file; the seed's files may be Latin-1 (Spanish comments), then True."""
    try:
        return data.decode("utf-8-sig"), False
    except UnicodeDecodeError:
        return data.decode("cp1252", errors="replace"), True


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

    def read_lines(self, name: str) -> list[str]:
        """The lines of a list file (points.ini, words.ini) that hold something."""
        path = self.root / name
        if not path.is_file():
            return []
        return [line for line in decode(path.read_bytes())[0].splitlines() if line.strip()]

    def trash_stamp(self) -> str:
        self.trash_dir.mkdir(exist_ok=True)
        return time.strftime("%Y%m%d-%H%M%S") + f"-{time.time_ns() % 1_000_000_000:09d}"

    def room_for(self, kind: str, grows: int, new: bool = True) -> None:
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
