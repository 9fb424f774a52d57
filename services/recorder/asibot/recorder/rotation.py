"""Keeping the recordings folder within a size and an age: the oldest recordings go first.

Only the recordings directly in the folder are candidates: never a file a recorder is
writing (its lock is held), never a file that is not an MCAP recording, never anything in a subfolder (`fixtures/` is committed test data,
`foxglove/` holds exports the user asked for).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path

from asibot.recorder.live import being_written
from asibot.recorder.reader import NotARecording, check_recording

log = logging.getLogger("asibot.recorder")

DEFAULT_MAX_BYTES = 10_000_000_000
#: No age limit unless asked: a session a user kept is theirs; the size limit alone keeps
#: the disk from filling, and removes nothing while there is room.
DEFAULT_MAX_AGE_DAYS = 0.0
DAY_S = 86400.0


@dataclasses.dataclass(frozen=True)
class Retention:
    """At most `max_bytes` of recordings, none older than `max_age_days`; 0 means no limit."""

    max_bytes: int = DEFAULT_MAX_BYTES
    max_age_days: float = DEFAULT_MAX_AGE_DAYS

    def __post_init__(self) -> None:
        if self.max_bytes < 0 or not self.max_age_days >= 0:
            raise ValueError("the recordings' size and age limits must be 0 (no limit) or more, "
                             f"not {self.max_bytes} bytes and {self.max_age_days} days")


@dataclasses.dataclass(frozen=True)
class FileInfo:
    path: Path
    size: int
    mtime: float      # s since the epoch: when it was last written


def over_limits(files: list[FileInfo], retention: Retention, now: float, keep: set[Path]) -> list[FileInfo]:
    """Which of `files` to remove, oldest first: all too old, then the oldest until the total
    fits. Files in `keep` count toward the total but are never chosen."""
    removable = sorted((f for f in files if f.path not in keep), key=lambda f: (f.mtime, f.path.name))
    chosen: list[FileInfo] = []
    if retention.max_age_days:
        oldest_allowed = now - retention.max_age_days * DAY_S
        chosen = [f for f in removable if f.mtime < oldest_allowed]
    if retention.max_bytes:
        total = sum(f.size for f in files) - sum(f.size for f in chosen)
        for f in removable:
            if total <= retention.max_bytes:
                break
            if f not in chosen:
                chosen.append(f)
                total -= f.size
    return chosen


def recordings_in(folder: Path) -> list[FileInfo]:
    found = []
    for p in folder.glob("*.mcap"):
        try:
            st = p.stat()
            check_recording(p)
        except (FileNotFoundError, IsADirectoryError, NotARecording):
            continue                # removed meanwhile (another recorder's rotation), or not ours
        found.append(FileInfo(p, st.st_size, st.st_mtime))
    return found


def prune(folder: Path | str, retention: Retention, keep: tuple[Path, ...] = (),
          now: float | None = None) -> list[Path]:
    """Remove the recordings of `folder` that exceed `retention`; returns (and logs) them."""
    folder = Path(folder)
    now = time.time() if now is None else now
    files = recordings_in(folder)
    live = {f.path for f in files if being_written(f.path)} | {Path(p) for p in keep}
    removed = []
    for f in over_limits(files, retention, now, live):
        try:
            f.path.unlink()
        except FileNotFoundError:
            continue
        except OSError as exc:
            log.warning("could not remove the old recording %s (%s); remove it by hand", f.path, exc)
            continue
        age_days = (now - f.mtime) / DAY_S
        log.info("removed the old recording %s (%.1f MB, %.1f days old) to keep %s within %s",
                 f.path.name, f.size / 1e6, age_days, folder, describe(retention))
        removed.append(f.path)
    return removed


def describe(retention: Retention) -> str:
    size = f"{retention.max_bytes / 1e9:g} GB" if retention.max_bytes else "no size limit"
    age = f"{retention.max_age_days:g} days" if retention.max_age_days else "no age limit"
    return f"{size} and {age}"
