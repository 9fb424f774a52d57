"""Benchmark of the MuJoCo sim: prints one markdown table (what, value, unit, budget).

Real-time factor is read from the sim's own Health reports (simulated seconds elapsed over
producer-clock seconds elapsed, first to last report of the run) while the service runs as a real process with cameras at 10 Hz; CPU is
the process's user+system time over wall time (100 % = one core of the 2).

    python bench/bench_sim.py [--quick]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import threading
import time

os.environ.setdefault("MUJOCO_GL", "osmesa")

from asibot import keys, testing
from asibot import messages as m
from asibot.bus import Bus
from asibot.sim.cameras import Camera
from asibot.sim.simulation import Simulation

from table import QUICK_HELP, print_table  # bench/table.py: run as `python bench/<name>.py`

RUN_S = 12.0
WARM_UP_S = 2.0     # the cameras' first renders
#: physics steps timed (after a fifth as many to warm up), and renders timed per image
STEPS, RENDERS = 2500, 10
ROWS: list[tuple[str, str, str, str]] = []


def row(what: str, value: float, unit: str, budget: str, fmt: str = "{:.2f}") -> None:
    ROWS.append((what, fmt.format(value), unit, budget))


def step_time(robot: str) -> None:
    sim = Simulation(robot)
    sim.step(STEPS // 5)
    n = STEPS
    t = time.perf_counter()
    sim.step(n)
    us = (time.perf_counter() - t) / n * 1e6
    row(f"physics step, {sim.world} (2 ms step, controllers included)", us, "us", "<= 2000 (real time)", "{:.0f}")


def camera_times() -> None:
    sim = Simulation("pioneer-sim")
    for w, h in ((320, 240), (640, 480)):
        cam = Camera(sim.model, "front", w, h, sim.scene.base.body)
        for method in ("render", "ray"):
            cam.depth(sim.data, method)
            t = time.perf_counter()
            for _ in range(RENDERS):
                cam.depth(sim.data, method)
            row(f"depth image {w}x{h}, {'OSMesa render' if method == 'render' else 'mj_multiRay'}",
                (time.perf_counter() - t) / RENDERS * 1e3, "ms", "<= 100 (10 Hz)", "{:.1f}")
        cam.rgb_jpeg(sim.data)
        t = time.perf_counter()
        for _ in range(RENDERS):
            cam.rgb_jpeg(sim.data)
        row(f"RGB image {w}x{h}, render + JPEG", (time.perf_counter() - t) / RENDERS * 1e3, "ms", "<= 100 (10 Hz)",
            "{:.1f}")
        cam.close()


def cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def run_worlds(robots: list[str], fast: bool = False) -> dict[str, tuple[float, float]]:
    """Run the given robots' worlds at once; returns robot -> (RTF, CPU %)."""
    reports: dict[str, list[tuple[int, float]]] = {r: [] for r in robots}
    lock = threading.Lock()
    with testing.router():
        extra = ["--fast"] if fast else []
        procs = {r: subprocess.Popen([sys.executable, "-m", "asibot.sim", "--robot", r, "--log-level", "warning"]
                                     + extra) for r in robots}
        bus = Bus("bench-sim")

        def on_health(msg: m.Health) -> None:
            if msg.instance in reports and "sim_time" in msg.details:
                with lock:
                    reports[msg.instance].append((msg.stamp, float(msg.details["sim_time"])))

        bus.subscribe("health/sim/*", m.Health, on_health)
        deadline = time.monotonic() + 40
        while time.monotonic() < deadline and not all(bus.alive(keys.driver_alive(r)) for r in robots):
            time.sleep(0.2)
        time.sleep(WARM_UP_S)
        with lock:
            for r in robots:
                reports[r].clear()
        cpu0 = {r: cpu_seconds(p.pid) for r, p in procs.items()}
        t0 = time.monotonic()
        time.sleep(RUN_S)
        wall = time.monotonic() - t0
        out = {}
        for r, p in procs.items():
            cpu = (cpu_seconds(p.pid) - cpu0[r]) / wall * 100
            with lock:
                rep = reports[r]
                rtf = ((rep[-1][1] - rep[0][1]) / ((rep[-1][0] - rep[0][0]) / 1e9)
                       if len(rep) >= 2 else float("nan"))
            out[r] = (rtf, cpu)
        for p in procs.values():
            p.terminate()
        for p in procs.values():
            p.wait(timeout=10)
        bus.close()
    return out


def main() -> int:
    global RUN_S, WARM_UP_S, STEPS, RENDERS
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    if ap.parse_args().quick:
        # Health comes every 2 s and the RTF needs two reports: shorter runs print nan for it.
        RUN_S, WARM_UP_S, STEPS, RENDERS = 0.5, 0.0, 50, 1
    step_time("asibot-sim")
    step_time("pioneer-sim")
    camera_times()
    for robot in ("asibot-sim", "pioneer-sim"):
        rtf, cpu = run_worlds([robot])[robot]
        row(f"real-time factor, {robot} alone, cameras 10 Hz", rtf, "x", ">= 1", "{:.3f}")
        row(f"CPU, {robot} alone", cpu, "% of a core", "-", "{:.0f}")
    both = run_worlds(["asibot-sim", "pioneer-sim"])
    for robot, (rtf, cpu) in both.items():
        row(f"real-time factor, {robot}, both worlds at once", rtf, "x", ">= 1", "{:.3f}")
        row(f"CPU, {robot}, both worlds at once", cpu, "% of a core", "-", "{:.0f}")
    for robot, (rtf, cpu) in run_worlds(["asibot-sim", "pioneer-sim"], fast=True).items():
        row(f"headroom: real-time factor with --fast, {robot}, both at once", rtf, "x", "> 1")
    print_table(ROWS)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
