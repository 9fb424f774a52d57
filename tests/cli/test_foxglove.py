"""`asibot foxglove`: the running stack served live to Foxglove until Ctrl-C.

The command runs as a process against a real router, as a user starts it beside `asibot up`;
a WebSocket client speaking Foxglove's protocol must see a message published on the bus. What
is served, and how, is tests/recording/test_live_view.py's."""

import json
import os
import signal
import socket
import struct
import subprocess
import sys
import threading
import time

import pytest
from websockets.sync.client import connect
from websockets.typing import Subprotocol

from asibot import keys, messages as m
from asibot.bus import Bus
from asibot.cli import foxglove as foxglovecli
from asibot.cli.main import main as asibot
from asibot.recorder import live_view
from asibot.testing import free_port, wait_until

BASE = "cli-base"


def test_it_serves_the_bus_on_loopback_until_ctrl_c(router):
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "asibot.cli.main", "foxglove", "--port", str(port)],
                            env=dict(os.environ), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out: list[str] = []
    threading.Thread(target=lambda: out.extend(proc.stdout), daemon=True).start()
    try:
        wait_until(lambda: "serving the stack" in "".join(out), 30, interval=0.1,
                   message=lambda: f"never said it serves: {''.join(out)}")
        assert f"at ws://127.0.0.1:{port}:" in "".join(out)
        with Bus("stack") as stack, connect(f"ws://127.0.0.1:{port}", open_timeout=10,
                                            subprotocols=[Subprotocol("foxglove.sdk.v1")]) as ws:
            battery = stack.publisher(keys.base_battery(BASE), m.Battery)
            channels: dict[str, dict] = {}
            sub = None
            deadline = time.monotonic() + 30
            while True:
                assert time.monotonic() < deadline, f"no battery message; advertised: {sorted(channels)}"
                battery.put(m.Battery(volts=12.25))
                try:
                    frame = ws.recv(0.1)
                except TimeoutError:
                    continue
                if isinstance(frame, str):
                    op = json.loads(frame)
                    channels.update({c["topic"]: c for c in op.get("channels", [])})
                    if sub is None and keys.base_battery(BASE) in channels:
                        sub = channels[keys.base_battery(BASE)]["id"]
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": sub, "channelId": sub}]}))
                elif frame[0] == 1 and struct.unpack_from("<I", frame, 1)[0] == sub:
                    break
        assert channels[keys.base_battery(BASE)]["schemaName"] == "asibot.Battery"
        assert json.loads(frame[13:])["volts"] == 12.25
        proc.send_signal(signal.SIGINT)
        assert proc.wait(20) == 130           # Ctrl-C: the shell's 128 + SIGINT
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    time.sleep(0.1)                           # the reader takes the last lines
    err = proc.stderr.read()
    assert "stopped:" in "".join(out) and "Traceback" not in err, err
    assert "lets other machines" not in err   # loopback: nothing to warn about


def test_a_port_in_use_is_one_sentence(memory_bus, capsys):
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        assert asibot(["foxglove", "--port", str(port)]) == 1
    err = capsys.readouterr().err
    assert f"could not serve on 127.0.0.1:{port}" in err and "--port" in err


def test_a_bad_port_is_refused_by_the_parser():
    r = subprocess.run([sys.executable, "-m", "asibot.cli.main", "foxglove", "--port", "70000"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.splitlines()[-1].endswith("give a port from 1 to 65535 (0: any free one), not '70000'")


def test_the_command_line_defaults_are_the_live_views():
    """Spelled twice so that `asibot --help` does not load foxglove-sdk: they must agree."""
    assert (foxglovecli.DEFAULT_HOST, foxglovecli.DEFAULT_PORT) == (live_view.DEFAULT_HOST, live_view.DEFAULT_PORT)
    assert live_view.DEFAULT_HOST == "127.0.0.1"


@pytest.mark.parametrize("host, warned", [("127.0.0.1", False), ("::1", False), ("localhost", False),
                                          ("0.0.0.0", True), ("192.168.1.20", True)])
def test_an_address_other_machines_reach_is_warned_of(host, warned):
    assert foxglovecli._loopback(host) is not warned
