"""Replay never drives a live robot unless told to: found as issue 10's finding 2, where
`asibot replay red_can.mcap --fast` moved the live sim arm and the can."""

import subprocess
import sys
from pathlib import Path

from asibot import keys, messages as m
from asibot.bus import Bus
from asibot.recorder.replay import LiveGuard, replay
from asibot.testing import wait_until

RED_CAN = Path(__file__).parents[2] / "recordings" / "fixtures" / "red_can.mcap"
ROBOT = "asibot-sim"  # the robot of the fixture


def asibot(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "asibot.cli.main", *argv], capture_output=True, text=True,
                          timeout=120)


class LiveDriver:
    """A driver that is alive and counts the commands it hears."""

    def __init__(self) -> None:
        self.bus = Bus("driver")
        self.commands: list[str] = []
        self.bus.subscribe("rb/**", m.ArmCommand, lambda k, msg: self.commands.append(k), with_key=True)
        self.bus.announce(keys.driver_alive(ROBOT))

    def close(self) -> None:
        self.bus.close()


def test_replay_refuses_while_a_driver_is_alive_and_says_what_to_do(router):
    driver = LiveDriver()
    try:
        r = asibot("replay", str(RED_CAN), "--fast")
        assert r.returncode == 2
        assert "asibot-sim" in r.stderr and "--prefix" in r.stderr and "--into-live" in r.stderr
        assert driver.commands == []
    finally:
        driver.close()


def test_replay_beside_a_live_stack_under_a_prefix_moves_nothing(router):
    driver = LiveDriver()
    seen = []
    with Bus("viewer") as viewer:
        viewer.subscribe_raw("again/**", lambda k, p, t: seen.append(k))
        try:
            r = asibot("replay", str(RED_CAN), "--fast", "--prefix", "again")
            assert r.returncode == 0, r.stderr
            wait_until(lambda: f"again/{keys.arm_command(ROBOT)}" in seen, 5)
            assert driver.commands == []
        finally:
            driver.close()


def test_into_live_replays_commands_with_a_warning(router):
    driver = LiveDriver()
    try:
        r = asibot("replay", str(RED_CAN), "--fast", "--into-live", "--only", keys.arm_command(ROBOT))
        assert r.returncode == 0 and "warning" in r.stderr
        wait_until(lambda: driver.commands, 5)
    finally:
        driver.close()


def test_without_live_drivers_everything_is_replayed(router):
    r = asibot("replay", str(RED_CAN), "--fast")
    assert r.returncode == 0 and "replayed" in r.stdout


def test_a_driver_that_comes_alive_during_a_replay_gets_no_commands():
    guard = LiveGuard()
    sent = []
    sent_before = replay(RED_CAN, lambda k, p: sent.append(k), speed=None, allows=guard.allows)
    assert any(keys.is_command(k) for k in sent) and sent_before == len(sent)
    guard.on_driver(keys.driver_alive(ROBOT), True)
    sent.clear()
    replay(RED_CAN, lambda k, p: sent.append(k), speed=None, allows=guard.allows)
    assert sent and not any(keys.is_command(k) for k in sent)
    assert guard.held > 0 and guard.drivers == {ROBOT}
    guard.on_driver(keys.driver_alive(ROBOT), False)
    assert guard.allows(keys.arm_command(ROBOT))


def test_a_bad_prefix_is_refused(router):
    r = asibot("replay", str(RED_CAN), "--prefix", "a/b")
    assert r.returncode == 2 and "--prefix" in r.stderr
