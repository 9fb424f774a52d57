"""Benchmark of the Cartesian control server: loop jitter, stat round trip, command path.

Two set-ups on a real Zenoh router, one markdown table:
- as deployed: the kinematics service (`python -m asibot.kinematics`) and an ideal driver each
  in their own process, the client and an observer of `arm/command` in this one;
- all in one process (server, driver, client), where the control loop's period is measured
  directly; every thread shares one GIL there, so its latencies are a pessimistic bound.

    python bench/bench_control.py [--quick]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import threading
import time

import numpy as np

from asibot import keys, robots, testing
from asibot.bus import Bus
from asibot.client import CartesianClient
from asibot.kinematics.model import solver_for
from asibot.messages import ArmCommand
from asibot.testing import IdealDriver

from table import QUICK_HELP, print_table  # bench/table.py: run as `python bench/<name>.py`

ROBOT = "asibot-sim"
START = np.radians([0, 30, 40, 30, 0])
DRIVER = f"""
import sys, numpy as np
from asibot import robots
from asibot.testing import IdealDriver
d = IdealDriver({ROBOT!r}, robots.get({ROBOT!r}))
d.set_joints(np.radians([0, 30, 40, 30, 0]))
print("READY", flush=True)
sys.stdin.read()
"""


RAW_SERVER = """
import sys, zenoh
from asibot.bus.zenoh_backend import client_config
s = zenoh.open(client_config(sys.argv[1]))
pub = s.declare_publisher("bench/raw/command", express=True)
def handle(query):
    pub.put(b"x" * 64)            # what a movv handler does: publish the reference, then reply
    query.reply(query.key_expr, b"{}", express=True)
    query.drop()
queryable = s.declare_queryable("bench/raw/movv", handle)
print("READY", flush=True)
sys.stdin.read()
"""


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q))


#: (stat round trips, movv commands, seconds of the movj whose loop periods are measured)
SAMPLES = (300, 150, 3.0)


def measure(client: CartesianClient, observer: Bus) -> tuple[list[float], list[float]]:
    """(stat round trips, client.movv -> first arm/command), in seconds."""
    rtt = []
    for _ in range(SAMPLES[0]):
        t0 = time.perf_counter()
        client.stat()
        rtt.append(time.perf_counter() - t0)
    arrived = threading.Event()
    got: list[float] = []
    observer.subscribe(keys.arm_command(ROBOT), ArmCommand,
                       lambda m: (got.append(time.perf_counter()), arrived.set()))
    time.sleep(0.3)
    path = []
    for _ in range(SAMPLES[1]):
        client.stop()
        time.sleep(0.03)
        arrived.clear()
        got.clear()
        t0 = time.perf_counter()
        client.movv([0.01, 0, 0, 0, 0])
        if arrived.wait(1.0):
            path.append(got[0] - t0)
    client.stop()
    return rtt, path


def deployed() -> tuple[list[float], list[float]]:
    env = dict(os.environ, ASIBOT_ROUTER=os.environ["ASIBOT_ROUTER"])
    driver = subprocess.Popen([sys.executable, "-c", DRIVER], env=env, stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    server = subprocess.Popen([sys.executable, "-m", "asibot.kinematics", "--robot", ROBOT], env=env)
    try:
        assert driver.stdout.readline().strip() == "READY"
        with CartesianClient(ROBOT, timeout=20) as client, Bus("bench-observer") as observer:
            testing.wait_until(lambda: client.state()["joints"][1] > 29, 20)
            return measure(client, observer)
    finally:
        for p in (server, driver):
            p.terminate()
            p.wait(10)


def raw_floor(endpoint: str) -> list[float]:
    """The same path in raw zenoh-python with nothing of ours: a query whose handler (a
    Zenoh callback, the fastest way in) publishes 64 bytes, received by a subscriber callback.
    It is the floor the command path sits on: two trips through the router and back."""
    import zenoh
    from asibot.bus.zenoh_backend import client_config

    server = subprocess.Popen([sys.executable, "-c", RAW_SERVER, endpoint], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    session = zenoh.open(client_config(endpoint))
    try:
        assert server.stdout.readline().strip() == "READY"
        arrived, got = threading.Event(), []
        sub = session.declare_subscriber("bench/raw/command",
                                         lambda sample: (got.append(time.perf_counter()), arrived.set()))
        time.sleep(0.3)
        path = []
        for _ in range(SAMPLES[1]):
            time.sleep(0.03)
            arrived.clear()
            got.clear()
            t0 = time.perf_counter()
            for _reply in session.get("bench/raw/movv", express=True, consolidation=zenoh.ConsolidationMode.NONE):
                pass
            if arrived.wait(1.0):
                path.append(got[0] - t0)
        sub.undeclare()
        return path
    finally:
        session.close()
        server.terminate()
        server.wait(10)


def in_process() -> tuple[dict, list[float], list[float]]:
    from asibot.kinematics.server import KinematicsServer
    spec = robots.get(ROBOT)
    driver = IdealDriver(ROBOT, spec)
    driver.set_joints(START)
    bus = Bus("kinematics")
    server = KinematicsServer(bus, ROBOT, solver_for(spec), spec, rate=100.0)
    testing.wait_until(lambda: server.ctl.q is not None and server.ctl.driver_alive, timeout=5)
    client, observer = CartesianClient(ROBOT), Bus("bench-observer")
    try:
        rtt, path = measure(client, observer)
        server.ticker._periods.clear()
        client.movj(joints=[10, 20, 30, 20, 10], duration=SAMPLES[2])
        client.wait(timeout=10)
        return server.ticker.stats(), rtt, path
    finally:
        client.close()
        server.close()
        for b in (observer, bus):
            b.close()
        driver.close()


def main() -> int:
    global SAMPLES
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    if ap.parse_args().quick:
        SAMPLES = (5, 5, 0.3)
    with testing.router() as endpoint:
        os.environ["ASIBOT_ROUTER"] = endpoint
        d_rtt, d_path = deployed()
        raw = raw_floor(endpoint)
        jitter, p_rtt, p_path = in_process()
    ms = 1e3
    rows = [
        (f"control loop period jitter p50 at 100 Hz ({jitter['n']} periods)", jitter["p50"] * ms, "ms", ""),
        ("control loop period jitter p99 at 100 Hz", jitter["p99"] * ms, "ms", "<= 2"),
    ]
    for where, rtt, path in (("separate processes", d_rtt, d_path), ("one process", p_rtt, p_path)):
        rows += [
            (f"RPC round trip `stat` p50, {where}", pct(rtt, 50) * ms, "ms", ""),
            (f"RPC round trip `stat` p99, {where}", pct(rtt, 99) * ms, "ms", ""),
            (f"command path client.movv -> arm/command p50, {where} ({len(path)} samples)",
             pct(path, 50) * ms, "ms", "<= 1"),
            (f"command path client.movv -> arm/command p99, {where}", pct(path, 99) * ms, "ms", "<= 5"),
        ]
    rows += [
        (f"raw zenoh-python floor of that path p50, separate processes ({len(raw)} samples)",
         pct(raw, 50) * ms, "ms", ""),
        ("raw zenoh-python floor of that path p99, separate processes", pct(raw, 99) * ms, "ms", ""),
        ("command path p50 over the raw floor, separate processes", pct(d_path, 50) / pct(raw, 50), "x", ""),
    ]
    print_table((what, f"{value:.3f}", unit, budget) for what, value, unit, budget in rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
