"""The handheld pointer: a phone's tilt or a gamepad to a kinematics `pointer` request (the
mapping), and over the page's socket to the real kinematics server and an ideal driver."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from asibot.errors import RpcError
from asibot.testing import wait_until
from asibot.web.pointer import DeviceReading, PointerMapping, PointerSettings

from .conftest import API_ROBOT as ROBOT, settle

S = PointerSettings()
MAP = PointerMapping(S)


def phone(pitch=0.0, roll=0.0, deadman=True, forward=True, backward=False):
    return DeviceReading("phone", pitch, roll, deadman, forward, backward)


def pad(up=0.0, right=0.0, deadman=True, forward=True, backward=False):
    return DeviceReading("gamepad", up, right, deadman, forward, backward)


# --- the mapping -------------------------------------------------------------------------

def test_a_phone_held_flat_points_the_tool_ahead_and_raising_its_top_points_it_up():
    assert MAP.request(phone(0.0), None) == {"deadman": True, "direction": "forward", "yaw": 0.0, "speed": S.speed, "pitch": 90.0}
    assert MAP.request(phone(30.0), None)["pitch"] == 60.0
    assert MAP.request(phone(-30.0), None)["pitch"] == 120.0
    assert MAP.request(phone(-90.0), None)["pitch"] == 180.0                     # on edge, top down: straight down
    assert MAP.request(phone(170.0), None)["pitch"] == 90.0 - S.pitch_limit     # past the limit: held there


def test_tipping_the_phone_turns_the_arm_past_a_dead_band():
    assert MAP.request(phone(roll=S.deadband - 1), None)["yaw"] == 0.0
    left = MAP.request(phone(roll=-(S.deadband + 10)), None)["yaw"]
    right = MAP.request(phone(roll=S.deadband + 10), None)["yaw"]
    assert left == pytest.approx(10 * S.yaw_gain) and right == pytest.approx(-10 * S.yaw_gain)   # left: counter-clockwise
    assert MAP.request(phone(roll=-90), None)["yaw"] == S.max_yaw


def test_nothing_moves_without_the_deadman_and_without_a_direction_only_the_tool_turns():
    assert MAP.request(phone(deadman=False), None) is None
    assert MAP.request(phone(deadman=False, roll=-40.0), None) is None
    assert MAP.request(phone(forward=False), None)["direction"] == "hold"
    assert MAP.request(phone(forward=False, backward=True), None)["direction"] == "backward"
    assert MAP.request(phone(forward=True, backward=True), None)["direction"] == "hold"


def test_a_gamepad_stick_leads_the_tools_pitch_and_turns_the_arm():
    assert "pitch" not in MAP.request(pad(up=S.stick_deadband / 2), 90.0)      # in the dead band: keep it
    assert MAP.request(pad(up=1.0), 90.0)["pitch"] == pytest.approx(90.0 - S.stick_lead)   # up: nose up
    assert MAP.request(pad(up=-1.0), 90.0)["pitch"] == pytest.approx(90.0 + S.stick_lead)
    assert "pitch" not in MAP.request(pad(up=1.0), None)                       # no Cartesian state yet
    assert MAP.request(pad(right=1.0), 90.0)["yaw"] == pytest.approx(-S.max_yaw)
    assert MAP.request(pad(right=-0.1), 90.0)["yaw"] == 0.0


@pytest.mark.parametrize("message, words", [
    ({"source": "wiimote", "pitch": 0, "roll": 0, "deadman": True}, ["source", "phone, gamepad", "wiimote"]),
    ({"source": "phone", "pitch": float("nan"), "roll": 0, "deadman": True}, ["phone's pitch", "-180 to 180", "nan"]),
    ({"source": "phone", "pitch": 0, "roll": 91, "deadman": True}, ["phone's roll", "-90 to 90", "91"]),
    ({"source": "phone", "pitch": "up", "roll": 0, "deadman": True}, ["phone's pitch", "'up'"]),
    ({"source": "phone", "pitch": True, "roll": 0, "deadman": True}, ["phone's pitch", "True"]),
    ({"source": "gamepad", "pitch": 1.5, "roll": 0, "deadman": True}, ["gamepad's pitch", "-1 to 1", "1.5"]),
    ({"source": "phone", "roll": 0, "deadman": True}, ["phone's pitch", "None"]),
    ({"source": "phone", "pitch": 0, "roll": 0, "deadman": "yes"}, ["deadman", "true or false", "'yes'"]),
    ({"source": "phone", "pitch": [1] * 1000, "roll": 0, "deadman": True}, ["phone's pitch", "..."]),
])
def test_a_bad_reading_gets_a_sentence_naming_the_field(message, words):
    with pytest.raises(RpcError) as exc:
        DeviceReading.from_message(message)
    assert exc.value.code == "bad_request"
    assert all(w in exc.value.message for w in words), exc.value.message
    assert len(exc.value.message) < 200


# --- over the page's socket, to the real kinematics server -------------------------------------

@pytest.fixture
def socket(web):
    client, svc, driver, server = web
    settle(web)
    with client.websocket_connect(f"ws://127.0.0.1:8080/ws?session={svc.web.session}") as ws:
        yield ws, svc, driver, server
    server.ctl.stop()


def tool(svc) -> np.ndarray:
    return np.array(svc.fleet.point(ROBOT), float)


def point(ws, **reading) -> None:
    ws.send_text(json.dumps({"type": "point", "robot": ROBOT, "source": "phone", "pitch": 0.0, "roll": 0.0,
                             "deadman": True, "forward": True, **reading}))


def test_tilting_a_phone_with_the_deadman_moves_the_tip_along_the_tool_and_release_stops_it(socket):
    ws, svc, driver, server = socket
    start = tool(svc)
    azimuth = math.atan2(start[1], start[0])
    sent = len(driver.commands)

    def moved_out() -> bool:
        point(ws)                       # a beat, as the page sends every beat_ms
        now = tool(svc)
        return math.hypot(now[0], now[1]) - math.hypot(start[0], start[1]) > 0.01
    wait_until(moved_out, timeout=5, interval=0.05, message="the tip did not move forward")
    now = tool(svc)
    assert abs(now[3] - 90.0) < abs(start[3] - 90.0) or abs(start[3] - 90.0) < 1.0   # the tool turns toward level
    assert abs(math.atan2(now[1], now[0]) - azimuth) < math.radians(2)               # no roll: no turn
    ws.send_text(json.dumps({"type": "release"}))
    wait_until(lambda: server.ctl.state == "not_controlling", timeout=2, message="release did not stop the pointer")
    assert len(driver.commands) > sent


def test_tipping_the_phone_left_turns_the_arm_counter_clockwise(socket):
    ws, svc, driver, server = socket
    start = tool(svc)
    az0 = math.atan2(start[1], start[0])

    def turned() -> bool:
        point(ws, roll=-40.0, forward=True, backward=True)      # both: the tip stays, the tool turns
        now = tool(svc)
        return math.atan2(now[1], now[0]) - az0 > math.radians(2)
    wait_until(turned, timeout=5, interval=0.05, message="the arm did not turn left")
    ws.send_text(json.dumps({"type": "release"}))


def test_a_bad_reading_is_refused_with_a_sentence_and_nothing_moves(socket):
    ws, svc, driver, server = socket
    sent = len(driver.commands)
    point(ws, pitch=float("nan"))
    reply = ws.receive_json()
    while reply["type"] != "refused":
        reply = ws.receive_json()
    assert "phone's pitch" in reply["text"] and "Nothing moved" in reply["text"]
    assert server.ctl.state == "not_controlling"
    assert len(driver.commands) == sent


def test_a_pointer_for_a_robot_that_is_not_there_is_refused(socket):
    ws, svc, driver, server = socket
    ws.send_text(json.dumps({"type": "point", "robot": "nobody", "source": "phone", "pitch": 0, "roll": 0,
                             "deadman": True, "forward": True}))
    reply = ws.receive_json()
    while reply["type"] != "refused":
        reply = ws.receive_json()
    assert "nobody" in reply["text"]


def test_a_bad_reading_in_the_middle_of_a_stream_stops_the_arm_at_once(socket):
    ws, svc, driver, server = socket
    wait_until(lambda: (point(ws), server.ctl.state == "pointer")[1], timeout=5, interval=0.05,
               message="the stream did not start")
    point(ws, roll=float("inf"))
    wait_until(lambda: server.ctl.state == "not_controlling", timeout=2, interval=0.01,
               message="a bad reading mid-stream left the arm moving")
