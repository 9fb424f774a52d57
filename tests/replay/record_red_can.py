"""Regenerate the replay fixture recordings/fixtures/red_can.mcap.

Runs "Give me the red can" against the simulated kitchen as a user would (`asibot up`, the
example program), then keeps the ASIBOT's arm and gripper topics of the session's recording.
Run it after a deliberate change to the kitchen or the controller, and commit the result:

    .venv/bin/python tests/replay/record_red_can.py
"""

from __future__ import annotations

import argparse
import importlib.util
import tempfile
from pathlib import Path

from asibot import keys
from asibot.recorder.reader import iter_messages

from fixture import write_fixture   # tests/replay/fixture.py, beside this script

ROOT = Path(__file__).resolve().parents[2]
E2E = ROOT / "tests" / "e2e" / "conftest.py"  # the end-to-end tests' `asibot up`: Stack, EXAMPLES
ROBOT = "asibot-sim"
FIXTURE = ROOT / "recordings" / "fixtures" / "red_can.mcap"
KEEP = (keys.arm_state(ROBOT), keys.arm_command(ROBOT), keys.cart_state(ROBOT),
        keys.gripper_state(ROBOT), keys.gripper_command(ROBOT))


def e2e():
    """The end-to-end tests' conftest, loaded from its file (it is no importable module)."""
    spec = importlib.util.spec_from_file_location("e2e_conftest", E2E)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main() -> int:
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    up = e2e()
    with tempfile.TemporaryDirectory() as folder:
        stack = up.Stack(Path(folder), "sim", ["recorder", "kinematics-asibot-sim"])
        try:
            stack.wait_alive("sim/asibot-sim", "kinematics/asibot-sim", "recorder/main")
            out = stack.run("-u", str(up.EXAMPLES / "give_me_the_red_can.py"), ROBOT)
            print(out.stdout, out.stderr)
            if out.returncode != 0:
                return 1
        finally:
            stack.stop()
        [session] = (Path(folder) / "recordings").glob("*.mcap")
        write_fixture(FIXTURE, "asibot replay fixture", (r for r in iter_messages(session) if r.key in KEEP))
    print(f"wrote {FIXTURE} ({FIXTURE.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
