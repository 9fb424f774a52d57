"""Reading and listing recordings, including files still being written or whose writer was killed.

Recovery: a file without its summary (the recorder crashed or was SIGKILLed) cannot be read
by the seeking reader, which starts at the footer. `iter_messages` therefore streams with
mcap's NonSeekingReader in file order and stops cleanly at the first incomplete record, which
yields every message of every complete chunk (the recorder closes a chunk every second).

Listing (`summarize`) reads a finished file's summary section and nothing else, a live or cut
file's chunk and message indexes (`asibot.recorder.index`), and scans only what neither serves.
"""

from __future__ import annotations

import dataclasses
import struct
import threading
from pathlib import Path
from typing import BinaryIO, Iterator

import zstandard
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader

from asibot.messages import TYPE_FIELD, decode_any
from asibot.recorder import index
from asibot.recorder.live import Follow, Snapshot, being_written
from asibot.recorder.writer import MAGIC, TYPE_METADATA


# What mcap and zstd raise on a half-written record or a damaged chunk: the reading stops there.
_UNREADABLE = (McapError, EOFError, ValueError, OSError, AssertionError, KeyError, struct.error,
               zstandard.ZstdError)


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
    live: bool = False         # a recorder is writing it now (so it is not complete yet)

    @property
    def duration(self) -> float:
        return (self.end - self.start) / 1e9 if self.messages else 0.0


def payload_type(payload: bytes) -> str:
    """The message type a recorded payload says it is (its `_type`), or "?"."""
    try:
        body = decode_any(payload)
    except Exception:
        return "?"
    return body.get(TYPE_FIELD, "?") if isinstance(body, dict) else "?"


class Reading:
    """Iterates a file's messages; afterwards `complete` says whether it ended cleanly.

    A file still being written is read as it was when the reading began, unless `follow`:
    then the reading waits for what the writer appends, until it closes the file or `stop`
    is set (`stopped` tells which).
    """

    def __init__(self, path: Path, follow: bool = False, stop: threading.Event | None = None) -> None:
        self.path = Path(path)
        self.complete = True
        self.live = False
        self.stopped = False
        self._follow, self._stop = follow, stop

    def __iter__(self) -> Iterator[Record]:
        with open(self.path, "rb") as f:
            _check_magic(f, self.path)
            self.live = being_written(self.path)
            source = Follow(f, self.path, self._stop) if self._follow else Snapshot(f)
            # mcap annotates IO[bytes], but its NonSeekingReader only ever calls read().
            reader = NonSeekingReader(source, validate_crcs=False)  # type: ignore[arg-type]
            it = reader.iter_messages(log_time_order=False)
            try:
                while True:
                    try:
                        _schema, channel, message = next(it)
                    except StopIteration:
                        return
                    except _UNREADABLE:
                        # A truncated tail or a damaged chunk: everything before it has been delivered.
                        self.complete = False
                        return
                    yield Record(channel.topic, message.log_time, message.data)
            finally:
                self.stopped = isinstance(source, Follow) and source.stopped


def iter_messages(path: Path | str) -> Iterator[Record]:
    """Every readable message in file order (recorded order); tolerates a truncated file."""
    return iter(Reading(Path(path)))


def summarize(path: Path | str) -> Summary:
    """Duration, counts and types of a recording, read from its indexes where it has them."""
    path = Path(path)
    with open(path, "rb") as f:
        _check_magic(f, path)
        live = being_written(path)
        summary = None if live else index.read_summary(f)
        if summary is not None:
            return _from_summary(f, path, summary)
        try:
            chunks = index.walk_chunks(f)
            s = _from_chunks(f, path, chunks) if chunks is not None else None
        except _UNREADABLE:
            s = None    # a damaged chunk: the scan below reads up to it and says so
        if s is not None:
            s.live = live
            return s
    s = _scan(path)
    s.live = live
    return s


def _from_summary(f: BinaryIO, path: Path, summary) -> Summary:
    stats = summary.statistics
    s = Summary(path, start=stats.message_start_time, end=stats.message_end_time,
                messages=stats.message_count)
    topics = {cid: ch.topic for cid, ch in summary.channels.items()}
    for cid, n in stats.channel_message_counts.items():
        s.counts[topics[cid]] = s.counts.get(topics[cid], 0) + n
    untyped = set()
    for cid, ch in summary.channels.items():
        if TYPE_METADATA in ch.metadata:
            s.types[ch.topic] = ch.metadata[TYPE_METADATA]
        elif stats.channel_message_counts.get(cid):
            untyped.add(cid)
    # Older recordings name no type: the first chunk holding each such channel tells it.
    for chunk in index.chunk_indexes(f) if untyped else []:
        if not untyped:
            break
        if untyped & chunk.message_index_offsets.keys():
            try:
                records = index.chunk_records(f, chunk.chunk_start_offset)
            except _UNREADABLE:
                continue    # a damaged chunk: its channels' types stay unknown
            for cid, payload in index.first_payloads(records).items():
                if cid in untyped:
                    s.types[topics[cid]] = payload_type(payload)
                    untyped.discard(cid)
    return s


def _from_chunks(f: BinaryIO, path: Path, chunks: list[index.ChunkInfo]) -> Summary | None:
    """A file without a summary, from chunk headers and message indexes; the chunks that bring
    a new channel, and the last one (its indexes may not have been written), are decompressed.
    None when an index names a channel no chunk defines: scan such a file."""
    s = Summary(path, complete=False)
    topics: dict[int, str] = {}
    for i, chunk in enumerate(chunks):
        last = i == len(chunks) - 1
        if last or not chunk.counts.keys() <= topics.keys():
            records = index.chunk_records(f, chunk.offset)
            for cid, ch in index.channels_in(records).items():
                topics[cid] = ch.topic
                if TYPE_METADATA in ch.metadata:
                    s.types.setdefault(ch.topic, ch.metadata[TYPE_METADATA])
            for cid, payload in index.first_payloads(records).items():
                if cid in topics and topics[cid] not in s.types:
                    s.types[topics[cid]] = payload_type(payload)
            if last:
                chunk.counts = index.chunk_counts(records)
        n = sum(chunk.counts.values())
        if not n:
            continue
        if not chunk.counts.keys() <= topics.keys():
            return None
        s.start = chunk.start if s.messages == 0 else min(s.start, chunk.start)
        s.end = max(s.end, chunk.end)
        s.messages += n
        for cid, count in chunk.counts.items():
            s.counts[topics[cid]] = s.counts.get(topics[cid], 0) + count
    return s


def _scan(path: Path) -> Summary:
    """Every message read: for files the indexes cannot describe."""
    reading = Reading(path)
    s = Summary(path)
    for rec in reading:
        if s.messages == 0:
            s.start = s.end = rec.log_time
        s.start, s.end = min(s.start, rec.log_time), max(s.end, rec.log_time)
        s.messages += 1
        s.counts[rec.key] = s.counts.get(rec.key, 0) + 1
        if rec.key not in s.types:
            s.types[rec.key] = payload_type(rec.payload)
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
