"""The safety every arm driver shares (asibot.safety.guarded_arm), on a two-joint arm made of
plain numbers: the drivers' own tests (tests/arm_driver, tests/katana_driver) check it
through their motors."""

from __future__ import annotations

import threading
import time

import pytest

from asibot.safety.arming import NotReady
from asibot.safety.events import CommandRefused
from asibot.safety.guarded_arm import FaultError, GuardedArm


class NumberArm(GuardedArm):
    """Two joints within +-1 rad; its "motors" are a list; its control thread serves resets."""

    arm = "the test arm"
    line = "the test cable"
    after_reset = "it holds"

    def __init__(self, reset=lambda: {"ok": True}) -> None:
        self.events: list[tuple[str, str, str]] = []
        super().__init__(["a", "b"], lambda level, code, text: self.events.append((level, code, text)))
        self.goal = [0.0, 0.0]
        self.velocity = [0.0, 0.0]
        self.held = 0
        self.reset_with = reset
        self._faulted = False

    def _hold(self) -> None:
        self.velocity = [0.0, 0.0]
        self.held += 1

    def _moving(self) -> bool:
        return any(self.velocity)

    def _streaming(self) -> bool:
        return any(self.velocity)

    def _check_limits(self, mode, values, velocities) -> None:
        if mode == "position" and any(abs(v) > 1.0 for v in values):
            raise CommandRefused("position_limit", "beyond +-1 rad")

    def _apply(self, mode, values, velocities, now) -> None:
        if mode == "position":
            self.goal = values
        else:
            self.velocity = values

    def _reset(self) -> dict:
        return self.reset_with()

    def _reset_failed(self, exc):
        return FaultError(f"it would not: {exc}") if isinstance(exc, OSError) else None

    def codes(self) -> list[str]:
        return [code for _, code, _ in self.events]


def test_a_command_of_the_wrong_shape_or_beyond_a_limit_changes_nothing():
    arm = NumberArm()
    with pytest.raises(ValueError, match="the test arm has 2 joints"):
        arm.command("position", [0.1])
    with pytest.raises(ValueError, match="mode must be"):
        arm.command("torque", [0.1, 0.1])
    with pytest.raises(CommandRefused, match="beyond"):
        arm.command("position", [0.5, 2.0])
    assert arm.goal == [0.0, 0.0] and arm.counters["rejected_commands"] == 3
    assert arm.command("position", [0.5, -0.5], controller="page") and arm.goal == [0.5, -0.5]


def test_the_estop_holds_ignores_and_then_wants_a_new_stream():
    arm = NumberArm()
    arm.command("velocity", [0.1, 0.0], controller="page")
    arm.set_estop(True, "a test", by="carer")
    assert arm.velocity == [0.0, 0.0] and arm.codes() == ["estop"]
    assert "by carer (a test)" in arm.events[0][2]
    assert arm.command("velocity", [0.1, 0.0], controller="page") is False      # ignored, not queued
    assert arm.counters["ignored_commands"] == 1
    arm.set_estop(False, by="carer")
    assert arm.codes()[-2:] == ["estop_released", "ready"]
    with pytest.raises(NotReady):           # the stream went on through the stop: it must pause first
        arm.command("velocity", [0.1, 0.0], controller="page")
    assert arm.velocity == [0.0, 0.0]


def test_a_new_holder_stops_a_moving_arm_and_an_idle_one_quietly():
    arm = NumberArm()
    arm.set_controller("page")
    assert arm.codes() == ["ready"] and arm.held == 0
    arm.velocity = [0.2, 0.0]
    arm.set_controller(None)
    assert arm.codes()[-1] == "controller_lost" and arm.held == 1


def test_the_watchdog_stops_a_quiet_stream_once():
    arm = NumberArm()
    arm.command("velocity", [0.1, 0.0], controller="page")
    later = time.monotonic() + arm.watchdog.period + 0.05
    arm._watch(later)
    arm._watch(later + 1.0)
    assert arm.velocity == [0.0, 0.0] and arm.codes() == ["watchdog"]


def serving(arm: NumberArm) -> threading.Thread:
    """The arm's control thread: serves a reset asked for, until the arm is dropped."""
    stop = threading.Event()

    def run() -> None:
        while not stop.is_set():
            try:
                arm._serve_reset()
            except RuntimeError:
                pass                # a bug in _reset: the real control thread logs it and goes on
            time.sleep(0.005)
    t = threading.Thread(target=run, daemon=True)
    t.stop = stop                   # type: ignore[attr-defined]
    t.start()
    return t


def test_a_fault_reset_runs_on_the_control_thread_and_arms_for_a_new_stream():
    arm = NumberArm()
    control = serving(arm)
    try:
        assert arm.reset_fault(timeout=5) == {"ok": True}
        assert arm.codes() == ["fault_reset", "ready"]
        assert arm.events[0][2] == "The fault was reset: it holds."
    finally:
        control.stop.set()


def test_a_reset_that_fails_says_why_and_a_bug_says_so_rather_than_hang():
    def cable() -> dict:
        raise OSError("unplugged")

    def bug() -> dict:
        raise RuntimeError("a bug")
    for failing, said in ((cable, "it would not: unplugged"), (bug, "internal error")):
        arm = NumberArm(failing)
        control = serving(arm)
        try:
            with pytest.raises(FaultError, match=said):
                arm.reset_fault(timeout=5)
            assert "fault_reset" not in arm.codes()
        finally:
            control.stop.set()


def test_a_reset_nobody_serves_times_out_naming_what_to_check():
    arm = NumberArm()
    with pytest.raises(FaultError, match="within 0.2 s; check the test cable"):
        arm.reset_fault(timeout=0.2)
    with pytest.raises(FaultError, match="already running"):
        arm.reset_fault(timeout=0.2)       # the first is still asked for: the control thread takes it later
