"""Bad or excessive input gets a sentence and changes nothing: caps on what the user's folder
keeps, JSON nested too deep, bodies too large however they are sent, `true` is not a number,
and what a killed save left behind is cleared at start."""

from __future__ import annotations

import io
import json
import os
import time
import zipfile

import pytest

from asibot.web.userdata import UserData, UserDataError
from asibot.web.userdata import folder as user_folder   # its limits

from .conftest import API_ROBOT, settle

PNG = b"\x89PNG\r\n\x1a\n" + b"\0" * 64


def test_the_folder_keeps_a_bounded_number_of_programs(tmp_path, monkeypatch):
    monkeypatch.setattr(user_folder, "MAX_PROGRAMS", 3)
    data = UserData(tmp_path)
    for n in range(3):
        data.save_program(f"p{n}", "print(1)\n")
    with pytest.raises(UserDataError, match="There are 3 programs already.*delete one"):
        data.save_program("p3", "print(1)\n")
    with pytest.raises(UserDataError, match="There are 3 programs"):
        data.new_program("p4")
    data.save_program("p0", "print(2)\n")                   # changing one is still fine
    assert data.programs() == ["p0", "p1", "p2"]


def test_the_folder_keeps_a_bounded_number_of_bytes(tmp_path, monkeypatch):
    monkeypatch.setattr(user_folder, "MAX_STORED_BYTES", 1000)
    data = UserData(tmp_path)
    data.save_program("small", "x = 1\n" * 100)              # 600 bytes
    with pytest.raises(UserDataError, match="past 0 MiB|Delete programs or icons"):
        data.save_program("more", "x = 1\n" * 100)
    with pytest.raises(UserDataError, match="Delete programs or icons"):
        data.save_program("small", "x = 1\n" * 200)           # growing past it
    with pytest.raises(UserDataError, match="Delete programs or icons"):
        data.add_icon("big.png", PNG + b"\0" * 600)
    assert data.programs() == ["small"] and data.read_program("small") == "x = 1\n" * 100


def test_an_import_stops_at_the_folders_limits(tmp_path, monkeypatch):
    """The attack: one small zip of many large, compressible programs filled the disk."""
    monkeypatch.setattr(user_folder, "MAX_PROGRAMS", 5)
    archive = io.BytesIO()
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as z:
        for n in range(250):
            z.writestr(f"p{n:03d}.py", "#" * 200_000 + "\n")
    data = UserData(tmp_path)
    report = data.import_zip(archive.getvalue())
    assert len(data.programs()) == 5
    assert sum("already" in s.reason for s in report.skipped) == 245


def test_icons_are_bounded_too(tmp_path, monkeypatch):
    monkeypatch.setattr(user_folder, "MAX_ICONS", 2)
    data = UserData(tmp_path)
    data.add_icon("a.png", PNG + b"a")
    data.add_icon("b.png", PNG + b"b")
    with pytest.raises(UserDataError, match="There are 2 icons already"):
        data.add_icon("c.png", PNG + b"c")


def test_what_a_killed_save_left_is_removed_at_start(tmp_path):
    (tmp_path / ".versions" / "p").mkdir(parents=True)
    old = [tmp_path / ".points.ini.abc123.tmp", tmp_path / ".versions" / "p" / ".1.py.x.tmp"]
    young = tmp_path / ".words.ini.def456.tmp"             # another process may be saving now
    for path in [*old, young]:
        path.write_bytes(b"half")
    hour_ago = time.time() - 3600
    for path in old:
        os.utime(path, (hour_ago, hour_ago))
    (tmp_path / "keep.tmp").write_bytes(b"a user's own file")
    UserData(tmp_path)
    assert not any(p.exists() for p in old)
    assert young.exists() and (tmp_path / "keep.tmp").exists()


# --- through the server ----------------------------------------------------------------------

def test_json_nested_too_deep_is_a_sentence_over_http_and_the_socket(web):
    client, svc, driver, server = web
    deep = b"[" * 100_000 + b"]" * 100_000
    reply = client.post("/api/points/x/rename", content=deep, headers={"content-type": "application/json"})
    assert reply.status_code == 400 and reply.json()["error"] == "bad_request"
    assert "JSON object" in reply.json()["message"]
    with client.websocket_connect(f"ws://127.0.0.1:8080/ws?session={svc.web.session}") as ws:
        assert ws.receive_json()["type"] == "hello"
        ws.send_text("[" * 100_000)
        ws.send_text("x" * 100_000)
        refusals = []
        while len(refusals) < 2:
            message = ws.receive_json()
            if message["type"] == "refused":
                refusals.append(message["text"])
    assert refusals == ["The page sent a message the server does not understand."] * 2


def test_a_chunked_body_over_the_limit_is_413(web):
    client, svc, driver, server = web

    def chunks():
        for _ in range(80):                                 # 5 MiB, no Content-Length
            yield b"x" * 65536
    reply = client.post("/api/programs", content=chunks(), headers={"content-type": "application/json"})
    assert reply.status_code == 413 and "nothing was changed" in reply.json()["message"]


@pytest.mark.parametrize("field", ["axis", "direction", "level"])
def test_true_is_not_a_number_for_a_held_jog_button(web, field):
    client, svc, driver, server = web
    settle(web)
    commands = len(driver.commands)
    hold = {"type": "hold", "robot": API_ROBOT, "space": "joint", "axis": 0, "direction": 1, "level": 3}
    hold[field] = True
    with client.websocket_connect(f"ws://127.0.0.1:8080/ws?session={svc.web.session}") as ws:
        ws.send_text(json.dumps(hold))
        while (message := ws.receive_json())["type"] != "refused":
            pass
    assert message["code"] == "bad_request" and "True" in message["text"]
    for command in list(driver.commands)[commands:]:          # at most the stop of a closed page: a hold
        assert not any(command.velocities) and command.values == pytest.approx(list(driver.commands)[commands - 1].values)


@pytest.mark.parametrize("minutes", [0, 241, True, 1.5, "10"])
def test_a_run_time_limit_is_a_whole_number_of_minutes(web, minutes):
    client, svc, driver, server = web
    client.post("/api/programs", json={"name": "limited"})
    reply = client.post("/api/programs/limited/run", json={"robot": API_ROBOT, "minutes": minutes})
    assert reply.status_code == 422 and "minutes" in reply.json()["message"]
    assert not svc.web.runner.running()


def test_the_time_limit_chosen_on_the_page_is_the_runs_limit(web, monkeypatch):
    client, svc, driver, server = web
    seen = {}
    monkeypatch.setattr(svc.web.runner, "start", lambda path, robot, name=None, wall_seconds=None:
                        seen.update(name=name, wall_seconds=wall_seconds))
    client.post("/api/programs", json={"name": "limited"})
    assert client.post("/api/programs/limited/run", json={"robot": API_ROBOT, "minutes": 2}).status_code == 200
    assert seen == {"name": "limited", "wall_seconds": 120.0}
