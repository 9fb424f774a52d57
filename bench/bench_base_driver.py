"""Benchmark of the Pioneer base driver against the in-process ARCOS emulator over loopback TCP.

Prints one markdown table: ARCOS command round trip (VEL sent -> the next SIP shows the
robot reacting; bounded by the 100 ms SIP cycle, docs/arcos.md "SIP"), SIP parse time, and the
latency from a cmd_vel published on Zenoh to its VEL bytes arriving on the serial line.

    python bench/bench_base_driver.py [--quick]
"""

from __future__ import annotations

import argparse
import random
import statistics
import sys
import time
import timeit

from asibot import keys, testing
from asibot.safety import ownership
from asibot.bus import Bus
from asibot.messages import Twist

from asibot.base_driver.arcos import ArcosClient
from asibot.base_driver.codec import Cmd
from asibot.base_driver.emulator import ArcosEmulator
from asibot.base_driver.link import open_link
from asibot.base_driver.params import P3AT_SH
from asibot.base_driver.service import BaseDriverService
from asibot.base_driver.sip import Sip, encode_sip, parse_sip
from asibot.base_driver.state import StateTracker

from table import QUICK_HELP, print_table  # bench/table.py: run as `python bench/<name>.py`


def pct(values: list[float], q: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, int(round(q / 100 * (len(s) - 1))))]


def round_trip(samples: int = 40) -> list[float]:
    """ms from writing VEL to the first SIP showing the wheels react.

    The robot is at rest at 0 or 200 mm/s before each command (so no stale SIP can match),
    and the command, sent at a random phase of the SIP cycle, switches to the other value.
    """
    out = []
    with ArcosEmulator() as emu:
        client = ArcosClient(open_link(emu.url))
        client.connect()

        def settle(v: int) -> None:
            steady = 0
            while steady < 2:                # two SIPs in a row at the setpoint
                for p in client.read_payloads():
                    if p[0] in (0x32, 0x33):
                        s = parse_sip(p)
                        steady = steady + 1 if (s.left_vel + s.right_vel) / 2 == v else 0

        try:
            current = 0
            settle(current)
            for _ in range(samples):
                target = 200 - current
                time.sleep(random.uniform(0.0, 0.1))     # a random phase in the 100 ms SIP cycle
                t0 = time.perf_counter()
                client.set_velocity(target, 0)
                done = False
                while not done:
                    for p in client.read_payloads():
                        if p[0] in (0x32, 0x33):
                            s = parse_sip(p)
                            if (s.left_vel + s.right_vel) / 2 != current:
                                out.append((time.perf_counter() - t0) * 1000)
                                done = True
                                break
                current = target
                settle(current)
        finally:
            client.close()
    return out


def parse_time(n: int = 20000) -> tuple[float, float]:
    """us per parse_sip and per parse + conversion to SI, for a full SIP (16 sonars + tail)."""
    payload = encode_sip(Sip(moving=True, xpos=1234, ypos=32000, thpos=512, left_vel=300, right_vel=320,
                             battery=128, sonars={i: 1000 + i for i in range(16)},
                             battery_x10=128, rot_vel_x10=40))
    t_parse = timeit.timeit(lambda: parse_sip(payload), number=n) / n * 1e6
    tracker = StateTracker(P3AT_SH)
    t_full = timeit.timeit(lambda: tracker.update(parse_sip(payload)), number=n) / n * 1e6
    return t_parse, t_full


def cmd_vel_latency(samples: int = 200) -> list[float]:
    """ms from Publisher.put(Twist) to the VEL packet read by the emulator."""
    with testing.router():
        with ArcosEmulator() as emu:
            svc_bus = Bus("base_driver")
            svc = BaseDriverService(svc_bus, "pioneer", emu.url)
            user = Bus("bench")
            try:
                controller = ownership.announce(user, "pioneer", "base", "bench")   # cmd_vel carries it
                testing.wait_until(lambda: svc.driver.connected and svc.holder.current == controller.id, 10)
                pub = user.publisher(keys.base_cmd_vel("pioneer"), Twist, express=True)
                controller.put(pub, Twist(vx=0.0, wz=0.0))
                time.sleep(0.5)
                out = []
                for i in range(samples):
                    mm = 101 + (i % 2)           # alternate so every command changes the setpoint
                    with emu.lock:
                        start = len(emu.robot.received)
                    t0 = time.monotonic()
                    controller.put(pub, Twist(vx=mm / 1000.0, wz=0.0))
                    deadline = t0 + 0.5
                    while time.monotonic() < deadline:
                        with emu.lock:
                            hit = [t for t, c, a in emu.robot.received[start:] if c == Cmd.VEL and a == mm]
                        if hit:
                            out.append((hit[0] - t0) * 1000)
                            break
                        time.sleep(0.002)     # the emulator stamps arrival; polling slowly spares the GIL
                    time.sleep(0.01)
                controller.put(pub, Twist(vx=0.0, wz=0.0))
            finally:
                user.close()
                svc.close()
                svc_bus.close()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    quick = ap.parse_args().quick
    rt = round_trip(3 if quick else 40)
    t_parse, t_full = parse_time(100 if quick else 20000)
    lat = cmd_vel_latency(5 if quick else 200)
    rows = [
        ("ARCOS command round trip p50 (VEL -> next SIP reflects it)", f"{statistics.median(rt):.1f}", "ms", "<= 100 (one SIP cycle; 50 expected)"),
        ("ARCOS command round trip p99", f"{pct(rt, 99):.1f}", "ms", "<= 110 (one 100 ms SIP cycle + 10)"),
        ("SIP parse (16 sonars + tail)", f"{t_parse:.1f}", "us", "<= 100"),
        ("SIP parse + conversion to SI", f"{t_full:.1f}", "us", "<= 200"),
        ("cmd_vel (Zenoh) -> VEL bytes on the line p50", f"{statistics.median(lat):.2f}", "ms", "<= 1"),
        ("cmd_vel (Zenoh) -> VEL bytes on the line p99", f"{pct(lat, 99):.2f}", "ms", "<= 5"),
        ("samples (round trip / cmd_vel)", f"{len(rt)} / {len(lat)}", "count", "-"),
    ]
    print_table(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
