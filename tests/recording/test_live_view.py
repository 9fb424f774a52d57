"""The live view (`asibot foxglove`): the bus on a Foxglove WebSocket server.

The stack is an in-memory bus fed by the test; the viewer is a WebSocket client speaking the
Foxglove protocol as the app does (conftest.FoxgloveClient): it must see every topic advertised
with its schema, and after subscribing get messages it decodes from that schema alone.
"""

from __future__ import annotations

import base64
import json
import socket
from pathlib import Path

import numpy as np
import pytest

from asibot import keys, messages as m
from asibot.bus import Bus
from asibot.recorder.live_view import LiveView
from asibot.testing import wait_until

BASE = "pioneer-sim"
JPEG = b"\xff\xd8 a frame \xff\xd9"
DEPTH = np.arange(6, dtype=np.float32).reshape(2, 3) / 2
MAP = np.array([[0, 100], [-1, 0]], np.int8)


@pytest.fixture
def stack(memory_bus):
    """The running stack, as far as the view can tell: a bus to publish on."""
    with Bus("stack") as bus:
        yield bus


@pytest.fixture
def view(stack):
    """The live view of `stack` on a free loopback port."""
    with Bus("foxglove") as bus, LiveView(bus, port=0) as live:
        yield live


def payload_of(client, protobuf, topic: str, sub: int) -> dict:
    """The newest message `client` got on `topic`, decoded with the schema it advertised."""
    channel = client.channels[topic]
    data = client.received[sub][-1][1]
    if channel["encoding"] == "json":
        return json.loads(data)
    return protobuf(base64.b64decode(channel["schema"])).decode(channel["schemaName"], data)


def test_every_topic_is_advertised_with_its_schema_and_served_once_subscribed(stack, view, foxglove_client,
                                                                            protobuf):
    rgb = stack.publisher(keys.camera_rgb(BASE, "front"), m.RgbImage)
    depth = stack.publisher(keys.camera_depth(BASE, "front"), m.DepthImage)
    battery = stack.publisher(keys.base_battery(BASE), m.Battery)

    def publish() -> None:
        rgb.put(m.RgbImage(jpeg=JPEG, width=3, height=2))
        depth.put(m.DepthImage(depth=DEPTH))
        battery.put(m.Battery(volts=12.5))

    client = foxglove_client(view.url)
    assert client.info["op"] == "serverInfo" and client.info["name"] == "asibot"
    assert client.info["capabilities"] == []          # no publishing from Foxglove: a viewer never commands
    topics = (keys.camera_rgb(BASE, "front"), keys.camera_depth(BASE, "front"), keys.base_battery(BASE))
    client.wait(lambda: all(t in client.channels for t in topics), 10, "not every topic was advertised", publish)
    advertised = {t: (c["schemaName"], c["encoding"], c["schemaEncoding"]) for t, c in client.channels.items()}
    assert advertised[topics[0]] == ("foxglove.CompressedImage", "protobuf", "protobuf")
    assert advertised[topics[1]] == ("foxglove.RawImage", "protobuf", "protobuf")
    assert advertised[topics[2]] == ("asibot.Battery", "json", "jsonschema")

    subs = [client.subscribe(t) for t in topics]
    client.wait(lambda: all(s in client.received for s in subs), 10, "no message after subscribing", publish)
    image = payload_of(client, protobuf, topics[0], subs[0])
    assert (image["data"], image["format"], image["frame_id"]) == (JPEG, "jpeg", "pioneer-sim/front_optical")
    pixels = payload_of(client, protobuf, topics[1], subs[1])
    assert pixels["encoding"] == "32FC1"
    assert np.array_equal(np.frombuffer(pixels["data"], "<f4").reshape(2, 3), DEPTH)
    assert payload_of(client, protobuf, topics[2], subs[2])["volts"] == 12.5
    assert view.messages >= 3 and view.skipped == 0


def test_a_map_latched_before_the_view_started_reaches_every_client_that_subscribes(stack, memory_bus,
                                                                                   foxglove_client, protobuf):
    """Nav publishes its map once: a client that subscribes later still gets it."""
    stack.latch(keys.nav_map(BASE), m.NavMap(resolution=0.1, origin=[0.0, 0.0, 0.0], data=MAP, name="home"))
    with Bus("foxglove") as bus, LiveView(bus, port=0) as live:
        for _ in range(2):                      # the second client comes after the first got it
            client = foxglove_client(live.url)
            client.wait(lambda: keys.nav_map(BASE) in client.channels, 10, "the map was not advertised")
            assert client.channels[keys.nav_map(BASE)]["schemaName"] == "foxglove.Grid"
            sub = client.subscribe(keys.nav_map(BASE))
            client.wait(lambda: sub in client.received, 10, "the latched map was not sent on subscribing")
            grid = payload_of(client, protobuf, keys.nav_map(BASE), sub)
            assert grid["frame_id"] == "pioneer-sim/map"
            assert np.array_equal(np.frombuffer(grid["data"], np.int8).reshape(2, 2), MAP)


def listening(port: int) -> set[str]:
    """The local addresses (hex, as the kernel writes them) of the TCP sockets listening on `port`."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        if not Path(table).exists():
            continue
        for line in Path(table).read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            address, hex_port = local.rsplit(":", 1)
            if state == "0A" and int(hex_port, 16) == port:      # 0A: LISTEN
                found.add(address)
    return found


@pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="reads Linux's socket table")
def test_it_listens_on_loopback_only_and_says_when_the_port_is_taken(view):
    assert view.url == f"ws://127.0.0.1:{view.port}"
    assert listening(view.port) == {"0100007F"}                  # 127.0.0.1, not 0.0.0.0 nor ::
    with Bus("second") as bus, pytest.raises(RuntimeError, match="in use"):
        LiveView(bus, port=view.port)


def test_a_message_that_is_not_valid_is_counted_and_the_rest_served(stack, view, foxglove_client):
    stack.put_raw(keys.arm_state("asibot-sim"), m.pack({"_type": "ArmState", "names": ["q1"], "positions": "oops",
                                                        "velocities": [], "stamp": 1}))
    stack.put_raw(keys.arm_state("asibot-sim"), b"\xc1 not msgpack")
    wait_until(lambda: view.skipped == 2, 10, message=lambda: f"skipped {view.skipped}, not 2")
    battery = stack.publisher(keys.base_battery(BASE), m.Battery)
    client = foxglove_client(view.url)
    client.wait(lambda: keys.base_battery(BASE) in client.channels, 10, "the battery was not advertised",
                lambda: battery.put(m.Battery(volts=11.0)))
    assert keys.arm_state("asibot-sim") not in client.channels


def bindable(port: int) -> bool:
    try:
        socket.create_server(("127.0.0.1", port)).close()
    except OSError:
        return False
    return True


def test_the_port_is_free_again_once_closed(stack):
    """So `asibot foxglove` can start again at once; the SDK lets go of it in the background."""
    with Bus("foxglove") as bus:
        with LiveView(bus, port=0) as live:
            port = live.port
            assert not bindable(port)
        wait_until(lambda: bindable(port), 5, message=f"port {port} still held after close()")
