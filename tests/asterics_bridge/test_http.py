"""The HTTP entry (AsTeRICS-Grid's HTTP actions and live elements) on a loopback port."""

import base64
import http.client
import json
import socket
import threading

from unittest.mock import ANY

import pytest

from asibot.testing import wait_until

from asibot.asterics_bridge.servers import Limits

from .harness import HTTP_TOKEN, OTHER, ROBOT, Bridge

AUTH = {"Authorization": f"Bearer {HTTP_TOKEN}"}
GRID = "https://grid.asterics.eu"


@pytest.fixture
def bridge(memory_bus):
    b = Bridge(memory_bus, limits=Limits(http_body_bytes=1024, http_header_bytes=2048), origins=(GRID,))
    yield b
    b.close()


def request(bridge, method, path, body=None, headers=None, auth=True):
    """One request, with the bridge's token unless `auth` is False or `headers` carry their own.
    The answer's headers are looked up as HTTP reads them: names in any case."""
    conn = http.client.HTTPConnection("127.0.0.1", bridge.servers.http_port, timeout=5)
    try:
        conn.request(method, path, body=body, headers={**(AUTH if auth else {}), **(headers or {})})
        r = conn.getresponse()
        return r.status, r.headers, r.read().decode()
    finally:
        conn.close()


def raw(bridge, data: bytes) -> bytes:
    with socket.create_connection(("127.0.0.1", bridge.servers.http_port), timeout=5) as s:
        s.sendall(data)
        out = b""
        while chunk := s.recv(65536):
            out += chunk
        return out


def test_text_plain_command_as_asterics_grid_sends_it(bridge):
    basic = base64.b64encode(f"asibot:{HTTP_TOKEN}".encode()).decode()     # authUser/authPw
    status, headers, body = request(bridge, "POST", "/command", "forward", {
        "Content-Type": "text/plain", "Origin": GRID, "Sec-Fetch-Site": "cross-site",
        "Authorization": f"Basic {basic}"})
    assert (status, body) == (200, "ok: forward, until you say stop\n")
    assert headers["Access-Control-Allow-Origin"] == GRID and headers["Vary"] == "Origin"
    assert bridge.nav.requests("primitive") == [{"name": "forward", "continuous": True}]
    status, _, body = request(bridge, "POST", "/command", "stop")
    assert (status, body) == (200, "ok: stopped base and arm\n")


def test_json_commands(bridge):
    status, headers, body = request(bridge, "POST", "/command", json.dumps({"command": "grab"}),
                                    {"Content-Type": "application/json"})
    assert status == 200 and json.loads(body) == {"ok": True, "text": "holding something"}
    assert headers["Content-Type"].startswith("application/json")
    status, _, body = request(bridge, "POST", "/command", json.dumps({"command": "arm up", "robot": OTHER}),
                              {"Content-Type": "application/json"})
    assert status == 200 and bridge.other_arm.verbs() == ["stat", "movl"]
    status, _, body = request(bridge, "POST", "/command", json.dumps({"command": "forwrd"}),
                              {"Content-Type": "application/json"})
    assert status == 400 and json.loads(body) == {"ok": False, "code": "not_understood",
                                                  "error": "unknown command 'forwrd'; did you mean 'forward'?"}


def test_cors_preflight_of_the_allowed_grid(bridge):
    status, headers, body = request(bridge, "OPTIONS", "/command", auth=False, headers={
        "Origin": GRID, "Access-Control-Request-Method": "POST",
        "Access-Control-Request-Headers": "content-type, authorization"})
    assert status == 204 and body == ""
    assert headers["Access-Control-Allow-Origin"] == GRID
    assert "POST" in headers["Access-Control-Allow-Methods"]
    assert {"content-type", "authorization"} <= set(headers["Access-Control-Allow-Headers"].split(", "))
    assert "Access-Control-Allow-Private-Network" not in headers      # not asked for
    status, headers, _ = request(bridge, "OPTIONS", "/command", auth=False, headers={
        "Origin": GRID, "Access-Control-Request-Method": "POST", "Access-Control-Request-Private-Network": "true"})
    assert status == 204 and headers["Access-Control-Allow-Private-Network"] == "true"


def test_a_program_s_preflight_gets_no_cors(bridge):
    status, headers, _ = request(bridge, "OPTIONS", "/command", auth=False)
    assert status == 204 and not any(h.lower().startswith("access-control") for h in headers)


def test_status_for_live_elements(bridge):
    request(bridge, "POST", "/command", "forward")
    wait_until(lambda: bridge.dispatcher.board.robot(ROBOT).nav is not None)
    bridge.event("goal_succeeded", "Arrived at fridge", level="info")
    wait_until(lambda: bridge.dispatcher.board.robot(ROBOT).last_event is not None)
    status, headers, body = request(bridge, "GET", "/status")
    st = json.loads(body)
    assert status == 200 and headers["Content-Type"].startswith("application/json")
    assert {"robot", "moving", "pose", "place", "last_event", "battery"} <= set(st)
    assert st["robot"] == ROBOT and st["moving"] is True and st["last_event"] == "goal reached"
    assert json.loads(request(bridge, "GET", f"/status?robot={OTHER}")[2])["robot"] == OTHER
    assert request(bridge, "GET", "/status?robot=a/b")[0] == 400


def test_status_tells_the_pose_on_the_map_once_nav_has_one(bridge):
    """Odometry starts where the robot was switched on; people mean the place on the map."""
    import math
    from asibot import keys
    from asibot import messages as m
    bridge.bus.publisher(keys.base_odom(ROBOT), m.Odometry).put(m.Odometry(x=0.0, y=0.0, theta=0.0))
    wait_until(lambda: json.loads(request(bridge, "GET", "/status")[2])["pose"] is not None)
    bridge.bus.publisher(keys.nav_pose(ROBOT), m.NavPose).put(
        m.NavPose(x=3.25, y=1.5, theta=math.pi / 2, covariance=[0.0] * 9, localised=True))
    wait_until(lambda: json.loads(request(bridge, "GET", "/status")[2])["pose"] == {"x": 3.25, "y": 1.5, "theta": 90.0})


@pytest.mark.parametrize("data, code", [
    (b"POST /command HTTP/1.1\r\nContent-Length: 999999\r\n\r\n", b"413"),
    (b"POST /command HTTP/1.1\r\nContent-Length: 5\r\nContent-Type: image/png\r\n\r\n\x89PNG\r", b"415"),
    (b"POST /command HTTP/1.1\r\nContent-Length: 4\r\n\r\n\xff\xfe\xfd\xfc", b"400"),
    (b"POST /command HTTP/1.1\r\nContent-Length: 4\r\nContent-Type: application/json\r\n\r\n{{{{", b"400"),
    (b"POST /command HTTP/1.1\r\nContent-Length: 2\r\nContent-Type: application/json\r\n\r\n[]", b"400"),
    (b"POST /command HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n" + b"400\r\n" + b"x" * 1024 + b"\r\n"
     + b"1\r\nx\r\n0\r\n\r\n", b"413"),
    (b"POST /command HTTP/1.1\r\nContent-Length: -3\r\n\r\n", b"400"),
    (b"POST /command HTTP/1.1\r\nX-Big: " + b"a" * 5000 + b"\r\n\r\n", b"431"),
    (b"garbage\r\n\r\n", b"400"),
    (b"GET /command HTTP/1.1\r\n\r\n", b"405"),
    (b"GET /nothing HTTP/1.1\r\n\r\n", b"404"),
])
def test_bad_http_is_answered_and_moves_nothing(bridge, data, code):
    own = b"HTTP/1.1\r\nConnection: close\r\nHost: 127.0.0.1\r\nAuthorization: Bearer " + HTTP_TOKEN.encode() + b"\r\n"
    reply = raw(bridge, data.replace(b"HTTP/1.1\r\n", own, 1))
    assert reply.split(b" ")[1] == code, reply[:200]
    status, _, body = request(bridge, "POST", "/command", "faster")
    assert status == 200
    assert bridge.nav.verbs() == ["settings"]


def test_a_huge_body_is_refused_unread(bridge):
    with socket.create_connection(("127.0.0.1", bridge.servers.http_port), timeout=5) as s:
        s.sendall(b"POST /command HTTP/1.1\r\nHost: localhost\r\nContent-Length: 100000000\r\n\r\n" + b"x" * 65536)
        assert s.recv(200).split(b" ")[1] == b"413"


def test_a_chunked_body_is_taken(bridge):
    """What a client that streams its body sends (no Content-Length): the command, in chunks."""
    chunks = b"".join(b"%x\r\n%s\r\n" % (len(part), part) for part in (b"for", b"ward")) + b"0\r\n\r\n"
    reply = raw(bridge, b"POST /command HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer "
                + HTTP_TOKEN.encode() + b"\r\nTransfer-Encoding: chunked\r\nConnection: close\r\n\r\n" + chunks)
    assert reply.startswith(b"HTTP/1.1 200 ") and reply.endswith(b"\r\n\r\nok: forward, until you say stop\n")
    assert bridge.nav.requests("primitive") == [{"name": "forward", "continuous": True}]


def test_keep_alive_two_requests_on_one_connection(bridge):
    with socket.create_connection(("127.0.0.1", bridge.servers.http_port), timeout=5) as s:
        for text in (b"faster", b"slower"):
            s.sendall(b"POST /command HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer " + HTTP_TOKEN.encode()
                      + b"\r\nContent-Length: %d\r\n\r\n%s" % (len(text), text))
            r = http.client.HTTPResponse(s)
            r.begin()
            assert (r.status, r.read(), r.will_close) == (200, b"ok: speed 3 of 5\n" if text == b"faster"
                                                          else b"ok: speed 2 of 5\n", False)
    assert len(bridge.nav.requests("settings")) == 2


def test_a_stop_does_not_wait_behind_a_slow_command(bridge):
    gate = threading.Event()
    slow = bridge.arm._act
    bridge.arm._act = lambda req: (gate.wait(10), slow(req))[1]
    answers: dict[str, tuple] = {}
    grab = threading.Thread(target=lambda: answers.update(grab=request(bridge, "POST", "/command", "grab")))
    grab.start()
    try:
        wait_until(lambda: bridge.arm.verbs() == ["act"])
        for auth in (True, False):       # with the token, and without (a session of its own)
            status, _, body = request(bridge, "POST", "/command", "stop", auth=auth)
            assert (status, body) == (200, "ok: stopped base and arm\n")
        assert "grab" not in answers
    finally:
        gate.set()
        grab.join(10)
    assert answers["grab"][::2] == (200, "ok: holding something\n")


def test_slow_heads_and_bodies_are_not_waited_for(memory_bus):
    """A head must come whole within `http_idle_s` (whole seconds) of the connection being free,
    however many bytes trickle in; a body within `http_idle_s` of its head."""
    b = Bridge(memory_bus, limits=Limits(http_idle_s=0.5))
    try:
        with socket.create_connection(("127.0.0.1", b.servers.http_port), timeout=5) as s:
            s.sendall(b"POST /command HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ")
            s.settimeout(0.1)

            def closed() -> bool:
                try:
                    s.sendall(b"a")
                    return s.recv(1) == b""
                except TimeoutError:
                    return False
                except OSError:        # the bridge closed it, and said so to this byte
                    return True
            wait_until(closed, 10, interval=0.1, message="a head trickling in held its connection")
        with socket.create_connection(("127.0.0.1", b.servers.http_port), timeout=5) as s:
            s.sendall(b"POST /command HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer " + HTTP_TOKEN.encode()
                      + b"\r\nContent-Length: 7\r\n\r\nfor")
            assert s.recv(200).startswith(b"HTTP/1.1 408 ")
        assert b.nav.calls == []
    finally:
        b.close()


def test_keep_alive_serves_several_requests(bridge):
    conn = http.client.HTTPConnection("127.0.0.1", bridge.servers.http_port, timeout=5)
    try:
        for text in ("faster", "slower", "status"):
            conn.request("POST", "/command", body=text, headers=AUTH)
            r = conn.getresponse()
            assert r.status == 200 and r.read().startswith(b"ok")
    finally:
        conn.close()


def test_the_token_guards_every_request_but_a_stop(memory_bus):
    b = Bridge(memory_bus, http_token="s3cret")
    try:
        status, headers, body = request(b, "POST", "/command", "forward", auth=False)
        assert status == 401 and "WWW-Authenticate" in headers and "http_token" in body
        assert request(b, "GET", "/status", auth=False)[0] == 401
        assert request(b, "POST", "/command", "forward", {"Authorization": "Bearer wrong"})[0] == 401
        assert request(b, "POST", "/command", "robot asibot-sim", auth=False)[0] == 401
        assert b.nav.calls == [] and b.servers.counters["refused_token"] == 4
        basic = base64.b64encode(b"asterics:s3cret").decode()
        assert request(b, "POST", "/command", "faster", {"Authorization": f"Basic {basic}"})[0] == 200
        assert request(b, "POST", "/command", "forward", {"Authorization": "Bearer s3cret"})[0] == 200
        assert request(b, "GET", "/status?token=s3cret", auth=False)[0] == 200
        # stopping is always safe: no token needed, as text or JSON
        assert request(b, "POST", "/command", "stop", auth=False) == (200, ANY, "ok: stopped base and arm\n")
        assert request(b, "POST", "/command", json.dumps({"command": "halt"}), {"Content-Type": "application/json"},
                       auth=False)[0] == 200
        assert [v for v, _ in b.nav.calls] == ["settings", "primitive", "primitive", "primitive"]
        assert [r["name"] for r in b.nav.requests("primitive")] == ["forward", "stop", "stop"]
    finally:
        b.close()


def test_a_bridge_without_http_token_takes_commands_from_programs(memory_bus):
    b = Bridge(memory_bus, http_token=None)
    try:
        assert request(b, "POST", "/command", "faster", auth=False)[0] == 200
    finally:
        b.close()
