"""Regenerate the replay fixture recordings/fixtures/nav_drive.mcap.

Drives the simulated Pioneer as a user would (`asibot up` with the apartment, perception, nav
and the recorder; `NavClient` primitives: forward 1 m, turn left 90 degrees and back, forward 0.5 m)
and keeps what the replay tests recompute from and compare with: the depth cameras (images and
their CameraInfo), the sonar, the odometry, perception's scans, nav's poses and the sim's
ground truth. Run it after a deliberate change to the apartment, perception or nav, and
commit the result:

    .venv/bin/python tests/replay/record_nav.py
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

from asibot import keys
from asibot.client import NavClient
from asibot.recorder.reader import iter_messages
from asibot.testing import Stack, wait_until

from fixture import write_fixture   # tests/replay/fixture.py, beside this script

ROOT = Path(__file__).resolve().parents[2]
ROBOT = "pioneer-sim"
FIXTURE = ROOT / "recordings" / "fixtures" / "nav_drive.mcap"
CAMERAS = ("front", "back")
KEEP = (keys.base_odom(ROBOT), keys.base_sonar(ROBOT), keys.scan(ROBOT), keys.nav_pose(ROBOT),
        keys.sim_truth(ROBOT), keys.base_cmd_vel(ROBOT),
        *(keys.camera_depth(ROBOT, c) for c in CAMERAS), *(keys.camera_info(ROBOT, c) for c in CAMERAS))


def main() -> int:
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    with tempfile.TemporaryDirectory() as folder:
        stack = Stack(Path(folder), "sim", ["recorder", "nav-pioneer-sim"], ROOT / "compose.yaml")
        os.environ["ASIBOT_ROUTER"] = stack.endpoint
        try:
            stack.wait_alive("recorder/main", "nav/pioneer-sim", timeout=120)
            with NavClient(ROBOT, timeout=10) as base:
                wait_until(lambda: base.status()["localised"], 30, interval=0.2)
                started = stack.bus.call(keys.nav_rpc(ROBOT, "status"), timeout=5)["pose"]
                print("start", started, flush=True)
                for step in (lambda: base.drive(1.0), lambda: base.primitive("turn left 90"),
                             lambda: base.primitive("turn right 90"), lambda: base.drive(0.5)):
                    step()
                    print(base.wait(timeout=60)["text"], flush=True)
        finally:
            stack.stop()
        [session] = (Path(folder) / "recordings").glob("*.mcap")
        # from the first command to the robot standing still again, plus a second either side
        records = [r for r in iter_messages(session) if r.key in KEEP]
        moving = [r.log_time for r in records if r.key == keys.base_cmd_vel(ROBOT)]
        first, last = moving[0] - 1_000_000_000, moving[-1] + 1_000_000_000
        write_fixture(FIXTURE, "asibot replay fixture: the Pioneer driving in the apartment",
                      (r for r in records if first <= r.log_time <= last))
    print(f"wrote {FIXTURE} ({FIXTURE.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
