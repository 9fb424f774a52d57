"""CAN bus load and command-to-frame latency of the ASIBOT arm driver (100 Hz, 5 drives).

Runs a Zenoh router, the arm driver service and the five emulated drives in this process on a
python-can virtual bus with a sniffer, then prints one markdown table:
- frames per second and bus load at the control rate: computed from the configured traffic
  (SYNC, RPDO3, TPDO3 per cycle; heartbeats; TPDO1 event timer) with worst-case stuffing, and
  measured on the bus with each frame's exact stuffed length;
- command-to-frame latency: ArmCommand put on Zenoh -> the RPDO carrying it on the CAN bus;
- SYNC period jitter as seen on the bus.

    python bench/bench_arm_driver.py [--quick]
"""

from __future__ import annotations

import argparse
import logging
import random
import struct
import threading
import time
import uuid

import can
import numpy as np

from asibot import keys, testing
from asibot.safety import ownership
from asibot.arm_driver import config, emulator
from asibot.arm_driver.bitlength import exact_bits, worst_case_bits
from asibot.arm_driver.service import ArmDriverService
from asibot.bus import Bus
from asibot.messages import ArmCommand, ArmState

from table import QUICK_HELP, print_table  # bench/table.py: run as `python bench/<name>.py`


class Sniffer(can.Listener):
    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.frames: list[tuple[float, int, bytes]] = []
        self.lock = threading.Lock()
        self.notifier = can.Notifier(self.bus, [self], timeout=0.01)

    def on_message_received(self, msg: can.Message) -> None:
        if not msg.is_error_frame:
            with self.lock:
                self.frames.append((msg.timestamp, msg.arbitration_id, bytes(msg.data)))

    def take(self) -> list[tuple[float, int, bytes]]:
        with self.lock:
            out, self.frames = self.frames, []
        return out

    def close(self) -> None:
        self.notifier.stop()
        self.bus.shutdown()


def computed_traffic(cfg: config.ArmConfig) -> tuple[float, float]:
    """Frames/s and bits/s of the steady state the configuration asks for."""
    n, rate = len(cfg.joints), cfg.control_rate_hz
    rpdo3, tpdo3, tpdo1 = cfg.pdos["rpdo3"], cfg.pdos["tpdo3"], cfg.pdos["tpdo1"]
    flows = [  # (frames per second, data bytes)
        (rate, 0),                                   # SYNC
        (rate * n, rpdo3.size),                      # set-points
        (rate * n / tpdo3.transmission, tpdo3.size),  # feedback on SYNC
        (n * 1000.0 / cfg.heartbeat_ms, 1),          # heartbeats
    ]
    if tpdo1.event_timer_ms:
        flows.append((n * 1000.0 / tpdo1.event_timer_ms, tpdo1.size))
    return sum(f for f, _ in flows), sum(f * worst_case_bits(b) for f, b in flows)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=3.0, help="bus-load measuring window")
    ap.add_argument("--samples", type=int, default=200, help="latency samples")
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    args = ap.parse_args()
    if args.quick:
        args.seconds, args.samples = 0.3, 5
    logging.basicConfig(level=logging.WARNING)
    cfg = config.load("asibot")
    channel = f"bench-{uuid.uuid4().hex[:8]}"
    with testing.router() as endpoint:
        sniffer = Sniffer(channel)
        emu = emulator.DriveEmulator(can.Bus(interface="virtual", channel=channel), cfg.nodes,
                                     encoders=emulator.encoders_of(cfg))
        service_bus = Bus("arm_driver", endpoint, wait=5)
        service = ArmDriverService(service_bus, "asibot", f"virtual:{channel}")
        client = Bus("bench", endpoint, wait=5)
        states: list[ArmState] = []
        client.subscribe(keys.arm_state("asibot"), ArmState, states.append)
        cmd = client.publisher(keys.arm_command("asibot"), ArmCommand, express=True)
        controller = ownership.announce(client, "asibot", "arm", "bench")   # commands carry it
        try:
            testing.wait_until(lambda: states and states[-1].mode == "idle", 15, message="driver did not start")
            testing.wait_until(lambda: service.holder.current == controller.id, 5, message="driver did not see the bench")
            cmd.wait_for_subscribers(5)

            # Bus load while streaming a slow motion on every joint.
            controller.put(cmd, ArmCommand(mode="position", values=[0.5] * 5))
            time.sleep(0.3)
            sniffer.take()
            t0 = time.time()
            time.sleep(args.seconds)
            frames = sniffer.take()
            span = time.time() - t0
            fps_measured = len(frames) / span
            load_measured = sum(exact_bits(cob, data) for _, cob, data in frames) / span / cfg.bitrate * 100
            fps_computed, bits_computed = computed_traffic(cfg)
            syncs = np.diff([ts for ts, cob, _ in frames if cob == 0x080])
            sync_jitter = float(np.percentile(np.abs(syncs - cfg.period), 99)) * 1000

            # Command -> RPDO latency: step node 1 by one count-resolvable amount and find the
            # first RPDO3 carrying exactly the new target.
            units = cfg.joints[0].units
            here = units.to_counts(states[-1].positions[0])
            home = units.to_rad(here)
            controller.put(cmd, ArmCommand(mode="position", values=[home] + list(states[-1].positions[1:])))
            time.sleep(0.3)
            rest = list(states[-1].positions[1:])
            latencies = []
            for i in range(args.samples):
                goal = home + (0.001 if i % 2 == 0 else 0.0)
                want = units.to_counts(goal)
                sniffer.take()
                sent = time.time()
                controller.put(cmd, ArmCommand(mode="position", values=[goal] + rest))
                deadline = time.monotonic() + 0.5
                found = None
                while found is None and time.monotonic() < deadline:
                    time.sleep(0.002)
                    for ts, cob, data in sniffer.take():
                        if cob == 0x401 and struct.unpack("<i", data)[0] == want and ts >= sent:
                            found = ts
                            break
                if found is not None:
                    latencies.append(found - sent)
                time.sleep(random.uniform(0.01, 0.03))
        finally:
            client.close()
            service.close()
            service_bus.close()
            emu.close()
            sniffer.close()

    lat = np.asarray(latencies) * 1000
    period_ms = cfg.period * 1000
    rows = [
        ("CAN frames/s at 100 Hz, 5 drives (computed)", f"{fps_computed:.0f}", "frames/s", "-"),
        ("CAN frames/s at 100 Hz, 5 drives (measured, emulated bus)", f"{fps_measured:.0f}", "frames/s", "-"),
        ("bus load of 1 Mbit/s (computed, worst-case stuffing)", f"{bits_computed / cfg.bitrate * 100:.1f}", "%", "<= 25"),
        ("bus load of 1 Mbit/s (measured, exact stuffing)", f"{load_measured:.1f}", "%", "<= 25"),
        ("arm/command on Zenoh -> RPDO on CAN, p50", f"{np.percentile(lat, 50):.2f}", "ms",
         f"<= {period_ms:.0f} (one SYNC period)"),
        ("arm/command on Zenoh -> RPDO on CAN, p99", f"{np.percentile(lat, 99):.2f}", "ms",
         f"<= {period_ms + 1:.0f} (period + 1 ms)"),
        ("latency samples received / sent", f"{len(latencies)}/{args.samples}", "", "all"),
        ("SYNC period jitter p99 (frame time stamps on the bus)", f"{sync_jitter:.2f}", "ms", "<= 2"),
    ]
    print_table(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
