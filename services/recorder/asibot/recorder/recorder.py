"""The recorder service: every key on the bus into recordings/<session>.mcap.

MCAP with message encoding `msgpack` (self-describing, so schema id 0) and zstd chunks.
The current chunk is closed and flushed at least every second, so a killed recorder loses at
most the last second; `asibot.recorder.reader.iter_messages` reads such a file up to its last
complete chunk.

    python -m asibot.recorder [--dir recordings] [--exclude 'rb/*/camera/**'] [--camera-hz 2]
        [--max-bytes 10G] [--max-age-days DAYS] [--max-file-bytes 500M] [--no-audio] [--no-pictures]

A session is split into parts of at most `--max-file-bytes` (plus one chunk), so rotation can
delete a long session piece by piece and each file stays quick to export. Camera images are
recorded at `--camera-hz` (`asibot.recorder.thinning`), and the folder is kept within
`--max-bytes` (and `--max-age-days`, when given) by deleting the oldest recordings
(`asibot.recorder.rotation`).

Recordings hold what the stack hears and sees: the web page's microphone audio
(`voice/audio/<source>`) and the cameras' pictures (`rb/<robot>/camera/<name>/depth|rgb`).
The folder is 0700 and every file 0600 (asibot.files.private_dir, open_private), so no other
user of the machine, and no user program in its sandbox, reads them; `--no-audio` and
`--no-pictures` (or $ASIBOT_RECORD_WITHOUT=audio,pictures) leave them out altogether.
"""

from __future__ import annotations

import argparse
import datetime as dt
import fnmatch
import logging
import os
import re
import threading
from pathlib import Path
from typing import BinaryIO, Callable

from asibot import keys, runtime
from asibot.files import open_private, private_dir
from asibot.recorder.live import hold_writer_lock
from asibot.recorder.reader import payload_type
from asibot.recorder.rotation import DEFAULT_MAX_AGE_DAYS, DEFAULT_MAX_BYTES, Retention, describe, prune
from asibot.recorder.thinning import DEFAULT_CAMERA_HZ, IMAGE_PATTERNS, CameraThinner
from asibot.recorder.writer import TYPE_METADATA, LeanWriter

log = logging.getLogger("asibot.recorder")

NAME = "recorder"
PROFILE = "asibot"
ENCODING = "msgpack"
DEFAULT_MAX_FILE_BYTES = 500_000_000
RING = 1 << 17
"""Samples that may wait for the recorder; past that the oldest are dropped. bench/bench_bus.py's
burst of 200,000 small messages comes at about 480,000 a second and is written at about
300,000, so about 75,000 wait at its end, more than the 65,536 of the ring before (which
dropped some in 1 run of 5). A waiting small sample costs about 350 bytes (46 MB for a full
ring, measured). The count bounds memory only for small messages: camera images, 1.2 MB
each, would fill it only if the disk stopped for hours (they come 20 a second at most)."""
PRUNE_PERIOD_S = 60.0
"""How often the folder is checked against the limits, besides at start and at each new part."""


WITHOUT_ENV = "ASIBOT_RECORD_WITHOUT"
"""What recordings leave out, comma-separated: `audio`, `pictures` (--no-audio, --no-pictures)."""
LEFT_OUT = {"audio": (keys.ALL_VOICE_AUDIO,), "pictures": IMAGE_PATTERNS}
"""The keys each of them stands for: the microphones' audio, the cameras' images (not their
calibrations, `info`, which hold nothing of the room)."""


def without_from_env(value: str | None = None) -> set[str]:
    """The words of $ASIBOT_RECORD_WITHOUT (`audio,pictures`); ValueError for another word."""
    text = os.environ.get(WITHOUT_ENV, "") if value is None else value
    words = {w for w in re.split(r"[\s,]+", text.strip().lower()) if w and w != "none"}
    unknown = sorted(words - LEFT_OUT.keys())
    if unknown:
        raise ValueError(f"{WITHOUT_ENV}={text!r}: {', '.join(unknown)} is not one of "
                         f"{', '.join(LEFT_OUT)} (what recordings may leave out, comma-separated)")
    return words


_WRITE, _THIN, _SKIP = object(), object(), object()
"""What the recorder does with a key's samples: write each, thin them (camera images), skip them."""


def session_name(now: dt.datetime | None = None, label: str = "") -> str:
    stamp = (now or dt.datetime.now()).strftime("%Y%m%d-%H%M%S")
    return f"{stamp}-{label}" if label else stamp


class McapRecorder:
    """Writes raw bus payloads to one MCAP file; thread-safe; flushes every `flush_period` s."""

    def __init__(self, path: Path, flush_period: float = 1.0, chunk_size: int = 1 << 20) -> None:
        self.path = Path(path)
        private_dir(self.path.parent)       # 0700: a recording holds the user's voice and pictures
        try:
            self._file: BinaryIO = open_private(self.path, "xb")     # 0600, whatever the umask
        except FileExistsError:
            raise FileExistsError(f"{self.path} exists; a recording is never overwritten") from None
        hold_writer_lock(self._file)
        self._writer = LeanWriter(self._file, chunk_size=chunk_size)
        self._writer.start(profile=PROFILE, library="asibot recorder")
        self._channels: dict[str, int] = {}
        self._lock = threading.Lock()
        # Held while the disk is asked to keep what was written (fsync), apart from `_lock`: an
        # fsync can take a slow disk a second, and every sample of the stack waits for `_lock`.
        self._syncing = threading.Lock()
        self._dirty = False
        self._closed = False
        self.count = 0
        self._stop = threading.Event()
        self._flusher = threading.Thread(target=self._flush_loop, args=(flush_period,),
                                         name="mcap-flush", daemon=True)
        self._flusher.start()

    def write(self, key: str, payload: bytes, log_time_ns: int, publish_time_ns: int | None = None) -> int:
        """Add one message; returns `size` (0 once closed), which Session checks after each."""
        with self._lock:
            if self._closed:
                return 0
            channel = self._channels.get(key)
            if channel is None:
                # The type of the first message names the channel's, so a listing reads no message.
                channel = self._writer.register_channel(key, ENCODING, {TYPE_METADATA: payload_type(payload)})
                self._channels[key] = channel
            self._writer.add_message(channel, log_time_ns, payload,
                                     publish_time_ns if publish_time_ns is not None else log_time_ns,
                                     sequence=self.count & 0xFFFFFFFF)
            self.count += 1
            self._dirty = True
            return self._writer.size

    @property
    def size(self) -> int:
        """Bytes in the file so far, the open chunk (at most a second's worth) not included."""
        return self._writer.size

    def flush(self) -> None:
        """Close the open chunk and push it to the disk; messages are written meanwhile."""
        with self._syncing:
            with self._lock:
                if self._closed or not self._dirty:
                    return
                self._writer.flush()  # closes the current chunk
                self._file.flush()
                self._dirty = False
            # The file stays open: close() waits for `_syncing`.
            os.fsync(self._file.fileno())

    def _flush_loop(self, period: float) -> None:
        while not self._stop.wait(period):
            try:
                self.flush()
            except Exception:
                log.exception("flush failed")

    def close(self) -> None:
        """Finish the file with its summary, so readers can seek; idempotent."""
        self._stop.set()
        with self._syncing, self._lock:
            if self._closed:
                return
            self._closed = True
            self._writer.finish()
            self._file.close()


class Session:
    """One recording session in one file or more: a new part starts once a file holds
    `max_file_bytes` (0: never); thread-safe like McapRecorder."""

    def __init__(self, directory: Path, label: str = "", max_file_bytes: int = DEFAULT_MAX_FILE_BYTES,
                 on_new_part: Callable[[Path], None] | None = None) -> None:
        if max_file_bytes < 0:
            raise ValueError(f"the size of a recording file must be 0 (no limit) or more, not {max_file_bytes}")
        self.directory, self.name = Path(directory), session_name(label=label)
        self.max_file_bytes = max_file_bytes
        self.part = 1
        self.recorder = McapRecorder(self._part_path())
        self.files = [self.recorder.path]
        self._on_new_part = on_new_part
        self._earlier = 0        # messages in the parts before this one
        self._lock = threading.Lock()
        self._closed = False

    def _part_path(self) -> Path:
        suffix = f"-part{self.part}" if self.part > 1 else ""
        return self.directory / f"{self.name}{suffix}.mcap"

    @property
    def path(self) -> Path:
        """The file being written."""
        return self.recorder.path

    @property
    def count(self) -> int:
        return self._earlier + self.recorder.count

    def write(self, key: str, payload: bytes, log_time_ns: int) -> None:
        if self.recorder.write(key, payload, log_time_ns) >= self.max_file_bytes > 0:
            self._next_part()

    def _next_part(self) -> None:
        with self._lock:
            if self._closed:
                return
            full = self.recorder
            self.part += 1
            # Only this thread writes, so `full.count` is final: `count` never goes back.
            self._earlier, self.recorder = self._earlier + full.count, McapRecorder(self._part_path())
            self.files.append(self.recorder.path)
            full.close()
        log.info("%s holds %.0f MB: the session goes on in %s", full.path.name, full.size / 1e6,
                 self.recorder.path.name)
        if self._on_new_part is not None:
            self._on_new_part(self.recorder.path)

    def close(self) -> None:
        with self._lock:
            self._closed = True
            self.recorder.close()


class RecorderService(runtime.Service):
    """Subscribes to every key and hands each sample, unless excluded, left out (`without`:
    `audio`, `pictures`, LEFT_OUT) or a camera frame over the rate, to a Session; keeps the
    folder within the retention limits."""

    def __init__(self, bus, directory: Path, label: str = "", exclude: list[str] | None = None,
                 camera_hz: float = DEFAULT_CAMERA_HZ, retention: Retention = Retention(),
                 max_file_bytes: int = DEFAULT_MAX_FILE_BYTES, without: tuple[str, ...] | set[str] = ()) -> None:
        unknown = sorted(set(without) - LEFT_OUT.keys())
        if unknown:
            raise ValueError(f"recordings can leave out {' and '.join(LEFT_OUT)}, not {', '.join(unknown)}")
        if retention.max_bytes and max_file_bytes and retention.max_bytes < 2 * max_file_bytes:
            raise ValueError(f"--max-bytes ({retention.max_bytes}) must be at least twice --max-file-bytes "
                             f"({max_file_bytes}), or the file being written alone would fill it: "
                             "raise --max-bytes or lower --max-file-bytes")
        self.thinner = CameraThinner(camera_hz)
        self.retention = retention
        self.directory = Path(directory)
        self.without = sorted(without)
        self.exclude = list(exclude or []) + [p for what in self.without for p in LEFT_OUT[what]]
        self._routes: dict[str, object] = {}  # key -> _WRITE, _THIN or _SKIP
        self.skipped = 0
        self.removed = 0
        self._prune_now = threading.Event()
        self._stop = threading.Event()
        self.recorder = Session(self.directory, label, max_file_bytes, on_new_part=lambda p: self._prune_now.set())
        self._pruner = threading.Thread(target=self._prune_loop, name="recordings-rotation", daemon=True)
        self._pruner.start()
        self._sub = bus.subscribe_raw(keys.EVERYTHING, self._on_sample, maxsize=RING)
        log.info("recording to %s (camera images at %s, folder kept within %s%s)", self.recorder.path,
                 f"{camera_hz:g} Hz" if camera_hz else "every frame", describe(retention),
                 f"; without {' and '.join(self.without)}" if self.without else "")

    def _on_sample(self, key: str, payload: bytes, t_ns: int) -> None:
        # Every sample of the stack passes here: one dict lookup decides what a key gets.
        route = self._routes.get(key)
        if route is None:
            route = self._routes[key] = self._route(key)
        if route is _WRITE or (route is _THIN and self.thinner.keep_frame(key, t_ns)):
            self.recorder.write(key, payload, t_ns)
        elif route is _SKIP:
            self.skipped += 1

    def _route(self, key: str) -> object:
        """What a key's samples get, decided once (fnmatch costs about 1 us a pattern)."""
        if any(fnmatch.fnmatchcase(key, p) for p in self.exclude):
            return _SKIP
        return _THIN if self.thinner.thins(key) else _WRITE

    def _prune_loop(self) -> None:
        while not self._stop.is_set():
            try:
                self.removed += len(prune(self.directory, self.retention, keep=(self.recorder.path,)))
            except Exception:
                log.exception("rotation of the old recordings failed; it is tried again in a minute")
            self._prune_now.wait(PRUNE_PERIOD_S)
            self._prune_now.clear()

    def health(self) -> dict:
        return {"file": str(self.recorder.path), "messages": self.recorder.count,
                "skipped": self.skipped, "camera_frames_skipped": self.thinner.skipped,
                "recordings_removed": self.removed, "without": self.without}

    def close(self) -> None:
        self._sub.close()
        self._stop.set()
        self._prune_now.set()
        self._pruner.join(timeout=2.0)
        self.recorder.close()
        log.info("wrote %d messages to %s", self.recorder.count, ", ".join(str(p) for p in self.recorder.files))


_SIZE = re.compile(r"\s*(\d+(?:\.\d+)?)\s*([kmgt]?)b?\s*", re.IGNORECASE)
_UNITS = {"": 1, "k": 10**3, "m": 10**6, "g": 10**9, "t": 10**12}


def byte_size(text: str) -> int:
    """`500M`, `10G`, `2.5g` or a number of bytes; decimal units, as disks are sold."""
    match = _SIZE.fullmatch(text)
    if match is None:
        raise argparse.ArgumentTypeError(f"a size looks like 500M, 10G or 0 (no limit), not {text!r}")
    return int(float(match[1]) * _UNITS[match[2].lower()])


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dir", default=os.environ.get("ASIBOT_RECORDINGS", "recordings"),
                   help="folder for the .mcap files (default: recordings)")
    p.add_argument("--label", default=os.environ.get("ASIBOT_PROFILE", ""), help="added to the file name")
    p.add_argument("--exclude", action="append", default=[],
                   help="key pattern (fnmatch, e.g. 'rb/*/camera/*/rgb') not to record; repeatable")
    p.add_argument("--camera-hz", type=float, default=DEFAULT_CAMERA_HZ,
                   help=f"camera images (depth, rgb) recorded per second and camera (default {DEFAULT_CAMERA_HZ:g}; "
                        "0 records every frame)")
    p.add_argument("--max-bytes", type=byte_size, default=DEFAULT_MAX_BYTES,
                   help=f"the oldest recordings are deleted past this total (default {DEFAULT_MAX_BYTES / 1e9:g}G; 0: no limit)")
    p.add_argument("--max-age-days", type=float, default=DEFAULT_MAX_AGE_DAYS,
                   help="recordings older than this are deleted (default: no age limit, only --max-bytes)")
    p.add_argument("--max-file-bytes", type=byte_size, default=DEFAULT_MAX_FILE_BYTES,
                   help=f"a session goes on in a new file (-part2 ...) past this size "
                        f"(default {DEFAULT_MAX_FILE_BYTES / 1e6:g}M; 0: one file)")
    p.add_argument("--audio", action=argparse.BooleanOptionalAction, default=None,
                   help="--no-audio leaves the microphones' audio (voice/audio/*, the web page's) out "
                        f"of the recordings (default: recorded, unless ${WITHOUT_ENV} names audio)")
    p.add_argument("--pictures", action=argparse.BooleanOptionalAction, default=None,
                   help="--no-pictures leaves the cameras' images (rb/*/camera/*/depth, rgb) out of "
                        f"the recordings (default: recorded, unless ${WITHOUT_ENV} names pictures)")


def leave_out(args) -> set[str]:
    """What to leave out: --no-audio / --no-pictures, else $ASIBOT_RECORD_WITHOUT; `--audio`
    records it whatever the variable says."""
    left_out = without_from_env()
    for what in LEFT_OUT:
        flag = getattr(args, what, None)
        if flag is True:
            left_out.discard(what)
        elif flag is False:
            left_out.add(what)
    return left_out


def build(bus, args) -> RecorderService:
    return RecorderService(bus, Path(args.dir), args.label, args.exclude, camera_hz=args.camera_hz,
                           retention=Retention(args.max_bytes, args.max_age_days),
                           max_file_bytes=args.max_file_bytes, without=leave_out(args))
