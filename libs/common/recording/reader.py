"""Reading and listing recordings, including files whose writer was killed.

Recovery: a file without its summary (the recorder crashed or was SIGKILLed) cannot be read
by the seeking reader, which starts at the footer. `iter_messages` therefore streams with
mcap's NonSeekingReader in file order and stops cleanly at the first incomplete record, which
yields every message of every complete chunk (the recorder closes a chunk every second).
"""

from __future__ import annotations

import dataclasses
import struct
from pathlib import Path
from typing import Iterator

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader

from asibot.messages import TYPE_FIELD, decode_any
from asibot.recording.writer import MAGIC


class NotARecording(ValueError):
    """The file is not an MCAP recording (its first bytes are not the MCAP magic)."""


def _check_magic(f, path: Path) -> None:
    if f.read(len(MAGIC)) != MAGIC:
        raise NotARecording(f"{path} is not an MCAP recording (`asibot recordings` lists them)")
    f.seek(0)


def check_recording(path: Path | str) -> None:
    """Raise NotARecording unless `path` starts like an MCAP file."""
    with open(path, "rb") as f:
        _check_magic(f, Path(path))


@dataclasses.dataclass
class Record:
    key: str
    log_time: int      # ns
    payload: bytes


@dataclasses.dataclass
class Summary:
    path: Path
    start: int = 0
    end: int = 0
    messages: int = 0
    counts: dict[str, int] = dataclasses.field(default_factory=dict)
    types: dict[str, str] = dataclasses.field(default_factory=dict)
    complete: bool = True
    unreadable: bool = False   # not an MCAP file at all

    @property
    def duration(self) -> float:
        return (self.end - self.start) / 1e9 if self.messages else 0.0


class Reading:
    """Iterates a file's messages; afterwards `complete` says whether it ended cleanly."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.complete = True

    def __iter__(self) -> Iterator[Record]:
        with open(self.path, "rb") as f:
            _check_magic(f, self.path)
            reader = NonSeekingReader(f, validate_crcs=False)
            it = reader.iter_messages(log_time_order=False)
            while True:
                try:
                    _schema, channel, message = next(it)
                except StopIteration:
                    return
                except (McapError, EOFError, ValueError, OSError, AssertionError, KeyError, struct.error):
                    # Truncated tail (the reader raises EndOfFile or a decode error on a
                    # half-written record): everything before it has been delivered.
                    self.complete = False
                    return
                yield Record(channel.topic, message.log_time, message.data)


def iter_messages(path: Path | str) -> Iterator[Record]:
    """Every readable message in file order (recorded order); tolerates a truncated file."""
    return iter(Reading(Path(path)))


def summarize(path: Path | str) -> Summary:
    reading = Reading(Path(path))
    s = Summary(Path(path))
    for rec in reading:
        if s.messages == 0:
            s.start = s.end = rec.log_time
        s.start, s.end = min(s.start, rec.log_time), max(s.end, rec.log_time)
        s.messages += 1
        s.counts[rec.key] = s.counts.get(rec.key, 0) + 1
        if rec.key not in s.types:
            try:
                body = decode_any(rec.payload)
                s.types[rec.key] = body.get(TYPE_FIELD, "?") if isinstance(body, dict) else "?"
            except Exception:
                s.types[rec.key] = "?"
    s.complete = reading.complete
    return s


def list_recordings(directory: Path | str) -> list[Summary]:
    d = Path(directory)
    if not d.is_dir():
        return []
    found = []
    for p in sorted(d.glob("*.mcap")):
        try:
            found.append(summarize(p))
        except NotARecording:
            found.append(Summary(p, complete=False, unreadable=True))
    return found
