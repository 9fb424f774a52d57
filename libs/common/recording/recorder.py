"""The recorder service: every key on the bus into recordings/<session>.mcap.

MCAP with message encoding `msgpack` (self-describing, so schema id 0) and zstd chunks.
The current chunk is closed and flushed at least every second, so a killed recorder loses at
most the last second; `asibot.recording.reader.iter_messages` reads such a file up to its last
complete chunk.

    python -m asibot.recording [--dir recordings] [--exclude 'rb/*/camera/**']
"""

from __future__ import annotations

import argparse
import datetime as dt
import fnmatch
import logging
import os
import threading
from pathlib import Path
from typing import BinaryIO


from asibot import keys, runtime
from asibot.recording.writer import LeanWriter

log = logging.getLogger("asibot.recorder")

NAME = "recorder"
PROFILE = "asibot"
ENCODING = "msgpack"


def session_name(now: dt.datetime | None = None, label: str = "") -> str:
    stamp = (now or dt.datetime.now()).strftime("%Y%m%d-%H%M%S")
    return f"{stamp}-{label}" if label else stamp


class McapRecorder:
    """Writes raw bus payloads to one MCAP file; thread-safe; flushes every `flush_period` s."""

    def __init__(self, path: Path, flush_period: float = 1.0, chunk_size: int = 1 << 20) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.exists():
            raise FileExistsError(f"{self.path} exists; a recording is never overwritten")
        self._file: BinaryIO = open(self.path, "wb")
        self._writer = LeanWriter(self._file, chunk_size=chunk_size)
        self._writer.start(profile=PROFILE, library="asibot recorder")
        self._channels: dict[str, int] = {}
        self._lock = threading.Lock()
        self._dirty = False
        self._closed = False
        self.count = 0
        self._stop = threading.Event()
        self._flusher = threading.Thread(target=self._flush_loop, args=(flush_period,),
                                         name="mcap-flush", daemon=True)
        self._flusher.start()

    def write(self, key: str, payload: bytes, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        with self._lock:
            if self._closed:
                return
            channel = self._channels.get(key)
            if channel is None:
                channel = self._writer.register_channel(key, ENCODING)
                self._channels[key] = channel
            self._writer.add_message(channel, log_time_ns, payload,
                                     publish_time_ns if publish_time_ns is not None else log_time_ns,
                                     sequence=self.count & 0xFFFFFFFF)
            self.count += 1
            self._dirty = True

    def flush(self) -> None:
        """Close the open chunk and push it to the disk."""
        with self._lock:
            if self._closed or not self._dirty:
                return
            self._writer.flush()  # closes the current chunk
            self._file.flush()
            os.fsync(self._file.fileno())
            self._dirty = False

    def _flush_loop(self, period: float) -> None:
        while not self._stop.wait(period):
            try:
                self.flush()
            except Exception:
                log.exception("flush failed")

    def close(self) -> None:
        """Finish the file with its summary, so readers can seek; idempotent."""
        self._stop.set()
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._writer.finish()
            self._file.close()


class RecorderService(runtime.Service):
    """Subscribes to every key and hands each sample to an McapRecorder."""

    def __init__(self, bus, directory: Path, label: str = "", exclude: list[str] | None = None) -> None:
        self.recorder = McapRecorder(Path(directory) / f"{session_name(label=label)}.mcap")
        self.exclude = list(exclude or [])
        self.skipped = 0
        self._sub = bus.subscribe_raw(keys.EVERYTHING, self._on_sample, maxsize=1 << 16)
        log.info("recording to %s", self.recorder.path)

    def _on_sample(self, key: str, payload: bytes, t_ns: int) -> None:
        if self.exclude and any(fnmatch.fnmatchcase(key, p) for p in self.exclude):
            self.skipped += 1
            return
        self.recorder.write(key, payload, t_ns)

    def health(self) -> dict:
        return {"file": str(self.recorder.path), "messages": self.recorder.count,
                "skipped": self.skipped}

    def close(self) -> None:
        self._sub.close()
        self.recorder.close()
        log.info("wrote %d messages to %s", self.recorder.count, self.recorder.path)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dir", default=os.environ.get("ASIBOT_RECORDINGS", "recordings"),
                   help="folder for the .mcap files (default: recordings)")
    p.add_argument("--label", default=os.environ.get("ASIBOT_PROFILE", ""), help="added to the file name")
    p.add_argument("--exclude", action="append", default=[],
                   help="key pattern (fnmatch, e.g. 'rb/*/camera/*/rgb') not to record; repeatable")


def build(bus, args) -> RecorderService:
    return RecorderService(bus, Path(args.dir), args.label, args.exclude)

