"""Command-line options: bad values are refused with a sentence that says what to type."""

import argparse

import pytest

from asibot.sim.service import _noise, _size, add_arguments


def parser():
    p = argparse.ArgumentParser()
    add_arguments(p)
    return p


def test_defaults_are_real_time_cameras_at_10_hz_320x240():
    a = parser().parse_args([])
    assert (a.fast, a.viewer, a.camera_hz, a.camera_size, a.depth_method) == (False, False, 10.0, (320, 240), "render")


def test_world_fast_and_sizes_parse():
    a = parser().parse_args(["--world", "apartment", "--fast", "--camera-size", "640x480", "--odom-noise", "0,0.1"])
    assert (a.world, a.fast, a.camera_size, a.odom_noise) == ("apartment", True, (640, 480), (0.0, 0.1))


@pytest.mark.parametrize("text", ["320", "axb", "4x4", "99999x10"])
def test_bad_camera_sizes_are_refused(text):
    with pytest.raises(argparse.ArgumentTypeError, match="camera size"):
        _size(text)


@pytest.mark.parametrize("text", ["0.1", "x,y", "-0.1,0"])
def test_bad_noise_is_refused(text):
    with pytest.raises(argparse.ArgumentTypeError, match="noise"):
        _noise(text)


def test_unknown_world_is_refused():
    with pytest.raises(SystemExit):
        parser().parse_args(["--world", "moon"])
