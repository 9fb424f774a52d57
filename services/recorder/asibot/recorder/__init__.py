"""Recordings: the recorder service, the MCAP files it writes, and what reads them.

- `recorder`: the service (`python -m asibot.recorder --dir recordings`): every key on the
  bus into `<dir>/<date>-<time>.mcap`, msgpack payloads, zstd chunks flushed every second;
  `Session` splits a long session into parts.
- `thinning`: camera images recorded at a lower rate (`CameraThinner`).
- `rotation`: the folder kept within a size and an age (`Retention`, `prune`).
- `writer`: `LeanWriter`, the recorder's fast MCAP writer.
- `reader`: `iter_messages`, `Reading`, `summarize`, `list_recordings`; reads a file whose
  writer was killed up to its last complete chunk, and a live one as it was or following it.
- `index`: a file's contents from its summary or its chunk and message indexes.
- `live`: the writer's lock, and reading a file that is still being written.
- `replay`: `replay.replay(path, put, speed=...)` republishes a recording.
- `export`: `export_foxglove(path)` rewrites a recording for Foxglove (foxglove-sdk: its
  well-known schemas, images binary; JSON with our schema for the rest).
- `live_view`: `LiveView(bus)` serves the running stack on a Foxglove WebSocket server.
- `conversions` (one function per message type), `jsonable`, `frames`, `channels`: what the
  export and the live view share, so a session looks the same recorded or live.
"""

from __future__ import annotations

# `replay` stays the module: binding its function here would hide the module behind it.
from asibot.recorder import (channels, conversions, export, frames, index, jsonable, live, live_view, reader,
                             recorder, replay, rotation, thinning, writer)
from asibot.recorder.export import ExportSummary, export_foxglove
from asibot.recorder.live_view import LiveView
from asibot.recorder.reader import (NotARecording, Reading, Record, Summary, check_recording,
                                     iter_messages, list_recordings, summarize)
from asibot.recorder.recorder import McapRecorder, RecorderService, Session
from asibot.recorder.rotation import Retention, prune
from asibot.recorder.thinning import CameraThinner
from asibot.recorder.writer import LeanWriter

__all__ = [
    "channels", "conversions", "export", "frames", "index", "jsonable", "live", "live_view", "reader",
    "recorder", "replay", "rotation", "thinning", "writer",
    "ExportSummary", "export_foxglove", "LiveView",
    "NotARecording", "Reading", "Record", "Summary", "check_recording", "iter_messages",
    "list_recordings", "summarize",
    "McapRecorder", "RecorderService", "Session", "Retention", "prune", "CameraThinner", "LeanWriter",
]
