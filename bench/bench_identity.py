"""What signed commands cost (asibot.safety.identity), beside unsigned ones measured in the same run.

A controller signs every ArmCommand it sends and the driver checks the signature and the
sequence number before it obeys (`Controller.put`, `Holder.refusal`). Measured here: the CPU
time of each side per command, and the time from a controller's put to the end of the
driver's check over the in-memory bus, signed and (the reference, the check before issue 25:
the sender's id compared with the holder's) unsigned, alternately. The kinematics service
streams 100 commands a second, so "share of a core at 100 Hz" is what it costs a running arm.

    python bench/bench_identity.py [--quick]
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from table import QUICK_HELP, print_table, times  # noqa: E402

from asibot import keys  # noqa: E402
from asibot.safety import ownership  # noqa: E402
from asibot.bus import Bus  # noqa: E402
from asibot.messages import ArmCommand  # noqa: E402
from asibot.testing import memory_bus, wait_until  # noqa: E402

ROBOT = "bench-arm"
VALUES = [0.1, 0.2, 0.3, 0.4, 0.5]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help=QUICK_HELP)
    args = parser.parse_args()
    runs = 5 if args.quick else 2000
    me = ownership.Controller(ROBOT, "arm", "bench")
    holder = ownership.Holder(ROBOT, "arm")
    holder.update(keys.controller_alive(ROBOT, me.id), True)
    plain = ArmCommand(mode="position", values=VALUES, controller=me.id)

    sign = times(lambda: me.sign(ArmCommand(mode="position", values=VALUES)), runs)
    build = times(lambda: ArmCommand(mode="position", values=VALUES, controller=me.id), runs)
    signed = [me.sign(ArmCommand(mode="position", values=VALUES)) for _ in range(runs + 1)]
    it = iter(signed)
    check = times(lambda: holder.refusal(next(it)), runs)
    compare = times(lambda: plain.controller == holder.current, runs)

    # Over the bus: put -> the driver's check done, signed and unsigned taking turns.
    with memory_bus("bench-identity"):
        sender, driver = Bus("controller"), Bus("driver")
        done = threading.Event()
        refused: list[object] = []

        def on_signed(cmd: ArmCommand) -> None:
            why = holder.refusal(cmd)
            if why is not None:
                refused.append(why)
            done.set()

        def on_plain(cmd: ArmCommand) -> None:
            if cmd.controller != holder.current:
                refused.append(cmd)
            done.set()

        driver.subscribe(keys.arm_command(ROBOT), ArmCommand, on_signed)
        driver.subscribe(keys.arm_command("bench-plain"), ArmCommand, on_plain)
        pub_signed = sender.publisher(keys.arm_command(ROBOT), ArmCommand)
        pub_plain = sender.publisher(keys.arm_command("bench-plain"), ArmCommand)
        wait_until(lambda: pub_signed.wait_for_subscribers(1) and pub_plain.wait_for_subscribers(1), 5)
        trips = {"signed": [], "plain": []}
        for i in range(runs):
            for kind in ("signed", "plain"):
                done.clear()
                start = time.perf_counter()
                if kind == "signed":
                    me.put(pub_signed, ArmCommand(mode="position", values=VALUES))
                else:
                    pub_plain.put(ArmCommand(mode="position", values=VALUES, controller=me.id))
                done.wait(5)
                trips[kind].append(time.perf_counter() - start)
        sender.close()
        driver.close()
    if refused:
        raise SystemExit(f"{len(refused)} commands were refused: {refused[0]}")

    def us(t) -> float:
        return float(np.median(t)) * 1e6

    def pct(t, q) -> float:
        return float(np.percentile(t, q)) * 1e6

    rows = [
        ("controller: make a command (median)", us(sign), us(build), "us"),
        ("driver: check it (median)", us(check), us(compare), "us"),
        ("both sides, share of a core at 100 Hz", (us(sign) + us(check)) * 100 / 1e4,
         (us(build) + us(compare)) * 100 / 1e4, "%"),
        ("put -> checked, p50", pct(trips["signed"], 50), pct(trips["plain"], 50), "us"),
        ("put -> checked, p99", pct(trips["signed"], 99), pct(trips["plain"], 99), "us"),
    ]
    print(f"{runs} commands each, ArmCommand of 5 joints, Ed25519 (libsodium), in-memory bus")
    print_table(rows, header=("what", "signed", "unsigned (reference)", "unit"))


if __name__ == "__main__":
    main()
