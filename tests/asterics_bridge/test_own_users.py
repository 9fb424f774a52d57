"""The bridge obeys only its own users: not a web page the user visits (CORS, Origin, Host,
DNS rebinding, a page's fetch to the TCP port), not a client that holds slots without
speaking; and a stop always gets through. Raw sockets on loopback, the doubles on the
in-memory bus."""

import json
import socket

import pytest

from asibot.testing import wait_until

from asibot.asterics_bridge import netconnection as nc
from asibot.asterics_bridge.servers import Limits

from .harness import HTTP_TOKEN, Bridge, Client, command, say
from .test_http import request

GRID = "https://grid.asterics.eu"
EVIL = "http://evil.example"


@pytest.fixture
def bridge(memory_bus):
    b = Bridge(memory_bus, origins=(GRID,))
    yield b
    b.close()


def untouched(bridge) -> bool:
    return bridge.nav.calls == [] and bridge.arm.calls == [] and bridge.other_arm.calls == [] \
        and bridge.tasks.calls == []


def cors_headers(headers: dict) -> list[str]:
    return [h for h in headers if h.lower().startswith("access-control")]


# ---------------------------------------------------------------- HTTP: pages of other origins
@pytest.mark.parametrize("method, path, body, headers", [
    # a "simple" request: the browser sends it without asking first
    ("POST", "/command", "turn left", {"Content-Type": "text/plain", "Origin": EVIL, "Sec-Fetch-Site": "cross-site"}),
    ("POST", "/command", "turn left", {"Content-Type": "text/plain", "Origin": "null"}),    # a sandboxed frame
    ("POST", "/command", "goto fridge", {"Content-Type": "application/x-www-form-urlencoded", "Origin": EVIL}),
    ("POST", "/command", json.dumps({"command": "grab"}), {"Content-Type": "application/json", "Origin": EVIL}),
    ("POST", "/command", "stop", {"Content-Type": "text/plain", "Origin": EVIL}),   # not even a stop
    # another port of this machine is another origin (same site)
    ("POST", "/command", "forward", {"Origin": "http://127.0.0.1:9999", "Sec-Fetch-Site": "same-site"}),
    ("GET", "/status", None, {"Origin": EVIL, "Sec-Fetch-Site": "cross-site"}),
    # a no-cors GET (an <img>, fetch no-cors) carries no Origin, only Fetch Metadata
    ("GET", "/status", None, {"Sec-Fetch-Site": "cross-site", "Sec-Fetch-Mode": "no-cors"}),
    ("GET", "/", None, {"Sec-Fetch-Site": "same-site", "Sec-Fetch-Mode": "no-cors"}),
])
def test_a_foreign_page_is_refused_even_without_a_preflight(bridge, method, path, body, headers):
    """Even with the token (a page cannot know it, but the refusal must not depend on that)."""
    status, got, text = request(bridge, method, path, body, headers)
    assert status == 403, (status, text)
    assert text.startswith("error: A page of") or text.startswith("error: Another site's page")
    assert "--allow-origin" in text
    assert cors_headers(got) == []
    assert untouched(bridge)
    assert bridge.servers.counters["refused_origin"] == 1


def test_a_stranger_s_preflight_gets_no_permission(bridge):
    status, headers, _ = request(bridge, "OPTIONS", "/command", auth=False, headers={
        "Origin": EVIL, "Access-Control-Request-Method": "POST",
        "Access-Control-Request-Headers": "content-type", "Access-Control-Request-Private-Network": "true"})
    assert status == 403 and cors_headers(headers) == []


def test_the_allowed_grid_is_served(bridge):
    status, headers, body = request(bridge, "GET", "/status", headers={"Origin": GRID, "Sec-Fetch-Site": "cross-site"})
    assert status == 200 and headers["Access-Control-Allow-Origin"] == GRID and json.loads(body)["robot"]


def _forward_to(host: str | None) -> bytes:
    """A POST of 'forward' with the token, by the name `host` (None: no Host header)."""
    head = b"" if host is None else f"Host: {host}\r\n".encode()
    return (b"POST /command HTTP/1.1\r\n" + head + b"Authorization: Bearer " + HTTP_TOKEN.encode()
            + b"\r\nContent-Length: 7\r\nConnection: close\r\n\r\nforward")


@pytest.mark.parametrize("host", ["evil.example", "evil.example:8090", "127.0.0.1.evil.example", "",
                                  "robot.local"])
def test_a_name_not_the_bridge_s_is_refused(bridge, host):
    """DNS rebinding: the attacker's name resolves to 127.0.0.1 and its page reads as same-origin."""
    reply = _exchange(bridge.servers.http_port, _forward_to(host))
    assert reply.startswith(b"HTTP/1.1 400 "), reply[:100]
    assert b"This server does not answer to" in reply and b"access-control" not in reply.lower()
    assert untouched(bridge) and bridge.servers.counters["refused_host"] == 1


def test_a_request_without_a_host_is_not_read(bridge):
    """HTTP/1.1 needs a Host header: the HTTP parser refuses a request without one before any
    check of the bridge's."""
    reply = _exchange(bridge.servers.http_port, _forward_to(None))
    assert reply.startswith(b"HTTP/1.1 400 "), reply[:100]
    assert b"a Host header" in reply and b"access-control" not in reply.lower()
    assert untouched(bridge)


def test_the_bridge_s_own_names_and_those_the_user_adds(memory_bus):
    b = Bridge(memory_bus, hosts=("robot.local",))
    try:
        port = b.servers.http_port
        for host in (f"127.0.0.1:{port}", f"localhost:{port}", f"[::1]:{port}", f"ROBOT.local:{port}"):
            assert request(b, "POST", "/command", "faster", {"Host": host})[0] == 200, host
        assert len(b.nav.requests("settings")) == 4
    finally:
        b.close()


@pytest.mark.parametrize("body", [
    {"command": True}, {"command": 1}, {"command": None}, {"robot": "pioneer-sim"},
    {"command": "forward", "robot": True}, {"command": "forward", "robot": False}, {"command": "forward", "robot": 0},
    {"command": "forward", "robot": ""}, {"command": "forward", "speed": 3}, {"command": ["forward"]},
    True, 5, None, ["forward"],
])
def test_bad_json_is_a_sentence_and_changes_nothing(bridge, body):
    status, _, text = request(bridge, "POST", "/command", json.dumps(body), {"Content-Type": "application/json"})
    answer = json.loads(text)
    assert status == 400 and answer["ok"] is False and answer["code"] == "bad_request"
    assert answer["error"].startswith("Send JSON {\"command\": \"forward\"}")
    assert untouched(bridge)


# ---------------------------------------------------------------- TCP: a web page's fetch to 21112
def _exchange(port: int, *parts: bytes) -> bytes:
    """Send `parts` (each its own segment) and read until the bridge closes."""
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        for part in parts:
            s.sendall(part)
        reply = b""
        while chunk := s.recv(65536):
            reply += chunk
        return reply


BROWSER_POST = (b"POST / HTTP/1.1\r\nHost: 127.0.0.1:21112\r\nConnection: keep-alive\r\nContent-Length: 12\r\n"
                b"Content-Type: text/plain;charset=UTF-8\r\nOrigin: http://evil.example\r\nSec-Fetch-Mode: no-cors\r\n"
                b"\r\ngoto fridge\n")


@pytest.mark.parametrize("parts", [
    (BROWSER_POST,),
    (BROWSER_POST[:18], BROWSER_POST[18:]),                   # the request line whole, the rest later
    (b"POST /command HTTP/1.0\r\n\r\nforward\n",),
    (b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\r\nstop\nforward\n",),
    (b"PUT /x?forward HTTP/1.1\nforward\n",),
])
def test_a_connection_that_starts_like_http_is_refused_before_any_line_runs(bridge, parts):
    reply = _exchange(bridge.servers.tcp_port, *parts)
    assert reply.startswith(b"HTTP/1.1 400 Bad Request\r\n"), reply[:200]
    assert b"not HTTP; HTTP clients use its HTTP port" in reply and b"Access-Control" not in reply
    assert untouched(bridge) and bridge.dispatcher.counters["commands"] == 0
    assert bridge.servers.counters["refused_http_like"] == 1


@pytest.mark.parametrize("first", [b"POST /" + b"a" * 2000 + b" HTTP/1.1\r\n", b"\xff\xfe\n"])
def test_a_connection_whose_first_line_cannot_be_read_runs_nothing(bridge, first):
    """A page's request line longer than a line may be (a long URL) is unreadable, not harmless:
    its headers and body must not run either."""
    rest = b"Host: 127.0.0.1\r\nContent-Length: 12\r\n\r\ngoto fridge\n"
    answer = _exchange(bridge.servers.tcp_port, first + rest).decode().splitlines()
    assert len(answer) == 1 and answer[0].startswith("error: ")
    assert answer[0].endswith("A connection must start with a command; this one is closed.")
    assert untouched(bridge) and bridge.dispatcher.counters["commands"] == 0


def test_http_in_a_later_line_is_just_a_bad_command(bridge):
    """Only the first line tells a web page: a text client's later lines are commands as ever."""
    c = Client(bridge.servers.tcp_port)
    try:
        assert say(c, "faster").startswith("ok")
        assert say(c, "GET / HTTP/1.1").startswith("error: unknown command")
    finally:
        c.close()


# ---------------------------------------------------------------- TCP: slots
def test_silent_and_half_finished_connections_are_closed(memory_bus):
    b = Bridge(memory_bus, limits=Limits(first_item_s=1.0, partial_s=0.5))
    silent, half, talker = (Client(b.servers.tcp_port) for _ in range(3))
    try:
        half.send(b"@")
        command(talker, "status")
        wait_until(lambda: half.closed, 5, message="a lone '@' held its slot")
        assert half.lines() == ["error: This connection is closed: a frame or line was begun and not finished "
                                "in 0.5 s. Connect again and send a whole command at once (a line, or a "
                                "NetConnection frame)."]
        wait_until(lambda: silent.closed, 5, message="a silent connection held its slot")
        assert silent.lines()[0].startswith("error: This connection is closed: nothing whole came in 1 s.")
        # the talker, connected as early and silent since, stays: an ARE waits for its user
        assert not talker.closed and b.servers.clients() == 1
        assert command(talker, "faster").startswith("ok")
        # once it spoke, a frame it begins must still be finished
        talker.send(nc.encode_string(1, "forward")[:5])
        wait_until(lambda: talker.closed, 5)
        assert b.servers.counters["closed_idle"] == 3
        assert "primitive" not in b.nav.verbs()
    finally:
        for c in (silent, half, talker):
            c.close()
        b.close()


def _raw_clients(port: int, n: int, first: bytes) -> list[socket.socket]:
    out = []
    for _ in range(n):
        s = socket.create_connection(("127.0.0.1", port), timeout=5)
        s.sendall(first)
        out.append(s)
    return out


def test_two_hundred_half_frames_do_not_lock_out_a_stop(memory_bus):
    """The reviewer's attack on a bridge with the default limits: 200 clients each sending '@'.
    A stop still gets through at once, and the slots come free within `partial_s`."""
    b = Bridge(memory_bus)
    holders = _raw_clients(b.servers.tcp_port, 200, b"@")
    try:
        wait_until(lambda: b.servers.clients() == Limits.per_address, 10)
        c = Client(b.servers.tcp_port)
        c.send(b"stop\n")
        wait_until(lambda: c.closed, 10)
        assert c.lines() == ["ok: stopped base and arm",
                             f"error: 127.0.0.1 holds {Limits.per_address} connections to the bridge already, the "
                             "most one address may; close one of them, or try again later."]
        assert b.nav.requests("primitive") == [{"name": "stop"}]
        wait_until(lambda: b.servers.clients() == 0, Limits.partial_s + 10,
                   message="the half frames still hold their slots")
        c = Client(b.servers.tcp_port)
        assert say(c, "forward").startswith("ok: forward")
        c.close()
    finally:
        for s in holders:
            s.close()
        b.close()


FULL = "the bridge serves 2 clients at most; try again later."


@pytest.mark.parametrize("first, answers", [
    (nc.encode_string(1, "stop"), ["ok: stopped base and arm", FULL]),
    (nc.encode_event(3), ["ok: stopped base and arm", FULL]),          # the switch mapped to stop
    (nc.encode_string(1, "forward"), [FULL]),
])
def test_a_full_bridge_still_takes_a_stop(memory_bus, first, answers):
    b = Bridge(memory_bus, limits=Limits(max_clients=2))
    holders = [Client(b.servers.tcp_port) for _ in range(2)]
    try:
        for h in holders:
            command(h, "status")
        extra = Client(b.servers.tcp_port)
        extra.send(first)
        wait_until(lambda: extra.closed, 5)
        assert extra.strings(2) == answers
        stops = [{"name": "stop"}] if len(answers) == 2 else []
        assert b.nav.requests("primitive") == stops and b.servers.counters["refused_full"] == 1
    finally:
        for h in holders:
            h.close()
        b.close()


def test_a_silent_client_of_a_full_bridge_is_told_in_a_line(memory_bus):
    b = Bridge(memory_bus, limits=Limits(max_clients=1, refused_wait_s=0.3))
    holder = Client(b.servers.tcp_port)
    try:
        command(holder, "status")
        extra = Client(b.servers.tcp_port)
        wait_until(lambda: extra.closed, 5)
        assert extra.lines() == ["error: the bridge serves 1 clients at most; try again later."]
    finally:
        holder.close()
        b.close()


def test_one_address_cannot_take_every_slot(memory_bus):
    """On loopback every program is 127.0.0.1; another machine (here 127.0.0.2) keeps its share."""
    b = Bridge(memory_bus, limits=Limits(max_clients=4, per_address=2))
    cs = [Client(b.servers.tcp_port) for _ in range(2)]
    try:
        for c in cs:
            command(c, "status")
        third = Client(b.servers.tcp_port)
        third.send(b"forward\n")
        wait_until(lambda: third.closed, 5)
        assert third.lines() == ["error: 127.0.0.1 holds 2 connections to the bridge already, the most one "
                                 "address may; close one of them, or try again later."]
        other = Client(b.servers.tcp_port, source="127.0.0.2")
        cs.append(other)
        assert say(other, "forward").startswith("ok: forward")
        assert [r["name"] for r in b.nav.requests("primitive")] == ["forward"]
        assert b.servers.counters["refused_address"] == 1
    finally:
        for c in cs:
            c.close()
        b.close()
