"""Private by default (issue 51): every folder the stack makes is 0700 and its files 0600,
whatever the umask and whichever process makes the user's data folder first."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from asibot import files
from asibot.files import data_dir
from asibot.testing import file_mode




@pytest.fixture
def new_data(tmp_path, monkeypatch) -> Path:
    """$ASIBOT_DATA named but not made yet, under a folder as open as a home folder can be."""
    home = tmp_path / "home"
    home.mkdir()
    home.chmod(0o755)
    monkeypatch.setenv("ASIBOT_DATA", str(home / "share" / "asibot"))
    return home / "share" / "asibot"


def test_private_dir_makes_every_missing_folder_0700_and_open_private_0600(tmp_path, permissive_umask):
    tmp_path.chmod(0o755)
    folder = files.private_dir(tmp_path / "a" / "b")
    assert folder == tmp_path / "a" / "b"
    assert (file_mode(tmp_path / "a"), file_mode(folder)) == (0o700, 0o700)
    assert file_mode(tmp_path) == 0o755                      # a folder that was there is not ours to change
    with files.open_private(folder / "new", "xb") as f:
        f.write(b"secret")
    assert file_mode(folder / "new") == 0o600
    with pytest.raises(FileExistsError):
        files.open_private(folder / "new", "xb")
    (folder / "old").write_bytes(b"")
    (folder / "old").chmod(0o644)
    with files.open_private(folder / "old", "wb") as f:       # an existing file is made private too
        f.write(b"x")
    assert file_mode(folder / "old") == 0o600


def test_a_folder_of_ours_open_to_others_is_made_private_and_said_once(tmp_path, caplog):
    folder = tmp_path / "recordings"
    folder.mkdir()
    folder.chmod(0o755)
    with caplog.at_level(logging.INFO, logger="asibot.files"):
        files.private_dir(folder)
        folder.chmod(0o755)                            # opened again by hand
        files.private_dir(folder)
    assert file_mode(folder) == 0o700
    said = [r for r in caplog.records if str(folder) in r.getMessage()]
    assert len(said) == 1 and "open to other users (755)" in said[0].getMessage(), caplog.text
    chosen = tmp_path / "exports"                       # a folder the user named for one file
    chosen.mkdir()
    chosen.chmod(0o755)
    files.private_dir(chosen, tighten=False)
    assert file_mode(chosen) == 0o755


def test_a_file_where_a_folder_should_be_is_refused(tmp_path):
    (tmp_path / "f").write_text("")
    with pytest.raises(OSError):
        files.private_dir(tmp_path / "f")


def _bridge(data: Path) -> list[Path]:
    from asibot.asterics_bridge import http_token
    http_token.ensure_token()
    return [data / "asterics"]


def _nav(data: Path) -> list[Path]:
    from asibot.nav.places import Places
    from asibot.nav.geometry import Pose
    Places.for_robot("pioneer-sim").save_position(Pose(1.0, 2.0, 0.5))
    return [data / "nav", data / "nav" / "pioneer-sim"]


def _voice(data: Path) -> list[Path]:
    from asibot.voice.pronunciations import Pronunciations
    Pronunciations(data_dir() / "voice" / "pronunciations.json").add("zorblat", ("Z", "AO", "R", "B", "L", "AE", "T"))
    return [data / "voice"]


def _web_lan(data: Path) -> list[Path]:
    from asibot.web import lan
    from asibot.web.userdata import default_root
    lan.ensure_token(default_root() / ".lan")
    return [data / ".lan"]


@pytest.mark.parametrize("first", [_bridge, _nav, _voice, _web_lan], ids=["asterics-bridge", "nav", "voice", "web-lan"])
def test_the_data_folder_is_private_whichever_service_makes_it_first(new_data, permissive_umask, first):
    made = first(new_data)
    for folder in [new_data.parent, new_data, *made]:
        assert file_mode(folder) == 0o700, f"{folder} is {file_mode(folder):03o}"
    written = [p for p in new_data.rglob("*") if p.is_file()]
    assert written and all(file_mode(p) == 0o600 for p in written), {str(p): f"{file_mode(p):03o}" for p in written}


def test_a_data_folder_left_open_is_made_private_when_a_service_opens_it(new_data, caplog):
    new_data.mkdir(parents=True)
    new_data.chmod(0o755)                               # made by an older version, or by hand
    with caplog.at_level(logging.INFO, logger="asibot.files"):
        assert data_dir() == new_data
    assert file_mode(new_data) == 0o700
    assert "made private (0700)" in caplog.text
