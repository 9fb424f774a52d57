"""Export a recording so Foxglove (or Lichtblick) opens it: `asibot export FILE --foxglove`.

Recordings are msgpack, which Foxglove cannot decode (reference middleware.md 0.7), so the
export rewrites every message in a new MCAP file written by Foxglove's SDK (foxglove-sdk):
well-known Foxglove schemas in protobuf where a message has one (images stay binary), JSON
with our own schema for the rest. `asibot.recorder.conversions` has the table of what
becomes what; the live view (`asibot foxglove`) converts the bus the same way.
"""

from __future__ import annotations

import dataclasses
import os
import threading
from pathlib import Path

import foxglove
from foxglove.mcap import MCAPCompression, MCAPWriteOptions

from asibot.errors import MessageError
from asibot.files import open_private, private_dir
from asibot.messages import decode_any
from asibot.recorder.channels import Channels
from asibot.recorder.conversions import convert
from asibot.recorder.reader import Reading, check_recording

__all__ = ["ExportSummary", "convert", "default_output", "export_foxglove"]


@dataclasses.dataclass
class ExportSummary:
    source: Path
    output: Path
    messages: int = 0          # messages written
    skipped: int = 0           # not MessagePack, not a valid message, or another type than its topic's
    schemas: dict[str, str] = dataclasses.field(default_factory=dict)   # topic -> schema name
    complete: bool = True      # False when the source ended in a truncated chunk
    live: bool = False         # the source was being written when the export began
    stopped: bool = False      # a follow was ended by `stop` (Ctrl-C), not by the writer


def default_output(source: Path) -> Path:
    """`recordings/foxglove/<name>.mcap`: beside the recordings, not among them."""
    return source.parent / "foxglove" / source.name


def _write(records: Reading, output: Path, summary: ExportSummary) -> None:
    """Every record converted into `output`, a new MCAP file flushed to the disk."""
    context = foxglove.Context()       # this export's channels only
    channels = Channels(context)
    options = MCAPWriteOptions(compression=MCAPCompression.Zstd, profile="")
    with open_private(output, "wb") as f:      # 0600: it holds what the recording holds
        with foxglove.open_mcap(f, context=context, writer_options=options):
            for rec in records:
                try:
                    out = convert(rec.key, decode_any(rec.payload))
                except MessageError:
                    summary.skipped += 1
                    continue
                for topic, message in out:
                    if channels.log(topic, message, rec.log_time):
                        summary.messages += 1
                    else:
                        summary.skipped += 1
        f.flush()
        os.fsync(f.fileno())
    summary.schemas = dict(channels.schemas)


def export_foxglove(source: Path | str, output: Path | str | None = None, *, follow: bool = False,
                    stop: threading.Event | None = None) -> ExportSummary:
    """Write `output` (default: `default_output(source)`) and summarise it.

    A recording still being written is exported as it was when the export began; with
    `follow`, the export goes on with what the recorder appends until it closes the file or
    `stop` is set. The output appears atomically: a crash leaves no half-written file under
    its name, and the source recording is never touched. It is 0600, as recordings are
    (asibot.files.open_private), in a folder made 0700 if missing.
    """
    source = Path(source)
    check_recording(source)
    chosen = output is not None
    output = Path(output) if output is not None else default_output(source)
    if output.resolve() == source.resolve():
        raise ValueError(f"the export would overwrite the recording {source}; choose another output file")
    summary = ExportSummary(source, output)
    # recordings/foxglove/ is ours, made or found 0700; a folder the user chose is only made if missing.
    private_dir(output.parent, tighten=not chosen)
    tmp = output.with_name(f".{output.name}.partial")
    records = Reading(source, follow=follow, stop=stop)
    try:
        _write(records, tmp, summary)
        summary.complete, summary.live, summary.stopped = records.complete, records.live, records.stopped
        os.replace(tmp, output)
    finally:
        tmp.unlink(missing_ok=True)
    return summary
