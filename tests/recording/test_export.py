"""`asibot export --foxglove`: recordings rewritten by Foxglove's SDK, in Foxglove's schemas.

The file is read back with the mcap reader, as the Foxglove app reads it: each channel's schema
name and encoding, every well-known message decoded from the protobuf schema the file carries
(not by the SDK that wrote it), every JSON message validated against its JSON schema, and the
values (an image's bytes above all) compared with what was recorded.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader

from asibot import keys, messages as m
from asibot.cli.main import main as asibot
from asibot.poses import point_rotation
from asibot.recorder import export
from asibot.recorder.export import export_foxglove
from asibot.recorder.reader import NotARecording
from asibot.recorder.writer import LeanWriter

T0 = 1_795_000_000_123_456_789
ROBOT, BASE = "asibot-sim", "pioneer-sim"
DEPTH = np.arange(12, dtype=np.float32).reshape(3, 4) / 4
JPEG = b"\xff\xd8 not really \xff\xd9"
MAP = np.array([[0, 100, -1], [0, 0, 100]], np.int8)


def matrix_of_quaternion(q) -> np.ndarray:
    """3x3 rotation of a (w, x, y, z) quaternion: the export's quaternion, checked independently."""
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def write_recording(path: Path, items: list[tuple[str, bytes]], *, finish: bool = True) -> None:
    """A recording as the recorder writes it: msgpack payloads, one channel per key."""
    with open(path, "wb") as f:
        w = LeanWriter(f, chunk_size=512)
        w.start("", "test")
        channels: dict[str, int] = {}
        for i, (key, payload) in enumerate(items):
            if key not in channels:
                channels[key] = w.register_channel(key, "msgpack")
            w.add_message(channels[key], T0 + i * 1_000_000, payload, T0 + i * 1_000_000)
        if finish:
            w.finish()
        else:
            w.flush()


def session() -> list[tuple[str, bytes]]:
    return [(k, m.encode(msg)) for k, msg in [
        (keys.arm_state(ROBOT), m.ArmState(names=["q1", "q2"], positions=[0.1, -0.2], velocities=[0.0, 0.5],
                                           mode="position", stamp=T0)),
        (keys.cart_state(ROBOT), m.CartState(state="movl", pose=[0.5, 0.5, 1.0, math.pi / 2, 0.3],
                                             joints=[0, 0, 0, 0, 0], stamp=T0)),
        (keys.base_odom(BASE), m.Odometry(x=1.0, y=2.0, theta=math.pi / 2, vx=0.3, wz=-0.1, stamp=T0)),
        (keys.camera_depth(BASE, "front"), m.DepthImage(depth=DEPTH, stamp=T0)),
        (keys.camera_depth(BASE, "back"), m.DepthImage(depth=(DEPTH * 1000).astype(np.uint16), stamp=T0)),
        (keys.camera_rgb(BASE, "rgb"), m.RgbImage(jpeg=JPEG, width=4, height=3, stamp=T0)),
        (keys.camera_info(BASE, "front"), m.CameraInfo(width=4, height=3, fx=2.0, fy=2.5, cx=1.5, cy=1.0,
                                                       pose=[0.2, 0.0, 0.3, 0.5, -0.5, 0.5, -0.5],
                                                       frame="front_optical", stamp=T0)),
        (keys.scan(BASE), m.LaserScan(angle_min=-1.0, angle_increment=0.5, range_min=0.1, range_max=5.0,
                                      ranges=np.array([1.0, np.inf, 2.0, np.nan, 3.0]), stamp=T0)),
        (keys.nav_map(BASE), m.NavMap(resolution=0.05, origin=[-1.0, 2.0, 0.0], data=MAP, name="home", stamp=T0)),
        (keys.nav_pose(BASE), m.NavPose(x=1.0, y=2.0, theta=0.0, covariance=[0.1] * 9, localised=True,
                                        particles=np.array([[1.0, 2.0, 0.0], [1.1, 2.1, 0.2]], np.float32),
                                        stamp=T0)),
        (keys.nav_path(BASE), m.NavPath(goal_id=4, points=np.array([[0.0, 0.0], [1.0, 0.5]], np.float32),
                                        length=1.1, stamp=T0)),
        ("events", m.Event(level="warning", code="estop", text="Emergency stop engaged.", stamp=T0)),
        (keys.voice_audio("web-1"), m.AudioChunk(data=np.array([0.5, -1.0, 2.0], "<f4").tobytes(), rate=16000,
                                                 sample="float32", stamp=T0)),
        (keys.base_sonar(BASE), m.Sonar(ranges=[1.0, float("nan")], angles=[0.5, -0.5], stamp=T0)),
        (keys.gripper_state(ROBOT), m.GripperState(opening=0.04, holding=True, stamp=T0)),
    ]]


#: What session() becomes: the schema of each topic.
SCHEMAS = {
    keys.arm_state(ROBOT): "foxglove.JointStates", f"{keys.arm_state(ROBOT)}/extra": "asibot.ArmState.extra",
    keys.cart_state(ROBOT): "foxglove.PoseInFrame", f"{keys.cart_state(ROBOT)}/extra": "asibot.CartState.extra",
    keys.base_odom(BASE): "foxglove.Odometry", "/tf": "foxglove.FrameTransform",
    keys.camera_depth(BASE, "front"): "foxglove.RawImage", keys.camera_depth(BASE, "back"): "foxglove.RawImage",
    keys.camera_rgb(BASE, "rgb"): "foxglove.CompressedImage",
    keys.camera_info(BASE, "front"): "foxglove.CameraCalibration", keys.scan(BASE): "foxglove.LaserScan",
    keys.nav_map(BASE): "foxglove.Grid", f"{keys.nav_map(BASE)}/extra": "asibot.NavMap.extra",
    keys.nav_pose(BASE): "foxglove.PoseInFrame", f"{keys.nav_pose(BASE)}/particles": "foxglove.PosesInFrame",
    f"{keys.nav_pose(BASE)}/extra": "asibot.NavPose.extra",
    keys.nav_path(BASE): "foxglove.PosesInFrame", f"{keys.nav_path(BASE)}/extra": "asibot.NavPath.extra",
    "events": "foxglove.Log", keys.voice_audio("web-1"): "foxglove.RawAudio",
    keys.base_sonar(BASE): "asibot.Sonar", keys.gripper_state(ROBOT): "asibot.GripperState",
}
MESSAGES = len(SCHEMAS) + 1          # one message a topic, and /tf has two (odometry, camera mount)


def read_export(path: Path, protobuf) -> list[tuple[str, str, dict, int]]:
    """(topic, schema name, decoded message, log_time) of every exported message, each decoded
    as Foxglove decodes it: protobuf from the file's own schema, JSON checked against its schema."""
    out = []
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if schema.name.startswith("foxglove."):
                assert (schema.encoding, channel.message_encoding) == ("protobuf", "protobuf"), schema.name
                obj = protobuf(schema.data).decode(schema.name, message.data)
            else:
                assert (schema.encoding, channel.message_encoding) == ("jsonschema", "json"), schema.name
                obj, body = json.loads(message.data), json.loads(schema.data)
                jsonschema.validate(obj, body)
                assert body["title"] == schema.name
            out.append((channel.topic, schema.name, obj, message.log_time))
    return out


def test_every_topic_has_its_foxglove_schema_binary_or_json(tmp_path, protobuf):
    src = tmp_path / "session.mcap"
    write_recording(src, session())
    summary = export_foxglove(src)
    assert summary.output == tmp_path / "foxglove" / "session.mcap"
    assert summary.complete and summary.skipped == 0
    exported = read_export(summary.output, protobuf)
    assert summary.messages == len(exported) == MESSAGES
    assert {t: n for t, n, _, _ in exported} == SCHEMAS == summary.schemas


def test_images_are_their_bytes(tmp_path, protobuf):
    """Not base64 in JSON: the pixels and the JPEG as they were recorded, in a binary field."""
    src = tmp_path / "session.mcap"
    write_recording(src, session())
    msg = {t: o for t, _, o, _ in read_export(export_foxglove(src).output, protobuf)}
    front = msg[keys.camera_depth(BASE, "front")]
    assert (front["encoding"], front["width"], front["height"], front["step"]) == ("32FC1", 4, 3, 16)
    assert np.array_equal(np.frombuffer(front["data"], "<f4").reshape(3, 4), DEPTH)
    assert front["frame_id"] == "pioneer-sim/front_optical"
    back = msg[keys.camera_depth(BASE, "back")]
    assert (back["encoding"], back["step"]) == ("16UC1", 8)
    assert np.array_equal(np.frombuffer(back["data"], "<u2").reshape(3, 4), (DEPTH * 1000).astype(np.uint16))
    rgb = msg[keys.camera_rgb(BASE, "rgb")]
    assert (rgb["data"], rgb["format"]) == (JPEG, "jpeg")
    audio = msg[keys.voice_audio("web-1")]
    assert (audio["format"], audio["sample_rate"], audio["number_of_channels"]) == ("pcm-s16", 16000, 1)
    assert np.frombuffer(audio["data"], "<i2").tolist() == [16384, -32767, 32767]     # clipped to [-1, 1]


def test_values_survive_the_conversion(tmp_path, protobuf):
    src = tmp_path / "session.mcap"
    write_recording(src, session())
    out = read_export(export_foxglove(src, tmp_path / "out.mcap").output, protobuf)
    msg = {t: o for t, _, o, _ in out if t != "/tf"}
    tf = {o["child_frame_id"]: o for t, _, o, _ in out if t == "/tf"}
    stamp = {"seconds": T0 // 10**9, "nanos": T0 % 10**9}

    joints = msg[keys.arm_state(ROBOT)]
    assert joints["timestamp"] == stamp
    assert [(j["name"], j["position"], j["velocity"]) for j in joints["joints"]] == [("q1", 0.1, 0.0),
                                                                                  ("q2", -0.2, 0.5)]
    assert msg[f"{keys.arm_state(ROBOT)}/extra"] == {"mode": "position", "fault": "", "stamp": T0}

    # The tool pose: the point's convention (Rz(azimuth) Ry Rz) as a quaternion.
    cart = msg[keys.cart_state(ROBOT)]
    assert cart["frame_id"] == "asibot-sim/base"
    q = cart["pose"]["orientation"]
    assert matrix_of_quaternion([q["w"], q["x"], q["y"], q["z"]]) == pytest.approx(
        point_rotation(0.5, 0.5, math.pi / 2, 0.3))
    assert msg[f"{keys.cart_state(ROBOT)}/extra"]["state"] == "movl"

    odom = msg[keys.base_odom(BASE)]
    assert (odom["frame_id"], odom["body_frame_id"]) == ("pioneer-sim/odom", "pioneer-sim/base")
    assert odom["pose"]["position"] == {"x": 1.0, "y": 2.0, "z": 0}
    assert odom["pose"]["orientation"] == pytest.approx({"x": 0, "y": 0, "z": math.sqrt(.5), "w": math.sqrt(.5)})
    assert (odom["linear_velocity"]["x"], odom["angular_velocity"]["z"]) == (0.3, -0.1)
    assert tf["pioneer-sim/base"]["parent_frame_id"] == "pioneer-sim/odom"
    assert tf["pioneer-sim/front_optical"]["parent_frame_id"] == "pioneer-sim/base"
    assert tf["pioneer-sim/front_optical"]["rotation"] == {"x": -0.5, "y": 0.5, "z": -0.5, "w": 0.5}

    info = msg[keys.camera_info(BASE, "front")]
    assert info["K"] == [2.0, 0, 1.5, 0, 2.5, 1.0, 0, 0, 1] and len(info["P"]) == 12

    scan = msg[keys.scan(BASE)]
    assert (scan["start_angle"], scan["end_angle"]) == (-1.0, 1.0)
    assert scan["ranges"] == [1.0, 6.0, 2.0, 6.0, 3.0]          # no return: beyond range_max

    grid = msg[keys.nav_map(BASE)]
    assert (grid["frame_id"], grid["column_count"], grid["row_stride"], grid["cell_stride"]) == (
        "pioneer-sim/map", 3, 3, 1)
    assert grid["cell_size"] == {"x": 0.05, "y": 0.05}
    assert grid["pose"]["position"] == {"x": -1.0, "y": 2.0, "z": 0}
    assert [(f["name"], f["type"]) for f in grid["fields"]] == [("occupancy", 2)]    # int8
    assert np.array_equal(np.frombuffer(grid["data"], np.int8).reshape(2, 3), MAP)    # row 0 at the origin
    assert msg[f"{keys.nav_map(BASE)}/extra"]["name"] == "home"

    pose = msg[keys.nav_pose(BASE)]
    assert pose["frame_id"] == "pioneer-sim/map" and pose["pose"]["position"] == {"x": 1.0, "y": 2.0, "z": 0}
    particles = msg[f"{keys.nav_pose(BASE)}/particles"]["poses"]
    assert [p["position"]["x"] for p in particles] == pytest.approx([1.0, 1.1])
    assert msg[f"{keys.nav_pose(BASE)}/extra"]["localised"] is True
    path = msg[keys.nav_path(BASE)]
    assert [(p["position"]["x"], p["position"]["y"]) for p in path["poses"]] == [(0, 0), (1.0, 0.5)]
    assert msg[f"{keys.nav_path(BASE)}/extra"]["goal_id"] == 4

    log = msg["events"]
    assert (log["level"], log["message"]) == (3, "[estop] Emergency stop engaged.")       # warning

    sonar = msg[keys.base_sonar(BASE)]
    assert sonar["ranges"] == [1.0, None]                       # JSON has no NaN


def test_log_time_is_the_recorded_time_and_the_stamp_the_message_timestamp(tmp_path, protobuf):
    src = tmp_path / "session.mcap"
    state = m.ArmState(names=["q1"], positions=[0.1], velocities=[], stamp=T0 - 5_000_000)
    write_recording(src, [(keys.arm_state(ROBOT), m.encode(state))])
    with open(export_foxglove(src).output, "rb") as f:
        exported = {c.topic: (s, msg) for s, c, msg in make_reader(f).iter_messages()}
    schema, message = exported[keys.arm_state(ROBOT)]
    assert message.log_time == message.publish_time == T0     # when the recorder received it
    stamp = protobuf(schema.data).decode(schema.name, message.data)["timestamp"]
    assert stamp["seconds"] * 10**9 + stamp["nanos"] == T0 - 5_000_000


def test_a_topic_keeps_the_type_of_its_first_message(tmp_path):
    """A channel has one schema: another type's messages on its key are counted, not written."""
    src = tmp_path / "session.mcap"
    key = keys.base_battery(BASE)
    write_recording(src, [(key, m.encode(m.Battery(volts=12.5))), (key, m.encode(m.Sonar(ranges=[], angles=[]))),
                          (key, m.encode(m.Battery(volts=12.4)))])
    summary = export_foxglove(src)
    assert (summary.messages, summary.skipped, summary.schemas) == (2, 1, {key: "asibot.Battery"})


def test_a_bad_message_is_skipped_and_the_rest_exported(tmp_path):
    src = tmp_path / "session.mcap"
    bad = m.pack({"_type": "ArmState", "names": ["q1"], "positions": "oops", "velocities": [], "stamp": T0})
    write_recording(src, [(keys.arm_state(ROBOT), bad), (keys.arm_state(ROBOT), b"\xc1 not msgpack")] + session())
    summary = export_foxglove(src)
    assert summary.skipped == 2 and summary.messages == MESSAGES


def test_a_recording_whose_writer_was_killed_exports_up_to_its_last_chunk(tmp_path, protobuf):
    src = tmp_path / "crashed.mcap"
    write_recording(src, session() * 3, finish=False)
    data = src.read_bytes()
    src.write_bytes(data[: len(data) // 2])           # killed while writing a chunk
    summary = export_foxglove(src)
    assert not summary.complete
    assert 0 < summary.messages < 3 * MESSAGES
    assert len(read_export(summary.output, protobuf)) == summary.messages


def test_bad_input_changes_nothing(tmp_path, monkeypatch):
    notes = tmp_path / "notes.mcap"
    notes.write_text("not a recording")
    with pytest.raises(NotARecording):
        export_foxglove(notes)
    src = tmp_path / "session.mcap"
    write_recording(src, session())
    before = src.read_bytes()
    with pytest.raises(ValueError, match="would overwrite the recording"):
        export_foxglove(src, src)
    assert src.read_bytes() == before
    # A crash half-way leaves neither a partial file nor a damaged earlier export.
    out = tmp_path / "out.mcap"
    out.write_bytes(b"an earlier export")
    def crash(key, body):
        raise RuntimeError("disk on fire")
    monkeypatch.setattr(export, "convert", crash)
    with pytest.raises(RuntimeError):
        export_foxglove(src, out)
    assert out.read_bytes() == b"an earlier export"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.mcap", "out.mcap", "session.mcap"]


def test_the_command_line(tmp_path, capsys):
    src = tmp_path / "session.mcap"
    write_recording(src, session())
    assert asibot(["export", str(src), "--foxglove", "-v"]) == 0
    out = capsys.readouterr().out
    assert f"wrote {MESSAGES} messages on {len(SCHEMAS)} topics to {tmp_path / 'foxglove' / 'session.mcap'}" in out
    assert "foxglove.RawImage" in out and "asibot.Sonar" in out
    assert asibot(["export", str(tmp_path / "missing.mcap")]) == 1
    assert "no such recording" in capsys.readouterr().err
    (tmp_path / "a-file").write_text("")
    assert asibot(["export", str(src), "-o", str(tmp_path / "a-file" / "out.mcap")]) == 1
    assert "could not write the export" in capsys.readouterr().err
    assert asibot(["export", str(src), "-o", str(src)]) == 2
    assert "would overwrite the recording" in capsys.readouterr().err
    # Exports live apart from the recordings, so `asibot recordings` does not list them.
    assert asibot(["recordings", str(tmp_path)]) == 0
    assert "foxglove" not in capsys.readouterr().out
