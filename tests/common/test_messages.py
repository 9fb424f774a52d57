import math

import msgpack
import numpy as np
import pytest
from hypothesis import given, strategies as st

from asibot import messages as m
from asibot.errors import MessageError


def test_every_registered_message_round_trips():
    samples = [
        m.ArmState(names=["q1", "q2"], positions=[0.1, -0.2], velocities=[0.0, 1.5], mode="position"),
        m.ArmCommand(mode="velocity", values=[0.1, 0.2]),
        m.GripperState(opening=0.04, holding=True), m.GripperCommand(opening=0.0),
        m.Twist(vx=0.3, wz=-0.1), m.Odometry(x=1, y=2, theta=0.5),
        m.Sonar(ranges=[1.0] * 16, angles=[0.0] * 16), m.Bumpers(front=[False] * 5, rear=[True] * 5),
        m.Battery(volts=12.6),
        m.DepthImage(depth=np.arange(12, dtype=np.float32).reshape(3, 4)),
        m.RgbImage(jpeg=b"\xff\xd8jpeg", width=4, height=3),
        m.CameraInfo(width=4, height=3, fx=2, fy=2, cx=2, cy=1.5, pose=[0, 0, 0, 1, 0, 0, 0]),
        m.LaserScan(angle_min=-1, angle_increment=0.01, range_min=0.1, range_max=10,
                    ranges=np.ones(200, np.float32)),
        m.Pose2D(x=1, y=2, theta=3), m.CartState(state="movl", pose=[0, 0, 1.4, 0, 0], joints=[0] * 5),
        m.EStop(engaged=True, reason="button"), m.Event(level="warning", code="obstacle", text="Obstacle ahead."),
        m.Health(service="s", instance="i", uptime=1.0, pid=3, details={"a": 1}),
        m.NavPose(x=1, y=2, theta=0.5, covariance=[0.1] * 9, localised=True,
                  particles=np.ones((4, 3), np.float32)),
        m.NavMap(resolution=0.05, origin=[-1.0, -2.0, 0.0], data=np.full((3, 4), -1, np.int8), name="apartment"),
        m.NavPath(goal_id=3, points=np.zeros((2, 2), np.float32), length=1.5),
        m.NavStatus(goal_id=3, state="active", text="driving to fridge, 3.2 m left", place="fridge",
                    goal=[1.0, 2.0, 0.0], distance=3.2, eta=8.0, speed=2, width=3),
        m.AudioChunk(data=b"\x00\x01" * 160, rate=16000),
        m.VoiceHeard(source="web-1", action="launch", text="drink", word="drink", confidence=0.8,
                     task="Drink water", said="Starting Drink water."),
    ]
    assert {type(s).__name__ for s in samples} == set(m.REGISTRY)
    for msg in samples:
        back = m.decode(type(msg), m.encode(msg))
        for name in msg._fields:
            a, b = getattr(msg, name), getattr(back, name)
            if isinstance(a, np.ndarray):
                assert a.dtype == b.dtype and np.array_equal(a, b)
            else:
                assert a == b, name


def test_every_message_has_a_stamp_in_nanoseconds():
    msg = m.Battery(volts=12.0)
    assert msg.stamp > 1_600_000_000 * 10**9


@given(st.lists(st.floats(allow_nan=False, allow_infinity=False), max_size=10))
def test_float_lists_survive_exactly(values):
    msg = m.ArmCommand(mode="position", values=values)
    assert m.decode(m.ArmCommand, m.encode(msg)).values == values


@pytest.mark.parametrize("payload, field", [
    ({"names": ["q1"], "positions": ["high"], "velocities": []}, "positions[]"),
    ({"names": ["q1"], "velocities": []}, "positions"),
    ({"names": "q1", "positions": [], "velocities": []}, "names"),
    ({"names": [], "positions": [], "velocities": [], "mode": 3}, "mode"),
    ({"_type": "Twist", "vx": 1.0, "wz": 0.0}, "_type"),
])
def test_wrong_fields_are_named(payload, field):
    with pytest.raises(MessageError) as err:
        m.decode(m.ArmState, msgpack.packb(payload))
    assert err.value.field == field
    assert field.rstrip("[]") in str(err.value)


@pytest.mark.parametrize("data", [b"", b"\xc1", b"\x93\x01\x02\x03", msgpack.packb([1, 2]), b"\xff" * 7])
def test_garbage_is_a_message_error(data):
    with pytest.raises(MessageError):
        m.decode(m.Twist, data)


def test_values_that_would_move_a_robot_must_be_finite():
    for bad in (math.nan, math.inf):
        with pytest.raises(MessageError, match="finite"):
            m.decode(m.Twist, msgpack.packb({"vx": bad, "wz": 0.0}))
    with pytest.raises(MessageError, match="mode"):
        m.ArmCommand(mode="fly", values=[0.0])


def test_bools_are_not_numbers_and_ints_are_floats():
    with pytest.raises(MessageError):
        m.decode(m.Battery, msgpack.packb({"volts": True}))
    assert m.decode(m.Battery, msgpack.packb({"volts": 12})).volts == 12.0


def test_unknown_fields_are_ignored_for_forward_compatibility():
    msg = m.decode(m.Battery, msgpack.packb({"volts": 12.5, "temperature": 40}))
    assert msg.volts == 12.5


def test_numpy_object_arrays_are_refused():
    with pytest.raises(TypeError):
        m.pack({"a": np.array([object()])})
