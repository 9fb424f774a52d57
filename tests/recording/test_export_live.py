"""`asibot export` of a recording still being written (issue 10).

Without --follow it exports what the file held when the export began and stops; with
--follow it goes on until the writer closes the file, dies, or the user presses Ctrl-C. The
writer is a real recorder (McapRecorder) in another process, stepped batch by batch from the
test, so what was written before and after the export began is known exactly.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
from pathlib import Path
from typing import Callable

import pytest
from mcap.reader import make_reader

from asibot import keys, messages as m
from asibot.cli.main import main as asibot
from asibot.recorder import export
from asibot.recorder.export import ExportSummary, export_foxglove
from asibot.recorder.live import being_written
from asibot.recorder.recorder import McapRecorder
from asibot.testing import wait_until

KEY = keys.arm_state("live")
BATCH = 50
T0 = 1_795_000_000_000_000_000

# Writes a batch of BATCH arm states, flushes it to disk (as the recorder does every second),
# prints the total, and waits for a line on stdin before going on; after the last batch,
# "close" finishes the file and "hold" keeps it open until the process is killed.
WRITER = f"""
import sys, time
from asibot import messages as m
from asibot.recorder.recorder import McapRecorder
path, batches, end = sys.argv[1], int(sys.argv[2]), sys.argv[3]
rec = McapRecorder(path, flush_period=3600)
i = 0
for b in range(batches):
    for _ in range({BATCH}):
        rec.write({KEY!r}, m.encode(m.ArmState(names=["q1"], positions=[float(i)], velocities=[0.0])),
                  {T0} + i * 1_000_000)
        i += 1
    rec.flush()
    print(i, flush=True)
    sys.stdin.readline()
if end == "close":
    rec.close()
    print("closed", flush=True)
else:
    time.sleep(3600)
"""


class Writer:
    """The writer process, one batch at a time."""

    def __init__(self, path: Path, batches: int, end: str) -> None:
        self.path = path
        self.proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path), str(batches), end],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self.written = int(self.proc.stdout.readline())

    def next_batch(self) -> int:
        self.proc.stdin.write("\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline().strip()
        if line != "closed":
            self.written = int(line)
        return self.written

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(10)


@pytest.fixture
def writer(tmp_path):
    """Starts the writer process on tmp_path/rec.mcap; kills it at the end of the test."""
    started: list[Writer] = []

    def start(batches: int, end: str) -> Writer:
        started.append(Writer(tmp_path / "rec.mcap", batches, end))
        return started[-1]

    yield start
    for w in started:
        w.close()


def first(n: int) -> list[float]:
    """The positions of the first n messages the writer wrote."""
    return [float(i) for i in range(n)]


@pytest.fixture
def converted(calls) -> list[tuple]:
    """Every message the export has converted so far (to know how far it has read)."""
    return calls(export, "convert")


class Export:
    """export_foxglove in a thread, as the CLI runs it in its main thread."""

    def __init__(self, source: Path, **kwargs) -> None:
        self.output = source.parent / "out.mcap"
        self.result: ExportSummary | None = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, args=(source, kwargs), daemon=True)
        self.thread.start()

    def _run(self, source: Path, kwargs: dict) -> None:
        try:
            self.result = export_foxglove(source, self.output, **kwargs)
        except BaseException as exc:     # handed to the test's thread
            self.error = exc

    def wait(self, timeout: float = 60.0) -> ExportSummary:
        self.thread.join(timeout)
        assert not self.thread.is_alive(), f"the export did not end within {timeout} s"
        if self.error is not None:
            raise self.error
        return self.result


@pytest.fixture
def positions(protobuf) -> Callable[[Path], list[float]]:
    """`positions(path)`: the position of every arm state exported to `path`, decoded from its
    protobuf as Foxglove decodes it."""
    def read(path: Path) -> list[float]:
        with open(path, "rb") as f:
            return [protobuf(schema.data).decode(schema.name, msg.data)["joints"][0]["position"]
                    for schema, ch, msg in make_reader(f).iter_messages() if ch.topic == KEY]
    return read


def test_export_of_a_live_recording_stops_at_what_it_held_when_it_began(writer, monkeypatch, positions):
    w = writer(batches=4, end="hold")
    started, go_on = threading.Event(), threading.Event()
    real = export.convert

    def convert_then_wait(key, body):
        started.set()
        go_on.wait(30)          # the writer appends while this export is under way
        return real(key, body)

    monkeypatch.setattr(export, "convert", convert_then_wait)
    run = Export(w.path)
    assert started.wait(30), "the export did not start"
    for _ in range(3):
        w.next_batch()
    go_on.set()
    summary = run.wait()
    assert w.proc.poll() is None and being_written(w.path)   # the writer is still at it
    assert summary.live and not summary.complete and not summary.stopped
    assert summary.messages == 2 * BATCH      # only the first batch: each state, and its mode on /extra
    assert positions(run.output) == first(BATCH)
    assert w.written == 4 * BATCH


def test_follow_goes_on_until_the_writer_closes_the_file(writer, converted, positions):
    w = writer(batches=5, end="close")
    run = Export(w.path, follow=True)
    wait_until(lambda: len(converted) == BATCH, 30, message="the export did not read the first batch")
    for n in range(2, 6):
        w.next_batch()
        wait_until(lambda: len(converted) == w.written, 30,
                   message=f"the export did not follow batch {n}")
        assert run.thread.is_alive()    # everything so far is read, and it waits for more
    assert w.next_batch() == 5 * BATCH and w.proc.wait(10) == 0   # "closed"
    summary = run.wait()
    assert summary.complete and not summary.stopped
    assert positions(run.output) == first(5 * BATCH)


def test_follow_ends_with_what_was_on_disk_when_the_writer_is_killed(writer, converted, positions):
    w = writer(batches=3, end="hold")
    run = Export(w.path, follow=True)
    w.next_batch()
    w.next_batch()
    wait_until(lambda: len(converted) == 3 * BATCH, 30, message="the export did not follow")
    w.proc.kill()
    summary = run.wait()
    assert not summary.complete and not summary.stopped
    assert positions(run.output) == first(3 * BATCH)


def test_follow_stops_when_asked_and_keeps_what_it_exported(writer, converted, positions):
    w = writer(batches=2, end="hold")
    stop = threading.Event()
    run = Export(w.path, follow=True, stop=stop)
    wait_until(lambda: len(converted) == BATCH, 30, message="the export did not start")
    stop.set()
    summary = run.wait()
    assert summary.stopped and summary.live and not summary.complete
    assert positions(run.output) == first(BATCH)
    assert w.proc.poll() is None


def test_the_command_says_a_live_recording_was_exported_up_to_its_start(tmp_path, capsys):
    source = tmp_path / "rec.mcap"
    rec = McapRecorder(source, flush_period=3600)
    try:
        for i in range(10):
            rec.write(KEY, m.encode(m.ArmState(names=["q1"], positions=[float(i)], velocities=[0.0])), T0 + i)
        rec.flush()
        assert asibot(["export", str(source), "-o", str(tmp_path / "out.mcap")]) == 0
        out = capsys.readouterr().out
        assert "wrote 20 messages on 2 topics" in out     # each state, and its mode on /extra
        assert "still being written" in out and "--follow" in out
    finally:
        rec.close()


def test_the_command_follows_until_ctrl_c(tmp_path, writer, positions):
    w = writer(batches=2, end="hold")
    out = tmp_path / "out.mcap"
    cli = subprocess.Popen([sys.executable, "-m", "asibot.cli.main", "export", str(w.path), "--follow", "-o", str(out)],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        w.next_batch()
        # the export writes its output under a hidden name until it ends
        partial = tmp_path / f".{out.name}.partial"
        wait_until(lambda: partial.exists(), 30, message="the export did not start")
        cli.send_signal(signal.SIGINT)
        stdout, stderr = cli.communicate(timeout=60)
    finally:
        cli.kill()
    assert cli.returncode == 130, stderr   # Ctrl-C: the shell's 128 + SIGINT
    assert "stopped following on Ctrl-C" in stdout
    exported = positions(out)
    assert exported == first(len(exported))
    assert w.proc.poll() is None
