"""Writing a replay fixture: the chosen records of a session, compressed hard (it lives in git)."""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

from asibot.recorder.reader import Record
from asibot.recorder.writer import LeanWriter


def write_fixture(path: Path, label: str, records: Iterable[Record]) -> None:
    """Write `records` (as read by `iter_messages`) to `path`, one channel per key."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        writer = LeanWriter(f, chunk_size=8 << 20, level=19)     # small in git
        writer.start("", label)
        channels: dict[str, int] = {}
        for rec in records:
            if rec.key not in channels:
                channels[rec.key] = writer.register_channel(rec.key, "msgpack")
            writer.add_message(channels[rec.key], rec.log_time, rec.payload, rec.log_time)
        writer.finish()
