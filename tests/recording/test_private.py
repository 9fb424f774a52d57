"""Recordings hold the page's microphone audio and the camera pictures (issue 51): they are
0600 files in a 0700 folder whatever the umask, parts and exports too, and the recorder can
leave audio and pictures out (--no-audio, --no-pictures, $ASIBOT_RECORD_WITHOUT)."""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

import numpy as np
import pytest

from asibot import keys, messages as m
from asibot.bus import Bus
from asibot.cli import compose
from asibot.cli.launcher import local_environment
from asibot.recorder.export import default_output, export_foxglove
from asibot.recorder.reader import iter_messages
from asibot.recorder.recorder import RecorderService, add_arguments, build
from asibot.recorder.rotation import Retention
from asibot.testing import wait_until
from asibot.testing import file_mode

ROOT = Path(__file__).resolve().parents[2]
ROBOT = "private"
STATE = keys.arm_state(ROBOT)
AUDIO = keys.voice_audio("web-1")
RGB, DEPTH, INFO = keys.camera_rgb(ROBOT, "front"), keys.camera_depth(ROBOT, "front"), keys.camera_info(ROBOT, "front")




def arguments(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_arguments(p)
    return p.parse_args(list(argv))


def test_a_recording_its_parts_its_folder_and_its_export_are_private(tmp_path, memory_bus, permissive_umask, caplog):
    tmp_path.chmod(0o755)
    folder = tmp_path / "new" / "recordings"
    with Bus("rec") as bus, caplog.at_level(logging.INFO, logger="asibot.files"):
        svc = RecorderService(bus, folder, retention=Retention(max_bytes=0), max_file_bytes=2_000)
        try:
            state = bus.publisher(STATE, m.ArmState)
            i = 0

            def two_parts() -> bool:
                nonlocal i
                for _ in range(20):     # until the one-second flush has made the first part full
                    state.put(m.ArmState(names=["q1"], positions=[float(i)], velocities=[0.0]))
                    i += 1
                time.sleep(0.02)
                return len(svc.recorder.files) >= 2
            wait_until(two_parts, 15, message=lambda: f"no second part after {i} messages: {svc.health()}")
        finally:
            svc.close()
    files = svc.recorder.files
    assert files[1].name.endswith("-part2.mcap")
    assert sorted(folder.glob("*.mcap")) == sorted(files)
    assert (file_mode(tmp_path / "new"), file_mode(folder)) == (0o700, 0o700)
    assert {f.name: f"{file_mode(f):03o}" for f in files} == {f.name: "600" for f in files}
    assert file_mode(tmp_path) == 0o755                # not the recorder's folder: left as it was
    assert "open to other users" not in caplog.text      # nothing to tighten in folders it made

    summary = export_foxglove(files[0])
    assert summary.output == default_output(files[0]) and summary.messages > 0
    assert (file_mode(summary.output.parent), file_mode(summary.output)) == (0o700, 0o600)


def test_a_recordings_folder_open_to_others_is_made_private_and_said_once(tmp_path, memory_bus, caplog):
    folder = tmp_path / "recordings"
    folder.mkdir()
    folder.chmod(0o755)                            # as the image's, or a checkout's, was
    with Bus("rec") as bus, caplog.at_level(logging.INFO, logger="asibot.files"):
        svc = build(bus, arguments("--dir", str(folder)))
        svc.close()
        svc = build(bus, arguments("--dir", str(folder), "--label", "again"))     # the recorder restarted
        svc.close()
    assert file_mode(folder) == 0o700
    assert all(file_mode(f) == 0o600 for f in folder.glob("*.mcap"))
    said = [r.getMessage() for r in caplog.records if "open to other users" in r.getMessage()]
    assert len(said) == 1 and str(folder) in said[0] and "(755)" in said[0], said


def publish_everything(bus: Bus, svc: RecorderService, expected_messages: int, expected_skipped: int) -> None:
    """An arm state, microphone audio, a colour and a depth picture and a calibration, until
    the recorder has seen each of them (a publisher's first put may come before it subscribed)."""
    pubs = [(bus.publisher(STATE, m.ArmState), m.ArmState(names=["q1"], positions=[0.1], velocities=[0.0])),
            (bus.publisher(AUDIO, m.AudioChunk), m.AudioChunk(data=b"\x01\x00" * 1600, rate=16000)),
            (bus.publisher(RGB, m.RgbImage), m.RgbImage(jpeg=b"\xff\xd8 a face \xff\xd9", width=4, height=3)),
            (bus.publisher(DEPTH, m.DepthImage), m.DepthImage(depth=np.ones((3, 4), np.float32))),
            (bus.publisher(INFO, m.CameraInfo), m.CameraInfo(width=4, height=3, fx=1.0, fy=1.0, cx=2.0, cy=1.5,
                                                            pose=[0, 0, 0, 1, 0, 0, 0], frame="front_optical"))]
    for pub, msg in pubs:
        pub.put(msg)
    wait_until(lambda: (svc.health()["messages"], svc.health()["skipped"]) == (expected_messages, expected_skipped),
               10, message=lambda: f"the recorder did not see every message: {svc.health()}")


@pytest.mark.parametrize("argv, env, left_out", [
    (["--no-audio"], "", {AUDIO}),
    (["--no-pictures"], "", {RGB, DEPTH}),
    (["--no-audio", "--no-pictures"], "", {AUDIO, RGB, DEPTH}),
    ([], "audio,pictures", {AUDIO, RGB, DEPTH}),
    ([], "pictures", {RGB, DEPTH}),
    (["--audio"], "audio, pictures", {RGB, DEPTH}),            # the command line wins
    ([], "", set()),
])
def test_audio_and_pictures_can_be_left_out_and_the_rest_is_recorded(tmp_path, memory_bus, monkeypatch,
                                                                     argv, env, left_out):
    monkeypatch.setenv("ASIBOT_RECORD_WITHOUT", env)
    everything = {STATE, AUDIO, RGB, DEPTH, INFO}
    with Bus("rec") as bus:
        svc = build(bus, arguments("--dir", str(tmp_path), "--camera-hz", "0", *argv))
        try:
            publish_everything(bus, svc, len(everything - left_out), len(left_out))
        finally:
            svc.close()
    recorded = {r.key for r in iter_messages(svc.recorder.path)}
    assert recorded == everything - left_out
    assert svc.health()["without"] == sorted({"audio" for k in left_out if k == AUDIO} |
                                             {"pictures" for k in left_out if k != AUDIO})


def test_an_unknown_word_in_the_variable_is_refused_with_the_words_it_takes(tmp_path, memory_bus, monkeypatch):
    monkeypatch.setenv("ASIBOT_RECORD_WITHOUT", "audio,video")
    with Bus("rec") as bus, pytest.raises(ValueError, match="video is not one of audio, pictures"):
        build(bus, arguments("--dir", str(tmp_path)))
    assert not list(tmp_path.glob("*.mcap"))


def test_compose_and_asibot_up_give_the_recorder_the_variable():
    text = (ROOT / "compose.yaml").read_text()
    spec = compose.parse(text, {"ASIBOT_RECORD_WITHOUT": "audio,pictures"})["recorder"]
    assert spec.environment["ASIBOT_RECORD_WITHOUT"] == "audio,pictures"
    assert local_environment(spec, "tcp/127.0.0.1:7447")["ASIBOT_RECORD_WITHOUT"] == "audio,pictures"
    unset = compose.parse(text, {})["recorder"]
    assert unset.environment.get("ASIBOT_RECORD_WITHOUT", "") == ""
