"""AsTeRICS bridge benchmark: the bridge on the in-memory bus, clients on loopback sockets, a
double of nav that publishes a Twist on `base_cmd_vel` when asked for a primitive (as nav's loop
would, minus its control cycle: nav's own delay is bench_nav's).

Rows (each beside a reference measured in the same run):
- a NetConnection "forward" frame in to the Twist out, p50/p99, beside the same primitive asked
  by a plain bus RPC call;
- a user Event on the bus to its string frame at a NetConnection client, p50/p99, beside the
  same Event to a plain bus subscriber;
- sustained commands per second ("faster", one nav RPC each) with 50 NetConnection clients
  sending 8 at a time each (the clients run in this process too, on the same two cores).

    python bench/bench_asterics.py [--quick]
"""

from __future__ import annotations

import argparse
import socket
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT / "tests"))

from table import QUICK_HELP, print_table  # noqa: E402

from asibot import keys  # noqa: E402
from asibot import messages as m  # noqa: E402
from asibot.bus import Bus  # noqa: E402

from asibot.asterics_bridge import netconnection as nc  # noqa: E402
from asibot.asterics_bridge.dispatcher import Dispatcher  # noqa: E402
from asibot.asterics_bridge.servers import Limits, Servers  # noqa: E402
from asterics_bridge.fakes import FakeNav  # noqa: E402  (tests/asterics_bridge: the nav double)

ROBOT = "pioneer-sim"


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) * 1000 if values else float("nan")


class FrameReader:
    """A blocking NetConnection client: send a frame, read until a frame on a port arrives."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port))
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.decoder = nc.Decoder()
        self.ports: list[int] = []       # ports of the string frames read and not consumed yet

    def until(self, port: int, count: int = 1) -> None:
        """Read until `count` string frames on `port` came (frames on other ports are dropped)."""
        while True:
            while self.ports and count:
                count -= self.ports.pop(0) == port
            if not count:
                return
            data = self.sock.recv(65536)
            if not data:
                raise ConnectionError("the bridge closed the connection")
            self.ports += [f.port for f in self.decoder.feed(data) if isinstance(f, nc.Frame) and f.kind == nc.STRING]

    def close(self) -> None:
        self.sock.close()


def command_to_cmd_vel(bus: Bus, port: int, n: int) -> tuple[list[float], list[float]]:
    twist = threading.Event()
    bus.subscribe(keys.base_cmd_vel(ROBOT), m.Twist, lambda t: twist.set() if t.vx else None)
    client = FrameReader(port)
    forward, stop = nc.encode_string(1, "forward"), nc.encode_string(1, "stop")
    via_bridge, via_rpc = [], []
    for i in range(n + 5):
        twist.clear()
        t0 = time.perf_counter()
        client.sock.sendall(forward)
        twist.wait(5)
        if i >= 5:
            via_bridge.append(time.perf_counter() - t0)
        client.until(2)                                       # the answer to forward
        client.sock.sendall(stop)
        client.until(2)
        twist.clear()
        t0 = time.perf_counter()
        bus.call(keys.nav_rpc(ROBOT, "primitive"), {"name": "forward", "continuous": True}, timeout=5)
        twist.wait(5)
        if i >= 5:
            via_rpc.append(time.perf_counter() - t0)
        bus.call(keys.nav_rpc(ROBOT, "primitive"), {"name": "stop"}, timeout=5)
    client.close()
    return via_bridge, via_rpc


def event_to_frame(bus: Bus, port: int, n: int) -> tuple[list[float], list[float]]:
    client = FrameReader(port)
    client.sock.sendall(nc.encode_string(1, "status"))       # announced: the bridge knows its robot
    client.until(2)
    events = bus.publisher(keys.events(ROBOT), m.Event)
    heard = threading.Event()
    listener = Bus("listener", bus.endpoint)
    listener.subscribe(keys.events(ROBOT), m.Event, lambda e: heard.set())
    to_frame, to_subscriber = [], []
    event = m.Event(level="info", code="goal_succeeded", text="Arrived at fridge")
    for i in range(n + 5):
        heard.clear()
        t0 = time.perf_counter()
        events.put(event)
        heard.wait(5)
        t1 = time.perf_counter()
        client.until(1)
        t2 = time.perf_counter()
        client.until(3)
        if i >= 5:
            to_subscriber.append(t1 - t0)
            to_frame.append(t2 - t0)
    client.close()
    listener.close()
    return to_frame, to_subscriber


def sustained(port: int, clients: int, seconds: float, burst: int = 8) -> float:
    done = [0] * clients
    stop = threading.Event()
    frames = nc.encode_string(1, "faster") * burst

    def run(i: int) -> None:
        c = FrameReader(port)
        while not stop.is_set():
            c.sock.sendall(frames)
            c.until(2, burst)
            done[i] += burst
        c.close()

    threads = [threading.Thread(target=run, args=(i,)) for i in range(clients)]
    for t in threads:
        t.start()
    time.sleep(0.5)                                           # all connected and running
    start, before = time.perf_counter(), sum(done)
    time.sleep(seconds)
    count, elapsed = sum(done) - before, time.perf_counter() - start
    stop.set()
    for t in threads:
        t.join()
    return count / elapsed


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    quick = ap.parse_args().quick
    n, seconds = (5, 0.5) if quick else (1000, 10.0)
    endpoint = "mem://bench-asterics"
    bus, svc_bus = Bus("bench", endpoint), Bus("asterics_bridge", endpoint)
    FakeNav(bus, ROBOT)
    dispatcher = Dispatcher(svc_bus, ROBOT)
    servers = Servers(dispatcher, tcp_port=0, http_port=None, limits=Limits(per_address=Limits.max_clients)).start()
    try:
        bridge, rpc = command_to_cmd_vel(bus, servers.tcp_port, n)
        frame, sub = event_to_frame(bus, servers.tcp_port, n)
        rate = sustained(servers.tcp_port, 50, seconds)
    finally:
        servers.close()
        dispatcher.close()
        svc_bus.close()
        bus.close()
    rows = [
        ("NetConnection 'forward' frame in -> Twist on cmd_vel, p50", pct(bridge, 50), "ms", "5"),
        ("NetConnection 'forward' frame in -> Twist on cmd_vel, p99", pct(bridge, 99), "ms", "20"),
        ("reference: bus RPC primitive -> Twist on cmd_vel, p50", pct(rpc, 50), "ms", "-"),
        ("reference: bus RPC primitive -> Twist on cmd_vel, p99", pct(rpc, 99), "ms", "-"),
        ("user Event on the bus -> port-1 string frame at the client, p50", pct(frame, 50), "ms", "5"),
        ("user Event on the bus -> port-1 string frame at the client, p99", pct(frame, 99), "ms", "20"),
        ("reference: user Event -> a plain bus subscriber, p50", pct(sub, 50), "ms", "-"),
        ("reference: user Event -> a plain bus subscriber, p99", pct(sub, 99), "ms", "-"),
        ("sustained commands with 50 NetConnection clients (8 in flight each)", rate, "commands/s", "500"),
    ]
    print_table(rows)


if __name__ == "__main__":
    main()
