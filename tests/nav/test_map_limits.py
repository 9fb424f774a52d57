"""What nav keeps on disk is bounded (issue 51, point 3): a program may call map_save (and
save_place), so the robot's maps folder holds at most mapfile.MAX_MAPS maps and
MAX_MAPS_BYTES, and its places places.MAX_PLACES. A save past a cap is refused with a sentence
(how much is kept, the limit, how to free room) and writes nothing. The service is driven over
the in-memory bus, as a program would."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from asibot.bus import Bus
from asibot.client import NavClient
from asibot.errors import RpcError
from asibot.nav import mapfile, places as nav_places
from asibot.nav.errors import NavError
from asibot.nav.geometry import Pose
from asibot.nav.grid import GridInfo, OccupancyGrid
from asibot.nav.service import NavService

ROBOT = "pioneer-sim"
START = Pose(0.75, 1.5, math.pi)


@pytest.fixture
def nav(memory_bus, apartment, world_places, tmp_path, monkeypatch):
    """A NavService on the in-memory bus whose built map is the apartment (no mapping drive
    needed to save one), its maps folder in tmp_path; (client, service, maps folder)."""
    monkeypatch.setenv("ASIBOT_DATA", str(tmp_path))
    bus = Bus("nav", memory_bus)
    svc = NavService(bus, ROBOT, apartment, world_places, START, run_loop=False, map_period=0.0)
    svc.pilot.map_grid = lambda: apartment.grid
    try:
        with NavClient(ROBOT) as client:
            yield client, svc, tmp_path / "nav" / ROBOT / "maps"
    finally:
        svc.close()
        bus.close()


def folder_bytes(folder) -> int:
    return sum(p.stat().st_size for p in folder.iterdir() if p.is_file())


def test_map_save_past_the_count_is_refused_with_a_sentence(nav):
    """The attack: 300 map_save calls wrote 300 maps in 3 s."""
    client, svc, maps = nav
    refusals = []
    for n in range(30):
        try:
            client.map_save(f"map {n}")
        except RpcError as exc:
            refusals.append(exc)
    saved = sorted(p.name for p in maps.iterdir())
    assert len(saved) == 2 * 20, f"{len(saved) // 2} maps saved"       # a YAML and an image each
    assert len(refusals) == 10 and {e.code for e in refusals} == {"bad_request"}
    for exc in refusals:
        assert re.fullmatch(rf"There are 20 maps of {ROBOT} already, the most kept \(they take \d+ KiB of 64 MiB\), "
                            rf"so the map was not saved\. Save over a map you no longer use \(the same name "
                            rf"replaces it\) or delete old maps in {re.escape(str(maps))}\.", exc.message), exc.message
    client.map_save("map 3")                   # saving over one is still fine
    with pytest.raises(RpcError, match="20 maps of pioneer-sim already"):   # the map in use is saved the same way
        client._call("save_map", name="another")
    assert sorted(p.name for p in maps.iterdir()) == saved
    assert mapfile.MAX_MAPS == 20              # the figure docs/nav.md gives


def test_maps_count_bytes(nav, monkeypatch, apartment):
    """Twenty maps of a large building would be 500 MB: the folder's bytes are capped too."""
    client, svc, maps = nav
    big = OccupancyGrid(GridInfo(5000, 5000, 0.05), np.zeros((5000, 5000), np.int8))   # 250 m square: 25 MB
    svc.pilot.map_grid = lambda: big
    client.map_save("first")
    client.map_save("second")
    two = folder_bytes(maps)
    with pytest.raises(RpcError, match=rf"^The maps of {ROBOT} take 47.7 MiB of 64 MiB \(2 maps, at most 20\); this "
                                       r"one needs 23.8 MiB more, so it was not saved\. Save over a map you no longer "
                                       r"use \(the same name replaces it\) or delete old maps in " + re.escape(str(maps))):
        client.map_save("third")
    assert sorted(p.stem for p in maps.iterdir()) == ["first", "first", "second", "second"]
    assert folder_bytes(maps) == two
    svc.pilot.map_grid = lambda: apartment.grid
    client.map_save("third")                   # a small one still fits
    client.map_save("first", use=True)         # the same name: only what it adds counts
    assert mapfile.MAX_MAPS_BYTES == 64 * 2**20 and folder_bytes(maps) <= mapfile.MAX_MAPS_BYTES


def test_places_past_the_count_are_refused_with_a_sentence(world_places, monkeypatch):
    monkeypatch.setattr(nav_places, "MAX_PLACES", 6)
    have = len(world_places.list())
    for n in range(6 - have):
        world_places.add(f"spot {n}", Pose(2.0, 1.5, 0.0))
    before = world_places.user_file.read_bytes()
    with pytest.raises(NavError, match=r"^There are already 6 places, the most I keep \(6\), so 'one more' was not "
                                       r"saved: remove one you no longer use first \(Remove on the Base page, or "
                                       r"remove_place\)\."):
        world_places.add("one more", Pose(2.0, 1.5, 0.0))
    assert world_places.user_file.read_bytes() == before
    world_places.add("spot 0", Pose(2.5, 1.5, 0.0), replace=True)   # moving one is still fine
    world_places.remove("spot 1")
    world_places.add("one more", Pose(2.0, 1.5, 0.0))
