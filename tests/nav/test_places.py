"""Named places: the world's list, user changes persisted atomically, names validated."""

from __future__ import annotations

import math

import pytest
import yaml

from asibot.nav.errors import NavError
from asibot.nav.geometry import Pose
from asibot.nav.places import Places, user_places_file, world_places_file


def test_the_worlds_places(world_places):
    names = [p.name for p in world_places.list()]
    assert names == ["charging station", "desk", "fridge", "shelf"]
    assert world_places.get("Fridge").pose == Pose(8.7, 1.0, 0.0)
    assert world_places.get("  charging   STATION ").name == "charging station"


def test_unknown_place_suggests(world_places):
    with pytest.raises(NavError, match="I know no place called 'frige'. Did you mean 'fridge'?") as err:
        world_places.get("frige")
    assert "Known places: charging station, desk, fridge, shelf" in err.value.message


def test_add_rename_remove_persist_and_never_touch_the_world_file(tmp_path, apartment):
    world_before = world_places_file().read_bytes()
    places = Places(tmp_path / "places.yaml", world_places_file(), apartment.grid.info)
    places.add("sofa", Pose(2.0, 3.0, 0.5))
    places.rename("fridge", "Kühlschrank")
    places.remove("shelf")
    again = Places(tmp_path / "places.yaml", world_places_file())
    assert [p.name for p in again.list()] == ["charging station", "desk", "Kühlschrank", "sofa"]
    assert again.get("kühlschrank").pose == Pose(8.7, 1.0, 0.0)
    assert again.get("sofa").pose == Pose(2.0, 3.0, 0.5)
    assert world_places_file().read_bytes() == world_before
    doc = yaml.safe_load((tmp_path / "places.yaml").read_text(encoding="utf-8"))
    assert doc["frame"] == "map" and set(doc["places"]["sofa"]) == {"x", "y", "theta"}
    assert [p.name for p in tmp_path.iterdir()] == ["places.yaml"]       # no temp file left


def test_save_this_place_twice_and_duplicates(world_places):
    world_places.add("by the window", Pose(1.0, 6.0, 1.0))
    with pytest.raises(NavError, match="already a place called 'by the window'"):
        world_places.add("By The  Window", Pose(1.5, 6.0, 1.0))
    world_places.add("by the window", Pose(1.5, 6.0, 1.0), replace=True)
    assert world_places.get("by the window").pose.x == 1.5
    with pytest.raises(NavError, match="already a place called 'desk'"):
        world_places.rename("fridge", "DESK")


@pytest.mark.parametrize("name, words", [
    ("../etc/passwd", "because of '/'"),
    ("a\\b", "because of '\\\\\\\\'"),
    ("", "needs a name"),
    ("   ", "needs a name"),
    ("x" * 41, "at most 40"),
    ("bell\x07", "because of"),
    ("_hidden", "first character"),
    ("nul\x00", "because of"),
    (42, "must be text"),
])
def test_bad_names_are_sentences_and_nothing_is_saved(world_places, name, words):
    with pytest.raises(NavError, match=words):
        world_places.add(name, Pose(1.0, 1.0, 0.0))
    assert not world_places.user_file.exists()


def test_bad_poses_are_refused(tmp_path, apartment):
    places = Places(tmp_path / "p.yaml", world_places_file(), apartment.grid.info)
    for pose, words in (((math.nan, 1.0, 0.0), "finite"), ((100.0, 1.0, 0.0), "outside the map"),
                        ((1.0,), "three numbers")):
        with pytest.raises(NavError, match=words):
            places.add("here", pose)
    assert not (tmp_path / "p.yaml").exists()


def test_a_failed_write_changes_nothing(world_places, monkeypatch):
    world_places.add("sofa", Pose(2.0, 3.0, 0.0))
    before = world_places.user_file.read_bytes()

    def boom(*_):
        raise OSError("disk full")
    monkeypatch.setattr("asibot.files.os.replace", boom)
    with pytest.raises(OSError):
        world_places.remove("sofa")
    assert world_places.get("sofa").pose == Pose(2.0, 3.0, 0.0)
    assert world_places.user_file.read_bytes() == before
    assert sorted(p.name for p in world_places.user_file.parent.iterdir()) == ["places.yaml"]


def test_save_and_recall_position(world_places):
    with pytest.raises(NavError, match="No position is saved yet"):
        world_places.recall_position()
    world_places.save_position(Pose(3.0, 2.0, 1.0))
    again = Places(world_places.user_file, world_places_file())
    assert again.recall_position() == Pose(3.0, 2.0, 1.0)
    assert [p.name for p in again.list()] == ["charging station", "desk", "fridge", "shelf"]


def test_user_file_location(monkeypatch, tmp_path):
    monkeypatch.setenv("ASIBOT_DATA", str(tmp_path))
    assert user_places_file("pioneer-sim") == tmp_path / "nav" / "pioneer-sim" / "places.yaml"
    with pytest.raises(NavError, match="not a robot id"):
        user_places_file("../x")


def test_a_broken_user_file_is_a_sentence(tmp_path):
    (tmp_path / "p.yaml").write_text("places: [1, 2\n")
    with pytest.raises(NavError, match="not valid YAML"):
        Places(tmp_path / "p.yaml", world_places_file())
    (tmp_path / "p.yaml").write_text("places:\n  'a/b': {x: 1, y: 2, theta: 0}\n")
    with pytest.raises(NavError, match="because of '/'"):
        Places(tmp_path / "p.yaml", world_places_file())
