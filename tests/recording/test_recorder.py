"""Recording to MCAP, listing, replaying, and recovering a file whose writer was killed."""

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from asibot import keys, messages as m
from asibot.bus import Bus
from asibot.cli.main import main as asibot
from asibot.recorder.reader import NotARecording, iter_messages, list_recordings, summarize
from asibot.recorder.recorder import McapRecorder
from asibot.recorder.replay import replay
from asibot.testing import scheduling_delay, wait_until


def start_recorder(directory: Path) -> subprocess.Popen:
    p = subprocess.Popen([sys.executable, "-m", "asibot.recorder", "--dir", str(directory)],
                         stderr=subprocess.PIPE, text=True)
    for line in p.stderr:
        if "running" in line:
            return p
    raise AssertionError("recorder did not start")


def one_file(directory: Path) -> Path:
    files = list(directory.glob("*.mcap"))
    assert len(files) == 1, files
    return files[0]


def publish_pattern(bus: Bus) -> list[tuple[str, bytes, float]]:
    """Two topics with a known rhythm: 25 states every 20 ms, one twist every 100 ms."""
    state = bus.publisher(keys.arm_state("rec"), m.ArmState)
    twist = bus.publisher(keys.base_cmd_vel("rec"), m.Twist)
    # Each is put once: the router must know the recorder's subscription first, or it drops them.
    assert state.wait_for_subscribers(10) and twist.wait_for_subscribers(10), "the recorder never subscribed"
    sent = []
    t0 = time.monotonic()
    for i in range(25):
        msg = m.ArmState(names=["q1"], positions=[i * 0.1], velocities=[0.0])
        state.put(msg)
        sent.append((state.key, m.encode(msg), time.monotonic() - t0))
        if i % 5 == 0:
            tw = m.Twist(vx=0.1 * i, wz=0.0)
            twist.put(tw)
            sent.append((twist.key, m.encode(tw), time.monotonic() - t0))
        time.sleep(0.02)
    return sent


@pytest.mark.slow
def test_record_then_replay_reproduces_topics_payloads_and_timing(router, tmp_path, capsys):
    rec = start_recorder(tmp_path)
    with Bus("pub") as bus:
        sent = publish_pattern(bus)
        time.sleep(0.3)
    rec.send_signal(signal.SIGTERM)
    assert rec.wait(5) == 0
    path = one_file(tmp_path)

    summary = summarize(path)
    assert summary.complete
    assert summary.counts[keys.arm_state("rec")] == 25
    assert summary.counts[keys.base_cmd_vel("rec")] == 5
    assert summary.types[keys.base_cmd_vel("rec")] == "Twist"
    assert asibot(["recordings", str(tmp_path), "-v"]) == 0
    out = capsys.readouterr().out
    assert path.name in out and keys.arm_state("rec") in out

    # replay into a fresh subscriber and compare
    with Bus("sub") as sub_bus, Bus("player") as player:
        got = []
        sub_bus.subscribe_raw("rb/rec/**", lambda k, p, t: got.append((k, p, time.monotonic())))
        # The replay puts each message once: a probe first shows the router routes the player's
        # puts to the new subscriber (before that, they are dropped).
        probe = "rb/rec/probe"
        wait_until(lambda: player.put_raw(probe, b"") or any(k == probe for k, *_ in got), 10, interval=0.05,
                   message="the player's puts never reached the subscriber")
        put_at: list[float] = []
        delay = scheduling_delay()  # how late this machine wakes a sleeper right now
        assert replay(path, lambda k, p: put_at.append(time.monotonic()) or player.put_raw(k, p), speed=1.0) == 30
        wait_until(lambda: len([g for g in got if g[0] != probe]) == 30, 3)
    assert [(k, p) for k, p, _ in got if k != probe] == [(k, p) for k, p, _ in sent]
    # The replay keeps the recorded timing: each message goes out when it is due, late by no more
    # than the machine's own scheduling delay (measured above; a loaded CI machine has more).
    t_sent = [t - sent[0][2] for *_, t in sent]
    t_put = [t - put_at[0] for t in put_at]
    assert max(abs(a - b) for a, b in zip(t_sent, t_put)) < 0.03 + 3 * delay


def test_replay_as_fast_as_possible_and_filters(router, tmp_path):
    path = tmp_path / "x.mcap"
    r = McapRecorder(path)
    for i in range(100):
        r.write("rb/a/arm/state" if i % 2 else "health/x/y", bytes([i]), 1_000_000_000 * i)
    r.close()
    seen = []
    t = time.monotonic()
    assert replay(path, lambda k, p: seen.append(k), speed=None) == 50  # health/** excluded by default
    assert time.monotonic() - t < 5, "100 s of recording replayed without waiting"
    assert set(seen) == {"rb/a/arm/state"}
    with pytest.raises(ValueError):
        replay(path, lambda k, p: None, speed=0)


@pytest.mark.slow
def test_killed_recorder_file_is_recovered(router, tmp_path, capsys):
    rec = start_recorder(tmp_path)
    with Bus("pub") as bus:
        pub = bus.publisher(keys.arm_state("crash"), m.ArmState, block=True)
        assert pub.wait_for_subscribers(10), "the recorder never subscribed"   # or the first puts are dropped
        for i in range(500):
            pub.put(m.ArmState(names=["q1"], positions=[float(i)], velocities=[0.0]))
        time.sleep(1.6)  # at least one flush period: these 500 are on disk
        for i in range(500, 600):
            pub.put(m.ArmState(names=["q1"], positions=[float(i)], velocities=[0.0]))
        rec.kill()
        rec.wait()
    path = one_file(tmp_path)
    records = [r for r in iter_messages(path) if r.key == keys.arm_state("crash")]
    assert len(records) >= 500
    positions = [m.decode(m.ArmState, r.payload).positions[0] for r in records]
    assert positions == [float(i) for i in range(len(records))]
    s = list_recordings(tmp_path)[0]
    assert not s.complete
    asibot(["recordings", str(tmp_path)])
    assert "recovered" in capsys.readouterr().out


def test_messages_are_written_while_the_disk_is_slow_to_keep_them(tmp_path, monkeypatch):
    """A slow disk can take a second over an fsync, and every sample of the stack waits for the
    recorder's lock: the fsync is outside it."""
    entered, release = threading.Event(), threading.Event()
    fsync = os.fsync

    def slow_fsync(fd: int) -> None:
        entered.set()
        release.wait(10)
        fsync(fd)

    monkeypatch.setattr(os, "fsync", slow_fsync)
    rec = McapRecorder(tmp_path / "slow.mcap", flush_period=3600)
    payload = m.encode(m.Battery(volts=12.0))
    rec.write("rb/slow/battery", payload, 1)
    flusher = threading.Thread(target=rec.flush)
    flusher.start()
    assert entered.wait(5), "the flush never asked the disk"
    written = threading.Event()
    threading.Thread(target=lambda: (rec.write("rb/slow/battery", payload, 2), written.set())).start()
    try:
        assert written.wait(5), "a message waited for the disk"
    finally:
        release.set()
        flusher.join(5)
    rec.close()
    assert [r.log_time for r in iter_messages(tmp_path / "slow.mcap")] == [1, 2]


def test_recorder_never_overwrites(tmp_path):
    (tmp_path / "a.mcap").write_bytes(b"precious")
    with pytest.raises(FileExistsError):
        McapRecorder(tmp_path / "a.mcap")
    assert (tmp_path / "a.mcap").read_bytes() == b"precious"


def test_a_file_that_is_not_a_recording_is_refused_clearly(tmp_path, capsys):
    (tmp_path / "notes.mcap").write_text("shopping list")
    assert asibot(["replay", str(tmp_path / "notes.mcap")]) == 1
    assert "is not an MCAP recording" in capsys.readouterr().err
    assert asibot(["recordings", str(tmp_path)]) == 0
    assert "not an MCAP file" in capsys.readouterr().out
    with pytest.raises(NotARecording):
        list(iter_messages(tmp_path / "notes.mcap"))
    assert (tmp_path / "notes.mcap").read_text() == "shopping list"
