"""Programs without Python: the steps' models and limits, the templates, the Python they
generate (compiled, read, and run against a recording client), their storage beside the program
and the in-sync logic, and the routes on the `web` fixture."""

from __future__ import annotations

import json
import sys
from importlib import resources

import pytest
from pydantic import ValidationError

import asibot.client
from asibot.errors import RpcError
from asibot.web import steps as S
from asibot.web.userdata import AlreadyExists, NotFound, UserData, UserDataError

from .conftest import settle

CAN = [0.0, 0.5, 0.09, 180.0, 0.0]
POINTS = {"grasp-can": CAN, "shelf": [0.3, 0.3, 0.5, 90.0, 0.0], "if": [0.2, 0.4, 0.3, 180.0, 0.0]}


# --- models ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("bad", [
    {"kind": "fly"},
    {"kind": "move"},                                           # no point
    {"kind": "move", "point": "grasp can"},                     # not a point name
    {"kind": "move", "point": "grasp-can", "how": "curvy"},
    {"kind": "move", "point": "grasp-can", "speed": 9},         # no such field
    {"kind": "move", "point": "grasp-can", "above": 1},         # not a bool
    {"kind": "close", "check": "yes"},
    {"kind": "wait", "seconds": 0},
    {"kind": "wait", "seconds": -1},
    {"kind": "wait", "seconds": True},
    {"kind": "wait", "seconds": S.MAX_WAIT + 1},
    {"kind": "say", "text": ""},
    {"kind": "say", "text": "   "},
    {"kind": "say", "text": "two\nlines"},
    {"kind": "say", "text": "x" * (S.MAX_SAY + 1)},
    {"kind": "repeat", "times": 0, "steps": []},
    {"kind": "repeat", "times": S.MAX_TIMES + 1, "steps": []},
    {"kind": "repeat", "times": 2, "steps": [{"kind": "wait"}]},
])
def test_the_models_refuse_bad_steps(bad):
    with pytest.raises(ValidationError):
        S.STEPS.validate_python([bad])
    with pytest.raises(UserDataError, match="The steps are not valid"):
        S.parse([bad])


def test_limits_on_depth_and_count_are_sentences():
    deep: dict = {"kind": "wait", "seconds": 1}
    for _ in range(S.MAX_DEPTH):
        deep = {"kind": "repeat", "times": 2, "steps": [deep]}
    S.parse([deep])
    with pytest.raises(UserDataError, match=f"only {S.MAX_DEPTH} deep"):
        S.parse([{"kind": "repeat", "times": 2, "steps": [deep]}])
    S.parse([{"kind": "open"}] * S.MAX_STEPS)
    with pytest.raises(UserDataError, match=f"the most a steps program may have is {S.MAX_STEPS}"):
        S.parse([{"kind": "open"}] * S.MAX_STEPS + [{"kind": "close"}])


def test_a_step_round_trips_through_json_with_its_defaults():
    steps = S.parse([{"kind": "move", "point": "grasp-can"}, {"kind": "close"},
                     {"kind": "repeat", "times": 2, "steps": [{"kind": "say", "text": "hi"}]}])
    assert S.dump(steps) == [
        {"kind": "move", "point": "grasp-can", "how": "auto", "above": False, "slow": False},
        {"kind": "close", "check": True},
        {"kind": "repeat", "times": 2, "steps": [{"kind": "say", "text": "hi"}]}]
    assert S.parse(json.loads(json.dumps(S.dump(steps)))) == steps


# --- templates and sentences ----------------------------------------------------------------------
def test_pick_it_up_is_the_whole_pick_from_one_point():
    steps = S.pick_it_up("grasp-can")
    assert [p["sentence"] for p in S.describe(steps, POINTS)] == [
        "Open the gripper",
        "Move above grasp-can (joint move)",
        "Move to grasp-can slowly (straight move)",
        "Close the gripper and check it holds something",
        "Move above grasp-can (straight move)"]
    above = S.plan(steps, POINTS)[1]
    assert above.target == "above grasp-can"
    assert above.values == pytest.approx([0.0, 0.5, 0.09 + S.ABOVE_HEIGHT, 180.0, 0.0])


def test_put_it_down_is_the_place():
    assert [p["sentence"] for p in S.describe(S.put_it_down("shelf"), POINTS)] == [
        "Move above shelf (joint move)", "Move to shelf slowly (straight move)",
        "Open the gripper", "Move above shelf (straight move)"]
    with pytest.raises(UserDataError):
        S.put_it_down("no such point!")


def test_auto_is_joint_for_travel_and_straight_only_for_a_short_final_approach():
    near = [CAN[0], CAN[1], CAN[2] + S.APPROACH_DISTANCE - 0.001, *CAN[3:]]
    far = [CAN[0], CAN[1], CAN[2] + S.APPROACH_DISTANCE + 0.001, *CAN[3:]]
    turned = [*near[:3], 180.0 - S.APPROACH_TURN - 1, 0.0]
    points = {"can": CAN, "near": near, "far": far, "turned": turned}
    cases = [
        ([S.Move(point="can")], ["joint"]),                                     # where the arm starts is unknown
        ([S.Move(point="near"), S.Move(point="can")], ["joint", "straight"]),   # a short approach
        ([S.Move(point="far"), S.Move(point="can")], ["joint", "joint"]),       # too far for one
        ([S.Move(point="turned"), S.Move(point="can")], ["joint", "joint"]),    # turns the tool too much
        ([S.Move(point="can"), S.Move(point="can", above=True)], ["joint", "straight"]),   # a lift
        ([S.Move(point="near", how="straight"), S.Move(point="far", how="joint")], ["straight", "joint"]),
        # The start of a Repeat is not known either (its second round starts where its first ended).
        ([S.Move(point="near"), S.Repeat(times=2, steps=[S.Move(point="can")])], ["joint", "joint"]),
        # After a Repeat, the arm is where its last move took it.
        ([S.Repeat(times=2, steps=[S.Move(point="near")]), S.Move(point="can")], ["joint", "straight"]),
    ]
    for steps, hows in cases:
        got = [p.how for p in S._flat_planned(S.plan(steps, points)) if p.how is not None]
        assert got == hows, (steps, got)
    assert S.describe([S.Move(point="near"), S.Move(point="can")], points)[1]["sentence"] == \
        "Move to can (straight move, chosen automatically)"


def test_a_missing_point_is_refused_with_the_step_and_its_name():
    steps = [S.Open(), S.Repeat(times=2, steps=[S.Wait(seconds=1), S.Move(point="grasp-cup")])]
    with pytest.raises(UserDataError, match=r"Step 2\.2 moves to the point 'grasp-cup', but there is no point"):
        S.generate("p", steps, POINTS)


# --- the generated program ------------------------------------------------------------------------
def everything() -> list:
    return [*S.pick_it_up("grasp-can"), S.Move(point="shelf"), S.Wait(seconds=1.5), S.Say(text='Here it "is"'),
            S.Repeat(times=2, steps=[S.Move(point="if", slow=True), S.Close(check=False)]),
            S.Repeat(times=3), *S.put_it_down("shelf")]


def test_the_generated_program_compiles_and_reads_like_the_seeds():
    text = S.generate("give_me_the_can", everything(), POINTS)
    compile(text, "give_me_the_can.py", "exec")
    seed = resources.files("asibot.examples").joinpath("template.py").read_text(encoding="utf-8")
    robot_line = next(line for line in seed.splitlines() if line.startswith("robot_name ="))
    assert robot_line in text.splitlines()
    assert "from asibot.client import CartesianClient" in text
    assert f"{S.CLIENT} = CartesianClient()" in text and f"{S.CLIENT}.open(robot_name)" in text
    # The points as literal lists, each named in a comment; "above" is a point too, named.
    assert "grasp_can = [0.0, 0.5, 0.09, 180.0, 0.0]  # grasp-can\n" in text
    assert "above_grasp_can = [0.0, 0.5, 0.21, 180.0, 0.0]  # above grasp-can (0.12 m higher)\n" in text
    assert "if_point = [0.2, 0.4, 0.3, 180.0, 0.0]  # if\n" in text     # a keyword is not a name
    assert "straight(above_grasp_can, 'above grasp-can')" in text
    assert "print('Here it \"is\"')" in text
    assert "for _ in range(2):\n    print('Move to if slowly (joint move, chosen automatically)')" in text
    assert "for _ in range(3):\n    pass" in text
    assert text.rstrip().endswith(f"{S.CLIENT}.close()")


def test_a_program_holds_only_what_its_steps_use():
    text = S.generate("hello", [S.Say(text="hello"), S.Open()], POINTS)
    compile(text, "hello.py", "exec")
    for unused in ("import time", "RpcError", "def straight", "def close_and_check", "SLOW_", "# The points"):
        assert unused not in text


def test_point_variables_never_collide():
    names = S.variable_names(["a-b", "a_b", "above a-b", "simCart", "3d", "straight"])
    assert len(set(names.values())) == 6
    assert names["a-b"] == "a_b" and names["a_b"] == "a_b_2" and names["simCart"] == "simCart_2"
    assert names["3d"] == "p_3d" and all(n.isidentifier() for n in names.values())


class Recorder:
    """A CartesianClient that records what the program asks and refuses as told."""

    def __init__(self, script: dict) -> None:
        self.script, self.calls = script, []

    def open(self, robot):
        self.calls.append(("open", robot))

    def close(self):
        self.calls.append(("close",))

    def movj(self, point, speed=None):
        self.calls.append(("movj", list(point)))

    def movl(self, point, speed=None):
        self.calls.append(("movl", list(point), speed))
        code = self.script.get("movl")
        if code:
            raise RpcError(code, f"The straight line passes a singularity ({code}).")

    def wait(self):
        self.calls.append(("wait",))

    def grip(self, close=True):
        self.calls.append(("grip", close))
        if close and self.script.get("grip"):
            raise RpcError(self.script["grip"], "The gripper was still moving 4 s after the command.")
        holding = self.script.get("holding", True)
        if close and isinstance(holding, list):      # one answer a close, in turn
            return holding.pop(0)
        return holding if close else False

    def stat(self):
        moves = [c for c in self.calls if c[0] in ("movj", "movl")]
        return list(moves[-1][1]) if moves else [0.3, 0.0, 0.5, 180.0, 0.0]


class Looker:
    """A LookClient that answers each find from a script: a place, or a refusal."""

    def __init__(self, answers: list) -> None:
        self.answers, self.calls = answers, []

    def open(self, robot):
        self.calls.append(("open", robot))

    def close(self):
        self.calls.append(("close",))

    def find(self, thing):
        self.calls.append(("find", thing["name"]))
        answer = self.answers.pop(0)
        if isinstance(answer, RpcError):
            raise answer
        reach = [answer[0], answer[1], 0.09, 180.0, 0.0]
        return {"says": f"I see the {thing['name']}, 12 cm from where it was taught.", "reach": reach,
                "above": [answer[0], answer[1], 0.21, 180.0, 0.0], "moved": 0.12, "seen": []}


def run_generated(text: str, monkeypatch, script: dict, looks: list | None = None) -> Recorder:
    robot = Recorder(script)
    monkeypatch.setattr(asibot.client, "CartesianClient", lambda: robot)
    monkeypatch.setattr(asibot.client, "LookClient", lambda: Looker(list(looks or [])))
    monkeypatch.setattr(sys, "argv", ["program.py", "asibot-sim"])
    exec(compile(text, "program.py", "exec"), {"__name__": "__main__"})
    return robot


def test_a_refused_straight_move_is_made_as_a_joint_move_with_a_notice(monkeypatch, capsys):
    text = S.generate("pick", S.pick_it_up("grasp-can"), POINTS)
    robot = run_generated(text, monkeypatch, {"movl": "unreachable"})
    out = capsys.readouterr().out
    assert "Notice: the straight move to grasp-can cannot be done" in out
    assert "Notice: the straight move to above grasp-can cannot be done" in out
    assert "making it a joint move instead." in out and out.rstrip().endswith("done!")
    moves = [c for c in robot.calls if c[0] in ("movj", "movl")]
    assert moves == [("movj", [0.0, 0.5, 0.21, 180.0, 0.0]),
                     ("movl", CAN, S.SLOW_STRAIGHT), ("movj", CAN),
                     ("movl", [0.0, 0.5, 0.21, 180.0, 0.0], None), ("movj", [0.0, 0.5, 0.21, 180.0, 0.0])]
    # Only that refusal: any other ends the program with the client's error.
    with pytest.raises(RpcError, match="estop"):
        run_generated(text, monkeypatch, {"movl": "estop"})


def test_a_close_on_nothing_opens_goes_back_up_and_stops_with_the_sentence(monkeypatch, capsys):
    """Issue 52: never left down at the spot with the gripper open: up ABOVE_HEIGHT, then the end."""
    text = S.generate("pick", S.pick_it_up("grasp-can"), POINTS)
    robot = run_generated(text, monkeypatch, {})
    assert ("grip", True) in robot.calls and robot.calls[-1] == ("close",)
    said = "Nothing in the gripper after closing at grasp-can; the arm went back up, the gripper open."
    with pytest.raises(SystemExit) as ended:
        run_generated(text, monkeypatch, {"holding": False})
    assert ended.value.code == said
    robot = asibot.client.CartesianClient()   # the recorder of that run
    after = robot.calls[robot.calls.index(("grip", True)) + 1:]
    assert after == [("grip", False), ("movl", [CAN[0], CAN[1], CAN[2] + S.ABOVE_HEIGHT, *CAN[3:]], None),
                     ("wait",), ("close",)]
    # Fingers that do not settle (pushing on the can's side) hold nothing either; other refusals end it as they are.
    with pytest.raises(SystemExit) as ended:
        run_generated(text, monkeypatch, {"grip": "timeout"})
    assert ended.value.code == said
    assert asibot.client.CartesianClient().calls[-1] == ("close",)
    with pytest.raises(RpcError, match="still moving"):
        run_generated(text, monkeypatch, {"grip": "estop"})


THING = {"name": "red can", "colour": "red", "height": 0.12, "width": 0.066, "where": [0.0, 0.5, 0.02]}


def test_a_taught_thing_is_looked_for_and_picked_where_it_stands_now(monkeypatch, capsys):
    steps = S.pick_up_thing(THING)
    assert [s.kind for s in steps] == ["open", "find", "move", "move", "close", "move"]
    text = S.generate("pick_up_red_can", steps, {})
    assert "0.5, 0.09" not in text          # no grasp of where it was taught: only what it is
    robot = run_generated(text, monkeypatch, {}, looks=[(0.0, 0.62)])
    out = capsys.readouterr().out
    assert "I see the red can, 12 cm from where it was taught." in out and out.rstrip().endswith("done!")
    moves = [c[:2] for c in robot.calls if c[0] in ("movj", "movl")]
    assert moves == [("movj", [0.0, 0.62, 0.21, 180.0, 0.0]), ("movl", [0.0, 0.62, 0.09, 180.0, 0.0]),
                     ("movl", [0.0, 0.62, 0.21, 180.0, 0.0])]


def test_a_close_on_nothing_looks_again_and_tries_once_more(monkeypatch, capsys):
    text = S.generate("pick_up_red_can", S.pick_up_thing(THING), {})
    robot = run_generated(text, monkeypatch, {"holding": [False, True]}, looks=[(0.0, 0.62), (0.02, 0.6)])
    out = capsys.readouterr().out
    assert "Nothing in the gripper at the red can: I look for it again and try once more." in out
    moves = [c[:2] for c in robot.calls if c[0] in ("movj", "movl")]
    assert moves[-3:] == [("movj", [0.02, 0.6, 0.21, 180.0, 0.0]), ("movl", [0.02, 0.6, 0.09, 180.0, 0.0]),
                          ("movl", [0.02, 0.6, 0.21, 180.0, 0.0])]       # the lift from where it was found again
    # Twice nothing: up, open, and the sentence.
    with pytest.raises(SystemExit) as ended:
        run_generated(text, monkeypatch, {"holding": [False, False]}, looks=[(0.0, 0.62), (0.02, 0.6)])
    assert ended.value.code == ("Nothing in the gripper after two tries at the red can; the arm went back up, "
                                "the gripper open.")
    last = asibot.client.CartesianClient().calls
    assert last[-3:] == [("movl", [0.02, 0.6, 0.09 + S.ABOVE_HEIGHT, 180.0, 0.0], None), ("wait",), ("close",)]


def test_a_thing_not_found_says_what_was_seen_and_the_arm_does_not_move(monkeypatch, capsys):
    text = S.generate("pick_up_red_can", S.pick_up_thing(THING), {})
    seen = "I looked for the red can and see a green object 9 cm tall, but no red can."
    with pytest.raises(SystemExit) as ended:
        run_generated(text, monkeypatch, {}, looks=[RpcError("not_found", seen)])
    assert ended.value.code == seen
    assert not [c for c in asibot.client.CartesianClient().calls if c[0] in ("movj", "movl")]


def test_a_move_to_a_thing_nobody_looked_for_is_refused():
    with pytest.raises(UserDataError, match="no step before it looks for the red can"):
        S.generate("p", [S.Move(thing="red can")], {})
    with pytest.raises(ValueError, match="a point or to a thing"):
        S.Move(point="grasp-can", thing="red can")


# --- storage and in sync --------------------------------------------------------------------------
@pytest.fixture
def data(tmp_path):
    d = UserData(tmp_path)
    d.add_point("grasp-can", CAN)
    return d


def test_steps_are_saved_beside_the_program_with_the_hash_of_its_python(data):
    made = data.steps.save("pick", S.pick_it_up("grasp-can"), new=True)
    assert data.read_program("pick") == made.text
    stored = json.loads((data.root / "pick.steps.json").read_text())
    assert stored["format"] == 1 and len(stored["steps"]) == 5
    saved = data.steps.read("pick")
    assert saved is not None and saved.in_sync and saved.steps == S.pick_it_up("grasp-can")
    assert not data.steps.points_changed("pick", saved)
    with pytest.raises(AlreadyExists):
        data.steps.save("pick", [], new=True)
    assert data.programs() == ["pick"]      # the steps file is not a program


def test_python_edited_afterwards_is_no_longer_in_sync_and_both_are_kept(data):
    made = data.steps.save("pick", S.pick_it_up("grasp-can"), new=True)
    edited = made.text.replace("print(\"done!\")", "print(\"all done\")")
    data.save_program("pick", edited)
    saved = data.steps.read("pick")
    assert saved is not None and not saved.in_sync and saved.steps == S.pick_it_up("grasp-can")
    # Saving the steps again replaces that Python only once the person confirms.
    with pytest.raises(UserDataError, match="was edited after its steps made it"):
        data.steps.save("pick", [S.Open()])
    assert data.read_program("pick") == edited and data.steps.read("pick").steps == S.pick_it_up("grasp-can")
    again = data.steps.save("pick", [S.Open()], replace=True)
    assert data.read_program("pick") == again.text and data.steps.read("pick").in_sync
    kept = [data.read_version("pick", v.id) for v in data.versions("pick")]
    assert edited in kept and made.text in kept
    assert len(list((data.root / ".versions" / "pick").glob("*.steps.json"))) == 1


def test_a_program_written_in_python_has_no_steps_until_confirmed(data):
    data.new_program("hand")
    assert data.steps.read("hand") is None
    with pytest.raises(UserDataError, match="written in Python"):
        data.steps.save("hand", [S.Open()])
    data.steps.save("hand", [S.Open()], replace=True)
    assert data.steps.read("hand").in_sync
    with pytest.raises(NotFound):
        data.steps.read("nothing")
    with pytest.raises(NotFound):
        data.steps.save("nothing", [])


def test_a_missing_point_is_refused_at_save_and_nothing_is_written(data):
    data.steps.save("pick", S.pick_it_up("grasp-can"), new=True)
    before = (data.read_program("pick"), (data.root / "pick.steps.json").read_bytes())
    with pytest.raises(UserDataError, match="no point with that name"):
        data.steps.save("pick", S.pick_it_up("grasp-cup"))
    with pytest.raises(UserDataError):
        data.steps.save("other", S.pick_it_up("grasp-cup"), new=True)
    assert (data.read_program("pick"), (data.root / "pick.steps.json").read_bytes()) == before
    assert data.programs() == ["pick"]


def test_a_point_captured_again_says_the_program_would_change(data):
    data.steps.save("pick", S.pick_it_up("grasp-can"), new=True)
    data.add_point("grasp-can", [0.01, 0.5, 0.09, 180.0, 0.0], replace=True)
    saved = data.steps.read("pick")
    assert saved.in_sync and data.steps.points_changed("pick", saved)
    data.delete_point("grasp-can")
    assert data.steps.points_changed("pick", data.steps.read("pick"))


def test_the_steps_follow_their_program(data):
    data.steps.save("pick", S.pick_it_up("grasp-can"), new=True)
    data.rename_program("pick", "fetch")
    assert not (data.root / "pick.steps.json").exists()
    assert data.steps.read("fetch").steps == S.pick_it_up("grasp-can")
    data.delete_program("fetch")
    assert not (data.root / "fetch.steps.json").exists()
    assert list((data.root / ".trash").glob("*-fetch.steps.json"))


def test_a_broken_steps_file_is_a_sentence(data):
    data.steps.save("pick", [S.Open()], new=True)
    (data.root / "pick.steps.json").write_text("{ not json")
    with pytest.raises(UserDataError, match="not JSON"):
        data.steps.read("pick")
    (data.root / "pick.steps.json").write_text(json.dumps({"format": 1, "steps": [{"kind": "fly"}]}))
    with pytest.raises(UserDataError, match="The steps are not valid"):
        data.steps.read("pick")


# --- routes ---------------------------------------------------------------------------------------
@pytest.fixture
def api(web):
    settle(web)
    client, svc = web[0], web[1]
    svc.web.data.add_point("grasp-can", CAN, replace=True)
    yield client
    for name in svc.web.data.programs():
        svc.web.data.delete_program(name)


def sentence(reply, status: int, *words: str) -> None:
    assert reply.status_code == status, reply.text
    message = reply.json()["message"]
    assert message.endswith("."), message
    for w in words:
        assert w in message, message


def test_a_program_made_from_the_pick_template(api):
    r = api.post("/api/step-programs", json={"name": "fetch", "template": "pick_it_up", "point": "grasp-can"})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["in_sync"] and body["described"][1]["sentence"] == "Move above grasp-can (joint move)"
    assert api.get("/api/programs/fetch").json()["text"] == body["text"]
    got = api.get("/api/programs/fetch/steps").json()
    assert got["steps"] == body["steps"] and got["in_sync"] and not got["points_changed"]
    sentence(api.post("/api/step-programs", json={"name": "fetch", "template": "empty"}), 409, "already exists")
    sentence(api.post("/api/step-programs", json={"name": "x", "template": "pick_it_up", "point": "nope"}), 404, "nope")
    sentence(api.post("/api/step-programs", json={"name": "x", "template": "pick_it_up"}), 400, "Choose the point")
    assert "x" not in api.get("/api/programs").json()["programs"]


def test_teaching_a_thing_again_asks_then_updates_the_same_program_and_its_task(api):
    """Issue 52: re-teaching the red can updates the program its task runs (after asking), rather
    than making pick_up_red_can_2 beside a task that still runs the old one."""
    def made(thing, if_exists):
        return api.post("/api/step-programs", json={"template": "pick_it_up", "thing": thing, "if_exists": if_exists})
    first = made(THING, "ask")
    assert first.status_code == 200 and first.json()["name"] == "pick_up_red_can" and not first.json()["replaced"]
    r = api.put("/api/tasks/Give%20me%20the%20red%20can", json={"program": "pick_up_red_can", "words": [], "icon": "can.svg"})
    assert r.status_code == 200, r.text
    moved = {**THING, "where": [0.1, 0.45, 0.02]}
    asked = made(moved, "ask")
    sentence(asked, 409, "A program already picks up the red can: pick_up_red_can", "“Give me the red can”", "Update it")
    assert asked.json()["error"] == "exists"
    assert api.get("/api/programs").json()["programs"] == ["pick_up_red_can"]          # nothing made
    assert "[0.0, 0.5, 0.02]" in api.get("/api/programs/pick_up_red_can").json()["text"]
    updated = made(moved, "replace")
    assert updated.status_code == 200, updated.text
    body = updated.json()
    assert body["name"] == "pick_up_red_can" and body["replaced"] and body["tasks"] == ["Give me the red can"]
    assert "[0.1, 0.45, 0.02]" in api.get("/api/programs/pick_up_red_can").json()["text"]
    assert [t["program"] for t in api.get("/api/tasks").json()["tasks"]] == ["pick_up_red_can"]
    another = made(moved, "number")
    assert another.json()["name"] == "pick_up_red_can_2" and not another.json()["replaced"]
    bad = api.post("/api/step-programs", json={"template": "pick_it_up", "thing": THING, "if_exists": "overwrite"})
    assert bad.status_code in (400, 422), bad.text
    assert api.delete("/api/tasks/Give%20me%20the%20red%20can").status_code == 200


def test_steps_routes_save_preview_and_answer_templates(api):
    api.post("/api/step-programs", json={"name": "fetch", "template": "empty"})
    tpl = api.post("/api/programs/fetch/steps/template", json={"template": "put_it_down", "point": "grasp-can"}).json()
    assert [d["sentence"] for d in tpl["described"]][2] == "Open the gripper"
    assert api.get("/api/programs/fetch/steps").json()["steps"] == []      # answered, not saved
    preview = api.post("/api/programs/fetch/steps/preview", json={"steps": tpl["steps"]}).json()
    compile(preview["text"], "fetch.py", "exec")
    saved = api.put("/api/programs/fetch/steps", json={"steps": tpl["steps"]}).json()
    assert saved["text"] == preview["text"] and saved["in_sync"]
    assert api.get("/api/programs/fetch").json()["text"] == saved["text"]
    # Edited as Python: not in sync; a save of the steps asks first.
    api.put("/api/programs/fetch", json={"text": saved["text"] + "# mine\n"})
    assert api.get("/api/programs/fetch/steps").json()["in_sync"] is False
    sentence(api.put("/api/programs/fetch/steps", json={"steps": []}), 400, "Confirm")
    assert api.get("/api/programs/fetch").json()["text"].endswith("# mine\n")
    assert api.put("/api/programs/fetch/steps", json={"steps": [], "replace_python": True}).json()["in_sync"]


@pytest.mark.parametrize("method, path, body, status, words", [
    ("put", "/api/programs/fetch/steps", {"steps": [{"kind": "wait", "seconds": 0}]}, 422, ["steps.0.wait.seconds"]),
    ("put", "/api/programs/fetch/steps", {"steps": [{"kind": "move", "point": "grasp-cup"}]}, 400, ["grasp-cup"]),
    ("put", "/api/programs/fetch/steps", {"steps": [{"kind": "fly"}]}, 422, ["kind"]),
    ("put", "/api/programs/fetch/steps", {"steps": [], "extra": 1}, 422, ["extra"]),
    ("put", "/api/programs/nope/steps", {"steps": []}, 404, ["nope"]),
    ("get", "/api/programs/nope/steps", None, 404, ["nope"]),
    ("post", "/api/programs/fetch/steps/template", {"template": "juggle", "point": "grasp-can"}, 422, ["template"]),
    ("post", "/api/programs/fetch/steps/template", {"template": "pick_it_up", "point": "a b"}, 400, ["a b"]),
    ("post", "/api/programs/nope/steps/template", {"template": "pick_it_up", "point": "grasp-can"}, 404, ["nope"]),
    ("post", "/api/programs/fetch/steps/preview", {"steps": [{"kind": "say", "text": "a\nb"}]}, 422, ["text"]),
    ("post", "/api/step-programs", {"name": "../x", "template": "empty"}, 400, ["program name"]),
])
def test_bad_steps_requests_are_sentences_and_change_nothing(api, method, path, body, status, words):
    api.post("/api/step-programs", json={"name": "fetch", "template": "pick_it_up", "point": "grasp-can"})
    before = api.get("/api/programs/fetch").json()["text"], api.get("/api/programs/fetch/steps").json()["steps"]
    reply = api.request(method.upper(), path, json=body) if body is not None else api.get(path)
    sentence(reply, status, *words)
    assert (api.get("/api/programs/fetch").json()["text"], api.get("/api/programs/fetch/steps").json()["steps"]) == before
    assert sorted(api.get("/api/programs").json()["programs"]) == ["fetch"]


def test_steps_whose_point_is_gone_are_still_shown(api, web):
    api.post("/api/step-programs", json={"name": "fetch", "template": "pick_it_up", "point": "grasp-can"})
    web[1].web.data.delete_point("grasp-can")
    got = api.get("/api/programs/fetch/steps").json()
    assert got["described"] is None and got["points_changed"] and len(got["steps"]) == 5
    web[1].web.data.add_point("grasp-can", CAN)


def test_a_template_program_is_named_after_the_template_and_the_point():
    assert S.program_name("pick_it_up", "red can", []) == "pick_up_red_can"
    assert S.program_name("pick_it_up", "red-can", ["pick_up_red-can", "pick_up_red-can_2"]) == "pick_up_red-can_3"
    assert S.program_name("put_it_down", "shelf", ["pick_up_shelf"]) == "put_down_shelf"
