"""The recordings folder kept within a size and an age, and long sessions split into parts (issue 10)."""

from __future__ import annotations

import argparse
import logging
import os
import time
from pathlib import Path

import pytest

from asibot import keys, messages as m
from asibot.bus import Bus
from asibot.recorder.reader import iter_messages, summarize
from asibot.recorder.recorder import McapRecorder, RecorderService, Session, build, add_arguments, byte_size
from asibot.recorder.rotation import DAY_S, FileInfo, Retention, over_limits, prune
from asibot.testing import wait_until

NOW = 1_800_000_000.0
MB = 1_000_000


def info(name: str, mb: float, days_old: float) -> FileInfo:
    return FileInfo(Path(name), int(mb * MB), NOW - days_old * DAY_S)


def test_the_oldest_go_first_until_the_total_fits():
    files = [info("c.mcap", 40, 1), info("a.mcap", 40, 3), info("b.mcap", 40, 2), info("d.mcap", 40, 0)]
    chosen = over_limits(files, Retention(max_bytes=100 * MB, max_age_days=0), NOW, keep=set())
    assert [f.path.name for f in chosen] == ["a.mcap", "b.mcap"]
    assert over_limits(files, Retention(max_bytes=160 * MB, max_age_days=0), NOW, keep=set()) == []


def test_too_old_recordings_go_whatever_the_size():
    files = [info("old.mcap", 1, 31), info("new.mcap", 1, 29)]
    chosen = over_limits(files, Retention(max_bytes=0, max_age_days=30), NOW, keep=set())
    assert [f.path.name for f in chosen] == ["old.mcap"]


def test_a_kept_file_counts_toward_the_total_but_is_never_chosen():
    files = [info("writing.mcap", 90, 5), info("a.mcap", 20, 1), info("b.mcap", 20, 0)]
    chosen = over_limits(files, Retention(max_bytes=100 * MB, max_age_days=1),
                         NOW, keep={Path("writing.mcap")})
    assert [f.path.name for f in chosen] == ["a.mcap", "b.mcap"]


def make(path: Path, mb: float, days_old: float, now: float = NOW) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"\x89MCAP0\r\n" + bytes(int(mb * MB)))
    os.utime(path, (now - days_old * DAY_S,) * 2)
    return path


def test_prune_spares_the_live_recording_fixtures_and_exports_and_logs_what_it_removed(tmp_path, caplog):
    old = make(tmp_path / "20250101-000000.mcap", 1, 400)
    middle = make(tmp_path / "20250601-000000.mcap", 1, 20)
    recent = make(tmp_path / "20250701-000000.mcap", 1, 1)
    fixture = make(tmp_path / "fixtures" / "red_can.mcap", 1, 500)
    exported = make(tmp_path / "foxglove" / "20250101-000000.mcap", 1, 400)
    notes = tmp_path / "notes.mcap"         # not a recording, whatever its name
    notes.write_text("shopping list")
    os.utime(notes, (NOW - 900 * DAY_S,) * 2)
    live = McapRecorder(tmp_path / "live.mcap")     # a recorder of another session, writing
    os.utime(live.path, (NOW - 1000 * DAY_S,) * 2)
    try:
        with caplog.at_level(logging.INFO, logger="asibot.recorder"):
            removed = prune(tmp_path, Retention(max_bytes=int(1.5 * MB), max_age_days=30), now=NOW)
        assert removed == [old, middle]
        assert not old.exists() and not middle.exists()
        assert recent.exists() and fixture.exists() and exported.exists() and live.path.exists()
        assert notes.read_text() == "shopping list"
        assert "removed the old recording 20250101-000000.mcap" in caplog.text
        assert "20250601-000000.mcap" in caplog.text
    finally:
        live.close()


def test_a_session_goes_on_in_a_new_file_past_the_size_limit(tmp_path):
    session = Session(tmp_path, "sim", max_file_bytes=20_000)
    key = keys.arm_state("split")
    for i in range(3000):
        session.write(key, m.encode(m.ArmState(names=["q1"], positions=[float(i)], velocities=[0.0])),
                      1_000_000 * i)
        if i % 100 == 99:
            session.recorder.flush()     # the recorder's one-second flush
    session.close()
    files = sorted(tmp_path.glob("*.mcap"), key=lambda p: session.files.index(p))
    assert len(files) >= 3 and files == session.files
    assert files[0].name == f"{session.name}.mcap" and files[1].name == f"{session.name}-part2.mcap"
    assert all(summarize(f).complete for f in files)
    got = [m.decode(m.ArmState, r.payload).positions[0] for f in files for r in iter_messages(f)]
    assert got == [float(i) for i in range(3000)] and session.count == 3000
    assert all(f.stat().st_size < 20_000 + 8_000 for f in files)    # a limit plus at most a chunk


def arguments(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_arguments(p)
    return p.parse_args(list(argv))


def test_the_recorder_prunes_its_folder_at_start(tmp_path, memory_bus):
    old = make(tmp_path / "20240101-000000.mcap", 0.1, 31, now=time.time())
    kept = make(tmp_path / "20250101-000000.mcap", 0.1, 29, now=time.time())
    with Bus("rec") as bus:
        svc = build(bus, arguments("--dir", str(tmp_path), "--max-age-days", "30"))
        try:
            wait_until(lambda: svc.health()["recordings_removed"] == 1, 10,
                       message="the old recording was not removed")
            assert not old.exists() and kept.exists() and svc.recorder.path.exists()
        finally:
            svc.close()


@pytest.mark.parametrize("argv, words", [
    (["--max-bytes", "lots"], "a size looks like 500M"),
    (["--max-file-bytes=-1G"], "a size looks like 500M"),
])
def test_bad_sizes_are_refused_with_what_to_type(argv, words, capsys):
    with pytest.raises(SystemExit):
        arguments(*argv)
    assert words in capsys.readouterr().err


@pytest.mark.parametrize("kwargs, words", [
    ({"retention": Retention(max_bytes=100 * MB), "max_file_bytes": 80 * MB}, "at least twice --max-file-bytes"),
    ({"camera_hz": -1.0}, "camera recording rate must be 0"),
])
def test_bad_limits_are_refused_before_any_file_is_made(tmp_path, memory_bus, kwargs, words):
    with Bus("rec") as bus, pytest.raises(ValueError, match=words):
        RecorderService(bus, tmp_path / "recs", **kwargs)
    assert not (tmp_path / "recs").exists()


def test_negative_limits_are_refused():
    with pytest.raises(ValueError, match="0 \\(no limit\\) or more"):
        Retention(max_bytes=-1)
    assert byte_size("1.5G") == 1_500_000_000 and byte_size("0") == 0
