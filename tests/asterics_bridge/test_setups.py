"""The shipped set-ups: the AsTeRICS-Grid keyboards against AsTeRICS-Grid's data model fields
(the reference's section 3.3 and its model classes), the ARE model against the plugin's ports."""

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from asibot.asterics_bridge import grids
from asibot.asterics_bridge import vocabulary as vocab
from asibot.asterics_bridge.servers import DEFAULT_HTTP_PORT, DEFAULT_TCP_PORT

SETUPS = Path(__file__).resolve().parents[2] / "services" / "asterics_bridge" / "asibot" / "asterics_bridge" / "setups"
GRIDS = SETUPS / "asibot-robot.grd.json"
MODEL = SETUPS / "switch-scanning-netconnection.acs"

GRID_DATA_FIELDS = {"id", "modelName", "modelVersion", "label", "rowCount", "minColumnCount", "gridElements",
                    "additionalFiles", "webRadios", "showGlobalGrid", "globalGridId", "keyboardMode",
                    "backgroundColor", "thumbnail", "locale", "isShortVersion"}
ELEMENT_FIELDS = {"id", "width", "height", "x", "y", "label", "image", "actions", "type", "backgroundColor",
                  "hidden", "vocabularyLevel"}
LIVE_FIELDS = {"mode", "updateSeconds", "liveAction", "dateTimeFormat", "appState", "extractMode",
               "extractSelector", "extractIndex", "extractMappings", "chooseValues"}
HTTP_FIELDS = {"id", "modelName", "modelVersion", "restUrl", "method", "contentType", "acceptHeader", "body",
               "authUser", "authPw", "noCorsMode", "useCorsProxy", "isLiveAction"}
NAVIGATE_FIELDS = {"id", "modelName", "modelVersion", "navType", "toGridId", "addToCollectElem",
                   "searchCollectedText", "searchText"}
ELEMENT_TYPES = {"ELEMENT_TYPE_NORMAL", "ELEMENT_TYPE_COLLECT", "ELEMENT_TYPE_PREDICTION", "ELEMENT_TYPE_LIVE"}
MODEL_VERSION = {"major": 6, "minor": 0, "patch": 0}
#: The CellBoard plugin's properties (its bundle_descriptor.xml in asterics/AsTeRICS, c846951a;
#: the 2013 ARE 2.2 lacks the nine from scanCycles on).
CELLBOARD_PROPERTIES = {
    "caption", "rows", "columns", "textColor", "backgroundColor", "scanColor", "scanMode", "hoverTime",
    "scanCycles", "hoverIndicator", "hoverFrameThickness", "enableEdit", "enableClickSelection",
    "commandSeparator", "keyboardFile", "ignoreKeyboardFileProperties", "displayGUI",
} | {f"{kind}{i}" for kind in ("cellText", "actionText", "cellImage") for i in range(1, 37)}


@pytest.fixture(scope="module")
def backup():
    return json.loads(GRIDS.read_text(encoding="utf-8-sig"))


def test_the_file_is_the_generator_s_output():
    assert GRIDS.read_text() == grids.text(), "regenerate: python -m asibot.asterics_bridge.grids > " + str(GRIDS)


def test_the_backup_holds_three_grids_and_a_home(backup):
    assert set(backup) == {"grids", "dictionaries", "metadata"}
    ids = [g["id"] for g in backup["grids"]]
    assert len(ids) == 3 == len(set(ids))
    assert backup["metadata"]["homeGridId"] in ids


def test_every_field_is_asterics_grid_s(backup):
    for g in backup["grids"]:
        assert set(g) <= GRID_DATA_FIELDS, set(g) - GRID_DATA_FIELDS
        assert g["modelName"] == "GridData" and json.loads(g["modelVersion"]) == MODEL_VERSION
        assert isinstance(g["label"], dict) and all(isinstance(v, str) for v in g["label"].values())
        assert isinstance(g["rowCount"], int) and isinstance(g["minColumnCount"], int)
        for e in g["gridElements"]:
            allowed = ELEMENT_FIELDS | (LIVE_FIELDS if e["type"] == "ELEMENT_TYPE_LIVE" else set())
            assert set(e) <= allowed, set(e) - allowed
            assert {"id", "width", "height", "x", "y", "label", "actions", "type"} <= set(e)
            assert e["type"] in ELEMENT_TYPES and isinstance(e["label"], dict)
            for a in e["actions"] + ([e["liveAction"]] if "liveAction" in e else []):
                fields = {"GridActionHTTP": HTTP_FIELDS, "GridActionNavigate": NAVIGATE_FIELDS}[a["modelName"]]
                assert set(a) <= fields, set(a) - fields
                assert json.loads(a["modelVersion"]) == MODEL_VERSION


def test_cells_fit_the_grid_and_do_not_overlap(backup):
    for g in backup["grids"]:
        taken = set()
        for e in g["gridElements"]:
            cells = {(e["x"] + dx, e["y"] + dy) for dx in range(e["width"]) for dy in range(e["height"])}
            assert all(0 <= x < g["minColumnCount"] and 0 <= y < g["rowCount"] for x, y in cells), e["id"]
            assert not cells & taken, e["id"]
            taken |= cells


def test_every_button_sends_a_command_of_the_vocabulary_to_the_bridge(backup):
    sent = []
    for g in backup["grids"]:
        for e in g["gridElements"]:
            for a in e["actions"]:
                if a["modelName"] == "GridActionHTTP":
                    assert a["restUrl"] == f"http://127.0.0.1:{DEFAULT_HTTP_PORT}/command"
                    assert (a["method"], a["contentType"]) == ("POST", "text/plain")
                    vocab.parse(a["body"])
                    sent.append(a["body"])
                else:
                    assert a["toGridId"] in [x["id"] for x in backup["grids"]]
    words = {vocab.parse(s).word for s in sent}
    assert set(vocab.PRIMITIVES) | set(vocab.ARM_STEPS) | {"stop", "grab", "release", "goto"} <= words
    assert {f"goto {p}" for p in grids.PLACES} <= set(sent)


def test_live_elements_read_status_fields(backup):
    lives = [e for g in backup["grids"] for e in g["gridElements"] if e["type"] == "ELEMENT_TYPE_LIVE"]
    assert lives
    for e in lives:
        action = e["liveAction"]
        assert action["restUrl"] == f"http://127.0.0.1:{DEFAULT_HTTP_PORT}/status" and action["method"] == "GET"
        assert action["isLiveAction"] is True
        assert e["mode"] == "MODE_ACTION_RESULT" and e["extractMode"] == "EXTRACT_JSON"
        assert e["extractSelector"] in ("text", "last_event", "state", "place", "moving", "battery")
        # AsTeRICS-Grid shows a label's "{0}" as it is while the value is empty (no nav, no event
        # yet): the value is appended to a label without one instead
        assert e["label"]["en"].strip() and "{0}" not in e["label"]["en"]


def test_the_are_model_wires_a_scanning_keyboard_to_netconnection():
    root = ET.parse(MODEL).getroot()
    assert root.tag == "model" and root.get("modelName")
    comps = {c.get("id"): c for c in root.iter("component") if c.get("type_id")}
    net = comps["NetConnection.1"]
    assert net.get("type_id") == "asterics.NetConnection"
    props = {p.get("name"): p.get("value") for p in net.iter("property")}
    assert props == {"connectionType": "1", "IP": "127.0.0.1", "port": str(DEFAULT_TCP_PORT),
                     "multisession": "false"}
    board = {p.get("name"): p.get("value") for p in comps["CellBoard.1"].iter("property")}
    # Every property of the plugin, as the ACS saves a model: the ARE 2.2 fails on a missing one
    assert set(board) == CELLBOARD_PROPERTIES, set(board) ^ CELLBOARD_PROPERTIES
    actions = [v for k, v in board.items() if k.startswith("actionText") and v]
    # rows, columns and scanMode are indexes into the ACS's combo boxes: rows "2" is 3 rows
    # (CellBoardInstance.getRowCount() is propRows + 1; seen as a 4 x 4 board in a real ARE)
    assert (int(board["rows"]) + 1, int(board["columns"]) + 1) == (3, 3) == (len(actions) // 3, 3)
    assert board["scanMode"] == "1"    # row-column: "none//row-column//column-row//directed//hover"
    for action in actions:
        vocab.parse(action)
    (channel,) = root.iter("channel")
    assert [(c.find("component").get("id"), c.find("port").get("id")) for c in channel] == [
        ("CellBoard.1", "selectedCellText"), ("NetConnection.1", "stringInputPort1")]
    for ec in root.iter("eventChannel"):
        assert len(ec.find("targets").findall("target")) == 1   # the ARE refuses two targets
    # One switch: a Timer scans on every second (an endless loop, started with the model)
    timer = {p.get("name"): p.get("value") for p in comps["Timer.1"].iter("property")}
    assert comps["Timer.1"].get("type_id") == "asterics.Timer"
    assert timer == {"mode": "2", "repeatCounter": "1", "timePeriod": "1000", "resolution": "50",
                     "waitPeriod": "0", "autostart": "true"}
    (scan,) = root.iter("eventChannel")
    assert [(e.find("component").get("id"), e.find("eventPort").get("id")) for e in scan.iter()
            if e.tag in ("source", "target")] == [("Timer.1", "periodFinished"), ("CellBoard.1", "scanMove")]
    # A GUI plugin without <gui> gets no screen area in the ARE: the keyboard would be invisible.
    gui = comps["CellBoard.1"].find("gui")
    area = {e.tag: int(e.text) for e in gui}
    assert list(area) == ["posX", "posY", "width", "height"] and area["width"] > 0 and area["height"] > 0
    window = root.find("modelGUI")
    assert [e.tag for e in window] == ["Decoration", "Fullscreen", "AlwaysOnTop", "ToSystemTray",
                                       "ShopControlPanel", "AREGUIWindow"]   # the schema's order
    assert list(root)[-1] is window and [c.tag for c in comps["CellBoard.1"]] == [
        "description", "properties", "layout", "gui"]


def test_the_docs_table_lists_every_word():
    doc = (Path(__file__).resolve().parents[2] / "docs" / "asterics.md").read_text()
    for w in vocab.WORDS:
        assert f"| `{w.word}{f' <{w.arg}>' if w.arg else ''}` |" in doc, w.word


def test_the_user_s_grids_carry_the_bridge_s_address_and_token(backup):
    """AsTeRICS-Grid sends authUser/authPw as Basic auth; the bridge reads the password."""
    mine = grids.backup("http://127.0.0.1:8091", "t0ken")
    actions = [a for g in mine["grids"] for e in g["gridElements"]
               for a in e["actions"] + ([e["liveAction"]] if "liveAction" in e else [])
               if a["modelName"] == "GridActionHTTP"]
    assert len(actions) == len([a for g in backup["grids"] for e in g["gridElements"]
                                for a in e["actions"] + ([e["liveAction"]] if "liveAction" in e else [])
                                if a["modelName"] == "GridActionHTTP"])
    for a in actions:
        assert set(a) <= HTTP_FIELDS and (a["authUser"], a["authPw"]) == (grids.AUTH_USER, "t0ken")
        assert a["restUrl"] in ("http://127.0.0.1:8091/command", "http://127.0.0.1:8091/status")
    shipped = json.dumps(backup)
    assert "authPw" not in shipped        # the shipped file cannot know the user's token
