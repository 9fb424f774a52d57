"""Fixtures for the navigation logic tests: the sim's apartment map and its named places."""

from __future__ import annotations

from pathlib import Path

import pytest

from asibot.nav.mapfile import LoadedMap, load_map
from asibot.nav.places import Places, world_places_file

MAPS = Path(__file__).resolve().parents[2] / "libs" / "common" / "asibot" / "maps"


@pytest.fixture(scope="session")
def apartment() -> LoadedMap:
    return load_map(MAPS / "apartment.yaml")


@pytest.fixture
def world_places(tmp_path) -> Places:
    """The world's places, with a user file in a temporary folder (never the real one)."""
    return Places(tmp_path / "places.yaml", world_places_file("apartment"))
