"""The shared map_server reader: every format gives map_server's values, shipped maps load as
before the reader moved here, and bad files are refused with a sentence."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from asibot.errors import AsibotError
from asibot.rosmap import MAX_CELLS, MapFileError, read_map

MAPS = Path(__file__).resolve().parents[2] / "libs" / "common" / "asibot" / "maps"
YAML = ("image: {image}\nresolution: 0.05\norigin: [1.0, -2.0, 0.0]\nnegate: {negate}\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\nmode: {mode}\n")
GREYS = np.arange(256, dtype=np.uint8).reshape(16, 16)


def image_loader(channels: tuple[int, ...], has_alpha: bool, mode: str, negate: bool,
                 occ_th: float = 0.65, free_th: float = 0.196) -> int:
    """ROS 1 map_server's image_loader.cpp for one pixel of 8-bit channels (alpha last), as the
    C++ reads it: the reference. An image without alpha is opaque (nav2; ROS 1 reads a colour)."""
    n = len(channels)
    avg_n = n if mode == "trinary" or not has_alpha else n - 1
    avg = sum(channels[:avg_n]) / avg_n
    alpha = channels[-1] if has_alpha else 255
    if negate:
        avg = 255 - avg
    if mode == "raw":
        v = int(avg)                                 # double into unsigned char, into the int8 map
        return v if v < 128 else v - 256
    occ = (255 - avg) / 255.0
    if occ > occ_th:
        return 100
    if occ < free_th:
        return 0
    if mode == "trinary" or alpha < 1:
        return -1
    return int(1 + 98 * (occ - free_th) / (occ_th - free_th))


def reference(img: np.ndarray, mode: str, negate: bool) -> np.ndarray:
    """image_loader over a BGR(A)/grey uint8 image, in grid order (row 0 at the bottom)."""
    px = img.reshape(img.shape[0], img.shape[1], -1)
    has_alpha = px.shape[2] == 4
    out = [[image_loader(tuple(int(c) for c in p), has_alpha, mode, negate) for p in row] for row in px]
    return np.array(out[::-1], dtype=np.int64)


def write_map(folder: Path, image: bytes, suffix: str = ".pgm", negate: int = 0, mode: str = "trinary") -> Path:
    (folder / f"m{suffix}").write_bytes(image)
    (folder / "m.yaml").write_text(YAML.format(image=f"m{suffix}", negate=negate, mode=mode))
    return folder / "m.yaml"


def encoded(img: np.ndarray, ext: str, *params: int) -> bytes:
    ok, buf = cv2.imencode(ext, img, list(params))
    assert ok
    return buf.tobytes()


#: The same greys in every format map_server maps come in; 16 bits are the greys times 257.
FORMATS = {
    "P5": lambda img: (encoded(img, ".pgm"), ".pgm"),
    "P2": lambda img: (encoded(img, ".pgm", cv2.IMWRITE_PXM_BINARY, 0), ".pgm"),
    "PNG": lambda img: (encoded(img, ".png"), ".png"),
    "BMP": lambda img: (encoded(img, ".bmp"), ".bmp"),
    "PNG 16-bit": lambda img: (encoded(img.astype(np.uint16) * 257, ".png"), ".png"),
    "PGM 16-bit": lambda img: (encoded(img.astype(np.uint16) * 257, ".pgm"), ".pgm"),
}


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("mode", ["trinary", "scale", "raw"])
@pytest.mark.parametrize("negate", [0, 1])
def test_every_grey_in_every_format_loads_as_map_server_loads_it(tmp_path, fmt, mode, negate):
    data, suffix = FORMATS[fmt](GREYS)
    m = read_map(write_map(tmp_path, data, suffix, negate, mode))
    assert m.values.dtype == np.int8 and m.values.flags.c_contiguous
    assert np.array_equal(m.values.astype(np.int64), reference(GREYS, mode, bool(negate)))
    assert m.settings.mode == mode and m.settings.negate == bool(negate) and m.image_path == tmp_path / f"m{suffix}"


def test_png_and_bmp_give_the_grid_of_the_pgm_of_the_same_picture(tmp_path):
    rng = np.random.default_rng(1)
    picture = rng.choice(np.array([0, 205, 254, 100, 180], np.uint8), size=(37, 53))
    grids = {}
    for fmt in ("P5", "PNG", "BMP"):
        folder = tmp_path / fmt
        folder.mkdir()
        data, suffix = FORMATS[fmt](picture)
        grids[fmt] = read_map(write_map(folder, data, suffix)).values
    assert np.array_equal(grids["PNG"], grids["P5"]) and np.array_equal(grids["BMP"], grids["P5"])
    assert set(np.unique(grids["P5"])) == {-1, 0, 100}


@pytest.mark.parametrize("ext", [".png", ".bmp", ".ppm"])
@pytest.mark.parametrize("mode", ["trinary", "scale", "raw"])
def test_a_colour_image_is_averaged_to_grey(tmp_path, ext, mode):
    rng = np.random.default_rng(2)
    bgr = rng.integers(0, 256, size=(12, 20, 3), dtype=np.uint8)   # most means are not whole numbers
    bgr[0, 0], bgr[0, 1] = (0, 0, 255), (200, 250, 10)             # pure red is dark: 85 on average
    m = read_map(write_map(tmp_path, encoded(bgr, ext), ext, mode=mode))
    assert np.array_equal(m.values.astype(np.int64), reference(bgr, mode, False))
    top = m.values[-1]
    assert top[0] == (100 if mode != "raw" else 85)


@pytest.mark.parametrize("mode", ["trinary", "scale", "raw"])
def test_alpha_as_map_servers_modes_read_it(tmp_path, mode):
    rng = np.random.default_rng(3)
    bgra = rng.integers(0, 256, size=(10, 16, 4), dtype=np.uint8)
    bgra[:, :8, 3] = 0                                   # the left half fully transparent
    bgra[0, 0] = (150, 150, 150, 0)                      # occupancy 0.41: between the thresholds
    bgra[0, 1] = (150, 150, 150, 255)
    bgra[0, 8] = (255, 255, 255, 0)                      # white: free, transparent or not (scale)
    m = read_map(write_map(tmp_path, encoded(bgra, ".png"), ".png", mode=mode))
    assert np.array_equal(m.values.astype(np.int64), reference(bgra, mode, False))
    top = m.values[-1]
    if mode == "scale":       # transparent means unknown where the grey says neither free nor occupied
        assert top[0] == -1 and 1 <= top[1] <= 99
    elif mode == "trinary":   # alpha averaged in: transparent white is (3 * 255 + 0) / 4, unknown
        assert top[8] == -1
    else:                     # raw ignores alpha
        assert top[0] == top[1] == 150 - 256


def test_a_32_bit_bmp_with_alpha_left_at_zero_is_opaque(tmp_path):
    grey = np.stack([GREYS] * 3, axis=2)
    bgra = np.concatenate([grey, np.zeros((16, 16, 1), np.uint8)], axis=2)
    m = read_map(write_map(tmp_path, encoded(bgra, ".bmp"), ".bmp"))
    assert np.array_equal(m.values.astype(np.int64), reference(GREYS, "trinary", False))


def test_negate_swaps_black_and_white(tmp_path):
    plain = read_map(write_map(tmp_path, encoded(GREYS, ".png"), ".png")).values
    negated = read_map(write_map(tmp_path, encoded(255 - GREYS, ".png"), ".png", negate=1)).values
    assert np.array_equal(plain, negated)
    assert plain[-1, 0] == 100 and negated[-1, 0] == 100   # black, then white negated: occupied


def test_trinary_and_scale_differ_only_between_the_thresholds(tmp_path):
    png = encoded(GREYS, ".png")
    trinary = read_map(write_map(tmp_path, png, ".png", mode="trinary")).values
    scale = read_map(write_map(tmp_path, png, ".png", mode="scale")).values
    between = trinary == -1
    assert between.sum() == 116                       # greys 90..205: occupancy in [0.196, 0.65]
    assert np.array_equal(trinary[~between], scale[~between])
    assert scale[between].min() == 1 and scale[between].max() == 98   # 1 + 98 p', truncated; no grey gives 99


def test_a_pnm_maxval_below_255_is_stretched_as_sdl_image_does(tmp_path):
    want = [[0, 255, 119], [255, 0, 136]]
    binary = b"P5\n# a comment\n3 2\n15\n" + bytes([0, 15, 7, 15, 0, 8])
    ascii_ = b"P2\n# a comment\n3 2\n# another\n15\n0 15 7\n15 0 8\n"
    wide = b"P5\n3 2\n1000\n" + np.array([0, 1000, 467, 1000, 0, 534], ">u2").tobytes()
    for data in (binary, ascii_, wide):
        m = read_map(write_map(tmp_path, data, mode="raw"))
        assert (m.values.view(np.uint8)[::-1]).tolist() == want


# ------------------------------------------------------------------ the maps shipped with the stack

def numpy_pgm(path: Path) -> np.ndarray:
    """A binary 8-bit PGM decoded with numpy alone, as the shipped maps are written."""
    data = path.read_bytes()
    header = re.match(rb"P5\s+(?:#[^\n]*\n\s*)*(\d+)\s+(\d+)\s+(\d+)\s", data)
    assert header and header.group(3) == b"255", f"{path} is not an 8-bit binary PGM"
    w, h = int(header.group(1)), int(header.group(2))
    return np.frombuffer(data, np.uint8, w * h, header.end()).reshape(h, w)


SHIPPED = sorted(MAPS.glob("*.yaml"))


@pytest.mark.parametrize("yaml_path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_every_shipped_map_loads_as_a_direct_decode_of_its_pgm(yaml_path):
    m = read_map(yaml_path)
    img = numpy_pgm(m.image_path)
    lut = np.array([image_loader((g,), False, m.settings.mode, m.settings.negate,
                                 m.settings.occupied_thresh, m.settings.free_thresh) for g in range(256)])
    assert np.array_equal(m.values.astype(np.int64), lut[img][::-1])


#: sha256 of the values the hand-written PGM reader gave (asibot.nav.mapfile before this reader),
#: for the apartment's image in every mode and negate.
OLD_APARTMENT = {
    ("trinary", 0): "a9fa49c8d4c41855afc397d4848a47dcf9922d950fa9765495e562be07e88e7e",
    ("trinary", 1): "33a476f1689db57abd9e4ba82f3c57e5ee0449d72e26e5726deec28b3db28f6e",
    ("scale", 0): "b2933c1a0cff10fb04737ab5efc9e441257d7b6fbcb25760c1cf1671dc923d86",
    ("scale", 1): "33a476f1689db57abd9e4ba82f3c57e5ee0449d72e26e5726deec28b3db28f6e",
    ("raw", 0): "b6298524fc34bbfea2b999767c8776f60526d88033084d5f62d492cfc308f64e",
    ("raw", 1): "42b2107cf45c15f275ea181154f2d41466ee35d5491de263cec46df7bd7ddae8",
}


@pytest.mark.parametrize("mode, negate", OLD_APARTMENT)
def test_the_apartment_loads_as_the_old_reader_loaded_it(tmp_path, mode, negate):
    (tmp_path / "a.yaml").write_text(YAML.format(image=MAPS / "apartment.pgm", negate=negate, mode=mode))
    m = read_map(tmp_path / "a.yaml")                   # an absolute image path, as map_server allows
    assert m.values.shape == (190, 230)
    assert hashlib.sha256(m.values.tobytes()).hexdigest() == OLD_APARTMENT[mode, negate]


# ------------------------------------------------------------------------------ bad files

def png_bytes() -> bytes:
    return encoded(GREYS, ".png")


@pytest.mark.parametrize("image, words", [
    (None, "names the image 'm.png', which cannot be read: No such file"),
    (b"", "is empty; a map image is a PGM, PNG or BMP"),
    (b"hello, I am text", "is not an image OpenCV can read; a map image is a PGM, PNG or BMP"),
    ("half a png", "looks like a PNG image but cannot be decoded: it is truncated or corrupt. Save the map image"),
    (b"P5\n4 4\n255\n" + bytes(5), "looks like a PGM image but cannot be decoded"),
    (encoded(np.ones((2, 2), np.float32), ".tiff"), "has float32 samples"),
])
def test_a_missing_or_broken_image_is_a_sentence(tmp_path, image, words):
    if image == "half a png":
        image = png_bytes()[:len(png_bytes()) // 2]
    (tmp_path / "m.yaml").write_text(YAML.format(image="m.png", negate=0, mode="trinary"))
    if image is not None:
        (tmp_path / "m.png").write_bytes(image)
    with pytest.raises(MapFileError, match=re.escape(words)) as err:
        read_map(tmp_path / "m.yaml")
    assert str(tmp_path / "m.yaml") in str(err.value)
    assert isinstance(err.value, ValueError) and isinstance(err.value, AsibotError)


def test_an_image_folder_is_a_sentence(tmp_path):
    (tmp_path / "m.png").mkdir()
    (tmp_path / "m.yaml").write_text(YAML.format(image="m.png", negate=0, mode="trinary"))
    with pytest.raises(MapFileError, match="which cannot be read: Is a directory"):
        read_map(tmp_path / "m.yaml")


@pytest.mark.parametrize("content, words", [
    (png_bytes(), "is a PNG image; give the map's YAML file"),
    (b"P2\n2 1\n255\n0 255\n", "is a PGM image; give the map's YAML file"),
    (b"\xff\xfe\x00binary", "is not a text file"),
    (b"image: [m.png\n", "is not valid YAML"),
])
def test_an_image_or_garbage_given_as_the_yaml(tmp_path, content, words):
    (tmp_path / "given").write_bytes(content)
    with pytest.raises(MapFileError, match=re.escape(words)):
        read_map(tmp_path / "given")


def test_too_many_cells_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr("asibot.rosmap.MAX_CELLS", 255)
    with pytest.raises(MapFileError, match="16 x 16 pixels; a map has at most 255 cells"):
        read_map(write_map(tmp_path, png_bytes(), ".png"))
    assert MAX_CELLS == 64_000_000


def test_defaults_fill_only_what_the_yaml_leaves_out(tmp_path):
    (tmp_path / "m.png").write_bytes(png_bytes())
    (tmp_path / "m.yaml").write_text("image: m.png\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 1\n")
    with pytest.raises(MapFileError, match="occupied_thresh, free_thresh are missing"):
        read_map(tmp_path / "m.yaml")
    m = read_map(tmp_path / "m.yaml", defaults={"negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.196})
    assert m.settings.negate and m.settings.occupied_thresh == 0.65 and m.settings.resolution == 0.1
