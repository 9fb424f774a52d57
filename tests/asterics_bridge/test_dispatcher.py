"""The dispatcher on the in-memory bus against doubles of nav, kinematics and the tasks."""

import pytest

from asibot.errors import RpcError
from asibot.testing import wait_until

from asibot.asterics_bridge.dispatcher import parse_events, parse_menu

from .harness import OTHER, ROBOT, Bridge


@pytest.fixture
def bridge(memory_bus):
    b = Bridge(memory_bus, sockets=False)
    yield b
    b.close()


@pytest.fixture
def session(bridge):
    return bridge.dispatcher.open_session("test")


def run(bridge, session, text):
    return bridge.dispatcher.execute(session, text)


@pytest.mark.parametrize("word, name, continuous", [
    ("forward", "forward", True), ("backward", "backward", True), ("turn left", "turn left", True),
    ("turn right", "turn right", True), ("curve left", "curve forward left", True),
    ("curve right", "curve forward right", True), ("curve back left", "curve backward left", True),
    ("curve back right", "curve backward right", True), ("turn around", "turn around", False),
    ("turn left 90", "turn left 90", False), ("Turn Right 90", "turn right 90", False),
])
def test_base_words_call_nav_primitives(bridge, session, word, name, continuous):
    reply = run(bridge, session, word)
    assert reply.ok, reply
    expected = {"name": name, "continuous": True} if continuous else {"name": name}
    assert bridge.nav.requests("primitive") == [expected]
    assert reply.text == bridge.nav.text


def test_stop_stops_base_and_arm(bridge, session):
    run(bridge, session, "forward")
    reply = run(bridge, session, "stop")
    assert reply.ok and reply.text == "stopped base and arm"
    assert bridge.nav.requests("primitive")[-1] == {"name": "stop"}
    assert bridge.arm.verbs() == ["stop"]


def test_settings_and_wider_follow_the_last_target(bridge, session):
    assert run(bridge, session, "faster").text == "speed 3 of 5"
    assert run(bridge, session, "wider").text == "width 4 of 5"             # after a base word: nav
    assert bridge.nav.requests("settings") == [{"change": "faster"}, {"change": "wider"}]
    run(bridge, session, "arm up")
    assert run(bridge, session, "wider").text == "arm step 20 mm"           # after an arm word: the arm step
    assert run(bridge, session, "wider").text == "arm step 40 mm"
    assert run(bridge, session, "wider").text == "arm step 40 mm (already the longest)"
    assert len(bridge.nav.requests("settings")) == 2
    run(bridge, session, "slower")
    assert run(bridge, session, "narrower").text == "width 3 of 5"


@pytest.mark.parametrize("word, axis, sign", [
    ("arm forward", 0, 1), ("arm backward", 0, -1), ("arm left", 1, 1), ("arm right", 1, -1),
    ("arm up", 2, 1), ("arm down", 2, -1)])
def test_arm_steps_are_straight_lines_of_the_step(bridge, session, word, axis, sign):
    before = list(bridge.arm.point)
    reply = run(bridge, session, word)
    assert reply.ok and reply.text == f"{word} 10 mm"
    (req,) = bridge.arm.requests("movl")
    expected = list(before)
    expected[axis] += sign * 0.010
    assert req["point"] == pytest.approx(expected)


def test_arm_step_levels(bridge, session):
    run(bridge, session, "arm up")
    for _ in range(5):
        run(bridge, session, "narrower")
    z = bridge.arm.point[2]
    run(bridge, session, "arm up")
    assert bridge.arm.point[2] == pytest.approx(z + 0.002)


def test_gripper_save_recall_home(bridge, session):
    assert run(bridge, session, "grab").text == "holding something"
    assert run(bridge, session, "release").text == "gripper open"
    assert bridge.arm.requests("act") == [{"action": "close"}, {"action": "open"}]
    saved = list(bridge.arm.point)
    assert run(bridge, session, "arm save").ok
    run(bridge, session, "arm up")
    assert run(bridge, session, "arm recall").ok
    assert bridge.arm.requests("movl")[-1]["point"] == pytest.approx(saved)
    assert run(bridge, session, "arm home").ok and bridge.arm.verbs()[-1] == "home"


def test_arm_recall_without_a_save_is_a_sentence(bridge, session):
    reply = run(bridge, session, "arm recall")
    assert not reply.ok and reply.text == f"No arm position is saved for {ROBOT} yet; say 'arm save' first."


def test_an_unreachable_move_gets_the_kinematics_sentence(bridge, session):
    bridge.arm.point = [0.795, 0.0, 0.0, 90.0, 0.0]
    reply = run(bridge, session, "arm forward")
    assert not reply.ok and reply.code == "unreachable"
    assert reply.text.startswith("The point is unreachable")


def test_goto_places_and_positions(bridge, session):
    reply = run(bridge, session, "goto Fridge")
    assert reply.ok and reply.text == "driving to fridge, 8.0 m left"
    assert bridge.nav.requests("goto") == [{"place": "fridge"}]
    reply = run(bridge, session, "goto frige")
    assert not reply.ok
    assert reply.text == ("unknown place 'frige'; did you mean 'fridge'? (places: fridge, shelf, desk, "
                          "charging station)")
    assert len(bridge.nav.requests("goto")) == 1
    assert run(bridge, session, "save position").text == "position saved"
    assert run(bridge, session, "recall position").ok
    assert run(bridge, session, "places").text == "places: fridge, shelf, desk, charging station"


def test_nav_refusals_pass_their_sentence(bridge, session):
    bridge.nav.refuse = RpcError("estop", "The emergency stop is engaged; release it before driving.")
    reply = run(bridge, session, "forward")
    assert not reply.ok and reply.code == "estop"
    assert reply.text == "The emergency stop is engaged; release it before driving."


def test_tasks(bridge, session):
    assert run(bridge, session, "run give me the red can").text == "running give me the red can"
    assert bridge.tasks.requests("launch") == [{"task": "give me the red can", "robot": ROBOT}]
    assert bridge.dispatcher.board.robot(ROBOT).task == "give me the red can"
    assert run(bridge, session, "stop").text == "stopped base and arm and task give me the red can"
    assert bridge.tasks.verbs()[-1] == "stop"
    reply = run(bridge, session, "run drnk")
    assert not reply.ok and reply.text == ("unknown task 'drnk'; did you mean 'drink'? "
                                           "(tasks: give me the red can, drink)")
    assert run(bridge, session, "tasks").text == "tasks: give me the red can, drink"


def test_robot_chooses_what_arm_words_drive(bridge, session):
    assert run(bridge, session, f"robot {OTHER}").text == f"now driving {OTHER}"
    run(bridge, session, "arm up")
    assert bridge.other_arm.verbs() == ["stat", "movl"] and bridge.arm.verbs() == []
    reply = run(bridge, session, "forward")          # no nav serves asibot-sim
    assert not reply.ok and reply.code == "unavailable"
    assert reply.text == (f"No nav service answers for robot '{OTHER}'; start it (asibot up), or choose another "
                          "robot with 'robot <id>'.")
    reply = run(bridge, session, "robot nobody")
    assert not reply.ok and reply.text.startswith("No robot 'nobody' answers")
    assert not run(bridge, session, "robot a/b").ok
    assert session.robot == OTHER


def test_malformed_commands_move_nothing(bridge, session):
    for text in ("forwrd", "", "goto", "arm", "fly to the moon", "x" * 500, "stop\x07", None, 12):
        assert not run(bridge, session, text).ok
    assert bridge.nav.calls == [] and bridge.arm.calls == [] and bridge.tasks.calls == []
    assert bridge.dispatcher.counters["not_understood"] == 9


def test_a_token_is_needed_first_when_set(memory_bus):
    b = Bridge(memory_bus, sockets=False, token="s3cret")
    try:
        s = b.dispatcher.open_session("lan")
        reply = b.dispatcher.execute(s, "forward")
        assert not reply.ok and reply.code == "forbidden" and "token" in reply.text
        assert not b.dispatcher.execute(s, "token wrong").ok
        assert b.dispatcher.execute(s, "token s3cret").ok
        assert b.dispatcher.execute(s, "forward").ok
        assert b.nav.requests("primitive") == [{"name": "forward", "continuous": True}]
    finally:
        b.close()


def test_scanning_menu(bridge, session):
    assert not run(bridge, session, "select").ok
    assert run(bridge, session, "next").text == "stop"
    assert run(bridge, session, "next").text == "forward"
    assert run(bridge, session, "select").ok
    assert bridge.nav.requests("primitive") == [{"name": "forward", "continuous": True}]
    assert run(bridge, session, "previous").text == "stop"


def test_longest_motion_is_stopped_and_the_client_told(bridge, session):
    told = []
    session.notify = told.append
    run(bridge, session, "forward")
    bridge.clock.t += 59
    bridge.dispatcher.expire()
    assert bridge.nav.requests("primitive")[-1]["name"] == "forward"
    bridge.clock.t += 2
    bridge.dispatcher.expire()
    assert bridge.nav.requests("primitive")[-1] == {"name": "stop"}
    assert told and told[0].phrase == "stopped" and "60 s is the longest" in told[0].text
    bridge.clock.t += 100
    bridge.dispatcher.expire()
    assert len(bridge.nav.requests("primitive")) == 2     # once


def test_steps_are_not_cut_by_the_longest_time(bridge, session):
    run(bridge, session, "turn around")
    bridge.clock.t += 1000
    bridge.dispatcher.expire()
    assert [r["name"] for r in bridge.nav.requests("primitive")] == ["turn around"]


def test_disconnect_stops_only_its_own_running_motion(bridge, session):
    other = bridge.dispatcher.open_session("other")
    run(bridge, session, "forward")
    run(bridge, other, "turn left")                  # the latest motion is the other client's
    bridge.dispatcher.close_session(session)
    assert [r["name"] for r in bridge.nav.requests("primitive")] == ["forward", "turn left"]
    bridge.dispatcher.close_session(other)
    assert bridge.nav.requests("primitive")[-1] == {"name": "stop"}
    assert bridge.dispatcher.counters["stops_on_disconnect"] == 1


def test_disconnect_after_nav_ended_the_motion_sends_nothing(bridge, session):
    run(bridge, session, "forward")
    bridge.nav.finish("aborted", "stopped: obstacle ahead, 0.4 m")
    wait_until(lambda: getattr(bridge.dispatcher.board.robot(ROBOT).nav, "state", "") == "aborted")
    bridge.dispatcher.close_session(session)
    assert [r["name"] for r in bridge.nav.requests("primitive")] == ["forward"]


def test_events_reach_the_sessions_of_their_robot(bridge, session):
    mine, theirs = [], []
    session.notify = mine.append
    other = bridge.dispatcher.open_session("other")
    other.robot, other.notify = OTHER, theirs.append
    bridge.event("drive_stopped", "Stopped: obstacle ahead, 0.4 m")
    bridge.event("goal_succeeded", "Arrived at fridge", level="info")
    bridge.event("task_done", "The task drink is done.", level="info", robot=OTHER)
    wait_until(lambda: len(mine) == 2 and len(theirs) == 1)
    assert [(n.phrase, n.alarm) for n in mine] == [("obstacle ahead", True), ("goal reached", False)]
    assert theirs[0].phrase == "task done"
    bridge.estop(True)
    wait_until(lambda: len(mine) == 3)
    assert (mine[2].phrase, mine[2].alarm) == ("estop", True)
    assert bridge.dispatcher.board.json(ROBOT)["estop"] is True


def test_status(bridge, session):
    run(bridge, session, "forward")
    wait_until(lambda: bridge.dispatcher.board.robot(ROBOT).nav is not None)
    assert run(bridge, session, "status").text.startswith(f"{ROBOT}: forward, until you say stop")
    st = bridge.dispatcher.board.json(ROBOT)
    assert st["moving"] is True and st["state"] == "active"


def test_options():
    assert parse_events("1=next, 3=stop") == {1: "next", 3: "stop"}
    for bad in ("0=stop", "11=stop", "x=stop", "1=fly"):
        with pytest.raises(ValueError):
            parse_events(bad)
    assert parse_menu("stop,forward") == ("stop", "forward")
    for bad in ("", "fly", "next"):
        with pytest.raises(ValueError):
            parse_menu(bad)
