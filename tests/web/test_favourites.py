"""The person's tasks and places on Home: counted where they are used, ranked by the carer's
order and then by use, kept in favourites.json, and refused with a sentence when a request is bad
(nothing changes)."""

from __future__ import annotations

import json

import pytest

from asibot.testing import wait_until
from asibot.web.userdata import UserDataError
from asibot.web.userdata.favourites import FILE, Favourites, Usage, place_key, task_key
from asibot.web.userdata.folder import Folder

from .conftest import API_ROBOT as ROBOT, settle


def test_the_carers_order_comes_first_then_the_most_used_then_by_name():
    usage = Usage(uses={"task:b": 1, "task:c": 5, "place:p/x": 2}, order=["task:a"])
    assert usage.rank(["task:b", "task:a", "task:c", "place:p/x", "task:d"]) == [
        "task:a", "task:c", "place:p/x", "task:b", "task:d"]
    # Never used: the Launcher's tasks before the places, each by name.
    assert Usage(uses={}, order=[]).rank(["place:p/a", "task:z", "task:b"]) == ["task:b", "task:z", "place:p/a"]
    # An item of the order that is gone (a task deleted) takes no place.
    assert Usage(uses={}, order=["task:gone", "task:b"]).rank(["task:a", "task:b"]) == ["task:b", "task:a"]


def test_what_the_person_uses_lately_comes_before_what_they_used_long_ago(tmp_path):
    day, now = 24 * 3600.0, 1_800_000_000.0
    fav = Favourites(Folder(tmp_path))
    for _ in range(10):
        fav.used(task_key("Brush my teeth"), now=now - 120 * day)        # every day, last winter
    for _ in range(2):
        fav.used(task_key("Give me the red can"), now=now - day)         # twice, this week
    usage = fav.read()
    assert usage.rank([task_key("Brush my teeth"), task_key("Give me the red can")], now=now) == [
        task_key("Give me the red can"), task_key("Brush my teeth")]
    assert usage.uses[task_key("Brush my teeth")] == 10                  # the count the Access page shows
    # Used the same long ago, more uses still come first; a file from before `last` keeps its counts.
    assert Usage({"task:a": 3, "task:b": 5}, []).rank(["task:a", "task:b"], now=now) == ["task:b", "task:a"]


def test_a_trip_to_a_place_counts_once_however_it_was_sent(tmp_path):
    """Nav's status names the place of its new goal: a trip from the page, the voice, the bridge
    or the command line counts once, and a trip to a point of the map not at all."""
    from asibot import keys
    from asibot.messages import NavStatus
    from asibot.web.trips import TripCounter
    fav = Favourites(Folder(tmp_path))
    trips = TripCounter(fav.used)
    key = keys.nav_status("pioneer-sim")

    def status(goal_id: int, state: str, place: str = "") -> None:
        trips.on_status(key, NavStatus(goal_id=goal_id, state=state, text="", place=place))

    status(0, "idle")
    for _ in range(5):                                   # the status repeats while the robot drives
        status(1, "active", "fridge")
    status(1, "succeeded", "fridge")
    status(2, "active")                                  # a point of the map: no place
    status(3, "active", "sofa")
    status(1, "active", "fridge")                        # nav restarted: its goals count from 1 again
    assert fav.read().uses == {place_key("pioneer-sim", "fridge"): 2, place_key("pioneer-sim", "sofa"): 1}


def test_a_web_restarted_during_a_trip_does_not_count_it_again(tmp_path):
    from asibot import keys
    from asibot.messages import NavStatus
    from asibot.web.trips import TripCounter
    fav = Favourites(Folder(tmp_path))
    key = keys.nav_status("pioneer-sim")
    TripCounter(fav.used).on_status(key, NavStatus(goal_id=0, state="idle", text=""))
    for counter in (TripCounter(fav.used), TripCounter(fav.used)):     # before and after the restart
        for _ in range(3):
            counter.on_status(key, NavStatus(goal_id=4, state="active", text="", place="fridge"))
    assert fav.read().uses == {}
    counter.on_status(key, NavStatus(goal_id=5, state="active", text="", place="sofa"))
    assert fav.read().uses == {place_key("pioneer-sim", "sofa"): 1}


def test_uses_and_the_order_are_kept_and_a_hand_edited_file_keeps_what_makes_sense(tmp_path):
    folder = Folder(tmp_path)
    fav = Favourites(folder)
    fav.used(task_key("Give me the red can"))
    fav.used(task_key("Give me the red can"))
    fav.used(place_key("pioneer-sim", "fridge"))
    fav.set_order([place_key("pioneer-sim", "fridge")])
    again = Favourites(Folder(tmp_path)).read()
    assert again.uses == {"task:Give me the red can": 2, "place:pioneer-sim/fridge": 1}
    assert again.order == ["place:pioneer-sim/fridge"]
    (tmp_path / FILE).write_text(json.dumps({"uses": {"task:a": 3, "nonsense": 4, "task:b": -1, "task:c": True},
                                             "order": ["task:a", 7, "task:a", "place:nobody"]}))
    kept = fav.read()
    assert kept.uses == {"task:a": 3} and kept.order == ["task:a"]
    (tmp_path / FILE).write_text("{not json")
    assert fav.read() == Usage({}, [], {})
    assert (tmp_path / (FILE + ".unreadable")).read_text() == "{not json"   # kept aside, not lost
    fav.used(task_key("a"))
    assert fav.read().uses == {"task:a": 1}


def test_a_use_that_cannot_be_counted_never_fails_what_it_counts(tmp_path):
    fav = Favourites(Folder(tmp_path))
    fav.used("not a key")                                  # logged, not raised
    (tmp_path / FILE).mkdir()                              # the file cannot be written
    fav.used(task_key("a"))                                # logged, not raised; nothing else touched
    assert (tmp_path / FILE).is_dir() and sorted(p.name for p in tmp_path.iterdir()) == [FILE]


@pytest.mark.parametrize("order,words", [
    (["fridge"], "is not an item"),
    (["task:a", "task:a"], "once"),
    (["place:fridge"], "is not an item"),
    (["x" * 300], "1 to 200 characters"),
])
def test_a_bad_order_is_refused_and_changes_nothing(tmp_path, order, words):
    fav = Favourites(Folder(tmp_path))
    fav.set_order(["task:a"])
    with pytest.raises(UserDataError, match=words):
        fav.set_order(order)
    assert fav.read().order == ["task:a"]


def test_home_lists_the_tasks_by_use_and_the_carer_can_order_them(web):
    client, svc, driver, server = web
    settle(web)
    client.put("/api/programs/fav_hello", json={"text": "print('hello')\n"})
    for name in ("Alpha", "Beta"):
        assert client.put(f"/api/tasks/{name}", json={"program": "fav_hello", "words": [], "icon": "face.svg"}).status_code == 200
    try:
        names = lambda: [i["name"] for i in client.get("/api/favourites").json()["items"] if i["name"] in ("Alpha", "Beta")]
        assert names() == ["Alpha", "Beta"]                       # never used: by name
        assert client.post("/api/tasks/Beta/launch", json={"robot": ROBOT}).status_code == 200
        wait_until(lambda: not svc.web.runner.status()["running"], timeout=20)
        assert names() == ["Beta", "Alpha"]                       # Beta was launched once
        beta = next(i for i in client.get("/api/favourites").json()["items"] if i["name"] == "Beta")
        assert beta == {"key": "task:Beta", "kind": "task", "name": "Beta", "icon": "face.svg", "robot": "", "uses": 1}
        reply = client.put("/api/favourites/order", json={"order": ["task:Alpha"]})
        assert reply.status_code == 200 and reply.json()["order"] == ["task:Alpha"]
        assert names() == ["Alpha", "Beta"]                       # the carer's order first
        before = (svc.web.data.root / FILE).read_bytes()
        for body, status in (({"order": ["Alpha"]}, 400), ({"order": "task:Alpha"}, 422), ({"order": [], "x": 1}, 422),
                             ({"order": [5]}, 422)):
            bad = client.put("/api/favourites/order", json=body)
            assert bad.status_code == status, bad.text
            assert bad.json()["message"]
        assert (svc.web.data.root / FILE).read_bytes() == before
        assert client.put("/api/favourites/order", json={"order": []}).json()["order"] == []
    finally:
        for name in ("Alpha", "Beta"):
            client.delete(f"/api/tasks/{name}")


def test_release_all_releases_every_stopped_robot_and_only_those(web):
    client, svc, driver, server = web
    settle(web)
    assert client.post("/api/release").json() == {"robots": []}
    assert client.post("/api/estop").json()["robots"] == [ROBOT]
    wait_until(lambda: svc.fleet.view(ROBOT)["estop"]["engaged"], timeout=5)
    assert client.post("/api/release").json() == {"robots": [ROBOT]}
    wait_until(lambda: not svc.fleet.view(ROBOT)["estop"]["engaged"], timeout=5)
    wait_until(lambda: not server.ctl.estop, timeout=5)
