"""The web Task Creator's user files: round trips, the seed's formats, refusals, versions and
atomic writes. Plain files in tmp_path; no server, no bus."""

from __future__ import annotations

import io
import math
import os
import signal
import struct
import subprocess
import sys
import threading
import time
import zipfile
import zlib
from pathlib import Path

import pytest

from asibot.web import userdata
from asibot.web.userdata import AlreadyExists, NotFound, UserData, UserDataError, seed


def png(width: int = 1, height: int = 1) -> bytes:
    """A real, tiny PNG."""
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    raw = b"".join(b"\x00" + b"\xff\x00\x00" * width for _ in range(height))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


JPEG = b"\xff\xd8\xff\xe0\x00\x10JFIF\x00" + b"\x00" * 32 + b"\xff\xd9"
GIF = b"GIF89a\x01\x00\x01\x00\x00\x00\x00;"
WEBP = b"RIFF\x1a\x00\x00\x00WEBPVP8L" + b"\x00" * 14


@pytest.fixture
def data(tmp_path: Path) -> UserData:
    return UserData(tmp_path / "data")


def snapshot(root: Path) -> dict[str, bytes]:
    """Every file under root, to prove that a refusal changed nothing."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def refused(data: UserData, kind: type[Exception], call, *args, match: str | None = None) -> str:
    """Call must raise `kind` with a sentence and leave every file as it was."""
    before = snapshot(data.root)
    with pytest.raises(kind, match=match) as info:
        call(*args)
    assert snapshot(data.root) == before
    message = str(info.value)
    assert message.endswith(".") and message[0].isupper(), message
    assert len(message) < 300, message
    return message


# ------------------------------------------------------------------------------ default root

def test_default_root_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("ASIBOT_DATA", str(tmp_path / "mine"))
    assert userdata.default_root() == tmp_path / "mine"
    monkeypatch.delenv("ASIBOT_DATA")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert userdata.default_root() == tmp_path / "xdg" / "asibot"
    monkeypatch.setenv("XDG_DATA_HOME", "relative/ignored")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert userdata.default_root() == tmp_path / "home" / ".local" / "share" / "asibot"


def test_the_folder_is_created(tmp_path):
    UserData(tmp_path / "a" / "b")
    assert (tmp_path / "a" / "b").is_dir()


# ------------------------------------------------------------------------------------ points

def test_points_round_trip(data):
    assert data.points() == [] and data.suggest_point_name() == "point-1"
    data.add_point("point-1", [0.0, 0.5, 0.21, 180, 0])
    data.add_point("above.can", [0.1, -0.2, 1e-05, 90.5, -45])
    assert data.suggest_point_name() == "point-2"
    assert data.point("above.can").values == [0.1, -0.2, 1e-05, 90.5, -45.0]
    assert (data.root / "points.ini").read_text() == ("point-1 0.0 0.5 0.21 180.0 0.0\n"
                                                      "above.can 0.1 -0.2 1e-05 90.5 -45.0\n")

    data.rename_point("point-1", "can")
    assert [p.name for p in data.points()] == ["can", "above.can"]  # renamed in place
    assert data.suggest_point_name() == "point-1"
    data.add_point("can", [1, 2, 3, 4, 5], replace=True)
    assert data.point("can").values == [1.0, 2.0, 3.0, 4.0, 5.0]
    data.delete_point("can")
    assert [p.name for p in UserData(data.root).points()] == ["above.can"]


def test_suggestion_takes_the_first_free_number(data):
    for n in (1, 2, 4):
        data.add_point(f"point-{n}", [0, 0, 1.4, 0, 0])
    assert data.suggest_point_name() == "point-3"


@pytest.mark.parametrize("values", [
    [0, 0, 1.4, 0], [0, 0, 1.4, 0, 0, 0], [], [math.nan, 0, 1, 0, 0], [0, math.inf, 1, 0, 0],
    [0, 0, -math.inf, 0, 0], ["0", 0, 1, 0, 0], [True, 0, 1, 0, 0], [None, 0, 1, 0, 0], "0 0 1 0 0", None,
])
def test_bad_point_values_are_refused(data, values):
    data.add_point("kept", [0, 0, 1.4, 0, 0])
    message = refused(data, UserDataError, data.add_point, "point-2", values)
    assert "point" in message


@pytest.mark.parametrize("name", ["", "../x", "a/b", "a b", "1abc", ".hidden", "x" * 65, "a\nb", "a\\b", None, 3])
def test_bad_point_names_are_refused(data, name):
    data.add_point("kept", [0, 0, 1.4, 0, 0])
    message = refused(data, UserDataError, data.add_point, name, [0, 0, 1, 0, 0])
    assert "point name" in message


def test_point_refusals(data):
    data.add_point("a", [0, 0, 1, 0, 0])
    data.add_point("b", [0, 0, 1, 0, 0])
    refused(data, AlreadyExists, data.add_point, "a", [0, 0, 1, 0, 0])
    refused(data, AlreadyExists, data.rename_point, "a", "b")
    refused(data, NotFound, data.rename_point, "c", "d")
    refused(data, NotFound, data.delete_point, "c")
    refused(data, NotFound, data.point, "c")
    refused(data, UserDataError, data.rename_point, "a", "../b")


def test_a_long_value_is_quoted_short(data):
    message = refused(data, UserDataError, data.add_point, "x" * 500, [0, 0, 1, 0, 0])
    assert "x" * 40 + "'..." in message and "x" * 41 not in message


def test_captures_from_many_threads_are_all_kept(data):
    def capture(thread: int) -> None:
        for n in range(10):
            data.add_point(f"t{thread}-{n}", [thread, n, 1.0, 0, 0])
    threads = [threading.Thread(target=capture, args=(k,)) for k in range(8)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert len(data.points()) == 80 and data.point("t7-9").values == [7.0, 9.0, 1.0, 0.0, 0.0]


def test_a_hand_broken_points_line_is_left_out(data):
    (data.root / "points.ini").write_text("good 0 0 1 0 0\nbroken 0 0\nbad nan 0 1 0 0\n\ngood2 1 1 1 1 1\n")
    assert [p.name for p in data.points()] == ["good", "good2"]


# ---------------------------------------------------------------------------------- programs

def test_new_program_comes_from_the_template(data):
    text = data.new_program("fetch")
    assert "CartesianClient" in text and text == data.read_program("fetch")
    assert data.programs() == ["fetch"]
    assert data.check_program(text) == []
    refused(data, AlreadyExists, data.new_program, "fetch")


def test_program_round_trip_rename_delete(data):
    data.save_program("drink", "print('drink')\n")
    data.save_program("Can_2-b", "print('can')\n")
    assert data.programs() == ["Can_2-b", "drink"]
    assert data.read_program("drink") == "print('drink')\n"
    data.save_program("drink", "print('more')\n")
    data.rename_program("drink", "water")
    assert data.programs() == ["Can_2-b", "water"]
    assert [v.size for v in data.versions("water")] == [len("print('drink')\n")]  # versions follow
    data.delete_program("water")
    assert data.programs() == ["Can_2-b"]
    trashed = sorted(p.name for p in (data.root / ".trash").iterdir())
    assert any(n.endswith("-water.py") for n in trashed) and any(n.endswith("-water.versions") for n in trashed)
    refused(data, NotFound, data.read_program, "water")
    refused(data, NotFound, data.delete_program, "water")
    refused(data, NotFound, data.rename_program, "water", "x")
    data.save_program("x", "pass\n")
    refused(data, AlreadyExists, data.rename_program, "x", "Can_2-b")


def test_programs_ignore_other_files(data):
    data.save_program("ok", "pass\n")
    for name in ("bad name.py", ".x.py", "1x.py"):
        (data.root / name).write_text("pass\n")
    (data.root / "dir.py").mkdir()
    assert data.programs() == ["ok"]


@pytest.mark.parametrize("name", ["", "../x", "a/b", "a b", "1abc", "_x", "a.b", "x" * 65, "a\x00b", "ä", None])
def test_bad_program_names_are_refused(data, name):
    message = refused(data, UserDataError, data.save_program, name, "pass\n")
    assert "program name" in message
    refused(data, UserDataError, data.new_program, name)
    refused(data, UserDataError, data.read_program, name)


def test_program_text_limits(data):
    data.save_program("p", "pass\n")
    big = "# " + "x" * userdata.MAX_PROGRAM_BYTES + "\n"
    assert "limit" in refused(data, UserDataError, data.save_program, "p", big)
    assert "limit" in refused(data, UserDataError, data.check_program, big)
    refused(data, UserDataError, data.save_program, "p", "a\x00b")
    refused(data, UserDataError, data.save_program, "p", b"pass\n")
    refused(data, UserDataError, data.save_program, "p", "\udc80")
    data.save_program("p", "# " + "é" * 1000 + "\n")  # limit is in bytes, UTF-8 is fine


def test_check_program_reports_line_and_column(data):
    assert data.check_program("x = 1\nprint(x)\n") == []
    [problem] = data.check_program("x = 1\nprint 'hello'\n")
    assert problem.line == 2 and problem.column >= 1 and "print" in problem.message
    [problem] = data.check_program("def f(:\n    pass\n")
    assert problem.line == 1
    [problem] = data.check_program("(" * 300)
    assert problem.line == 1 and "nested" in problem.message
    [problem] = data.check_program("-" * 100_000 + "1")  # too deep for the compiler, not a crash
    assert problem.line == 1
    [warning] = data.check_program("x = 1\nif x is 1:\n    pass\n")
    assert warning.line == 2 and warning.message.startswith("Warning:")


def test_check_program_never_runs_the_code(data, tmp_path):
    marker = tmp_path / "ran"
    assert data.check_program(f"open({str(marker)!r}, 'w').write('x')\n") == []
    assert not marker.exists()


def test_a_save_keeps_the_previous_version(data):
    data.save_program("p", "v1\n")
    assert data.versions("p") == []
    data.save_program("p", "v2\n")
    data.save_program("p", "v2\n")  # unchanged: no new version
    data.save_program("p", "v3\n")
    versions = data.versions("p")
    assert [data.read_version("p", v.id) for v in versions] == ["v2\n", "v1\n"]  # newest first
    assert all(abs(v.saved - time.time()) < 60 and v.size == 3 for v in versions)

    data.restore_version("p", versions[1].id)
    assert data.read_program("p") == "v1\n"
    assert data.read_version("p", data.versions("p")[0].id) == "v3\n"  # the restore can be undone

    refused(data, NotFound, data.read_version, "p", "123")
    for bad in ("../p", "1/2", "", "abc", None):
        refused(data, UserDataError, data.read_version, "p", bad)


def test_only_the_last_versions_are_kept(data):
    for n in range(userdata.VERSIONS_KEPT + 5):
        data.save_program("p", f"v{n}\n")
    versions = data.versions("p")
    assert len(versions) == userdata.VERSIONS_KEPT
    assert data.read_version("p", versions[0].id) == f"v{userdata.VERSIONS_KEPT + 3}\n"
    assert data.read_version("p", versions[-1].id) == "v4\n"


# ------------------------------------------------------------------------------------- words

def test_words_round_trip(data):
    data.add_word("water")
    data.add_word("  give me the red can ")
    data.add_word("¡Agua, por favor!")
    assert data.words() == ["water", "give me the red can", "¡Agua, por favor!"]
    refused(data, AlreadyExists, data.add_word, "WATER")
    data.delete_word("Water")
    assert UserData(data.root).words() == ["give me the red can", "¡Agua, por favor!"]
    refused(data, NotFound, data.delete_word, "water")


@pytest.mark.parametrize("word", ["", "   ", "a\nb", "a;b", "x" * 81, "tab\there", None, 5])
def test_bad_words_are_refused(data, word):
    data.add_word("kept")
    assert "word" in refused(data, UserDataError, data.add_word, word)


# ------------------------------------------------------------------------------------- tasks

def test_tasks_round_trip(data):
    data.save_program("fetch_can", "pass\n")
    task = data.save_task("Give me the red can", "fetch_can", ["red can", "can please"], "can.svg")
    assert task == data.task("Give me the red can")
    assert (data.root / "Give me the red can.task").read_text() == "fetch_can\nred can;can please\ncan.svg\n"
    assert data.words() == ["red can", "can please"]  # the task's words are recorded too
    data.save_task("Give me the red can", "fetch_can", [], "stop.svg")  # replaced
    assert data.task("Give me the red can").words == [] and data.task("Give me the red can").icon == "stop.svg"
    data.save_task("home", "fetch_can", ["home"], "home.svg")
    assert [t.name for t in data.tasks()] == ["Give me the red can", "home"]

    data.rename_program("fetch_can", "can")
    assert {t.program for t in data.tasks()} == {"can"}  # tasks follow their program
    assert data.task("home") == userdata.Task("home", "can", ["home"], "home.svg")
    assert "task" in refused(data, UserDataError, data.delete_program, "can")  # still used
    data.delete_task("home")
    data.delete_task("Give me the red can")
    assert data.tasks() == []
    data.delete_program("can")
    refused(data, NotFound, data.delete_task, "home")


def test_a_task_keeps_its_robot_in_a_fourth_line(data):
    """Ours name the robot a task runs on; the original ASIBOT's 3 lines still load (no robot)."""
    data.save_program("fetch_can", "pass\n")
    task = data.save_task("Give me the red can", "fetch_can", [], "can.svg", "asibot-sim")
    assert task.robot == "asibot-sim" and data.task("Give me the red can") == task
    assert (data.root / "Give me the red can.task").read_text() == "fetch_can\n\ncan.svg\nasibot-sim\n"
    (data.root / "old.task").write_text("fetch_can\ncan\ncan.svg\n")
    assert data.task("old").robot == ""
    data.rename_program("fetch_can", "can")
    assert data.task("Give me the red can").robot == "asibot-sim"          # kept when it follows its program
    assert "robot" in refused(data, UserDataError, data.save_task, "t", "can", [], "can.svg", "a/b")
    (data.root / "broken.task").write_text("can\n\ncan.svg\nno such/robot\n")
    assert "robot" in refused(data, UserDataError, data.task, "broken")


def test_task_refusals(data):
    data.save_program("p", "pass\n")
    data.save_task("t", "p", ["w"], "drink.svg")
    assert "program" in refused(data, NotFound, data.save_task, "t2", "nope", ["w"], "drink.svg")
    assert "icon" in refused(data, NotFound, data.save_task, "t2", "p", ["w"], "nope.png")
    refused(data, UserDataError, data.save_task, "t2", "p", ["w"], "../drink.svg")
    refused(data, UserDataError, data.save_task, "t2", "p", ["a;b"], "drink.svg")
    refused(data, UserDataError, data.save_task, "t2", "p", "w", "drink.svg")
    refused(data, UserDataError, data.save_task, "t2", "../p", ["w"], "drink.svg")
    refused(data, NotFound, data.task, "t2")


@pytest.mark.parametrize("name", ["", " ", "../x", "a/b", "a\\b", "..", ".hidden", "x" * 65, "a\nb", "a\x7fb", None])
def test_bad_task_names_are_refused(data, name):
    data.save_program("p", "pass\n")
    assert "task name" in refused(data, UserDataError, data.save_task, name, "p", [], "drink.svg")


def test_a_broken_task_file_is_left_out(data):
    data.save_program("p", "pass\n")
    data.save_task("good", "p", [], "home.svg")
    (data.root / "broken.task").write_text("p\n")
    assert [t.name for t in data.tasks()] == ["good"]
    assert "3 lines" in refused(data, UserDataError, data.task, "broken")
    (data.root / "broken.task").write_text("p\n\nhome.svg\nasibot-sim\nmore\n")
    assert "may have a 4th" in refused(data, UserDataError, data.task, "broken")


# ------------------------------------------------------------------------------------- icons

def test_shipped_icons_are_listed_and_readable(data):
    names = {i.name for i in data.icons() if i.shipped}
    assert {"drink.svg", "can.svg", "face.svg", "teeth.svg", "home.svg", "stop.svg"} <= names
    for name in ("drink", "can", "face", "teeth", "home", "stop"):
        svg = (userdata.SHIPPED_ICONS / f"{name}.svg").read_text()
        assert 'viewBox="0 0 96 96"' in svg and "<title" in svg and "<script" not in svg


def test_uploaded_icons(data):
    assert data.add_icon("My Glass!.PNG", png()) == "My-Glass.png"
    assert data.add_icon("My Glass!.PNG", png()) == "My-Glass.png"  # the same image again
    assert data.add_icon("My Glass!.PNG", png(2, 2)) == "My-Glass-2.png"  # another image, same name
    assert data.add_icon("C:\\photos\\can.jpeg", JPEG) == "can.jpg"  # our can.svg stays different
    assert data.add_icon("anim.gif", GIF) == "anim.gif"
    assert data.add_icon("disguised.png", WEBP) == "disguised.webp"  # the bytes decide the type
    assert data.add_icon("../../etc/passwd", png()) == "passwd.png"
    assert data.add_icon("....", GIF) == "icon.gif"
    uploaded = [i.name for i in data.icons() if not i.shipped]
    assert uploaded == sorted(["My-Glass.png", "My-Glass-2.png", "can.jpg", "anim.gif", "disguised.webp",
                               "passwd.png", "icon.gif"])
    assert data.icon_file("can.jpg").read_bytes() == JPEG
    assert data.icon_file("can.svg") == userdata.SHIPPED_ICONS / "can.svg"
    data.save_program("p", "pass\n")
    data.save_task("t", "p", [], "anim.gif")


@pytest.mark.parametrize("body", [
    b"<svg xmlns='http://www.w3.org/2000/svg'><script>alert(1)</script></svg>",
    b"<?xml version='1.0'?><svg/>", b"hello", b"", b"\x89PNG", b"RIFF\x00\x00\x00\x00WAVE....",
    b"\x89PNG\r\n\x1a\n" + b"\x00" * userdata.MAX_ICON_BYTES,
])
def test_bad_uploads_are_refused(data, body):
    refused(data, UserDataError, data.add_icon, "icon.png", body)


def test_icon_file_refusals(data):
    refused(data, NotFound, data.icon_file, "nope.png")
    for bad in ("../points.ini", "icons/x.png", "x.exe", "", ".png", "a b.png"):
        refused(data, UserDataError, data.icon_file, bad)
    (data.root / "icons").mkdir()
    (data.root / "icons" / "sneaky.svg").write_text("<svg><script/></svg>")  # put there by hand
    assert "sneaky.svg" not in {i.name for i in data.icons()}
    refused(data, NotFound, data.icon_file, "sneaky.svg")


# --------------------------------------------------------------------------- seed formats

PYTHON2_PROGRAM = """\
#!/usr/bin/python
# Programa de ejemplo: coge la lata
import yarp
from AsibotPy import *
home=[0,0,1.4,0,0]
simCart = CartesianClient()
simCart.open('/ravebot')
print 'hola, robot!'
simCart.movl(home)
simCart.wait()
simCart.close()
"""


def seed_folder(root: Path) -> Path:
    """A user folder as the seed's webInterface left it."""
    root.mkdir()
    (root / "points.ini").write_bytes(b"capture1 0.3 0.2 0.9 90 0\r\nabove_can 0 0.5 0.21 180 0\n"
                                      b"bad point 1 2 3 4 5\nshort 1 2\nnotnum a b c d e\ncapture1 0.3 0.2 0.8 90 0\n")
    (root / "words.ini").write_bytes("agua\ncan\n\nlata\xa0roja\nagua\n".encode("cp1252"))  # Latin-1, as in 2010
    (root / "template.py").write_text(PYTHON2_PROGRAM)
    (root / "water.py").write_text("print('water')\n")
    (root / "can.py").write_text("print('can')\n")
    (root / "bad name.py").write_text("pass\n")
    (root / "water.task").write_text("water\nagua\ndrinkWater.jpg\n")
    (root / "can.task").write_text("can.py\nlata roja\nmycan.png\n")
    (root / "home.task").write_text("home\nhome\nhome.png\n")  # its program is missing
    (root / "mycan.png").write_bytes(png())
    (root / "drinkWater.jpg").write_bytes(JPEG)  # the seed's own figure
    (root / "evil.svg").write_text("<svg><script>alert(1)</script></svg>")
    (root / "notes.txt").write_text("hi")
    (root / "link.py").symlink_to("/etc/passwd")
    return root


def test_import_a_seed_folder(data, tmp_path):
    report = data.import_folder(seed_folder(tmp_path / "seed"))
    assert [(p.name, p.values) for p in data.points()] == [
        ("above_can", [0.0, 0.5, 0.21, 180.0, 0.0]), ("capture1", [0.3, 0.2, 0.8, 90.0, 0.0])]  # the later line wins
    assert data.words() == ["agua", "can", "lata\xa0roja", "lata roja"]
    assert data.programs() == ["can", "template", "water"]
    assert data.read_program("template") == PYTHON2_PROGRAM  # kept as it was, to be fixed by the user
    assert data.tasks() == [userdata.Task("can", "can", ["lata roja"], "mycan.png"),
                            userdata.Task("water", "water", ["agua"], "drink.svg")]
    assert data.icon_file("mycan.png").read_bytes() == png()

    skipped = {s.item: s.reason for s in report.skipped}
    assert set(skipped) == {"points.ini line 3", "points.ini line 4", "points.ini line 5", "bad name.py",
                            "home.task", "drinkWater.jpg", "evil.svg", "notes.txt"}
    assert "program" in skipped["home.task"] and "drink.svg" in skipped["drinkWater.jpg"]
    assert "SVG" in skipped["evil.svg"]
    assert "task water" in report.imported and "icon mycan.png" in report.imported
    assert any("template" in n and "Python 3" in n for n in report.notes)
    assert any("words.ini" in n and "Latin-1" in n for n in report.notes)
    assert any("drink.svg" in n and "drinkWater.jpg" in n for n in report.notes)


def state(data: UserData) -> tuple:
    return (data.points(), data.words(), {p: data.read_program(p) for p in data.programs()}, data.tasks(),
            {i.name: data.icon_file(i.name).read_bytes() for i in data.icons() if not i.shipped})


def test_export_and_reimport_gives_the_same(data, tmp_path):
    data.import_folder(seed_folder(tmp_path / "seed"))
    data.save_program("water", "print('v2')\n")  # a version and a trash entry must stay behind
    data.save_program("gone", "pass\n")
    data.delete_program("gone")
    exported = data.export_zip()
    names = zipfile.ZipFile(io.BytesIO(exported)).namelist()
    assert not any(n.startswith((".versions", ".trash")) for n in names)
    assert {"points.ini", "words.ini", "water.py", "can.task", "icons/mycan.png"} <= set(names)

    other = UserData(tmp_path / "other")
    report = other.import_zip(exported)
    assert report.skipped == [] and state(other) == state(data)
    assert other.export_zip() and state(UserData(other.root)) == state(data)

    # The export is a seed folder too: unzipped, import_folder reads it the same way.
    unzipped = tmp_path / "unzipped"
    zipfile.ZipFile(io.BytesIO(exported)).extractall(unzipped)
    third = UserData(tmp_path / "third")
    third.import_folder(unzipped)
    assert state(third) == state(data)

    # Importing over itself changes nothing but keeps the replaced programs' old text.
    data.import_zip(exported)
    assert state(data) == state(other)


def test_a_zipped_seed_folder_with_its_top_folder(data, tmp_path):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("webInterface/points.ini", "p1 0 0 1.4 0 0\n")
        z.writestr("webInterface/go.py", "pass\n")
        z.writestr("webInterface/go.task", "go\n\nhome.png\n")
    report = data.import_zip(buf.getvalue())
    assert report.skipped == [] and data.tasks() == [userdata.Task("go", "go", [], "home.svg")]


def zip_of(entries: dict[str, bytes], compression: int = zipfile.ZIP_DEFLATED) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression) as z:
        for name, body in entries.items():
            z.writestr(name, body)
    return buf.getvalue()


@pytest.mark.parametrize("name", ["../x.py", "a/../../x.py", "/etc/x.py", "\\x.py", "C:/x.py", "..\\x.py"])
def test_traversal_zip_entries_refuse_the_zip(data, name):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("ok.py", b"pass\n")
        info = zipfile.ZipInfo("placeholder")
        info.filename = name  # as a hostile zip would hold it, unnormalised
        z.writestr(info, b"pass\n")
    assert "refused" in refused(data, UserDataError, data.import_zip, buf.getvalue())
    assert data.programs() == []


def test_link_entries_refuse_the_zip(data):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        info = zipfile.ZipInfo("points.ini")
        info.external_attr = (0o120777 << 16)
        z.writestr(info, "/etc/passwd")
    assert "link" in refused(data, UserDataError, data.import_zip, buf.getvalue())


def test_zip_bombs_are_refused(data, monkeypatch):
    # A program that claims a small size but unpacks past the limit: the lie is caught while reading.
    bomb = zip_of({"bomb.py": b"#" * (userdata.MAX_PROGRAM_BYTES + 10)})
    honest = zip_of({"bomb.py": b"#" * 10})
    z = zipfile.ZipFile(io.BytesIO(bomb))
    info = z.getinfo("bomb.py")
    lying = bomb.replace(struct.pack("<I", info.file_size), struct.pack("<I", 10))
    assert lying != bomb and honest
    assert "refused" in refused(data, UserDataError, data.import_zip, lying)

    # An honest but too big entry is skipped unread; many entries or a huge total refuse the zip.
    report = data.import_zip(bomb)
    assert [s.item for s in report.skipped] == ["bomb.py"] and data.programs() == []
    monkeypatch.setattr(seed, "MAX_ZIP_ENTRIES", 3)
    refused(data, UserDataError, data.import_zip, zip_of({f"p{n}.py": b"pass\n" for n in range(4)}))
    monkeypatch.setattr(seed, "MAX_ZIP_ENTRIES", 2000)
    monkeypatch.setattr(seed, "MAX_ZIP_TOTAL", 100_000)
    refused(data, UserDataError, data.import_zip, zip_of({f"p{n}.py": b"#" * 60_000 + b"\n" for n in range(2)}))
    refused(data, UserDataError, data.import_zip, b"not a zip")


def test_import_folder_refusals(data, tmp_path):
    refused(data, NotFound, data.import_folder, tmp_path / "nope")


# --------------------------------------------------------------------------- atomic writes

def test_a_failed_replace_leaves_the_old_file(data, monkeypatch):
    data.save_program("p", "old\n")
    data.add_point("a", [0, 0, 1, 0, 0])

    def broken(*args):
        raise OSError("disk gone")
    monkeypatch.setattr(os, "replace", broken)
    before = snapshot(data.root)
    with pytest.raises(OSError):
        data.save_program("p", "new\n")
    with pytest.raises(OSError):
        data.add_point("b", [0, 0, 1, 0, 0])
    monkeypatch.undo()
    assert data.read_program("p") == "old\n" and [p.name for p in data.points()] == ["a"]
    # No temp file is left behind; only the version kept before the write is new.
    after = snapshot(data.root)
    assert {k: v for k, v in after.items() if not k.startswith(".versions/")} == \
        {k: v for k, v in before.items() if not k.startswith(".versions/")}


def test_a_failed_write_leaves_the_old_file(data, monkeypatch):
    data.save_program("p", "old\n")

    def broken(fd):
        raise OSError("no space left")
    monkeypatch.setattr(os, "fsync", broken)
    with pytest.raises(OSError):
        data.save_program("p", "new\n")
    monkeypatch.undo()
    assert data.read_program("p") == "old\n"
    assert not [p for p in data.root.iterdir() if p.name.endswith(".tmp")]


KILLED_WRITER = """
import sys
from pathlib import Path
from asibot.web.userdata import UserData
data = UserData(Path(sys.argv[1]))
texts = ["# A\\n" + "a = 1\\n" * 40000, "# B\\n" + "b = 2\\n" * 40000]
n = 0
while True:
    data.save_program("p", texts[n % 2])
    n += 1
    if n == 2:
        print("saving", flush=True)
"""


@pytest.mark.parametrize("delay", [0.05, 0.13, 0.31])
def test_a_kill_during_saves_leaves_a_whole_file(tmp_path, delay):
    root = tmp_path / "data"
    child = subprocess.Popen([sys.executable, "-c", KILLED_WRITER, str(root)], stdout=subprocess.PIPE)
    try:
        assert child.stdout.readline() == b"saving\n"
        time.sleep(delay)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    data = UserData(root)
    text = data.read_program("p")
    assert text in ("# A\n" + "a = 1\n" * 40000, "# B\n" + "b = 2\n" * 40000)
    assert data.programs() == ["p"] and data.check_program(text) == []
    assert all(len(data.read_version("p", v.id)) == len(text) for v in data.versions("p"))
