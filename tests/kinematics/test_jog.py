"""The `jog` verb (the page's step buttons) against the ideal driver on the in-memory bus.

Steps add up from the previous step's target while it still moves; whatever else stops or
moves the arm forgets that target; a refused step says why and changes nothing; bad input
is `bad_request` with the field, like every verb's.
"""

import math
import time

import numpy as np
import pytest

from asibot.errors import RpcError
from asibot.testing import wait_until

#: Where the `client` fixture puts the arm, deg (conftest.START).
START = [0.0, 5.0, 5.0, 5.0, 0.0]
#: Joints (deg) from which the tool can go down and along x (START is almost stretched).
BENT = [0, 30, 40, 30, 0]


def jog(client, axis: str, step: float, level: int) -> dict:
    return client._call("jog", axis=axis, step=step, level=level)


def q1(server) -> float:
    """The first joint as measured, deg."""
    return math.degrees(server.ctl.q[0])


def stopped(client) -> list[float]:
    """The joints (deg) once the arm holds still after a stop."""
    assert wait_until(lambda: client.state()["state"] == "not_controlling", timeout=5)
    time.sleep(0.2)    # the hold reaches the driver
    return client.state()["joints"]


def settles_at(client, joints: list[float], atol: float = 0.2, timeout: float = 5.0) -> None:
    """The measured joints reach `joints` (deg, within `atol`) after the motion is done: the ideal
    driver moves at most its top speed a 10 ms tick, and on a loaded machine, where its ticks
    come late, it reaches the end of the path after the controller has sent it."""
    wait_until(lambda: np.allclose(client.state()["joints"][:len(joints)], joints, rtol=0, atol=atol), timeout,
               message=lambda: f"the arm stopped at {client.state()['joints']}, not {joints}")


def bent(client) -> list[float]:
    """Put the arm at BENT; the point there."""
    client.movj(joints=BENT, duration=0.5)
    assert client.wait(timeout=5)
    settles_at(client, BENT, atol=1e-6)      # a step starts from the end of the movj
    return client.stat()


def test_joint_steps_touched_while_moving_add_up_from_the_previous_target(client, server):
    # The slowest level: a step takes seconds, so the second is touched while the first moves
    # even on a loaded machine (at level 3 one took 0.8 s, less than a CI's stall).
    first = jog(client, "q1", 10.0, 1)
    assert first["joints"] == pytest.approx([10, 5, 5, 5, 0], abs=1e-9) and first["duration"] > 0
    here = q1(server)
    second = jog(client, "q1", 10.0, 1)
    assert here < 9.0                      # the first step was still on its way
    # From the first step's target, not from where the arm was: it does not stop short.
    assert second["joints"] == pytest.approx([20, 5, 5, 5, 0], abs=1e-9)
    assert client.wait(timeout=30)
    settles_at(client, [20, 5, 5, 5, 0])


def test_cartesian_steps_touched_while_moving_add_up_in_a_straight_line(client):
    bent(client)
    first = jog(client, "z", -0.05, 1)      # 1 cm/s: the first step is on its way for 5 s
    here = client.stat()[2]
    second = jog(client, "z", -0.05, 1)
    # Compared with the first step's target, not with a point measured before it: the arm's
    # last state can lag its stop by a hair on a loaded machine (0.1 mm, 0.01 deg seen).
    p1 = first["point"]
    assert here > p1[2] + 0.005, "the first step was still on its way"
    assert second["point"] == pytest.approx([p1[0], p1[1], p1[2] - 0.05, p1[3], p1[4]], abs=1e-6)
    assert client.wait(timeout=40)
    assert client.stat()[:3] == pytest.approx(second["point"][:3], abs=3e-3)


def test_a_stop_forgets_the_target_and_the_next_step_starts_where_the_arm_is(client, server):
    jog(client, "q1", 10.0, 1)
    assert wait_until(lambda: q1(server) > 0.5, timeout=5)
    client.stop()
    here = stopped(client)
    step = jog(client, "q1", 10.0, 1)
    assert here[0] < 9.0
    assert step["joints"][0] == pytest.approx(here[0] + 10.0, abs=0.05)   # not 20
    client.stop()


def test_the_estop_forgets_the_target(client, server):
    jog(client, "q1", 10.0, 1)
    assert wait_until(lambda: q1(server) > 0.5, timeout=5)
    client.estop("a test presses the button")
    try:
        assert wait_until(lambda: client.state()["estop"], timeout=5)
        with pytest.raises(RpcError) as err:
            jog(client, "q1", 10.0, 1)
        assert err.value.code == "estop" and "release it" in err.value.message
    finally:
        client.release()
    assert wait_until(lambda: not client.state()["estop"], timeout=5)
    here = stopped(client)
    step = jog(client, "q1", 10.0, 1)
    assert step["joints"][0] == pytest.approx(here[0] + 10.0, abs=0.05)
    client.stop()


def test_after_another_verbs_motion_a_step_starts_where_the_arm_is(client, server):
    jog(client, "q1", 10.0, 3)
    with pytest.raises(RpcError) as err:     # a step is a motion: another verb waits for it
        client.movj(joints=[40, 5, 5, 5, 0])
    assert err.value.code == "busy"
    assert client.wait(timeout=10)           # that step ended at 10 deg
    client.movj(joints=[40, 5, 5, 5, 0], duration=2.0)
    assert wait_until(lambda: q1(server) > 20.0, timeout=5)
    step = jog(client, "q1", 5.0, 5)
    assert step["joints"][0] > 25.0          # from where the movj had taken it, not from 10
    assert client.wait(timeout=10)
    settles_at(client, step["joints"][:1])


@pytest.mark.parametrize("axis,step,code,words", [
    ("z", 1.0, "unreachable", "beyond the arm's reach"),
    ("q2", 700.0, "joint_limit", "Joint 2 target 705.0 deg is outside its limits"),
])
def test_a_refused_step_says_why_and_changes_nothing(client, server, axis, step, code, words):
    before, sent = client.state()["joints"], server.cmd_pub.count
    with pytest.raises(RpcError) as err:
        jog(client, axis, step, 3)
    assert err.value.code == code and words in err.value.message and err.value.message.endswith(".")
    time.sleep(0.1)
    assert client.state()["state"] == "not_controlling" and server.cmd_pub.count == sent
    assert client.state()["joints"] == pytest.approx(before, abs=1e-6)


def test_a_step_whose_line_crosses_a_singularity_is_refused_with_where(client, driver, server):
    target = client.inv([0.5, 0.001, 1.2, 0.0, 0.0])
    driver.set_joints(np.radians(target))
    assert wait_until(lambda: np.allclose(client.state()["joints"], target, atol=1e-6), timeout=5)
    sent = server.cmd_pub.count
    with pytest.raises(RpcError) as err:     # both ends reachable, the line crosses the base axis
        jog(client, "x", -1.0, 3)
    assert err.value.code == "unreachable" and "50 % of the path" in err.value.message
    time.sleep(0.1)
    assert client.state()["state"] == "not_controlling" and server.cmd_pub.count == sent
    assert client.state()["joints"] == pytest.approx(target, abs=1e-6)


def test_a_step_refused_while_one_moves_leaves_that_one_running_and_its_target(client):
    jog(client, "q1", 10.0, 1)
    with pytest.raises(RpcError) as err:
        jog(client, "q2", 700.0, 1)
    assert err.value.code == "joint_limit"
    assert client.state()["state"] == "movj"                   # the first step goes on
    step = jog(client, "q1", 10.0, 1)
    assert step["joints"] == pytest.approx([20, 5, 5, 5, 0], abs=1e-9)   # and still counts
    client.stop()


def test_a_cartesian_step_refused_while_one_moves_leaves_that_one_running(client):
    p0 = bent(client)
    jog(client, "z", -0.05, 1)
    with pytest.raises(RpcError) as err:     # the end of this line is out of reach
        jog(client, "x", 0.3, 1)
    assert err.value.code == "unreachable"
    assert client.state()["state"] == "movl"
    step = jog(client, "z", -0.05, 1)
    assert step["point"][2] == pytest.approx(p0[2] - 0.1, abs=1e-6)
    client.stop()


@pytest.mark.parametrize("request_body,words", [
    ({"axis": "w", "step": 1.0, "level": 3}, "'axis' must be q1 or q2 or q3 or q4 or q5 or x or y or z"),
    ({"axis": "q6", "step": 1.0, "level": 3}, "'axis' must be"),
    ({"axis": 0, "step": 1.0, "level": 3}, "'axis' must be"),
    ({"axis": "x", "step": float("nan"), "level": 3}, "'step' must be a number in [-720, 720]"),
    ({"axis": "x", "step": float("inf"), "level": 3}, "'step' must be"),
    ({"axis": "x", "step": "0.1", "level": 3}, "'step' must be"),
    ({"axis": "x", "step": 0.01, "level": 0}, "'level' must be a whole number from 1 to 5; got 0."),
    ({"axis": "x", "step": 0.01, "level": 6}, "'level' must be a whole number from 1 to 5"),
    ({"axis": "x", "step": 0.01, "level": 2.0}, "'level' must be"),
    ({"axis": "x", "step": 0.01, "level": True}, "'level' must be"),
    ({"step": 0.01, "level": 3}, "jog needs 'axis'"),
    ({"axis": "x", "level": 3}, "jog needs 'step'"),
    ({"axis": "x", "step": 0.01}, "jog needs 'level'"),
    ({"axis": "x", "step": 0.01, "level": 3, "speed": 0.1}, "'speed' is not one of them"),
])
def test_bad_input_is_a_bad_request_naming_the_field(client, server, request_body, words):
    sent = server.cmd_pub.count
    with pytest.raises(RpcError) as err:
        client._call("jog", **request_body)
    assert err.value.code == "bad_request" and words in err.value.message, err.value.message
    assert client.state()["state"] == "not_controlling" and server.cmd_pub.count == sent
