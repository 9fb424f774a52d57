"""The user's data folder and how a user file is written, so a crash never truncates it.

One folder for everything a user makes (the web Task Creator's points, programs and tasks;
navigation's places in its `nav/`): $ASIBOT_DATA, else $XDG_DATA_HOME/asibot, else
~/.local/share/asibot, as users of other desktop programs expect.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import time
from pathlib import Path

#: A temporary file of write_atomic this much older than now was left by a killed process
#: (a younger one may be another process's save in progress).
LEFTOVER_AGE_S = 60.0


def data_dir() -> Path:
    """The user's data folder (see above)."""
    if os.environ.get("ASIBOT_DATA"):
        return Path(os.environ["ASIBOT_DATA"]).expanduser()
    xdg = os.environ.get("XDG_DATA_HOME", "")
    if xdg and os.path.isabs(xdg):  # the XDG spec says relative paths are to be ignored
        return Path(xdg) / "asibot"
    return Path.home() / ".local" / "share" / "asibot"


def write_atomic(path: Path, data: bytes) -> None:
    """Replace `path` by `data` whole or not at all (temp file, fsync, rename, fsync the folder)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    fsync_dir(path.parent)


def remove_leftovers(folder: Path) -> list[Path]:
    """Delete the temporary files write_atomic left in `folder` and below when its process was
    killed mid-save (the file it was replacing is whole); the paths removed."""
    removed = []
    now = time.time()
    for path in folder.rglob(".*.tmp"):
        with contextlib.suppress(OSError):   # gone already, or not ours to delete
            if path.is_file() and now - path.stat().st_mtime > LEFTOVER_AGE_S:
                path.unlink()
                removed.append(path)
    return removed


def fsync_dir(folder: Path) -> None:
    """Make a rename (or a new file) in `folder` durable: only a synced folder keeps it."""
    with contextlib.suppress(OSError):  # some filesystems cannot sync a folder
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
