"""Files still being written: the writer's lock, and what a reader sees of such a file.

A recorder holds an exclusive `flock` on its file for as long as it writes it. The kernel
drops the lock when the recorder dies, even by SIGKILL, so a file without a summary whose lock
is free was cut short ("recovered"), and one whose lock is held is live. Readers never take the
lock for longer than the test, so they never hold a writer up.

A reader of a live file must decide where it ends: `Snapshot` ends where the file ended when
reading began (an export of a live recording stops instead of chasing the writer), `Follow`
waits for more until the writer lets go of the file or the reader is told to stop.
"""

from __future__ import annotations

import fcntl
import os
import threading
from pathlib import Path
from typing import BinaryIO

POLL_S = 0.1
"""How often a follower looks for more: well under the writer's one-second chunks."""


def hold_writer_lock(f: BinaryIO) -> None:
    """Mark `f` as being written until it is closed (or its process dies)."""
    fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)


def being_written(path: Path | str) -> bool:
    """Whether a live writer holds `path`; False for a missing file."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)   # also drops the shared lock, if it was granted
    return False


class Snapshot:
    """`f` as it was when this was made: reads end at that size, whatever is appended later."""

    def __init__(self, f: BinaryIO) -> None:
        self._f = f
        self._left = os.fstat(f.fileno()).st_size - f.tell()

    def read(self, n: int = -1) -> bytes:
        n = self._left if n < 0 else min(n, self._left)
        data = self._f.read(n)
        self._left -= len(data)
        return data


class Follow:
    """`f` while its writer appends: a read waits for its bytes until the writer closes the
    file (the lock at `path` is free) or `stop` is set, and then returns what there is."""

    def __init__(self, f: BinaryIO, path: Path | str, stop: threading.Event | None = None) -> None:
        self._f, self._path = f, Path(path)
        self._stop = stop or threading.Event()
        self.stopped = False     # True when `stop` ended the reading, not the writer

    def read(self, n: int = -1) -> bytes:
        if n < 0:
            return self._f.read()
        got = bytearray(self._f.read(n))
        while len(got) < n:
            # The lock first, then the data: bytes written just before the writer let go are read.
            done = not being_written(self._path)
            got += self._f.read(n - len(got))
            if done or len(got) == n:
                break
            if self._stop.wait(POLL_S):
                self.stopped = True
                break
        return bytes(got)
