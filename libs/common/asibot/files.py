"""The user's data folder, how a user file is written so a crash never truncates it, and
the one rule for what the stack keeps on disk: private to its user.

One folder for everything a user makes (the web Task Creator's points, programs and tasks;
navigation's places in its `nav/`): $ASIBOT_DATA, else $XDG_DATA_HOME/asibot, else
~/.local/share/asibot, as users of other desktop programs expect.

Private (issue 51): every folder the stack makes for the user's data, the recordings (which
hold the page's microphone audio and the camera pictures) or its secrets is 0700 and every
such file 0600, whatever the umask and whichever process makes it first: `private_dir` and
`open_private` (write_atomic's files are 0600 too). A folder of ours found open to others is
made 0700 when a service opens it, and the log says so once.
"""

from __future__ import annotations

import contextlib
import logging
import os
import stat
import tempfile
import time
from pathlib import Path
from typing import BinaryIO, cast

log = logging.getLogger("asibot.files")

PRIVATE_DIR = 0o700
PRIVATE_FILE = 0o600

#: A temporary file of write_atomic this much older than now was left by a killed process
#: (a younger one may be another process's save in progress).
LEFTOVER_AGE_S = 60.0


def data_dir() -> Path:
    """The user's data folder (see above), made private (`private_dir`) here, so that it is
    0700 whichever service asks for it first (one that makes a subfolder with
    `mkdir(parents=True)` would leave it 0755). A folder that cannot be made is still named:
    its user's own write then says why."""
    if os.environ.get("ASIBOT_DATA"):
        folder = Path(os.environ["ASIBOT_DATA"]).expanduser()
    else:
        xdg = os.environ.get("XDG_DATA_HOME", "")
        if xdg and os.path.isabs(xdg):  # the XDG spec says relative paths are to be ignored
            folder = Path(xdg) / "asibot"
        else:
            folder = Path.home() / ".local" / "share" / "asibot"
    try:
        private_dir(folder)
    except OSError as exc:
        _say_once(folder, logging.WARNING, "the user's data folder %s cannot be made (%s)", folder, exc)
    return folder


_said: set[tuple[str, int]] = set()


def _say_once(path: Path, level: int, text: str, *args: object) -> None:
    """Log `text` once per folder and level in this process (services open their folders often)."""
    if (str(path), level) not in _said:
        _said.add((str(path), level))
        log.log(level, text, *args)


def private_dir(path: Path | str, tighten: bool = True) -> Path:
    """`path` as a folder only its owner may enter, made if needed; returns it.

    Each missing folder on the way, `path` included, is made 0700 whatever the umask. An
    existing `path` open to others is made 0700 (`tighten`, for a folder that is the stack's
    own: the data folder, the recordings), and the log says so once; without `tighten` (a
    folder the user named for one file, such as an export's) it is left as it is. A folder
    that is not its process's to change is logged once and used as it is."""
    path = Path(path)
    missing = []
    p = path
    while not os.path.lexists(p) and p != p.parent:
        missing.append(p)
        p = p.parent
    for p in reversed(missing):
        try:
            os.mkdir(p, PRIVATE_DIR)
        except FileExistsError:      # another process made it meanwhile
            if tighten:
                _tighten(p)
            continue
        os.chmod(p, PRIVATE_DIR)      # the umask may have taken bits from the owner's too
    if not path.is_dir():
        raise NotADirectoryError(f"{path} is not a folder")
    if tighten and not missing:
        _tighten(path)
    return path


def _tighten(folder: Path) -> None:
    mode = stat.S_IMODE(os.stat(folder).st_mode)
    if not mode & 0o077:
        return
    try:
        os.chmod(folder, PRIVATE_DIR)
    except OSError as exc:
        _say_once(folder, logging.WARNING, "%s is open to other users (%03o) and could not be made private "
                  "(%s): `chmod 700` it as its owner", folder, mode, exc.strerror or exc)
        return
    _say_once(folder, logging.INFO, "%s was open to other users (%03o): made private (0700), as the "
              "stack keeps every folder of its own", folder, mode)


_OPEN_FLAGS = {"wb": os.O_WRONLY | os.O_CREAT | os.O_TRUNC,
               "xb": os.O_WRONLY | os.O_CREAT | os.O_EXCL,
               "ab": os.O_WRONLY | os.O_CREAT | os.O_APPEND}


def open_private(path: Path | str, mode: str = "wb") -> BinaryIO:
    """`path` opened for writing as a file only its owner may read or write (0600, whatever
    the umask, an existing file too): `wb` makes or empties it, `xb` refuses an existing one
    (FileExistsError), `ab` appends."""
    fd = os.open(path, _OPEN_FLAGS[mode] | getattr(os, "O_CLOEXEC", 0), PRIVATE_FILE)
    try:
        os.fchmod(fd, PRIVATE_FILE)
        return cast(BinaryIO, os.fdopen(fd, mode))
    except BaseException:
        os.close(fd)
        raise


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
