"""Planning never holds the controller (issue 10, finding 3): a movl's path check runs
without the controller's lock, its end point is checked for reach before any path is
sampled, and stop, stat and cart/state answer while a plan is being checked.

The slow plan is made deterministic, not timed: a model whose path check waits for the
test's permission, so "stat answered while the movl was still being planned" is an ordering
of events, whatever the machine's load.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from asibot import keys
from asibot.bus import Bus
from asibot.errors import RpcError
from asibot.kinematics.controller import MOVL, NOT_CONTROLLING, Controller
from asibot.messages import CartState
from asibot.testing import wait_until

from .conftest import ROBOT, build, teardown
from .test_controller import Q0, ready
from .robot_under_test import asibot_model

#: Generous bound for anything that must answer at once (a loaded CI machine), s.
PROMPT = 5.0


class GatedModel:
    """The real ASIBOT model whose path checks (inv_path over more than one pose) wait, while
    `gate` is set, until the test sets `release`; it counts the poses it was asked to solve."""

    def __init__(self) -> None:
        self.model = asibot_model()
        self.gate = False
        self.planning = threading.Event()
        self.release = threading.Event()
        self.solved = 0

    def __getattr__(self, name):
        return getattr(self.model, name)

    def inv_path(self, poses, q0):
        self.solved += len(poses)
        if self.gate and len(poses) > 1:
            self.planning.set()
            self.release.wait(30)
        return self.model.inv_path(poses, q0)


@pytest.fixture
def gated(shared):
    """A robot of its own (on the module's bus) whose movl path checks wait for the test."""
    s = build(ROBOT + "-gated", model=GatedModel())
    try:
        yield s
    finally:
        s.server.model.release.set()
        teardown(s)


def start_movl(s, point) -> tuple[threading.Thread, dict]:
    """Send a movl (at 0.2 m/s) on a thread; its reply or refusal lands in the returned dict."""
    out: dict = {}

    def run() -> None:
        try:
            out["reply"] = s.bus.call(keys.cart_rpc(s.robot, "movl"), {"point": list(point), "speed": 0.2},
                                      timeout=60)
        except RpcError as exc:
            out["error"] = exc

    thread = threading.Thread(target=run, name="movl-request", daemon=True)
    thread.start()
    return thread, out


def target_near(s) -> list[float]:
    return (np.array(s.client.stat()) + [0.05, 0.0, -0.1, 0.0, 0.0]).tolist()


def test_stat_stop_and_cart_state_answer_while_a_movl_is_planned(gated):
    s, model = gated, gated.server.model
    target = target_near(s)
    states: list[CartState] = []
    observer = Bus("test-observer")
    observer.subscribe(keys.cart_state(s.robot), CartState, states.append)
    before = s.client.state()["joints"]
    model.gate = True
    try:
        thread, out = start_movl(s, target)
        assert model.planning.wait(PROMPT), "the movl never started its path check"
        # While the path is being checked:
        seen = len(states)
        assert s.client.state()["state"] == NOT_CONTROLLING
        wait_until(lambda: len(states) >= seen + 3, timeout=PROMPT, message="no cart/state while a movl is planned")
        s.client.stop()
        assert thread.is_alive() and not out, "stat and stop should answer before the plan is done"
    finally:
        model.release.set()
        observer.close()
    thread.join(PROMPT)
    # The stop came while the movl was planned: it is not started, and nothing moves.
    assert out["error"].code == "busy" and "stop" in out["error"].message
    assert "nothing moved" in out["error"].message
    assert s.server.ctl.state == NOT_CONTROLLING
    assert np.allclose(s.client.state()["joints"], before, atol=1e-6)


def test_a_movl_planned_while_stat_is_asked_then_starts(gated):
    s, model = gated, gated.server.model
    start = np.array(s.client.stat())
    target = target_near(s)
    model.gate = True
    try:
        thread, out = start_movl(s, target)
        assert model.planning.wait(PROMPT)
        for _ in range(3):
            s.client.stat()
        assert thread.is_alive() and not out
        planned_from, sent = s.server.ctl.q.copy(), len(s.driver.commands)
    finally:
        model.release.set()
    thread.join(PROMPT)
    assert out["reply"]["duration"] > 0 and s.server.ctl.state == MOVL
    # It starts from where it was planned (the first reference is the arm's position, no
    # jump for the time spent planning) and moves towards the target.
    wait_until(lambda: len(s.driver.commands) > sent, timeout=PROMPT)
    assert np.abs(np.array(s.driver.commands[sent].values) - planned_from).max() < np.radians(0.5)
    direction = (np.array(target) - start)[:3]
    wait_until(lambda: np.dot(np.array(s.client.stat())[:3] - start[:3], direction) > 0.01 * direction @ direction,
               timeout=PROMPT)
    s.client.stop()


def test_a_movl_to_a_distant_point_is_refused_before_any_path_is_sampled(gated):
    s, model = gated, gated.server.model
    before = s.client.state()["joints"]
    model.solved = 0
    for x in (1e5, 3e5):
        with pytest.raises(RpcError) as err:
            s.bus.call(keys.cart_rpc(s.robot, "movl"), {"point": [x, 0.0, 1.0, 0.0, 0.0]}, timeout=PROMPT)
        assert err.value.code == "unreachable" and "beyond the arm's reach" in err.value.message
    assert model.solved <= 2, f"{model.solved} poses solved to refuse two out-of-reach end points"
    assert s.server.ctl.state == NOT_CONTROLLING
    assert np.allclose(s.client.state()["joints"], before, atol=1e-6)


# --- the controller's rules for a plan that the world overtook -------------------------
def planned(c: Controller):
    return c.plan_movl(np.asarray(c.model.fwd(Q0)) + [0.0, 0.0, -0.05, 0.0, 0.0])


@pytest.mark.parametrize("meanwhile,code,word", [
    (lambda c: c.stop(), "busy", "stop"),
    (lambda c: (c.on_estop(True, "button"), c.on_estop(False, "")), "estop", "emergency stop"),
    (lambda c: c.on_estop(True, "button"), "estop", "emergency stop"),
    (lambda c: c.on_arm_state(Q0, "overcurrent on joint 2."), "fault", "fault"),
    (lambda c: c.on_driver(False), "unavailable", "driver"),
    (lambda c: c.stream(np.zeros(5), 0.0), "busy", "movv"),
    (lambda c: c.movj(Q0 + 0.1, 0.0), "busy", "movj"),
])
def test_a_plan_overtaken_by_events_is_not_started(meanwhile, code, word):
    c = ready()
    plan = planned(c)
    meanwhile(c)
    before = c.state
    with pytest.raises(RpcError) as err:
        c.start(plan, 1.0)
    assert err.value.code == code and word in err.value.message
    assert c.state == before and c.state != MOVL


def test_a_plan_nothing_overtook_starts():
    c = ready()
    plan = planned(c)
    c.on_arm_state(Q0, "")  # new measurements change nothing
    assert c.start(plan, 1.0) == plan.plan.duration and c.state == MOVL


def test_planning_ends_a_stream_so_the_plan_starts_where_the_arm_is():
    c = ready()
    c.stream(np.array([0.01, 0, 0, 0, 0]), 0.0)
    plan = planned(c)
    assert c.state == NOT_CONTROLLING   # the stream ended at the snapshot; the arm holds
    c.start(plan, 1.0)
    assert c.state == MOVL
