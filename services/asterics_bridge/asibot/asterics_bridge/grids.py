"""The AsTeRICS-Grid keyboards the bridge ships, built here and written to
`setups/asibot-robot.grd.json` (AsTeRICS-Grid's backup/import format, data model 6):

    python -m asibot.asterics_bridge.grids > services/asterics_bridge/asibot/asterics_bridge/setups/asibot-robot.grd.json

Three grids, the thesis's three keyboards: manual driving, automatic navigation to the places,
the arm. Every button is an HTTP action (POST text/plain to the bridge's /command); the top row
holds two live elements that poll GET /status (the robot's state, the last event) and buttons
to the other keyboards. tests/asterics_bridge/test_setups.py checks the file is this output
and that its fields are AsTeRICS-Grid's.

The shipped file has no token (it cannot know the user's); the bridge writes the user's copy
with its address and token in every HTTP action (`text(url, token)`, asibot.asterics_bridge.http_token):
AsTeRICS-Grid sends `authUser`/`authPw` as Basic auth, and the bridge takes the token as the password.
"""

from __future__ import annotations

import json
import sys

from asibot.asterics_bridge.servers import DEFAULT_HTTP_PORT

MODEL_VERSION = '{"major": 6, "minor": 0, "patch": 0}'
URL = f"http://127.0.0.1:{DEFAULT_HTTP_PORT}"
#: The user name of the Basic auth the user's grids send (the bridge reads only the password).
AUTH_USER = "asibot"
PLACES = ("fridge", "shelf", "desk", "charging station")
COLUMNS = 5
STOP_COLOUR, MOVE_COLOUR, SETTING_COLOUR, NAV_COLOUR = "#e53935", "#90caf9", "#fff59d", "#c5e1a5"

#: grid id -> (label, rows of (label, command, colour) or None for an empty cell)
KEYBOARDS: dict[str, tuple[str, list[list[tuple[str, str, str] | None]]]] = {
    "asibot-drive": ("Drive", [
        [("curve left", "curve left", MOVE_COLOUR), ("forward", "forward", MOVE_COLOUR),
         ("curve right", "curve right", MOVE_COLOUR), ("faster", "faster", SETTING_COLOUR),
         ("wider", "wider", SETTING_COLOUR)],
        [("turn left", "turn left", MOVE_COLOUR), ("STOP", "stop", STOP_COLOUR),
         ("turn right", "turn right", MOVE_COLOUR), ("slower", "slower", SETTING_COLOUR),
         ("narrower", "narrower", SETTING_COLOUR)],
        [("back left", "curve back left", MOVE_COLOUR), ("backward", "backward", MOVE_COLOUR),
         ("back right", "curve back right", MOVE_COLOUR), ("turn left 90", "turn left 90", MOVE_COLOUR),
         ("turn right 90", "turn right 90", MOVE_COLOUR)],
        [("turn around", "turn around", MOVE_COLOUR), None, None, None, None],
    ]),
    "asibot-places": ("Places", [
        [("fridge", "goto fridge", NAV_COLOUR), ("shelf", "goto shelf", NAV_COLOUR),
         ("desk", "goto desk", NAV_COLOUR), ("charging station", "goto charging station", NAV_COLOUR),
         ("STOP", "stop", STOP_COLOUR)],
        [("save position", "save position", SETTING_COLOUR), ("recall position", "recall position", NAV_COLOUR),
         None, None, None],
    ]),
    "asibot-arm": ("Arm", [
        [("arm left", "arm left", MOVE_COLOUR), ("arm forward", "arm forward", MOVE_COLOUR),
         ("arm right", "arm right", MOVE_COLOUR), ("arm up", "arm up", MOVE_COLOUR),
         ("STOP", "stop", STOP_COLOUR)],
        [None, ("arm backward", "arm backward", MOVE_COLOUR), None, ("arm down", "arm down", MOVE_COLOUR),
         ("grab", "grab", NAV_COLOUR)],
        [("wider", "wider", SETTING_COLOUR), ("narrower", "narrower", SETTING_COLOUR),
         ("arm home", "arm home", NAV_COLOUR), ("arm save", "arm save", SETTING_COLOUR),
         ("release", "release", NAV_COLOUR)],
        [("arm recall", "arm recall", NAV_COLOUR), None, None, None, None],
    ]),
}


def _label(text: str) -> dict:
    return {"en": text}


def _auth(token: str | None) -> dict:
    """AsTeRICS-Grid's Basic auth fields carrying the bridge's token (none: no fields)."""
    return {"authUser": AUTH_USER, "authPw": token} if token else {}


def http_action(element_id: str, body: str, url: str = URL, token: str | None = None) -> dict:
    return {"id": f"{element_id}-http", "modelName": "GridActionHTTP", "modelVersion": MODEL_VERSION,
            "restUrl": f"{url}/command", "method": "POST", "contentType": "text/plain", "body": body,
            **_auth(token), "noCorsMode": False, "useCorsProxy": False, "isLiveAction": False}


def _element(element_id: str, x: int, y: int, label: str, colour: str, actions: list, width: int = 1,
             kind: str = "ELEMENT_TYPE_NORMAL", **extra: object) -> dict:
    return {"id": element_id, "width": width, "height": 1, "x": x, "y": y, "label": _label(label),
            "actions": actions, "type": kind, "backgroundColor": colour, "hidden": False, **extra}


def _live(element_id: str, x: int, width: int, label: str, field: str, url: str, token: str | None) -> dict:
    """A live element showing `field` of GET /status after `label`. The label has no "{0}":
    AsTeRICS-Grid appends the value to a label without one, but shows "{0}" itself while the
    value is empty (no nav running, no event yet, the bridge not answering)."""
    status = {"id": f"{element_id}-http", "modelName": "GridActionHTTP", "modelVersion": MODEL_VERSION,
              "restUrl": f"{url}/status", "method": "GET", "contentType": "text/plain",
              "acceptHeader": "application/json", **_auth(token), "noCorsMode": False, "useCorsProxy": False,
              "isLiveAction": True}
    return _element(element_id, x, 0, label, "#ffffff", [], width, "ELEMENT_TYPE_LIVE",
                    mode="MODE_ACTION_RESULT", updateSeconds=1, liveAction=status, extractMode="EXTRACT_JSON",
                    extractSelector=field, extractMappings={})


def _navigate(element_id: str, x: int, label: str, to: str) -> dict:
    action = {"id": f"{element_id}-nav", "modelName": "GridActionNavigate", "modelVersion": MODEL_VERSION,
              "navType": "navigateToGrid", "toGridId": to}
    return _element(element_id, x, 0, label, "#d1c4e9", [action])


def grid(grid_id: str, url: str = URL, token: str | None = None) -> dict:
    label, rows = KEYBOARDS[grid_id]
    others = [g for g in KEYBOARDS if g != grid_id]
    elements = [_live(f"{grid_id}-state", 0, 2, "robot: ", "text", url, token),
                _live(f"{grid_id}-event", 2, 1, "event: ", "last_event", url, token)]
    elements += [_navigate(f"{grid_id}-to-{g}", 3 + i, KEYBOARDS[g][0], g) for i, g in enumerate(others)]
    for y, row in enumerate(rows, start=1):
        for x, cell in enumerate(row):
            if cell is not None:
                text, command, colour = cell
                eid = f"{grid_id}-{command.replace(' ', '-')}"
                elements.append(_element(eid, x, y, text, colour, [http_action(eid, command, url, token)]))
    return {"id": grid_id, "modelName": "GridData", "modelVersion": MODEL_VERSION, "label": _label(label),
            "rowCount": len(rows) + 1, "minColumnCount": COLUMNS, "gridElements": elements,
            "additionalFiles": [], "webRadios": [], "showGlobalGrid": False, "keyboardMode": None}


def backup(url: str = URL, token: str | None = None) -> dict:
    """The three keyboards as one AsTeRICS-Grid backup file (import it in "Manage grids"),
    calling the bridge at `url` with `token` (none: the shipped file, without auth fields)."""
    return {"grids": [grid(g, url, token) for g in KEYBOARDS], "dictionaries": [],
            "metadata": {"homeGridId": "asibot-drive"}}


def commands() -> list[str]:
    """Every command a button of the keyboards sends."""
    return [cell[1] for _, rows in KEYBOARDS.values() for row in rows for cell in row if cell is not None]


def text(url: str = URL, token: str | None = None) -> str:
    return json.dumps(backup(url, token), indent=1, ensure_ascii=False) + "\n"


if __name__ == "__main__":
    sys.stdout.write(text())
