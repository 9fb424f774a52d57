"""The web API on the in-memory bus: an ideal driver, the real kinematics server, the web app.

What a page (or anything else) can send: every action answers JSON; every bad input gets a
4xx with a sentence and changes nothing (no file written, no arm command sent).
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from asibot import keys
from asibot import messages as m
from asibot.bus import Bus
from asibot.errors import RpcError
from asibot.messages import EStop, GripperState
from asibot.testing import wait_until, release
from asibot.web.fleet import gripper_words
from asibot.web.motion import Motion

from .conftest import API_ROBOT as ROBOT, API_START as START, settle


@pytest.fixture
def api(web):
    settle(web)
    return web[0]


def refused(reply, status: int, *words: str) -> str:
    assert reply.status_code == status, reply.text
    body = reply.json()
    assert isinstance(body["message"], str) and body["message"].endswith((".", ")", "'")), body
    for w in words:
        assert w in body["message"], body["message"]
    return body["message"]


def test_the_page_and_its_packages_are_served_locally(api):
    assert "ASIBOT Task Creator" in api.get("/").text
    for path in ("/static/js/main.js", "/static/vendor/three.js", "/static/vendor/codemirror.js", "/static/css/app.css"):
        assert api.get(path).status_code == 200, path
    html = api.get("/").text
    assert "http://" not in html and "https://" not in html  # nothing from another server


def test_the_api_page_works_offline_from_our_own_files(api):
    html = api.get("/docs").text
    assert "/static/vendor/swagger/swagger-ui-bundle.js" in html and "/openapi.json" in html
    assert "cdn." not in html                                   # FastAPI's default page would need the internet
    for path in ("/static/vendor/swagger/swagger-ui-bundle.js", "/static/vendor/swagger/swagger-ui.css"):
        assert api.get(path).status_code == 200, path
    assert api.get("/redoc").status_code == 404                 # one API page, the one that works offline


def test_the_pages_files_are_asked_again_after_an_upgrade_and_go_out_compressed(api):
    first = api.get("/static/js/main.js", headers={"Accept-Encoding": "gzip"})
    assert first.headers["cache-control"] == "no-cache" and first.headers["etag"]
    assert first.headers["content-encoding"] == "gzip"
    again = api.get("/static/js/main.js", headers={"If-None-Match": first.headers["etag"]})
    assert again.status_code == 304                             # unchanged: nothing sent again
    assert api.get("/openapi.json", headers={"Accept-Encoding": "gzip"}).headers["content-encoding"] == "gzip"
    plain = api.get("/static/js/main.js", headers={"Accept-Encoding": "identity"})
    assert "content-encoding" not in plain.headers and plain.text.startswith("//")
    # the API's answers are not held back by a compressor (a camera's stream goes out frame by frame)
    assert "content-encoding" not in api.get("/api/robots", headers={"Accept-Encoding": "gzip"}).headers
    assert first.content == plain.content                       # (the client takes the gzip off)
    assert first.headers["etag"] == plain.headers["etag"] and first.headers["vary"] == "Accept-Encoding"
    assert first.headers["content-type"] == plain.headers["content-type"]


def test_a_changed_file_goes_out_compressed_as_it_is_now(tmp_path, monkeypatch):
    """Each version of a file is compressed once: an edit is served as edited, never the old gzip."""
    from fastapi import FastAPI
    from fastapi.testclient import TestClient

    from asibot.web.app import Static
    (tmp_path / "a.js").write_text("// one\n" + "x = 1;\n" * 400)
    app = FastAPI()
    app.mount("/static", Static(directory=tmp_path))
    client = TestClient(app)
    before = client.get("/static/a.js", headers={"Accept-Encoding": "gzip"})
    assert before.headers["content-encoding"] == "gzip" and before.content.startswith(b"// one")
    (tmp_path / "a.js").write_text("// two\n" + "x = 2;\n" * 500)
    after = client.get("/static/a.js", headers={"Accept-Encoding": "gzip"})
    assert after.headers["content-encoding"] == "gzip" and after.content.startswith(b"// two")
    assert after.headers["etag"] != before.headers["etag"]
    assert client.get("/static/a.js", headers={"Accept-Encoding": "gzip", "Range": "bytes=0-5"}).content == b"// two"


def test_the_page_names_every_module_main_js_imports_up_front(api):
    html = api.get("/").text
    preloaded = re.findall(r'<link rel="modulepreload" href="([^"]+)">', html)
    # main.js's own imports, and theirs (choose.js comes through scanning.js and others)
    for module in ("api.js", "connection.js", "scanning.js", "ui.js", "wizard.js", "choose.js", "settings.js"):
        assert f"/static/js/{module}" in preloaded, module
    assert len(preloaded) == len(set(preloaded))
    assert not any("/views/" in url or "vendor" in url for url in preloaded)  # a tab's code comes with its tab
    for url in preloaded:
        assert api.get(url).status_code == 200, url


def test_robots_come_from_the_bus_with_their_state(web, api):
    views = api.get("/api/robots").json()
    me = next(v for v in views if v["id"] == ROBOT)
    assert me["driver"] and me["controller"] and me["simulated"] and me["arm"] == "asibot"
    assert me["joints"]["deg"] == pytest.approx(np.degrees(START).tolist(), abs=0.01)
    assert len(me["point"]) == 5 and not me["estop"]["engaged"]
    model = api.get(f"/api/robots/{ROBOT}/model").json()
    assert "<robot" in model["urdf"] and model["joint_names"] == ["q1", "q2", "q3", "q4", "q5"]


def test_a_joint_step_moves_one_joint_by_five_degrees(web, api):
    client, svc, driver, server = web
    before = server.ctl.q.copy()
    assert api.post(f"/api/robots/{ROBOT}/step", json={"space": "joint", "axis": 1, "direction": 1, "level": 5}).status_code == 200
    wait_until(lambda: server.ctl.state == "not_controlling", timeout=10)
    wait_until(lambda: abs(server.ctl.q[1] - before[1] - math.radians(5)) < 1e-3, timeout=5)
    assert np.allclose(np.delete(server.ctl.q, 1), np.delete(before, 1), atol=1e-3)


def test_steps_touched_while_moving_add_up(web, api):
    client, svc, driver, server = web
    before = server.ctl.q.copy()
    for _ in range(3):
        assert api.post(f"/api/robots/{ROBOT}/step", json={"space": "joint", "axis": 0, "direction": -1, "level": 2}).status_code == 200
    wait_until(lambda: server.ctl.state == "not_controlling", timeout=20)
    wait_until(lambda: abs(server.ctl.q[0] - before[0] + math.radians(15)) < 1e-3, timeout=5)


class CallLog:
    """A bus that answers every call at once and keeps what was asked."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, dict]] = []

    def call(self, key: str, request: dict | None = None, timeout: float = 2.0) -> dict:
        self.calls.append((key, request or {}))
        return {"duration": 0.5}


def test_a_step_is_one_jog_request_and_the_page_keeps_no_target():
    """The kinematics service adds a step to the previous one's target (its `jog` verb), so a
    click is one request, with the page's step sizes and level, and nothing to remember here."""
    bus = CallLog()
    motion = Motion(bus)
    motion.step_joint(ROBOT, 1, -1, 2)
    motion.step_axis(ROBOT, 3, 1, 5)
    motion.step_axis(ROBOT, 0, -1, 1, step=0.02)
    jog = keys.cart_rpc(ROBOT, "jog")
    assert bus.calls == [(jog, {"axis": "q2", "step": -5.0, "level": 2}),
                         (jog, {"axis": "rot(y')", "step": 15.0, "level": 5}),
                         (jog, {"axis": "x", "step": -0.02, "level": 1})]


def test_capture_reads_the_arm_and_suggests_names(web, api):
    client, svc, driver, server = web
    p = api.post(f"/api/robots/{ROBOT}/capture", json={}).json()
    assert p["name"].startswith("point-") and p["values"] == pytest.approx(svc.fleet.point(ROBOT), abs=1e-6)
    named = api.post(f"/api/robots/{ROBOT}/capture", json={"name": "above_can"}).json()
    assert named["name"] == "above_can"
    names = [x["name"] for x in api.get("/api/points").json()["points"]]
    assert p["name"] in names and "above_can" in names
    refused(api.post(f"/api/robots/{ROBOT}/capture", json={"name": "above_can"}), 409, "above_can")


def test_a_capture_is_named_after_where_the_arm_is(web, api):
    """Above a point the user named: "above-<name>"; with the base at a named place: "<place>-N"."""
    client, svc, driver, server = web
    settle(web)
    for p in svc.web.data.points():          # only this test's points
        svc.web.data.delete_point(p.name)
    here = svc.fleet.point(ROBOT)
    below = [here[0], here[1], here[2] - 0.10, *here[3:]]
    svc.web.data.add_point("mug", below)
    assert api.get(f"/api/robots/{ROBOT}/suggested-point-name").json() == {"name": "above-mug"}
    assert api.post(f"/api/robots/{ROBOT}/capture", json={}).json()["name"] == "above-mug"
    assert api.get(f"/api/robots/{ROBOT}/suggested-point-name").json() == {"name": "above-mug-2"}

    status = svc.fleet.bus.publisher(keys.nav_status(ROBOT), m.NavStatus)
    status.put(m.NavStatus(goal_id=1, state="succeeded", text="Arrived at fridge", place="fridge"))
    wait_until(lambda: api.get(f"/api/robots/{ROBOT}/suggested-point-name").json()["name"] == "fridge-1", timeout=5)
    status.put(m.NavStatus(goal_id=2, state="active", text="driving to desk", place="desk"))
    wait_until(lambda: api.get(f"/api/robots/{ROBOT}/suggested-point-name").json()["name"] == "above-mug-2",
               timeout=5)   # on its way: at no place
    refused(api.get("/api/robots/nobody/suggested-point-name"), 503, "nobody")
    for name in ("mug", "above-mug"):
        svc.web.data.delete_point(name)


def test_unreachable_and_limits_answer_with_the_controllers_sentence(api):
    far = api.post(f"/api/robots/{ROBOT}/move", json={"kind": "movl", "values": [3, 0, 0, 0, 0]})
    assert far.status_code == 409 and far.json()["error"] == "unreachable"
    limit = api.post(f"/api/robots/{ROBOT}/move", json={"kind": "movj", "values": [0, 170, 0, 0, 0], "joints": True})
    assert limit.status_code == 409 and "Joint 2" in limit.json()["message"]


def test_estop_latches_and_refuses_motion_until_released(web, api):
    client, svc, driver, server = web
    assert api.post("/api/estop").json()["robots"] == [ROBOT]
    wait_until(lambda: server.ctl.estop, timeout=5)
    wait_until(lambda: svc.fleet.view(ROBOT)["estop"]["engaged"], timeout=5)
    refused(api.post(f"/api/robots/{ROBOT}/step", json={"space": "joint", "axis": 0, "direction": 1}), 409)
    assert api.post(f"/api/robots/{ROBOT}/release").status_code == 200
    wait_until(lambda: not server.ctl.estop, timeout=5)


@pytest.mark.parametrize("method,path,body,status,words", [
    ("post", f"/api/robots/{ROBOT}/step", {"space": "joint", "axis": "x", "direction": 1}, 422, ["axis"]),
    ("post", f"/api/robots/{ROBOT}/step", {"space": "joint", "axis": 9, "direction": 1}, 400, ["joint"]),
    ("post", f"/api/robots/{ROBOT}/step", {"space": "up", "axis": 0, "direction": 1}, 422, ["space"]),
    ("post", f"/api/robots/{ROBOT}/step", {"space": "joint", "axis": 0, "direction": 2}, 422, ["direction"]),
    ("post", f"/api/robots/{ROBOT}/step", {"space": "joint", "axis": 0, "direction": 1, "level": 9}, 422, ["level"]),
    ("post", f"/api/robots/{ROBOT}/step", {"space": "joint", "axis": 0, "direction": 1, "extra": 1}, 422, ["extra"]),
    ("post", f"/api/robots/{ROBOT}/move", {"kind": "movl", "values": [1e300, 0, 0, 0, 0]}, 400, []),
    ("post", f"/api/robots/{ROBOT}/move", {"kind": "movl", "values": ["a"] * 5}, 422, ["values"]),
    ("post", f"/api/robots/{ROBOT}/move", {"kind": "movl", "values": [0] * 500}, 422, ["values"]),
    ("post", f"/api/robots/{ROBOT}/move", {"kind": "teleport", "values": [0] * 5}, 422, ["kind"]),
    ("post", "/api/robots/nobody/step", {"space": "joint", "axis": 0, "direction": 1}, 503, ["nobody"]),
    ("post", "/api/robots/..%2Fetc/stop", {}, 404, []),
    ("get", "/api/robots/nobody/model", None, 400, ["nobody"]),
    ("post", f"/api/robots/{ROBOT}/gripper", {"close": "yes"}, 422, ["close"]),
    ("post", f"/api/robots/{ROBOT}/inv", {"point": [0, 0]}, 422, ["point"]),
    ("post", f"/api/robots/{ROBOT}/capture", {"name": "../../etc/passwd"}, 400, []),
    ("post", "/api/points/nope/rename", {"name": "x"}, 404, ["nope"]),
    ("delete", "/api/points/nope", None, 404, []),
    ("post", f"/api/robots/{ROBOT}/points/nope/go", {}, 404, []),
    ("post", "/api/programs", {"name": "../evil"}, 400, []),
    ("post", "/api/programs", {"name": 7}, 422, ["name"]),
    ("get", "/api/programs/nope", None, 404, []),
    ("put", "/api/programs/nope", {"text": 5}, 422, ["text"]),
    ("put", "/api/programs/a%2Fb", {"text": "x = 1"}, 404, []),
    ("post", "/api/programs/nope/run", {"robot": ROBOT}, 404, []),
    ("post", "/api/programs/nope/run", {"robot": "no robot!"}, 422, ["robot"]),
    ("post", "/api/words", {"text": ""}, 422, ["text"]),
    ("post", "/api/words", {"text": "a\nb"}, 400, []),
    ("delete", "/api/words/nope", None, 404, []),
    ("put", "/api/tasks/Give me", {"program": "nope", "icon": "can.svg"}, 404, ["nope"]),
    ("put", "/api/tasks/Give me", {"program": "x", "words": "w", "icon": "can.svg"}, 422, ["words"]),
    ("post", "/api/tasks/nope/launch", {"robot": ROBOT}, 404, []),
    ("get", "/api/icons/nope.png", None, 404, []),
    ("get", "/api/icons/..%2F..%2Fpasswd", None, 404, []),
    ("post", "/api/check", {"text": None}, 422, ["text"]),
])
def test_bad_input_gets_a_sentence_and_changes_nothing(web, api, method, path, body, status, words):
    client, svc, driver, server = web
    data = svc.web.data
    files_before = sorted(p.name for p in data.root.rglob("*"))
    commands_before = len(driver.commands)
    reply = getattr(api, method)(path, json=body) if body is not None else getattr(api, method)(path)
    if status == 404 and reply.headers.get("content-type", "").startswith("application/json") and "message" not in reply.json():
        assert reply.status_code == 404  # a route that does not exist
    else:
        refused(reply, status, *words)
    assert sorted(p.name for p in data.root.rglob("*")) == files_before
    assert len(driver.commands) == commands_before


def test_oversized_bodies_and_uploads_are_refused(web, api):
    refused(api.post("/api/programs", content=b"{" + b" " * 2_000_000 + b"}",
                     headers={"content-type": "application/json"}), 413, "larger")
    refused(api.post("/api/icons", files={"file": ("big.png", b"\x89PNG\r\n\x1a\n" + b"0" * (3 * 1024 * 1024), "image/png")}), 413)
    refused(api.post("/api/icons", files={"file": ("evil.svg", b"<svg onload='alert(1)'/>", "image/svg+xml")}), 400)
    refused(api.post("/api/import", files={"file": ("x.zip", b"not a zip", "application/zip")}), 400)


def test_a_program_runs_in_its_own_process_and_its_output_is_kept(web, api):
    assert api.post("/api/programs", json={"name": "hello_web"}).status_code == 200
    text = "import os, sys\nprint('robot', sys.argv[1])\nprint('pid', os.getpid())\n"
    assert api.put("/api/programs/hello_web", json={"text": text}).json()["problems"] == []
    status = api.post("/api/programs/hello_web/run", json={"robot": ROBOT}).json()
    assert status["running"] or status["last"]
    wait_until(lambda: not api.get("/api/run").json()["running"], timeout=20)
    run = api.get("/api/run").json()
    assert run["last"]["reason"] == "finished"
    lines = [line for stream, line in run["output"]]
    assert f"robot {ROBOT}" in lines and not any(line == f"pid {__import__('os').getpid()}" for line in lines)
    bad = api.put("/api/programs/hello_web", json={"text": "x = (\n"}).json()
    assert bad["problems"][0]["line"] == 1
    versions = api.get("/api/programs/hello_web").json()["versions"]
    assert versions, "the previous version is kept"
    restored = api.post(f"/api/programs/hello_web/versions/{versions[0]['id']}/restore").json()
    assert restored["text"] == text


def test_tasks_words_and_icons_round_trip_with_the_seed_files(api):
    api.post("/api/programs", json={"name": "can_task"})
    assert api.post("/api/words", json={"text": "give me the red can"}).status_code == 200
    task = api.put("/api/tasks/Red can", json={"program": "can_task", "words": ["give me the red can"], "icon": "can.svg"}).json()
    assert task == {"name": "Red can", "program": "can_task", "words": ["give me the red can"], "icon": "can.svg", "robot": ""}
    icons = [i["name"] for i in api.get("/api/icons").json()["icons"]]
    assert {"drink.svg", "can.svg", "face.svg", "teeth.svg", "home.svg", "stop.svg"} <= set(icons)
    exported = api.get("/api/export.zip")
    assert exported.status_code == 200 and exported.content[:2] == b"PK"
    report = api.post("/api/import", files={"file": ("seed.zip", exported.content, "application/zip")}).json()
    assert "Red can.task" in " ".join(report["imported"]) or report["imported"]
    assert any(t["name"] == "Red can" for t in api.get("/api/tasks").json()["tasks"])


def test_latched_estop_from_elsewhere_shows_on_the_page(web, api):
    client, svc, driver, server = web
    other = Bus("someone-else")
    try:
        other.latch(keys.estop(ROBOT), EStop(engaged=True, reason="pressed on the robot"))
        wait_until(lambda: svc.fleet.view(ROBOT)["estop"] == {"engaged": True, "reason": "pressed on the robot"}, timeout=5)
        release(other, ROBOT, reason="released")
        wait_until(lambda: not svc.fleet.view(ROBOT)["estop"]["engaged"], timeout=5)
    finally:
        other.close()


def test_other_services_launch_a_task_on_the_bus_and_hear_how_it_ended(web, api):
    """The AsTeRICS bridge or the voice service launch a Task Creator task as the Launcher does
    (`keys.tasks_rpc`), and the robot's events say it started and how it ended."""
    from asibot.errors import RpcError
    from asibot.messages import Event
    from asibot.testing import Inbox
    client, svc, driver, server = web
    api.put("/api/programs/say_hello", json={"text": "print('hello from a task')\n"})
    api.put("/api/tasks/Hello", json={"program": "say_hello", "words": [], "icon": "face.svg"})
    other = Bus("bridge")
    heard = Inbox()
    other.subscribe(keys.events(ROBOT), Event, heard)
    try:
        listed = other.call(keys.tasks_rpc("list"), {}, timeout=5)["tasks"]
        assert {"name": "Hello", "program": "say_hello", "words": [], "robot": ""} in listed
        for bad, code, words in (({"task": "Nope", "robot": ROBOT}, "bad_request", "no task named"),
                                 ({"task": "Hello", "robot": "ghost"}, "unavailable", "not connected"),
                                 ({"task": 5, "robot": ROBOT}, "bad_request", "'task' must be a task name"),
                                 ({"task": "Hello", "robot": ROBOT, "now": True}, "bad_request", "takes only")):
            with pytest.raises(RpcError, match=words) as err:
                other.call(keys.tasks_rpc("launch"), bad, timeout=5)
            assert err.value.code == code
        assert not heard.all() and not svc.web.runner.status()["program"] == "Hello"
        reply = other.call(keys.tasks_rpc("launch"), {"task": "Hello", "robot": ROBOT}, timeout=5)
        assert reply == {"ok": True, "task": "Hello", "program": "say_hello", "robot": ROBOT}
        wait_until(lambda: [e.code for e in heard.all()] == ["task_started", "task_done"], timeout=20)
        assert [e.text for e in heard.all()] == ["Hello: started", "Hello: done"]
        assert other.call(keys.tasks_rpc("status"), {}, timeout=5)["last"]["ok"] is True
    finally:
        other.close()


def test_a_task_runs_on_its_own_robot_whatever_robot_launches_it(web, api):
    """Issue 54: a task taught on one robot runs there from every tile, word and bridge command,
    whatever the page commands; a task of the original ASIBOT (no robot) runs where it is sent."""
    from asibot.errors import RpcError
    client, svc, driver, server = web
    api.put("/api/programs/say_where", json={"text": "import sys\nprint('on', sys.argv[1])\n"})
    made = api.put("/api/tasks/Here", json={"program": "say_where", "words": [], "icon": "face.svg", "robot": ROBOT})
    assert made.status_code == 200 and made.json()["robot"] == ROBOT, made.text
    assert (svc.web.data.root / "Here.task").read_text() == f"say_where\n\nface.svg\n{ROBOT}\n"
    other = Bus("bridge")
    try:
        reply = other.call(keys.tasks_rpc("launch"), {"task": "Here", "robot": "the-other-arm"}, timeout=5)
        assert reply["robot"] == ROBOT, reply
        wait_until(lambda: (svc.web.runner.status().get("last") or {}).get("program") == "Here", timeout=20)
        assert svc.web.runner.status()["last"]["robot"] == ROBOT
        # Its robot gone, it is refused rather than run elsewhere.
        api.put("/api/tasks/Elsewhere", json={"program": "say_where", "words": [], "icon": "face.svg", "robot": "ghost"})
        with pytest.raises(RpcError, match="Elsewhere runs on ghost, which is not connected"):
            other.call(keys.tasks_rpc("launch"), {"task": "Elsewhere", "robot": ROBOT}, timeout=5)
        refused = api.post("/api/tasks/Elsewhere/launch", json={"robot": ROBOT})
        assert refused.status_code == 503 and "runs on ghost" in refused.json()["message"], refused.text
    finally:
        other.close()
    bad = api.put("/api/tasks/Bad", json={"program": "say_where", "words": [], "icon": "face.svg", "robot": "../x"})
    assert bad.status_code == 422 and "Bad" not in [t["name"] for t in api.get("/api/tasks").json()["tasks"]]
    for name in ("Here", "Elsewhere"):
        api.delete(f"/api/tasks/{name}")


def test_the_voice_setting_without_the_voice_service_says_how_to_start_it(api):
    reply = api.get("/api/voice")
    assert reply.status_code == 503 and "voice service is not running" in reply.json()["message"]
    assert api.put("/api/voice", json={"confirm": True}).status_code == 503
    assert api.put("/api/voice", json={"confirm": "yes"}).status_code == 422
    assert api.put("/api/voice", json={"confirm": True, "shout": 1}).status_code == 422



def test_a_real_robot_has_no_world_to_put_back(web):
    client, svc, driver, server = web
    with pytest.raises(RpcError, match="asibot is a real robot: there is no simulated world to put back."):
        svc.web.motion.reset_world("asibot")


@pytest.mark.parametrize("opening, holding, says", [
    (0.08, False, "open (8.0 cm)"), (0.075, False, "open (7.5 cm)"), (0.04, False, "partly open (4.0 cm)"),
    (0.002, False, "closed, empty"), (0.066, True, "closed, holding something (6.6 cm)")])
def test_the_gripper_is_said_open_closed_or_holding(opening, holding, says):
    assert gripper_words(GripperState(opening=opening, holding=holding), 0.08) == says
