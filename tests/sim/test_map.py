"""The committed map is what the MJCF says, and the named places are reachable free cells."""

import math

import numpy as np
import yaml

from asibot.sim import make_map
from asibot.sim.places import load_places


def load_committed():
    meta = yaml.safe_load((make_map.MAPS_DIR / "apartment.yaml").read_text())
    raw = (make_map.MAPS_DIR / meta["image"]).read_bytes()
    return meta, raw


def test_committed_map_equals_a_fresh_generation(tmp_path):
    pgm, yml = make_map.write("apartment", tmp_path)
    meta, raw = load_committed()
    assert pgm.read_bytes() == raw, "libs/common/asibot/maps/apartment.pgm is stale: run python -m asibot.sim.make_map"
    assert yaml.safe_load(yml.read_text()) == meta


def cell(img: np.ndarray, meta: dict, x: float, y: float) -> int:
    col = int(math.floor((x - meta["origin"][0]) / meta["resolution"]))
    row = img.shape[0] - 1 - int(math.floor((y - meta["origin"][1]) / meta["resolution"]))
    return int(img[row, col])


def test_walls_furniture_and_places_are_where_the_world_has_them():
    img, (x0, y0) = make_map.occupancy("apartment")
    meta = {"origin": [x0, y0, 0.0], "resolution": make_map.RESOLUTION_M}
    assert meta["resolution"] == 0.05
    assert cell(img, meta, -0.05, 4.0) == make_map.OCCUPIED        # west wall
    assert cell(img, meta, 5.0, 3.6) == make_map.FREE              # the living-room door
    assert cell(img, meta, 9.6, 1.0) == make_map.OCCUPIED          # fridge
    assert cell(img, meta, 2.5, 4.2) == make_map.OCCUPIED          # sofa blocks the middle
    assert cell(img, meta, 7.0, 2.8) == make_map.OCCUPIED          # dining table top
    assert cell(img, meta, 1.0, 1.5) == make_map.FREE              # the robot's start
    places = load_places("apartment")
    assert set(places) == {"fridge", "shelf", "desk", "charging station"}
    for name, (x, y, _) in places.items():
        # the P3-AT's half-width (0.2525 m) around each place is free
        for dx in (-0.25, 0.0, 0.25):
            for dy in (-0.25, 0.0, 0.25):
                assert cell(img, meta, x + dx, y + dy) == make_map.FREE, name


def test_pgm_header_and_size_match_the_yaml():
    meta, raw = load_committed()
    assert raw.startswith(b"P5\n")
    lines = raw.split(b"\n", 4)
    w, h = (int(v) for v in lines[2].split())
    assert lines[3] == b"255" and len(lines[4]) == w * h
    assert meta["negate"] == 0 and meta["mode"] == "trinary"
