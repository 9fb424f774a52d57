"""The bridge's TCP port (NetConnection and text) on loopback sockets, against the doubles on the
in-memory bus: the measured bytes both ways, keepalives, every bad input of issue 15."""

import socket
import threading

import pytest

from asibot.testing import wait_until

from asibot.asterics_bridge import netconnection as nc
from asibot.asterics_bridge.servers import Limits

from .harness import OTHER, ROBOT, Bridge, Busy, Client, command, say
from .test_netconnection import EVENT_1, FORWARD, KEEPALIVE, OBSTACLE


@pytest.fixture
def bridge(memory_bus):
    b = Bridge(memory_bus, limits=Limits(keepalive_s=0.3))
    yield b
    b.close()


@pytest.fixture
def client(bridge):
    c = Client(bridge.servers.tcp_port)
    yield c
    c.close()


def primitives(bridge):
    return [r["name"] for r in bridge.nav.requests("primitive")]


def test_the_measured_exchange_byte_for_byte(bridge, client):
    client.send(FORWARD + EVENT_1)               # "forward" on port 1, then inputEvent1 (mapped to "next")
    wait_until(lambda: len(client.strings(2)) == 2)
    assert client.strings(2) == ["ok: forward, until you say stop", "ok: stop"]
    assert bridge.nav.requests("primitive") == [{"name": "forward", "continuous": True}]
    assert bridge.cmd_vel.all()[0].vx > 0
    start = len(client.bytes())
    bridge.event("drive_stopped", "Stopped: obstacle ahead, 0.4 m")
    sentence = nc.encode_string(3, "Stopped: obstacle ahead, 0.4 m")
    wait_until(lambda: len(client.bytes()) >= start + len(OBSTACLE + EVENT_1 + sentence))
    assert client.bytes()[start:] == OBSTACLE + EVENT_1 + sentence


def test_an_info_event_has_no_alarm_frame(bridge, client):
    command(client, "forward")
    start = len(client.bytes())
    bridge.event("goal_succeeded", "Arrived at fridge", level="info")
    expected = nc.encode_string(1, "goal reached") + nc.encode_string(3, "Arrived at fridge")
    wait_until(lambda: len(client.bytes()) >= start + len(expected))
    assert client.bytes()[start:start + len(expected)] == expected


def test_estop_is_an_alarm_for_the_clients_of_that_robot_only(bridge, client):
    other = Client(bridge.servers.tcp_port)
    try:
        command(client, "status")
        command(other, f"robot {OTHER}")
        bridge.estop(True)
        wait_until(lambda: "estop" in client.strings(1))
        assert nc.Frame("event", 1) in client.frames()
        command(other, "status")                     # answered after the estop went by
        assert "estop" not in other.strings(1)
    finally:
        other.close()


def test_keepalives_go_to_idle_netconnection_clients(bridge, client):
    client.send(KEEPALIVE)                            # the plugin's own: ignored, no answer
    wait_until(lambda: KEEPALIVE in client.bytes(), 5)
    assert client.frames() and all(f == nc.Frame("keepalive", 0) for f in client.frames())


def test_frames_split_across_segments(bridge, client):
    client.send(FORWARD[:4])
    wait_until(lambda: bridge.servers.clients() == 1)
    client.send(FORWARD[4:11])
    client.send(FORWARD[11:])
    assert client.wait_string(2) == ["ok: forward, until you say stop"]


def test_garbage_between_frames_is_ignored(bridge, client):
    client.send(KEEPALIVE + b"\x00\x01@NGARBAGE" + FORWARD + b"\xff\xfe" * 100)
    assert client.wait_string(2, 2) == [
        "'G' is not a NetConnection command (A, E, I, D or S); the frame was skipped.",
        "ok: forward, until you say stop"]
    assert command(client, "stop") == "ok: stopped base and arm"


@pytest.mark.parametrize("bad, answer", [
    (b"@NS\x01\xff\xff", "A string frame of 65535 bytes is longer than the 600 bytes NetConnection sends"),
    (b"@NS\x01\x00\x02\xd8\x00", "The string on port 1 is not valid UTF-16 (big-endian); it was ignored."),
    (b"@NS\x07\x00\x02\x00f", "A string frame goes on port 1 to 5, not 7"),
    (b"@NE\x09\x00\x00", "Event port 9 has no command (mapped: 1=next, 2=select, 3=stop); map it with --events."),
    (nc.encode_integer(1, 5), "Integer frames are not commands"),
    (nc.encode_double(2, 0.5), "Double frames are not commands"),
    (nc.encode_string(1, "forwrd"), "unknown command 'forwrd'; did you mean 'forward'?"),
])
def test_bad_input_is_answered_and_moves_nothing(bridge, client, bad, answer):
    client.send(bad)
    assert client.wait_string(2)[0].startswith(answer)
    assert command(client, "faster") == "ok: speed 3 of 5"     # still served, in order
    assert bridge.nav.verbs() == ["settings"]


def test_a_client_sending_only_bad_frames_is_dropped(bridge, client):
    client.send(b"@NZ\x01\x00\x00" * 60)
    wait_until(lambda: client.closed)
    assert bridge.servers.counters["dropped_bad"] == 1
    fresh = Client(bridge.servers.tcp_port)
    try:
        assert command(fresh, "faster").startswith("ok")
    finally:
        fresh.close()


def test_text_clients_get_lines(bridge):
    c = Client(bridge.servers.tcp_port)
    try:
        assert say(c, "Forward") == "ok: forward, until you say stop"
        assert say(c, "forwrd") == "error: unknown command 'forwrd'; did you mean 'forward'?"
        c.send(b"\xff\xfe\n")
        wait_until(lambda: any("UTF-8" in ln for ln in c.lines()))
        bridge.event("goal_succeeded", "Arrived at fridge", level="info")
        wait_until(lambda: "event goal reached: Arrived at fridge" in c.lines())
        bridge.estop(True)
        wait_until(lambda: any(ln.startswith("alarm estop: Emergency stop engaged") for ln in c.lines()))
        assert say(c, "stop") == "ok: stopped base and arm"
        assert primitives(bridge) == ["forward", "stop"]
    finally:
        c.close()


def test_a_client_that_disconnects_mid_motion_stops_the_robot(bridge, client):
    command(client, "forward")
    client.close()
    wait_until(lambda: primitives(bridge) == ["forward", "stop"])
    wait_until(lambda: bridge.cmd_vel.last().vx == 0.0)


def test_a_client_that_disconnects_right_after_a_command_stops_the_robot(bridge):
    c = Client(bridge.servers.tcp_port, read=False)
    c.send(b"forward\n")
    c.sock.shutdown(socket.SHUT_RDWR)
    c.close()
    wait_until(lambda: primitives(bridge) == ["forward", "stop"])


def test_a_text_client_that_never_reads_is_dropped_and_blocks_nobody(memory_bus):
    b = Bridge(memory_bus, limits=Limits(send_buffer=16384, sndbuf=4096))
    sleeper = Client(b.servers.tcp_port, rcvbuf=4096, read=False)
    reader = Client(b.servers.tcp_port)
    try:
        sleeper.send(b"status\n")
        command(reader, "status")
        wait_until(lambda: b.dispatcher.sessions() == 2)
        i = 0

        def dropped() -> bool:
            nonlocal i
            for _ in range(5):
                i += 1
                b.event("obstacle", f"Obstacle ahead, {i} m. " + "x" * 200, level="info")
            # the reader keeps up (a loaded machine must not make it the slow one)
            wait_until(lambda: len(reader.strings(1)) >= i, 10)
            return b.servers.counters["dropped_slow"] >= 1
        wait_until(dropped, 30, interval=0.01)
        wait_until(lambda: b.dispatcher.sessions() == 1)
        assert command(reader, "faster").startswith("ok")
        assert len(reader.strings(1)) >= 20               # the reader heard the events meanwhile
    finally:
        sleeper.close()
        reader.close()
        b.close()


def test_stop_does_not_wait_behind_a_slow_command(bridge, client):
    gate = threading.Event()
    slow = bridge.arm._act
    bridge.arm._act = lambda req: (gate.wait(5), slow(req))[1]
    try:
        client.send(nc.encode_string(1, "grab"))
        wait_until(lambda: bridge.arm.verbs() == ["act"])
        assert command(client, "stop") == "ok: stopped base and arm"
    finally:
        gate.set()
    assert client.wait_string(2, 2)[1] == "ok: holding something"


def test_a_flood_of_commands_is_bounded(memory_bus):
    b = Bridge(memory_bus, limits=Limits(queued_commands=2))
    gate = threading.Event()
    slow = b.arm._home
    b.arm._home = lambda req: (gate.wait(5), slow(req))[1]
    c = Client(b.servers.tcp_port)
    try:
        c.send(nc.encode_string(1, "arm home") * 10)
        wait_until(lambda: any(s.startswith("Busy") for s in c.strings(2)))
        gate.set()
        wait_until(lambda: len(c.strings(2)) == 10)
        busy = sum(s.startswith("Busy: ") for s in c.strings(2))
        assert c.strings(2).count("ok: arm going home") == 10 - busy <= 3    # one running, two waiting
        assert command(c, "faster").startswith("ok")
    finally:
        gate.set()
        c.close()
        b.close()


def test_fifty_clients_at_once(bridge):
    clients = [Client(bridge.servers.tcp_port) for _ in range(50)]
    try:
        for i, c in enumerate(clients):
            if i % 2:
                c.send(nc.encode_string(1, "faster") + nc.encode_string(1, "status"))
            else:
                c.send(b"slower\nstatus\n")
        for i, c in enumerate(clients):
            if i % 2:
                assert c.wait_string(2, 2)[0].startswith("ok: speed")
            else:
                assert c.wait_lines(2)[0].startswith("ok: speed")
        bridge.event("goal_succeeded", "Arrived at fridge", level="info")
        for i, c in enumerate(clients):
            if i % 2:
                c.wait_string(1)
            else:
                wait_until(lambda: "event goal reached: Arrived at fridge" in c.lines())
        assert len(bridge.nav.requests("settings")) == 50
    finally:
        for c in clients:
            c.close()


def test_beyond_the_client_limit_a_client_is_told_and_closed(memory_bus):
    """When every slot's client has a command under way, none makes room (test_own_users)."""
    b = Bridge(memory_bus, limits=Limits(max_clients=2))
    cs = [Client(b.servers.tcp_port) for _ in range(2)]
    busy = Busy(b, cs)
    try:
        extra = Client(b.servers.tcp_port)
        wait_until(lambda: extra.closed)
        assert extra.lines() == ["error: the bridge serves 2 clients at most, and each of them has a command under "
                                 "way; try again in a moment."]
        extra.close()
    finally:
        busy.release()
        for c in cs:
            c.close()
        b.close()


def test_a_token_is_asked_for_on_tcp(memory_bus):
    b = Bridge(memory_bus, token="s3cret")
    c = Client(b.servers.tcp_port)
    try:
        assert command(c, "forward").startswith("This bridge serves the network and needs its access token")
        assert command(c, "token s3cret") == "ok: token accepted"
        assert command(c, "forward").startswith("ok")
        assert primitives(b) == ["forward"]
    finally:
        c.close()
        b.close()


def test_the_robot_of_a_connection(bridge, client):
    assert command(client, f"robot {OTHER}") == f"ok: now driving {OTHER}"
    assert command(client, "arm up") == "ok: arm up 10 mm"
    assert bridge.other_arm.verbs() == ["stat", "movl"]
    assert command(client, f"robot {ROBOT}").startswith("ok")
