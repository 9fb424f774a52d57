"""`asibot recordings` reads summaries and indexes, not every chunk (issue 10).

A finished file is listed from its summary section alone: proved with a file whose chunk
data is destroyed but whose summary is intact. A file still being written, or cut short, is
listed from its chunk headers and message indexes, decompressing only the chunks that bring
a new channel and the last one: proved by counting decompressions.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from asibot import keys, messages as m
from asibot.cli.main import main as asibot
from asibot.recorder import index, reader
from asibot.recorder.reader import Reading, iter_messages, summarize
from asibot.recorder.recorder import McapRecorder
from asibot.recorder.writer import LeanWriter

T0 = 1_795_000_000_000_000_000
ARM, DEPTH, ODOM = keys.arm_state("lst"), keys.camera_depth("lst", "front"), keys.base_odom("lst")


def arm(i: int) -> bytes:
    return m.encode(m.ArmState(names=["q1"], positions=[float(i)], velocities=[0.0]))


def depth(i: int) -> bytes:
    return m.encode(m.DepthImage(depth=np.full((12, 16), i, np.float32)))


def write_session(rec: McapRecorder, n: int, first: int = 0) -> dict[str, int]:
    """n arm states, a depth image every 10th; odometry only from the 150th on (a channel
    that first appears in a later chunk). Returns the counts written."""
    counts = {ARM: 0, DEPTH: 0, ODOM: 0}
    for i in range(first, first + n):
        t = T0 + i * 10_000_000
        rec.write(ARM, arm(i), t)
        counts[ARM] += 1
        if i % 10 == 0:
            rec.write(DEPTH, depth(i), t)
            counts[DEPTH] += 1
        if i >= 150:
            rec.write(ODOM, m.encode(m.Odometry(x=float(i), y=0.0, theta=0.0)), t)
            counts[ODOM] += 1
    return {k: v for k, v in counts.items() if v}


def destroy_chunk_data(path: Path) -> int:
    """Overwrite every chunk's compressed bytes with zeros, leaving the summary intact."""
    with open(path, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    with open(path, "r+b") as f:
        for c in chunks:
            f.seek(c.chunk_start_offset + c.chunk_length - c.compressed_size)
            f.write(bytes(c.compressed_size))
    return len(chunks)


def test_a_finished_file_is_listed_from_its_summary_without_reading_a_chunk(tmp_path, capsys):
    path = tmp_path / "done.mcap"
    rec = McapRecorder(path, chunk_size=4096)
    written = write_session(rec, 400)
    rec.close()
    assert destroy_chunk_data(path) > 10

    whole = Reading(path)
    assert list(whole) == [] and not whole.complete      # the chunks really are unreadable
    s = summarize(path)
    assert s.complete and not s.live
    assert s.counts == written and s.messages == sum(written.values())
    assert (s.start, s.end) == (T0, T0 + 399 * 10_000_000)
    assert s.types == {ARM: "ArmState", DEPTH: "DepthImage", ODOM: "Odometry"}
    assert asibot(["recordings", str(tmp_path), "-v"]) == 0
    out = capsys.readouterr().out
    assert "done.mcap" in out and "recovered" not in out and "live (being" not in out
    assert f"{written[ARM]:>8}  ArmState" in out


def test_a_live_file_is_listed_from_its_message_indexes(tmp_path, calls, capsys):
    path = tmp_path / "now.mcap"
    rec = McapRecorder(path, chunk_size=4096, flush_period=3600)
    try:
        written = write_session(rec, 400)
        rec.flush()     # what the recorder does every second
        scanned = reader._scan(path)
        opened = calls(index, "chunk_records")
        s = summarize(path)
        with open(path, "rb") as f:
            assert len(index.walk_chunks(f)) > 10
        # the first chunk (arm, depth), the one where odometry starts, and the last
        assert len(opened) == 3
        assert s.live and not s.complete
        assert s.counts == written == scanned.counts
        assert (s.start, s.end, s.types) == (scanned.start, scanned.end, scanned.types)
        assert asibot(["recordings", str(tmp_path)]) == 0
        assert "live (being recorded)" in capsys.readouterr().out
    finally:
        rec.close()
    assert not summarize(path).live and asibot(["recordings", str(tmp_path)]) == 0
    assert "live (being recorded)" not in capsys.readouterr().out


def test_a_file_cut_short_is_listed_up_to_its_last_whole_chunk_and_marked_recovered(tmp_path, capsys):
    path = tmp_path / "cut.mcap"
    with open(path, "wb") as f:      # a writer that died: no summary, no lock, a torn tail
        w = LeanWriter(f)
        w.start("", "test")
        ch = {ARM: w.register_channel(ARM, "msgpack")}
        for i in range(300):
            w.add_message(ch[ARM], T0 + i, arm(i), T0 + i)
            if i % 50 == 49:
                w.flush()       # a chunk a second, as the recorder does
        whole = f.tell()
        for i in range(300, 320):
            w.add_message(ch[ARM], T0 + i, arm(i), T0 + i)
        w.flush()
    with open(path, "r+b") as f:
        f.truncate(whole + (path.stat().st_size - whole) // 2)
    s = summarize(path)
    assert not s.complete and not s.live
    assert s.counts == {ARM: 300} == {ARM: sum(1 for _ in iter_messages(path))}
    assert s.types == {ARM: "ArmState"}          # a file without type metadata: from its first chunk
    asibot(["recordings", str(tmp_path)])
    assert "recovered (writer did not finish)" in capsys.readouterr().out


def test_recordings_without_type_metadata_are_typed_from_one_chunk(tmp_path, calls):
    path = tmp_path / "old.mcap"
    with open(path, "wb") as f:      # as recordings made before channels named their type
        w = LeanWriter(f, chunk_size=1024)
        w.start("", "test")
        a, d = w.register_channel(ARM, "msgpack"), w.register_channel(DEPTH, "msgpack")
        for i in range(200):
            w.add_message(a, T0 + i, arm(i), T0 + i)
            if i == 0:
                w.add_message(d, T0, depth(0), T0)
        w.finish()
    opened = calls(index, "chunk_records")
    s = summarize(path)
    assert s.types == {ARM: "ArmState", DEPTH: "DepthImage"} and s.counts == {ARM: 200, DEPTH: 1}
    assert len(opened) == 1


@pytest.mark.parametrize("garbage", [b"", b"\x89MCAP0\r\n", b"\x89MCAP0\r\n" + b"\x05" * 40])
def test_files_that_end_early_or_hold_garbage_list_without_error(tmp_path, garbage):
    path = tmp_path / "odd.mcap"
    path.write_bytes(b"\x89MCAP0\r\n" + garbage)
    s = summarize(path)
    assert s.messages == 0 and not s.complete
