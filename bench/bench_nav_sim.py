"""Navigation in the simulated apartment: how long a trip to each named place takes and how far
the robot drives, judged by the simulator's ground truth.

`asibot up` with the apartment, perception and nav (as a user starts it); from the charging
station the robot is sent to each place in turn with `NavClient.goto` and `wait`. Each row
is beside two references measured in the same run: the straight-line distance between the
places, and the length of the way nav planned (its first NavPath), so a detour or a
hesitation shows as the driven length over the planned one.

    python bench/bench_nav_sim.py [--places fridge desk ...] [--quick]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from table import QUICK_HELP, print_table  # noqa: E402

from asibot import keys  # noqa: E402
from asibot import messages as m  # noqa: E402
from asibot.client import NavClient  # noqa: E402
from asibot.testing import Stack, wait_until  # noqa: E402

ROBOT = "pioneer-sim"
TRIP = ("fridge", "desk", "shelf", "charging station")
#: The robot starts 0.25 m from the charging station, facing away: the shortest whole trip there is
#: (plan, drive, turn, arrive), for the smoke run.
QUICK_TRIP = ("charging station",)


class Trace:
    """The sim's ground truth and nav's planned paths, as they come."""

    def __init__(self, bus) -> None:
        self.lock = threading.Lock()
        self.truth: list[tuple[float, float]] = []
        self.paths: dict[int, float] = {}
        bus.subscribe(keys.sim_truth(ROBOT), m.Pose2D, self._truth)
        bus.subscribe(keys.nav_path(ROBOT), m.NavPath, self._path)

    def _truth(self, p: m.Pose2D) -> None:
        with self.lock:
            self.truth.append((p.x, p.y))

    def _path(self, p: m.NavPath) -> None:
        with self.lock:
            if p.length > 0:
                self.paths.setdefault(p.goal_id, p.length)

    def driven(self, since: int) -> float:
        with self.lock:
            pts = self.truth[since:]
        return sum(math.dist(a, b) for a, b in zip(pts, pts[1:]))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--places", nargs="+", help=f"the places to visit, in order (default: {', '.join(TRIP)})")
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    args = ap.parse_args()
    args.places = args.places or list(QUICK_TRIP if args.quick else TRIP)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        stack = Stack(Path(folder), "sim", ["nav-pioneer-sim"], ROOT / "compose.yaml")
        os.environ["ASIBOT_ROUTER"] = stack.endpoint
        try:
            stack.wait_alive("nav/pioneer-sim", timeout=120)
            trace = Trace(stack.bus)
            base = NavClient(ROBOT, timeout=10)
            wait_until(lambda: base.status()["localised"], 30, interval=0.2)
            places = base.places()
            here = base.pose()
            for name in args.places:
                goal = places[name]
                mark = len(trace.truth)
                t0 = time.monotonic()
                gid = base.goto(name)
                try:
                    result = base.wait(gid, timeout=240)
                    outcome = "arrived"
                except Exception as exc:   # a bench reports a failed trip, it does not stop
                    result, outcome = {"recoveries": "?"}, f"failed: {exc}"
                took = time.monotonic() - t0
                straight = math.dist(here[:2], goal[:2])
                planned = trace.paths.get(gid, float("nan"))
                driven = trace.driven(mark)
                rows += [(f"to {name}: time ({outcome}, {result.get('recoveries', 0)} recoveries)", took, "s", "-"),
                         (f"to {name}: driven (ground truth)", driven, "m", "-"),
                         (f"reference: to {name}, planned path", planned, "m", "-"),
                         (f"reference: to {name}, straight line", straight, "m", "-")]
                here = base.pose()
            base.close()
        finally:
            stack.stop()
    print_table(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
