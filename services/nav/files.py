"""Where navigation keeps the user's data, and how it writes a file so a crash never truncates it.

The data folder is the one the web Task Creator uses (services/web/userdata.py): $ASIBOT_DATA,
else $XDG_DATA_HOME/asibot, else ~/.local/share/asibot; navigation's files go in its `nav/`.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path


def data_dir() -> Path:
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
    with contextlib.suppress(OSError):  # some filesystems cannot sync a folder
        dfd = os.open(path.parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
