"""SYNC and set-points of the ASIBOT arm driver: SYNC's period jitter and the largest set-point
step a drive applied per SYNC, for the three ways the master sends them, idle and with both
cores loaded, in one run.

Runs the arm driver (no Zenoh) and the five emulated drives in this process on a python-can
virtual bus with a sniffer, drives every joint back and forth at full speed, and measures on
the bus (each frame's time stamp) the SYNC period's deviation from 10 ms, p50 and p99, its
longest gap and the longest gap during a reset_fault of one tripped drive; and in the drives
(each SYNC's applied step, emulator.EmulatedDrive.steps) the largest step as a share of the
joint's max speed times the period: above 1, a real drive in cyclic synchronous position
jerks faster than the arm was planned for.
- "loop": the control loop sends every frame (before issue 29);
- "periodic": the interface's periodic sender repeats SYNC and each set-point apart (issue 29
  to 53): a late control period leaves a SYNC without a new set-point and the next with two;
- "synced": one clock sends each SYNC after one sample of set-points (since issue 53).
On a virtual bus the periodic sender is python-can's sender thread; SocketCAN's is the kernel's
broadcast manager, measured on a vcan interface when the machine has one (`--vcan vcan0`;
this bench does not create interfaces).

    python bench/bench_sync.py [--seconds 5] [--vcan vcan0] [--quick]
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import sys
import threading
import time
import uuid

import can
import numpy as np

from asibot.arm_driver import config, emulator
from asibot.arm_driver.driver import ArmDriver
from asibot.arm_driver.master import CanopenMaster
from asibot.testing import busy_cores, wait_until

from table import QUICK_HELP, print_table  # bench/table.py: run as `python bench/<name>.py`


class Sniffer(can.Listener):
    """SYNC time stamps as the bus carries them."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus
        self.syncs: list[float] = []
        self.lock = threading.Lock()
        self.notifier = can.Notifier(self.bus, [self], timeout=0.01)

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id == 0x080 and not msg.is_error_frame:
            with self.lock:
                self.syncs.append(msg.timestamp)

    def take(self) -> list[float]:
        with self.lock:
            out, self.syncs = self.syncs, []
        return out

    def close(self) -> None:
        self.notifier.stop()
        self.bus.shutdown()


def buses(kind: str, channel: str) -> tuple[can.BusABC, can.BusABC, can.BusABC]:
    """(the drives', the master's, the sniffer's) on one virtual channel or vcan interface."""
    if kind == "virtual":
        return tuple(can.Bus(interface="virtual", channel=channel) for _ in range(3))  # type: ignore[return-value]
    return tuple(can.Bus(interface="socketcan", channel=channel) for _ in range(3))  # type: ignore[return-value]


def measure(cfg: config.ArmConfig, kind: str, channel: str, sync: str, seconds: float) -> dict[str, float]:
    drives_bus, master_bus, sniffer_bus = buses(kind, channel)
    sniffer = Sniffer(sniffer_bus)
    emu = emulator.DriveEmulator(drives_bus, cfg.nodes, encoders=emulator.encoders_of(cfg))
    if sync == "loop":
        # Before issue 29 the drives watched no heartbeat; a loop-sent heartbeat starves during
        # reset_fault and the drives would stop by themselves (the reason it is not sent so).
        cfg = dataclasses.replace(cfg, drive_consumer_ms=60000)
    states: list = []
    driver = ArmDriver(CanopenMaster(master_bus, cfg, sync=sync), cfg, states.append, lambda *e: None)
    try:
        driver.start()
        wait_until(lambda: states and states[-1].mode == "idle", 15, message=lambda: f"driver not up: {driver.fault}")
        time.sleep(0.2)
        sniffer.take()
        for drive in emu.drives.values():
            drive.steps.clear()
        until = time.monotonic() + seconds
        goals = ([0.3, 0.3, -0.3, 0.3, 0.3], [0.0] * 5)
        while time.monotonic() < until:                       # back and forth at full speed
            goal = goals[0]
            driver.command("position", goal)
            while time.monotonic() < until and max(abs(a - b) for a, b in zip(states[-1].positions, goal)) > 1e-3:
                time.sleep(0.01)
            goals = goals[::-1]
        syncs = np.asarray(sniffer.take())
        dev = np.abs(np.diff(syncs) - cfg.period) * 1000
        step = max(max((abs(s) for s in emu.drives[j.node].steps), default=0)
                   / abs(j.units.to_counts(j.max_velocity * cfg.period)) for j in cfg.joints)
        # One drive trips and is reset: the longest time without SYNC meanwhile.
        emu.over_current(3)
        wait_until(lambda: states[-1].mode == "fault", 5)
        time.sleep(0.1)
        sniffer.take()
        start = time.time()
        driver.reset_fault()
        end = time.time()
        time.sleep(2 * cfg.period)
        during = [start, *[t for t in sniffer.take() if start <= t <= end], end]
        return {"p50": float(np.percentile(dev, 50)), "p99": float(np.percentile(dev, 99)),
                "gap": float(np.max(np.diff(syncs))) * 1000, "reset_gap": float(np.max(np.diff(during))) * 1000,
                "reset_s": end - start, "step": step}
    finally:
        driver.close()
        emu.close()
        sniffer.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=5.0, help="measuring window per row")
    ap.add_argument("--vcan", default="", help="also measure on this existing vcan interface (SocketCAN BCM)")
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    args = ap.parse_args()
    if args.quick:
        args.seconds = 0.3
    logging.basicConfig(level=logging.CRITICAL)       # the tripped drive's fault is the bench's own
    cfg = config.load("asibot")
    cores = os.cpu_count() or 2
    targets = [("virtual", f"bench-sync-{uuid.uuid4().hex[:8]}")]
    if args.vcan:
        targets.append(("socketcan", args.vcan))
    rows = []
    for kind, channel in targets:
        for load in ((0,) if args.quick else (0, cores)):     # the smoke run loads no cores
            for sync, label in (("loop", "control loop (before 29)"), ("periodic", "periodic sender (29 to 53)"),
                                ("synced", "one clock, a sample a SYNC (now)")):
                with busy_cores(load):
                    r = measure(cfg, kind, channel, sync, args.seconds)
                bus = "virtual bus" if kind == "virtual" else f"vcan {channel} (BCM)" if sync == "periodic" else f"vcan {channel}"
                rows.append((f"{label}, {bus}", "idle" if not load else f"{load} cores loaded",
                             f"{r['p50']:.2f}", f"{r['p99']:.2f}", f"{r['gap']:.1f}",
                             f"{r['reset_gap']:.0f} of {r['reset_s'] * 1000:.0f}", f"{r['step']:.2f}"))
    if not args.vcan:
        have = sorted(n for n in os.listdir("/sys/class/net") if n.startswith("vcan")) if os.path.isdir("/sys/class/net") else []
        rows.append(("SocketCAN BCM on vcan", f"not measured: {'run with --vcan ' + have[0] if have else 'no vcan interface here'}",
                     "-", "-", "-", "-", "-"))
    print_table(rows, header=("SYNC source", "machine", "|period - 10 ms| p50 (ms)", "p99 (ms)",
                              "longest period (ms)", "longest gap during reset_fault (ms) of its duration",
                              "largest step / (max speed x period)"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
