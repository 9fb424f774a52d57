"""JSON's `true` and `false` are not numbers (issue 51): a jog step with `"direction": true` is
refused, as the WebSocket's held button refuses it, and no number field of any request takes a
bool as 1 or 0. Every refusal is a 422 whose sentence names the field, and nothing moves."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
from pydantic import BaseModel, ValidationError

from asibot.web import app as _app    # noqa: F401  # imports every route module, so every request model
from asibot.web import page_messages, steps
from asibot.web.models import DIRECTION_RULE, Strict

from .conftest import API_ROBOT as ROBOT, settle
from .test_api import refused


@pytest.fixture
def api(web):
    settle(web)
    return web[0]


def _nothing_moved(web, commands: int, q: np.ndarray) -> None:
    """No command reached the driver and the arm stands where it stood, a while after the answer
    (a jog that slipped through would be on its way by then)."""
    client, svc, driver, server = web
    time.sleep(0.3)
    assert len(driver.commands) == commands, list(driver.commands)[commands:]
    assert server.ctl.state == "not_controlling"
    assert np.allclose(server.ctl.q, q, atol=1e-6)


STEP = {"space": "joint", "axis": 0, "direction": 1}


@pytest.mark.parametrize("field,value", [("direction", True), ("direction", False), ("direction", 1.0),
                                         ("axis", True), ("axis", False)])
def test_true_is_not_a_direction_or_an_axis_of_a_jog_step(web, api, field, value):
    client, svc, driver, server = web
    commands, q = len(driver.commands), server.ctl.q.copy()
    for space in ("joint", "cartesian"):
        message = refused(api.post(f"/api/robots/{ROBOT}/step", json={**STEP, "space": space, field: value}),
                          422, field, repr(value))
        if field == "direction":
            assert DIRECTION_RULE in message      # the WebSocket's sentence, as it refuses a held button
    _nothing_moved(web, commands, q)


@pytest.mark.parametrize("value", [True, False, 1.0, 2, 0, "1", None])
def test_http_and_the_websocket_refuse_the_same_directions(value):
    """One check of a jog's direction (models.Direction) for the REST step and the held button."""
    from asibot.web.api_robots import Step
    with pytest.raises(ValidationError) as http:
        Step.model_validate({**STEP, "direction": value})
    assert [e["loc"] for e in http.value.errors()] == [("direction",)]
    assert http.value.errors()[0]["msg"] == DIRECTION_RULE
    hold = {"type": "hold", "robot": ROBOT, "space": "joint", "axis": 0, "direction": value, "level": 3}
    with pytest.raises(page_messages.Refused) as ws:
        page_messages.read(json.dumps(hold), [ROBOT])
    assert ws.value.code == "bad_request" and ws.value.text == f"{DIRECTION_RULE}; got {value!r}."


@pytest.mark.parametrize("value", [1, -1])
def test_both_directions_are_still_taken(value):
    from asibot.web.api_robots import Step
    assert Step.model_validate({**STEP, "direction": value}).direction == value
    hold = {"type": "hold", "robot": ROBOT, "space": "joint", "axis": 0, "direction": value, "level": 3}
    assert page_messages.read(json.dumps(hold), [ROBOT]).direction == value


# Every number of every request body, where it is sent; `[]` marks a field that is a list of numbers.
ZERO = [0.3, 0.0, 0.3, 0.0, 0.0]
NUMBER_FIELDS = [
    (f"/api/robots/{ROBOT}/step", STEP, "axis"),
    (f"/api/robots/{ROBOT}/step", STEP, "direction"),
    (f"/api/robots/{ROBOT}/step", STEP, "level"),
    (f"/api/robots/{ROBOT}/step", STEP, "step"),
    (f"/api/robots/{ROBOT}/move", {"kind": "movj", "values": ZERO}, "values[]"),
    (f"/api/robots/{ROBOT}/move", {"kind": "movj", "values": ZERO}, "level"),
    (f"/api/robots/{ROBOT}/inv", {"point": ZERO}, "point[]"),
    (f"/api/robots/{ROBOT}/home", {}, "level"),
    (f"/api/robots/{ROBOT}/points/nope/go", {}, "level"),
    ("/api/points", {"values": ZERO}, "values[]"),
    ("/api/programs/nope/run", {"robot": ROBOT}, "minutes"),
    ("/api/voice/learn", {"word": "cup", "page": "0123abcd"}, "seconds"),
    (f"/api/base/{ROBOT}/goto", {}, "x"),
    (f"/api/base/{ROBOT}/goto", {}, "y"),
    (f"/api/base/{ROBOT}/goto", {"x": 1.0, "y": 1.0}, "theta_deg"),
    (f"/api/robots/{ROBOT}/cameras/nope/touch", {"u": 1, "v": 1}, "u"),
    (f"/api/robots/{ROBOT}/cameras/nope/touch", {"u": 1, "v": 1}, "v"),
    (f"/api/robots/{ROBOT}/cameras/nope/calibration/spot", {"u": 1, "v": 1}, "u"),
    ("/api/programs/nope/steps/preview", {"steps": [{"kind": "wait"}]}, "steps.0.wait.seconds"),
    ("/api/programs/nope/steps/preview", {"steps": [{"kind": "repeat"}]}, "steps.0.repeat.times"),
]


def _with(body: dict, field: str, value: object) -> tuple[dict, str]:
    """`body` with `value` where `field` says; and the field's name as the refusal says it."""
    body = json.loads(json.dumps(body))
    if field.endswith("[]"):
        field = field[:-2]
        body[field][2] = value
        return body, f"{field}.2"
    if field.startswith("steps."):
        body["steps"][0][field.rsplit(".", 1)[1]] = value
        return body, field
    body[field] = value
    return body, field


@pytest.mark.parametrize("value", [True, False])
@pytest.mark.parametrize("path,body,field", NUMBER_FIELDS, ids=[f"{p.split('/', 3)[-1]}:{f}" for p, _, f in NUMBER_FIELDS])
def test_no_number_field_takes_a_bool(web, api, path, body, field, value):
    client, svc, driver, server = web
    data = svc.web.data
    files = sorted(p.name for p in data.root.rglob("*"))
    commands, q = len(driver.commands), server.ctl.q.copy()
    sent, named = _with(body, field, value)
    refused(api.post(path, json=sent), 422, named, repr(value))
    assert sorted(p.name for p in data.root.rglob("*")) == files
    assert len(driver.commands) == commands and np.allclose(server.ctl.q, q, atol=1e-6)
    assert not svc.web.runner.running()


def _models() -> list[type[BaseModel]]:
    found, todo = [], [Strict, steps._Step]
    while todo:
        for sub in todo.pop().__subclasses__():
            found.append(sub)
            todo.append(sub)
    return found


def _numeric(schema: object) -> bool:
    """Whether a field's JSON schema takes a number (itself, in a union, or as a list's items);
    a field that is another model is that model's own row."""
    if isinstance(schema, list):
        return any(_numeric(s) for s in schema)
    if not isinstance(schema, dict) or "$ref" in schema:
        return False
    return schema.get("type") in ("integer", "number") or any(
        _numeric(schema.get(key)) for key in ("anyOf", "oneOf", "allOf", "items"))


def _number_fields() -> list[tuple[type[BaseModel], str, bool]]:
    rows = []
    for model in _models():
        whole = model.model_json_schema()
        if "$ref" in whole:     # a model that holds itself (Repeat): its schema is one of its $defs
            whole = whole["$defs"][whole["$ref"].rsplit("/", 1)[1]]
        for name, schema in whole.get("properties", {}).items():
            if _numeric(schema):
                listed = "array" in json.dumps({k: v for k, v in schema.items() if k != "items"})
                rows.append((model, name, listed))
    return rows


NUMBERS = _number_fields()


def test_every_number_field_is_in_the_audit():
    """The introspection finds the fields the HTTP test above sends, and no other: a new number
    field of a request model gets a row in NUMBER_FIELDS (and the audit below checks it)."""
    found = {(model.__name__, name) for model, name, _ in NUMBERS}
    assert found == {("Step", "axis"), ("Step", "direction"), ("Step", "level"), ("Step", "step"),
                     ("Move", "values"), ("Move", "level"), ("Target", "point"), ("Speed", "level"),
                     ("GoTo", "level"), ("KeepPoint", "values"), ("RunProgram", "minutes"), ("Learn", "seconds"),
                     ("Goal", "x"), ("Goal", "y"), ("Goal", "theta_deg"), ("Spot", "u"), ("Spot", "v"),
                     ("Wait", "seconds"), ("Repeat", "times")}


@pytest.mark.parametrize("value", [True, False])
@pytest.mark.parametrize("model,field,listed", NUMBERS, ids=[f"{m.__name__}.{f}" for m, f, _ in NUMBERS])
def test_no_request_model_takes_a_bool_as_a_number(model, field, listed, value):
    with pytest.raises(ValidationError) as refusal:
        model.model_validate({field: [value] * 5 if listed else value})
    assert any(e["loc"][0] == field and e["input"] is value for e in refusal.value.errors()), refusal.value.errors()
