"""Recordings: the recorder service, the MCAP files it writes, and what reads them.

- `recorder`: the service (`python -m asibot.recording --dir recordings`): every key on the
  bus into `<dir>/<date>-<time>.mcap`, msgpack payloads, zstd chunks flushed every second.
- `writer`: `LeanWriter`, the recorder's fast MCAP writer.
- `reader`: `iter_messages`, `Reading`, `summarize`, `list_recordings`; reads a file whose
  writer was killed up to its last complete chunk.
- `replay`: `replay.replay(path, put, speed=...)` republishes a recording.
- `export`: `export_foxglove(path)` rewrites a recording as JSON with Foxglove's schemas.
"""

from __future__ import annotations

# `replay` stays the module: binding its function here would hide the module behind it.
from asibot.recording import export, reader, recorder, replay, writer
from asibot.recording.export import ExportSummary, export_foxglove
from asibot.recording.reader import (NotARecording, Reading, Record, Summary, check_recording,
                                     iter_messages, list_recordings, summarize)
from asibot.recording.recorder import McapRecorder, RecorderService
from asibot.recording.writer import LeanWriter

__all__ = [
    "export", "reader", "recorder", "replay", "writer",
    "ExportSummary", "export_foxglove",
    "NotARecording", "Reading", "Record", "Summary", "check_recording", "iter_messages",
    "list_recordings", "summarize",
    "McapRecorder", "RecorderService", "LeanWriter",
]
