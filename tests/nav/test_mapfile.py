"""map_server maps: exact conversion rules, round trips, the sim's map, and bad files."""

from __future__ import annotations

import hashlib
import math

import cv2
import numpy as np
import pytest

from asibot.nav.errors import MapError
from asibot.nav.geometry import Pose
from asibot.nav.grid import GridInfo, OccupancyGrid
from asibot.nav.mapfile import load_map, pgm_bytes, save_map
from asibot.rosmap import MapSettings

from .conftest import MAPS

YAML = "image: {image}\nresolution: 0.05\norigin: [1.0, -2.0, 0.0]\nnegate: {negate}\n" \
       "occupied_thresh: 0.65\nfree_thresh: 0.196\n{mode}"


def image_loader(pixel: int, mode: str, negate: bool, occ_th: float = 0.65, free_th: float = 0.196) -> int:
    """map_server image_loader.cpp, one pixel at a time, as the C++ reads (the reference)."""
    avg = 255 - pixel if negate else pixel
    if mode == "raw":
        return avg if avg < 128 else avg - 256       # uchar into the int8 map
    occ = (255 - avg) / 255.0
    if occ > occ_th:
        return 100
    if occ < free_th:
        return 0
    if mode == "trinary":
        return -1
    return int(1 + 98 * (occ - free_th) / (occ_th - free_th))


def write_map(tmp_path, img: np.ndarray, negate: int = 0, mode: str = "") -> object:
    (tmp_path / "m.pgm").write_bytes(pgm_bytes(img))
    (tmp_path / "m.yaml").write_text(YAML.format(image="m.pgm", negate=negate, mode=f"mode: {mode}\n" if mode else ""))
    return tmp_path / "m.yaml"


@pytest.mark.parametrize("mode", ["trinary", "scale", "raw"])
@pytest.mark.parametrize("negate", [0, 1])
def test_every_grey_loads_as_map_server_loads_it(tmp_path, mode, negate):
    img = np.arange(256, dtype=np.uint8).reshape(16, 16)
    grid = load_map(write_map(tmp_path, img, negate, mode)).grid
    want = np.array([[image_loader(int(p), mode, bool(negate)) for p in row] for row in img[::-1]])
    assert np.array_equal(grid.data.astype(int), want)


def test_the_top_row_of_the_image_is_the_largest_y(tmp_path):
    img = np.full((4, 6), 254, np.uint8)
    img[0, 0] = 0                                       # top-left pixel occupied
    m = load_map(write_map(tmp_path, img))
    info = m.grid.info
    assert info.origin == Pose(1.0, -2.0, 0.0) and info.shape == (4, 6)
    x, y = 1.0 + 0.025, -2.0 + 4 * 0.05 - 0.025        # top-left cell centre in the world
    r, c = info.to_cell(x, y)
    assert m.grid.data[r, c] == 100 and (m.grid.data == 100).sum() == 1


@pytest.mark.parametrize("mode", ["trinary", "raw"])
def test_round_trip(tmp_path, mode):
    rng = np.random.default_rng(0)
    data = rng.choice(np.array([-1, 0, 100], np.int8), size=(37, 53))
    if mode == "raw":
        data = rng.integers(-128, 128, size=(37, 53)).astype(np.int8)
    info = GridInfo(53, 37, 0.025, Pose(-3.25, 4.5, 0.1))
    yml, pgm = save_map(OccupancyGrid(info, data), tmp_path / "saved.yaml", mode)
    back = load_map(yml)
    assert np.array_equal(back.grid.data, data)
    assert back.grid.info == info and back.meta.mode == mode
    assert pgm.read_bytes()[:2] == b"P5"


def test_scale_round_trip_and_unknown_refused(tmp_path):
    data = np.arange(101, dtype=np.int8).reshape(1, 101)
    info = GridInfo(101, 1, 0.05)
    yml, _ = save_map(OccupancyGrid(info, data), tmp_path / "s.yaml", "scale")
    back = load_map(yml).grid.data.astype(int)
    assert np.abs(back - data).max() <= 1          # 1..99 are 98 steps of occupancy: one may round
    assert back[0, 0] == 0 and back[0, 100] == 100
    with pytest.raises(MapError, match="unknown cells"):
        save_map(OccupancyGrid(info, np.full((1, 101), -1, np.int8)), tmp_path / "u.yaml", "scale")
    assert not (tmp_path / "u.yaml").exists()


def test_map_saver_colours(tmp_path):
    data = np.array([[0, 25, 26, 64, 65, 100, -1]], np.int8)
    _, pgm = save_map(OccupancyGrid(GridInfo(7, 1, 0.05), data), tmp_path / "c.yaml")
    assert list(cv2.imread(str(pgm), cv2.IMREAD_UNCHANGED)[0]) == [254, 254, 205, 205, 0, 0, 205]


def test_the_sims_apartment_map(apartment):
    info = apartment.grid.info
    assert (info.width, info.height, info.resolution) == (230, 190, 0.05)
    assert info.origin == Pose(-0.75, -0.75, 0.0)
    img = cv2.imread(str(MAPS / "apartment.pgm"), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(apartment.grid.data[0], np.where(img[-1] == 0, 100, np.where(img[-1] == 254, 0, -1)))
    occupied = apartment.grid.occupied
    assert occupied.sum() > 1000 and apartment.grid.free.sum() > 20000
    # the grid the hand-written PGM reader gave before maps were read by asibot.rosmap
    assert hashlib.sha256(apartment.grid.data.tobytes()).hexdigest() == \
        "a9fa49c8d4c41855afc397d4848a47dcf9922d950fa9765495e562be07e88e7e"


@pytest.mark.parametrize("ext", [".png", ".bmp", ".ppm"])
def test_png_bmp_and_colour_maps_load_as_the_pgm_of_the_same_picture(tmp_path, ext):
    img = np.random.default_rng(4).choice(np.array([0, 205, 254], np.uint8), size=(9, 14))
    pgm = load_map(write_map(tmp_path, img)).grid
    picture = img if ext != ".ppm" else np.stack([img] * 3, axis=2)   # a colour file of grey pixels
    ok, data = cv2.imencode(ext, picture)
    assert ok
    (tmp_path / f"m{ext}").write_bytes(data.tobytes())
    (tmp_path / "n.yaml").write_text(YAML.format(image=f"m{ext}", negate=0, mode=""))
    other = load_map(tmp_path / "n.yaml")
    assert np.array_equal(other.grid.data, pgm.data) and other.grid.info == pgm.info
    assert isinstance(other.meta, MapSettings) and other.meta.image == f"m{ext}"


@pytest.mark.parametrize("content, words", [
    (b"\x89PNG\r\n\x1a\n....", "looks like a PNG image but cannot be decoded"),
    (b"hello", "is not an image OpenCV can read; a map image is a PGM, PNG or BMP"),
    (b"P5\n4 4\n255\n" + bytes(5), "looks like a PGM image but cannot be decoded: it is truncated or corrupt"),
    (b"P5\n4\n", "looks like a PGM image but cannot be decoded"),
    (b"", "is empty"),
])
def test_a_broken_image_is_a_sentence(tmp_path, content, words):
    (tmp_path / "m.pgm").write_bytes(content)
    (tmp_path / "m.yaml").write_text(YAML.format(image="m.pgm", negate=0, mode=""))
    with pytest.raises(MapError, match=words) as err:
        load_map(tmp_path / "m.yaml")
    assert str(tmp_path / "m.pgm") in err.value.message and err.value.code == "bad_request"


@pytest.mark.parametrize("yaml_text, words", [
    ("image: m.pgm\nresolution: 0.05\n", "origin, negate, occupied_thresh, free_thresh are missing"),
    ("- just\n- a list\n", "must be a mapping"),
    ("image: m.pgm\nresolution: -1\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
     "resolution must be"),
    ("image: m.pgm\nresolution: .nan\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
     "resolution must be"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
     "origin must be"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 2\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
     "negate must be 0 or 1"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.1\nfree_thresh: 0.5\n",
     "must be below occupied_thresh"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
     "mode: fancy\n", "mode must be trinary, scale or raw"),
    ("image: nothere.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
     "cannot be read"),
    ("image: [m.pgm\n", "not valid YAML"),
])
def test_odd_yaml_is_a_sentence(tmp_path, yaml_text, words):
    (tmp_path / "m.pgm").write_bytes(pgm_bytes(np.zeros((2, 2), np.uint8)))
    (tmp_path / "m.yaml").write_text(yaml_text)
    with pytest.raises(MapError, match=words) as err:
        load_map(tmp_path / "m.yaml")
    assert str(tmp_path / "m.yaml") in err.value.message and err.value.code == "bad_request"


def test_an_image_given_as_the_map_and_a_missing_file(tmp_path):
    (tmp_path / "m.pgm").write_bytes(pgm_bytes(np.zeros((2, 2), np.uint8)))
    with pytest.raises(MapError, match="give the map's YAML"):
        load_map(tmp_path / "m.pgm")
    with pytest.raises(MapError, match="Cannot read the map"):
        load_map(tmp_path / "absent.yaml")


def test_a_failed_save_leaves_the_old_map(tmp_path, monkeypatch):
    info = GridInfo(3, 2, 0.05)
    save_map(OccupancyGrid(info, np.zeros((2, 3), np.int8)), tmp_path / "k.yaml")
    before = (tmp_path / "k.pgm").read_bytes(), (tmp_path / "k.yaml").read_bytes()

    def boom(*_):
        raise OSError("disk full")
    monkeypatch.setattr("asibot.files.os.replace", boom)
    with pytest.raises(OSError):
        save_map(OccupancyGrid(info, np.full((2, 3), 100, np.int8)), tmp_path / "k.yaml")
    assert ((tmp_path / "k.pgm").read_bytes(), (tmp_path / "k.yaml").read_bytes()) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["k.pgm", "k.yaml"]
    assert math.isfinite(load_map(tmp_path / "k.yaml").grid.info.resolution)
