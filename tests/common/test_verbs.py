"""One way to declare a verb (asibot.verbs): every RPC server of the tree serves a table, each
handler gets checked arguments, and the tables say the same things as the key catalogue."""

from __future__ import annotations

import ast
from pathlib import Path
from types import SimpleNamespace

import pytest

from asibot import keys, verbs
from asibot.bus import Bus
from asibot.errors import RpcError
from asibot.verbs import Field, Flag, Number, Numbers, OneOf, Text, Verb

ROOT = Path(__file__).resolve().parents[2]

TABLE = {
    "move": Verb({"to": Field(Numbers(("x", "y"), (Number(-1, 1, "m"),) * 2), required=True),
                  "fast": Field(Flag(), default=False)}, doc="go somewhere"),
    "name": Verb({"word": Field(Text("a word", longest=8), required=True),
                  "mood": Field(OneOf(("calm", "quick")))}),
}


@pytest.fixture
def served(memory_bus):
    """The table served on a memory bus; `calls` records what each handler and `before` got."""
    calls: list[tuple[str, SimpleNamespace]] = []
    with Bus("verbs-test", memory_bus) as bus:
        handlers = {"move": lambda a: calls.append(("move", a)) or {"moved": list(a.to)},
                    "name": lambda a: calls.append(("name", a)) or {"word": a.word}}
        verbs.serve(bus, lambda verb: f"test/rpc/{verb}", TABLE, handlers,
                    before=lambda verb, spec, args: calls.append(("before", args)))
        yield bus, calls


def test_a_handler_gets_the_checked_arguments_after_before(served):
    bus, calls = served
    assert bus.call("test/rpc/move", {"to": [0.5, -1]})["moved"] == [0.5, -1.0]
    assert [c[0] for c in calls] == ["before", "move"]
    args = calls[1][1]
    assert args.fast is False and list(args.to) == [0.5, -1.0]
    assert bus.call("test/rpc/name", {"word": "  hello "})["word"] == "hello"


@pytest.mark.parametrize("request_, sentence", [
    ({"to": [0, 0], "fsat": True}, "move takes only to, fast; 'fsat' is not one of them."),
    ({}, "move needs 'to':"),
    ({"to": [0, 2]}, "y = 2 is outside [-1, 1] m"),
    ({"to": [0, 0], "fast": 1}, "'fast' must be true or false; got 1."),
    ({"to": "x" * 100_000}, "(100000 characters)"),
    ([1, 2], "must be a map of named arguments"),
])
def test_a_bad_request_is_refused_in_one_sentence_before_anything_runs(served, request_, sentence):
    bus, calls = served
    with pytest.raises(RpcError) as err:
        bus.call("test/rpc/move", request_)
    assert err.value.code == "bad_request" and sentence in err.value.message
    assert len(err.value.message) < 300 and calls == []


def test_a_verb_without_a_handler_or_a_handler_without_a_verb_does_not_start(memory_bus):
    with Bus("verbs-test", memory_bus) as bus:
        with pytest.raises(ValueError, match=r"verbs without a handler: \['name'\]"):
            verbs.serve(bus, str, TABLE, {"move": dict})
        with pytest.raises(ValueError, match=r"handlers without a verb: \['jump'\]"):
            verbs.serve(bus, str, TABLE, {"move": dict, "name": dict, "jump": dict})


def test_a_verb_describes_itself_for_people():
    assert TABLE["move"].describe("move") == (
        "move(to: [x, y], 2 finite numbers (x, y in [-1, 1] m), fast?: true or false): go somewhere")


def _tables() -> dict[str, dict[str, Verb]]:
    from asibot.arm_driver.service import verbs as arm_driver_verbs
    from asibot.kinematics.requests import verbs as kinematics_verbs
    from asibot.nav.requests import VERBS as NAV
    from asibot.perception.service import VERBS as PERCEPTION
    from asibot.safety.driver_contract import VERBS as DRIVER
    from asibot.sim.service import VERBS as SIM
    from asibot.voice.service import VERBS as VOICE
    from asibot.web.look_bus import VERBS as LOOK
    from asibot.web.tasks_bus import VERBS as TASKS
    return {"kinematics": kinematics_verbs(6), "nav": NAV, "perception": PERCEPTION, "driver": DRIVER,
            "sim": SIM, "voice": VOICE, "tasks": TASKS, "look": LOOK, "arm_driver": arm_driver_verbs(("q1", "q2"))}


def test_every_table_names_the_verbs_of_the_key_catalogue():
    tables = _tables()
    assert set(tables["kinematics"]) == set(keys.RPC_VERBS_CART)
    assert set(tables["nav"]) == set(keys.RPC_VERBS_NAV)
    assert set(tables["perception"]) == set(keys.RPC_VERBS_PERCEPTION)
    assert set(tables["tasks"]) == set(keys.RPC_VERBS_TASKS)
    assert set(tables["look"]) == set(keys.RPC_VERBS_LOOK)
    assert set(tables["voice"]) == set(keys.RPC_VERBS_VOICE)


def test_every_verb_says_what_it_does():
    undocumented = [f"{service}.{verb}" for service, table in _tables().items()
                    for verb, spec in table.items() if not spec.doc]
    assert undocumented == []


def test_no_server_answers_a_bus_query_but_through_a_table():
    """`bus.serve` is called in one place, asibot.verbs.serve: a verb is always checked."""
    callers = []
    for path in [*ROOT.glob("libs/*/asibot/**/*.py"), *ROOT.glob("services/*/asibot/**/*.py")]:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "serve"
                    and isinstance(node.func.value, (ast.Name, ast.Attribute))
                    and getattr(node.func.value, "id", getattr(node.func.value, "attr", "")) == "bus"):
                callers.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert [c.split(":")[0] for c in callers] == ["libs/common/asibot/verbs.py"], callers
