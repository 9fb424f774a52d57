"""The bridge obeys only its own users: not a web page the user visits (CORS, Origin, Host,
DNS rebinding, a page's fetch to the TCP port), not a client that holds slots without
speaking; and a stop always gets through. Raw sockets on loopback, the doubles on the
in-memory bus."""

import json
import socket

from unittest.mock import ANY

import pytest

from asibot.testing import wait_until

from asibot.asterics_bridge import netconnection as nc
from asibot.asterics_bridge import slots
from asibot.asterics_bridge.servers import Limits

from .harness import HTTP_TOKEN, Bridge, Busy, Client, command, say
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


NESTED = "The body's JSON is nested too deeply to read; a command is one flat object, send {\"command\": \"forward\"}."


@pytest.mark.parametrize("body, code, answer", [
    # issue 51: 20 of 1,500 fuzzed bodies were a 500 (RecursionError) instead of a sentence
    ("[" * 2000 + "]" * 2000, 400, {"ok": False, "code": "bad_request", "error": NESTED}),
    ("[" * 4000, 400, {"ok": False, "code": "bad_request", "error": NESTED}),
    ('{"command": ' + "[" * 1500 + "]" * 1500 + "}", 400, {"ok": False, "code": "bad_request", "error": NESTED}),
    ('{"command": "forward", "robot": ' + "[" * 1500 + "]" * 1500 + "}", 400,
     {"ok": False, "code": "bad_request", "error": NESTED}),
    ("[" * 400 + "]" * 400, 400, ANY),          # readable: refused as any other list
    ("[" * 5000 + "]" * 5000, 413, "error: a command is at most 4096 bytes; this body has 10000.\n"),
    (json.dumps({"command": "forward " * 600}), 413, ANY),
])
def test_deep_or_huge_json_is_refused_with_a_sentence_and_changes_nothing(bridge, body, code, answer):
    status, _, text = request(bridge, "POST", "/command", body, {"Content-Type": "application/json"})
    assert status == code, text[:300]
    assert (json.loads(text) if code == 400 else text) == answer
    assert untouched(bridge)
    assert request(bridge, "POST", "/command", "faster")[0] == 200       # and the bridge serves on


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


ROOM = "error: This connection is closed to make room for a new one: "


def test_a_client_that_spoke_and_went_silent_loses_its_slot(memory_bus):
    """Issue 51: a client that sends one line and then nothing held its slot for ever; the
    first-line deadline was all there was. One that keeps sending something keeps its slot."""
    b = Bridge(memory_bus, limits=Limits(idle_s=1.0))
    quiet, chatty = Client(b.servers.tcp_port), Client(b.servers.tcp_port)
    try:
        assert say(quiet, "forward").startswith("ok: forward")
        assert say(chatty, "status").startswith("ok")
        # chatty sends an empty line (nothing runs) at every poll, quiet nothing
        wait_until(lambda: (chatty.send(b"\n"), quiet.closed)[1], 5, interval=0.1,
                   message="a client silent since its first line still holds its slot")
        assert quiet.lines()[-1] == ("error: This connection is closed: nothing came for 1 s. Connect again when "
                                     "you need the robot; a program that keeps its connection sends something (an "
                                     "empty line, or NetConnection's keepalive) at least every 1 s.")
        assert not chatty.closed and say(chatty, "faster").startswith("ok")
        wait_until(lambda: b.servers.clients() == 1)
        assert b.servers.counters["closed_idle"] == 1
        # what it started stops, as when it disconnects
        wait_until(lambda: [r["name"] for r in b.nav.requests("primitive")] == ["forward", "stop"])
    finally:
        quiet.close()
        chatty.close()
        b.close()


def test_fifty_local_clients_that_spoke_once_do_not_lock_out_a_newcomer(memory_bus):
    """Issue 51's attack with the default limits: 50 local clients send one whole line each and
    then nothing. A new client's `status` and `turn left` were refused for as long as they
    stayed; local programs have no per-address share now, and they are below the total."""
    b = Bridge(memory_bus)
    holders = _raw_clients(b.servers.tcp_port, 50, b"status\n")
    try:
        wait_until(lambda: b.dispatcher.counters["commands"] == 50, 10)
        c = Client(b.servers.tcp_port)
        assert say(c, "status").startswith("ok")
        assert say(c, "turn left").startswith("ok: turn left")
        assert say(c, "stop") == "ok: stopped base and arm"
        assert b.servers.counters["refused_address"] == b.servers.counters["refused_full"] == 0
        c.close()
    finally:
        for s in holders:
            s.close()
        b.close()


def test_a_full_bridge_makes_room_by_closing_the_longest_silent(memory_bus):
    b = Bridge(memory_bus, limits=Limits(max_clients=3))
    oldest, *others = holders = [Client(b.servers.tcp_port) for _ in range(3)]
    try:
        assert say(oldest, "forward").startswith("ok: forward")
        for h in others:
            assert say(h, "status").startswith("ok")
        newcomer = Client(b.servers.tcp_port)
        holders.append(newcomer)
        assert say(newcomer, "status").startswith("ok")
        wait_until(lambda: oldest.closed, 5, message="the longest silent connection still holds its slot")
        assert oldest.lines()[-1].startswith(ROOM + "the bridge's 3 slots were all taken, and this one had been "
                                             "silent the longest (")
        assert oldest.lines()[-1].endswith(" s). Connect again when you need the robot.")
        assert not any(h.closed for h in others) and all(say(h, "faster").startswith("ok") for h in others)
        assert b.servers.counters["closed_for_room"] == 1 and b.servers.counters["refused_full"] == 0
        # what the closed one started stops, as when it disconnects
        wait_until(lambda: [r["name"] for r in b.nav.requests("primitive")] == ["forward", "stop"])
    finally:
        for h in holders:
            h.close()
        b.close()


def test_two_hundred_half_frames_do_not_lock_out_a_stop(memory_bus):
    """The reviewer's attack on a bridge with the default limits: 200 clients each sending '@'.
    A newcomer takes the slot of one of them (they never sent anything whole), its stop runs at
    once, and the other slots come free within `partial_s`."""
    b = Bridge(memory_bus)
    holders = _raw_clients(b.servers.tcp_port, 200, b"@")
    try:
        wait_until(lambda: b.servers.counters["connections"] == 200, 10)
        assert b.servers.clients() <= Limits.max_clients and b.servers.counters["closed_for_room"] >= 100
        c = Client(b.servers.tcp_port)
        assert say(c, "stop") == "ok: stopped base and arm"
        assert b.nav.requests("primitive") == [{"name": "stop"}]
        wait_until(lambda: b.servers.clients() == 1, Limits.partial_s + 10,
                   message="the half frames still hold their slots")
        assert not c.closed and say(c, "forward").startswith("ok: forward")
        c.close()
    finally:
        for s in holders:
            s.close()
        b.close()


FULL = "the bridge serves 2 clients at most, and each of them has a command under way; try again in a moment."


@pytest.mark.parametrize("first, answers", [
    (nc.encode_string(1, "stop"), ["ok: stopped base and arm", FULL]),
    (nc.encode_event(3), ["ok: stopped base and arm", FULL]),          # the switch mapped to stop
    (nc.encode_string(1, "forward"), [FULL]),
])
def test_a_full_bridge_still_takes_a_stop(memory_bus, first, answers):
    b = Bridge(memory_bus, limits=Limits(max_clients=2))
    holders = [Client(b.servers.tcp_port) for _ in range(2)]
    busy = Busy(b, holders)
    try:
        extra = Client(b.servers.tcp_port)
        extra.send(first)
        wait_until(lambda: extra.closed, 5)
        assert extra.strings(2) == answers
        stops = [{"name": "stop"}] if len(answers) == 2 else []
        assert b.nav.requests("primitive") == stops and b.servers.counters["refused_full"] == 1
    finally:
        busy.release()
        for h in holders:
            h.close()
        b.close()


def test_a_silent_client_of_a_full_bridge_is_told_in_a_line(memory_bus):
    b = Bridge(memory_bus, limits=Limits(max_clients=1, refused_wait_s=0.3))
    holder = Client(b.servers.tcp_port)
    busy = Busy(b, [holder])
    try:
        extra = Client(b.servers.tcp_port)
        wait_until(lambda: extra.closed, 5)
        assert extra.lines() == ["error: the bridge serves 1 clients at most, and each of them has a command under "
                                 "way; try again in a moment."]
    finally:
        busy.release()
        holder.close()
        b.close()


def test_another_machine_makes_room_from_its_own_share(memory_bus, monkeypatch):
    """Another machine (127.0.0.2 plays one: loopback is this machine's) holds at most
    `per_address`; a newcomer of it over that share takes the slot of its own longest silent
    connection, never one of this machine's programs."""
    monkeypatch.setattr(slots, "group_of", lambda host: "127.0.0.2" if host == "127.0.0.2" else slots.LOOPBACK)
    b = Bridge(memory_bus, limits=Limits(max_clients=4, per_address=2))
    local = Client(b.servers.tcp_port)
    r1, r2 = remote = [Client(b.servers.tcp_port, source="127.0.0.2") for _ in range(2)]
    try:
        for c in (r1, local, r2):
            assert say(c, "status").startswith("ok")
        r3 = Client(b.servers.tcp_port, source="127.0.0.2")
        remote.append(r3)
        assert say(r3, "forward").startswith("ok: forward")
        wait_until(lambda: r1.closed, 5)
        assert r1.lines()[-1].startswith(ROOM + "127.0.0.2 held the 2 slots one address may, and this one had "
                                         "been silent the longest (")
        assert not local.closed and not r2.closed and say(local, "stop") == "ok: stopped base and arm"
        assert b.servers.counters["closed_for_room"] == 1 and b.servers.counters["refused_address"] == 0
    finally:
        for c in [local] + remote:
            c.close()
        b.close()
