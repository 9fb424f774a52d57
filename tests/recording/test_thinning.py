"""Camera images recorded at a lower rate by default; calibrations and the rest whole (issue 10)."""

from __future__ import annotations

import random

import numpy as np
import pytest

from asibot import keys, messages as m
from asibot.bus import Bus
from asibot.recorder.reader import iter_messages
from asibot.recorder.recorder import RecorderService
from asibot.recorder.thinning import CameraThinner, is_camera_image
from asibot.testing import wait_until

ROBOT = "thin"
DEPTH, RGB, INFO = keys.camera_depth(ROBOT, "front"), keys.camera_rgb(ROBOT, "rgb"), keys.camera_info(ROBOT, "front")
S = 1_000_000_000


def test_only_depth_and_rgb_images_are_camera_images():
    assert is_camera_image(DEPTH) and is_camera_image(RGB)
    assert not is_camera_image(INFO)
    assert not is_camera_image(keys.arm_state(ROBOT)) and not is_camera_image("voice/audio/web-1")


def test_a_jittery_10_hz_stream_becomes_2_hz_and_the_rest_stays_whole():
    thin = CameraThinner(2.0)
    rng = random.Random(7)
    assert thin.thins(DEPTH) and thin.thins(RGB)
    assert not thin.thins(INFO) and not thin.thins(keys.arm_state(ROBOT))    # kept whole
    kept = {DEPTH: 0, RGB: 0}
    frames = 600                        # 60 s at 10 Hz
    for i in range(frames):
        t = i * S // 10 + int(rng.uniform(-0.02, 0.02) * S)     # +-20 ms of jitter
        for key in kept:
            kept[key] += thin.keep_frame(key, t)
    assert 119 <= kept[DEPTH] <= 121 and 119 <= kept[RGB] <= 121       # 2 Hz for 60 s
    assert thin.skipped == 2 * frames - kept[DEPTH] - kept[RGB]


def test_zero_thins_nothing():
    assert not CameraThinner(0).thins(DEPTH)


def test_a_camera_that_pauses_starts_again_at_its_next_frame():
    thin = CameraThinner(2.0)
    assert thin.keep_frame(DEPTH, 0) and not thin.keep_frame(DEPTH, S // 10)
    assert thin.keep_frame(DEPTH, 60 * S)             # a minute later: kept at once
    assert not thin.keep_frame(DEPTH, 60 * S + S // 10) and thin.keep_frame(DEPTH, 60 * S + S // 2)


def depth(i: int) -> m.DepthImage:
    return m.DepthImage(depth=np.full((24, 32), i, np.float32))


@pytest.mark.parametrize("hz", [2.0, 0.0])
def test_the_recorder_thins_camera_images_and_counts_what_it_skipped(tmp_path, memory_bus, hz):
    n = 60
    with Bus("rec") as bus:
        svc = RecorderService(bus, tmp_path, camera_hz=hz)
        try:
            images = bus.publisher(DEPTH, m.DepthImage)
            infos = bus.publisher(INFO, m.CameraInfo)
            for i in range(n):              # a burst: far faster than 2 Hz
                images.put(depth(i))
                infos.put(m.CameraInfo(width=32, height=24, fx=1.0, fy=1.0, cx=16.0, cy=12.0,
                                       pose=[0, 0, 0, 1, 0, 0, 0], frame="front_optical"))
            wait_until(lambda: svc.health()["messages"] + svc.health()["camera_frames_skipped"] == 2 * n,
                       10, message="the recorder did not receive every message")
            skipped = svc.health()["camera_frames_skipped"]
        finally:
            svc.close()
    recorded = list(iter_messages(svc.recorder.path))
    kept = [r for r in recorded if r.key == DEPTH]
    assert sum(r.key == INFO for r in recorded) == n                    # calibrations whole
    assert len(kept) + skipped == n
    if hz:
        assert skipped > 0
        # each kept frame is at least its place in the 2 Hz schedule after the first
        assert all(r.log_time - kept[0].log_time >= i * S // 2 for i, r in enumerate(kept))
    else:
        assert skipped == 0
    first = m.decode(m.DepthImage, kept[0].payload)
    assert first.depth[0, 0] == 0.0      # the first frame of a stream is always kept
