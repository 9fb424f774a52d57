"""No set-point outruns a joint (issue 53): in cyclic synchronous position a drive follows each
SYNC's set-point within one period, so the step between two SYNCs must stay within the joint's
max speed times the period, whatever the control loop's timing. Both cores busy and a control
loop that stalls for 60 ms now and then: the motion lags (and health says so), it never jumps."""

from __future__ import annotations

import time

import pytest

from asibot.testing import busy_cores, wait_until

#: every this many control periods, the loop stalls (a garbage collection, a busy core)
STALL_EVERY = 25
STALL_S = 0.06


def _stalling(snapshot):
    calls = [0]

    def stalled_now_and_then():
        calls[0] += 1
        if calls[0] % STALL_EVERY == 0:
            time.sleep(STALL_S)
        return snapshot()
    return stalled_now_and_then


@pytest.mark.alone          # it loads both cores: nothing else in real time may run beside it
def test_no_set_point_step_outruns_a_joint_with_both_cores_busy_and_a_stalled_loop(rig):
    driver = rig.start_driver()
    wait_until(lambda: rig.states and rig.last.mode == "idle", 15, message=lambda: f"not up: {driver.fault}")
    rig.master.snapshot = _stalling(rig.master.snapshot)
    for drive in rig.emu.drives.values():
        drive.steps.clear()
    there, back = [0.4, 0.4, -0.4, 0.4, 0.4], [0.0] * 5
    with busy_cores(2):
        for goal in (there, back, there, back):          # full speed on every joint
            driver.command("position", goal)
            wait_until(lambda: all(abs(p - g) < 1e-3 for p, g in zip(rig.last.positions, goal)), 30,
                       message=lambda: f"at {rig.last.positions}, going to {goal}")
    for j in rig.cfg.joints:
        steps = rig.emu.drives[j.node].steps
        limit = abs(j.units.to_counts(j.max_velocity * rig.cfg.period))
        assert len(steps) > 100, f"joint {j.name}: only {len(steps)} SYNCs applied"
        largest = max(abs(s) for s in steps)
        # +1: each set-point is rounded to a whole count
        assert largest <= limit + 1, f"joint {j.name} was told to step {largest} counts in one SYNC (limit {limit})"
        assert largest >= limit - 1, f"joint {j.name} never moved at full speed ({largest} of {limit} counts)"
    health = driver.health()
    assert health["late_syncs"] > 0 and health["longest_lag_ms"] >= 10, health
