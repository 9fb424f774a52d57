"""What an HTTP command is: the body of POST /command as AsTeRICS-Grid and scripts send it,
and the dispatcher's reply as the HTTP answer they read.

A body is text (`forward`), a JSON string, or a JSON object `{"command": "forward"}` with an
optional `"robot"`; `?robot=` names the robot otherwise. Bad input is refused whole, with a
sentence, and changes nothing. A request that sends or accepts JSON is answered in JSON, any
other in one line of text (`ok: ...` or `error: ...`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from starlette.responses import PlainTextResponse, Response

from asibot import keys

from asibot.asterics_bridge.dispatcher import Reply

#: Reply codes -> HTTP status; any other code (busy, estop, an RPC's refusal) is a conflict.
REPLY_STATUS = {"ok": 200, "not_understood": 400, "bad_request": 400, "forbidden": 403, "unavailable": 503,
                "timeout": 504, "internal": 500}
CONFLICT = 409
#: The fields of a JSON command.
JSON_FIELDS = ("command", "robot")
#: Content types of a command ("": none given; a form's body is taken as text).
TYPES = ("text/plain", "application/json", "application/x-www-form-urlencoded", "")


def json_answer(status: int, data: object) -> Response:
    """JSON in UTF-8, said so (the text answers say it too)."""
    return Response(json.dumps(data), status, media_type="application/json; charset=utf-8")


def wants_json(headers: Mapping[str, str]) -> bool:
    return _content_type(headers) == "application/json" or "application/json" in headers.get("accept", "")


def command_of(query: Mapping[str, str], headers: Mapping[str, str], body: bytes) -> tuple[str, str] | Response:
    """The (robot, command text) of a POST /command ("" robot: the session's), or the answer
    to a body that is not one."""
    ctype = _content_type(headers)
    as_json = wants_json(headers)
    robot = query.get("robot", "")
    if ctype not in TYPES:
        return PlainTextResponse(f"error: send the command as text/plain or application/json, not {ctype[:40]}.\n",
                                 415)
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError:
        return reply_answer(Reply(False, "The body is not UTF-8 text; send a command such as 'forward'.",
                                  "bad_request"), as_json)
    if ctype == "application/json":
        data = parse_json(text)
        if isinstance(data, JsonRefusal):
            return reply_answer(Reply(False, data.sentence, "bad_request"), as_json)
        problem = json_problem(data)
        if problem:
            return reply_answer(Reply(False, problem, "bad_request"), as_json)
        if isinstance(data, dict):
            robot = data.get("robot", robot)
            data = data["command"]
        text = data
    if robot and not valid_robot(robot):
        return reply_answer(Reply(False, f"{robot[:40]!r} is not a robot id.", "bad_request"), as_json)
    return robot, text


@dataclass(frozen=True)
class JsonRefusal:
    """Why a body is not JSON the bridge reads."""
    sentence: str


def parse_json(text: str) -> Any:
    """The JSON value of `text`, or a JsonRefusal. A command is one level deep, but Python's
    parser recurses for each level of nesting: `[[[[...` of a few KiB would be a
    RecursionError (a 500), and is a bad request like any other bad JSON."""
    try:
        return json.loads(text)
    except RecursionError:
        return JsonRefusal("The body's JSON is nested too deeply to read; a command is one flat object, "
                           "send {\"command\": \"forward\"}.")
    except ValueError:
        return JsonRefusal("The body is not valid JSON; send {\"command\": \"forward\"}.")


def json_problem(data: object) -> str | None:
    """What is wrong with a JSON command, or None: a string, or an object with a string
    `command` and optionally a robot id `robot`, nothing else (a boolean is not a name)."""
    usage = "Send JSON {\"command\": \"forward\"} (and optionally \"robot\": \"pioneer-sim\")"
    if isinstance(data, str):
        return None
    if not isinstance(data, dict):
        return f"{usage}, not a JSON {type(data).__name__}."
    unknown = sorted(set(data) - set(JSON_FIELDS))
    if unknown:
        return f"{usage}; {', '.join(repr(k[:30]) for k in unknown)} is not a field of a command."
    if not isinstance(data.get("command"), str):
        return f"{usage}: \"command\" must be text, not {_json_kind(data.get('command'))}."
    if "robot" in data and not (isinstance(data["robot"], str) and data["robot"]):
        return f"{usage}: \"robot\" must be a robot id such as \"pioneer-sim\", not {_json_kind(data['robot'])}."
    return None


def valid_robot(robot: str) -> bool:
    try:
        keys.robot(robot)
        return True
    except ValueError:
        return False


def reply_answer(reply: Reply, as_json: bool) -> Response:
    """The dispatcher's reply as HTTP: its status from the reply's code, its sentence as a
    line or as JSON (`{"ok": true, "text": ...}`, `{"ok": false, "error": ..., "code": ...}`)."""
    status = REPLY_STATUS.get(reply.code, CONFLICT)
    if as_json:
        return json_answer(status, {"ok": reply.ok, "text": reply.text} if reply.ok else
                           {"ok": False, "error": reply.text, "code": reply.code})
    return PlainTextResponse(reply.line() + "\n", status)


def _content_type(headers: Mapping[str, str]) -> str:
    return headers.get("content-type", "text/plain").split(";")[0].strip().lower()


def _json_kind(value: object) -> str:
    if value is None:
        return "missing or null"
    return {bool: "a boolean", int: "a number", float: "a number", list: "a list", dict: "an object",
            str: "empty text"}.get(type(value), type(value).__name__)
