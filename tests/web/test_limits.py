"""Bad or excessive input gets a sentence and changes nothing: caps on what the user's folder
keeps (versions and trash counted, both bounded), JSON nested too deep, bodies too large however
they are sent, `true` is not a number, and what a killed save left behind is cleared at start."""

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
    with pytest.raises(UserDataError, match=r"^Your programs use 600 bytes of 1000 bytes \(versions 0 bytes, "
                                            r"trash 0 bytes, icons 0 bytes\); this program needs 600 bytes more, "
                                            r"so nothing was saved\. Delete programs .*empty the trash"):
        data.save_program("more", "x = 1\n" * 100)
    with pytest.raises(UserDataError, match="needs 1 KiB more"):  # growing past it (1200 bytes: its version kept too)
        data.save_program("small", "x = 1\n" * 200)
    with pytest.raises(UserDataError, match="this icon needs 672 bytes more"):
        data.add_icon("big.png", PNG + b"\0" * 600)
    assert data.programs() == ["small"] and data.read_program("small") == "x = 1\n" * 100
    assert data.versions("small") == [] and data.icons() == [i for i in data.icons() if i.shipped]


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


# --- issue 51, point 3: the cap counts everything the program store keeps --------------------

def disk_bytes(root) -> int:
    """Every byte in the folder, as the attacker measured it."""
    return sum(p.stat().st_size for p in root.rglob("*") if p.is_file() and not p.is_symlink())


def programs_zip(count: int, size: int, mark: str = "") -> bytes:
    """A small zip of `count` large, compressible programs (`mark` makes their text differ)."""
    archive = io.BytesIO()
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as z:
        for n in range(count):
            z.writestr(f"p{n:03d}.py", f"# {mark}\n" + "#" * (size - len(mark) - 3) + "\n")
    return archive.getvalue()


def test_many_imports_of_versions_stay_within_the_cap(tmp_path):
    """The attack: each import replaced every program, so each kept 30 MiB more of versions
    (20 imports of a 965 KiB zip wrote 641 MiB into .versions while the cap counted 32)."""
    data = UserData(tmp_path)
    for round in range(4):
        report = data.import_zip(programs_zip(120, 250_000, mark=f"round {round}"))
        assert disk_bytes(tmp_path) <= user_folder.MAX_STORED_BYTES, f"round {round}"
    refusals = [s.reason for s in report.skipped]
    assert refusals and all(r.startswith("Your programs use ") and " of 32 MiB (versions " in r
                            and "empty the trash" in r for r in refusals), refusals[:2]
    usage = data.usage()
    assert usage.total == disk_bytes(tmp_path) and usage.versions > 0


def test_normal_editing_keeps_a_bounded_history_and_never_hits_the_cap(tmp_path):
    data = UserData(tmp_path)
    for n in range(60):                        # a small program edited all day
        data.save_program("small", f"# edit {n}\n" + "x = 1\n" * 1000)
    assert len(data.versions("small")) == user_folder.VERSIONS_KEPT
    for n in range(30):                        # a program near the size limit, saved again and again
        data.save_program("big", f"# edit {n}\n" + "#" * 250_000 + "\n")
    big = data.versions("big")
    assert 1 <= len(big) <= 4 and sum(v.size for v in big) <= user_folder.VERSION_BYTES_KEPT
    assert data.read_version("big", big[0].id).startswith("# edit 28\n")        # the newest are kept
    assert disk_bytes(tmp_path / ".versions") <= 2 * user_folder.VERSION_BYTES_KEPT


def test_versions_kept_by_an_older_release_are_pruned_at_start(tmp_path):
    old = tmp_path / ".versions" / "p"
    old.mkdir(parents=True)
    for n in range(40):
        (old / f"{1_700_000_000_000_000_000 + n}.py").write_bytes(b"#" * 100_000)
    (tmp_path / "p.py").write_text("x = 1\n")
    data = UserData(tmp_path)
    kept = data.versions("p")
    assert len(kept) == 10 and kept[0].id == str(1_700_000_000_000_000_000 + 39)     # 1 MiB of them, the newest


def test_delete_and_reimport_no_longer_frees_the_cap(tmp_path):
    """The attack: deleting moved the files into .trash, never purged, and freed the cap for
    the same files imported again."""
    data = UserData(tmp_path)
    whole = programs_zip(140, 250_000)
    report = data.import_zip(whole)                     # fills the cap: the last ones are refused
    full = data.programs()
    assert report.skipped and len(full) < 140
    for name in full[:20]:
        data.delete_program(name)
    again = data.import_zip(whole)
    assert data.programs() == full[20:], "deleting freed the cap"
    assert disk_bytes(tmp_path) <= user_folder.MAX_STORED_BYTES
    reasons = {s.item: s.reason for s in again.skipped}
    assert "trash 4.8 MiB" in reasons["p000.py"] and "empty the trash" in reasons["p000.py"]
    emptied = data.empty_trash()                       # what the Program tab's "Empty the trash" does
    assert emptied.items == 20 and emptied.bytes >= 20 * 250_000
    data.import_zip(whole)
    assert data.programs() == full


def test_trash_older_than_30_days_is_purged(tmp_path):
    """The attack's other half: the trash was never purged."""
    data = UserData(tmp_path)
    for name in ("old", "older", "recent"):
        data.save_program(name, f"print({name!r})\n")
        data.save_program(name, f"print({name!r}, 2)\n")
    data.delete_program("old")
    data.delete_program("older")

    def deleted_31_days_ago() -> None:
        stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(time.time() - 31 * 86400))
        for entry in list((tmp_path / ".trash").iterdir()):      # <stamp>-<ns>-<name>
            entry.rename(entry.with_name(stamp + entry.name[15:]))
    deleted_31_days_ago()
    data.delete_program("recent")
    data.save_program("another", "print(1)\n")               # any write keeps the trash in bounds
    assert sorted(p.name.split("-", 3)[-1] for p in (tmp_path / ".trash").iterdir()) == ["recent.py", "recent.versions"]
    deleted_31_days_ago()
    UserData(tmp_path)                                        # and a start of the server
    assert list((tmp_path / ".trash").iterdir()) == []
    assert user_folder.TRASH_DAYS == 30                       # the figure docs/web-api.md gives


def test_the_trash_past_its_size_forgets_the_oldest_first(tmp_path, monkeypatch):
    monkeypatch.setattr(user_folder, "MAX_TRASH_BYTES", 2500)
    data = UserData(tmp_path)
    for name in ("a", "b", "c", "d"):
        data.save_program(name, "#" * 1000 + "\n")
        data.delete_program(name)
    left = sorted((tmp_path / ".trash").iterdir())
    assert [p.name.split("-", 3)[-1] for p in left] == ["c.py", "d.py"]
    assert data.usage().trash == 2002


def test_tasks_are_counted_and_bounded_too(tmp_path, monkeypatch):
    monkeypatch.setattr(user_folder, "MAX_TASKS", 2)
    data = UserData(tmp_path)
    data.save_program("p", "print(1)\n")
    data.save_task("one", "p", [], "drink.svg")
    data.save_task("two", "p", [], "drink.svg")
    with pytest.raises(UserDataError, match="There are 2 tasks already"):
        data.save_task("three", "p", [], "drink.svg")
    data.save_task("two", "p", ["water"], "drink.svg")      # changing one is still fine
    assert [t.name for t in data.tasks()] == ["one", "two"]


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


def test_the_program_tab_shows_what_is_kept_and_empties_the_trash(web):
    client, svc, driver, server = web
    client.delete("/api/trash")
    client.post("/api/programs", json={"name": "to_trash"})
    client.put("/api/programs/to_trash", json={"text": "print('a version')\n"})
    assert client.delete("/api/programs/to_trash").status_code == 200
    kept = client.get("/api/storage").json()
    assert kept["limit"] == user_folder.MAX_STORED_BYTES and kept["trash_items"] == 1    # the program (its versions go with it)
    assert kept["trash"] > 0 and kept["used"] == kept["programs"] + kept["icons"] + kept["versions"] + kept["trash"]
    emptied = client.delete("/api/trash").json()
    assert emptied["emptied"] == 1 and emptied["freed"] == kept["trash"]
    assert emptied["storage"]["trash"] == 0 and emptied["storage"]["trash_items"] == 0
    assert not list((svc.web.data.root / ".trash").iterdir())


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
