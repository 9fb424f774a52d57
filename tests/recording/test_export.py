"""`asibot export --foxglove`: recordings rewritten as JSON with Foxglove's schemas.

Two independent checks on every exported message: it validates against the JSON schema the
file carries (jsonschema), and Foxglove's own SDK (foxglove-sdk) accepts its fields when it
builds the official message, so a misspelt or mistyped field fails here, not in the app.
"""

from __future__ import annotations

import base64
import json
import math
from pathlib import Path

import foxglove.messages as fm
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
    depth = np.arange(12, dtype=np.float32).reshape(3, 4) / 4
    return [(k, m.encode(msg)) for k, msg in [
        (keys.arm_state(ROBOT), m.ArmState(names=["q1", "q2"], positions=[0.1, -0.2], velocities=[0.0, 0.5],
                                           mode="position", stamp=T0)),
        (keys.cart_state(ROBOT), m.CartState(state="movl", pose=[0.5, 0.5, 1.0, math.pi / 2, 0.3],
                                             joints=[0, 0, 0, 0, 0], stamp=T0)),
        (keys.base_odom(BASE), m.Odometry(x=1.0, y=2.0, theta=math.pi / 2, vx=0.3, stamp=T0)),
        (keys.camera_depth(BASE, "front"), m.DepthImage(depth=depth, stamp=T0)),
        (keys.camera_depth(BASE, "back"), m.DepthImage(depth=(depth * 1000).astype(np.uint16), stamp=T0)),
        (keys.camera_rgb(BASE, "rgb"), m.RgbImage(jpeg=b"\xff\xd8 not really \xff\xd9", width=4, height=3,
                                                  stamp=T0)),
        (keys.camera_info(BASE, "front"), m.CameraInfo(width=4, height=3, fx=2.0, fy=2.5, cx=1.5, cy=1.0,
                                                       pose=[0.2, 0.0, 0.3, 0.5, -0.5, 0.5, -0.5],
                                                       frame="front_optical", stamp=T0)),
        (keys.scan(BASE), m.LaserScan(angle_min=-1.0, angle_increment=0.5, range_min=0.1, range_max=5.0,
                                      ranges=np.array([1.0, np.inf, 2.0, np.nan, 3.0]), stamp=T0)),
        ("events", m.Event(level="warning", code="estop", text="Emergency stop engaged.", stamp=T0)),
        (keys.base_sonar(BASE), m.Sonar(ranges=[1.0, float("nan")], angles=[0.5, -0.5], stamp=T0)),
        (keys.gripper_state(ROBOT), m.GripperState(opening=0.04, holding=True, stamp=T0)),
    ]]


def read_export(path: Path) -> list[tuple[str, str, dict, dict, int]]:
    """(topic, schema name, schema, message, log_time) of every exported message."""
    out = []
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            assert (schema.encoding, channel.message_encoding) == ("jsonschema", "json")
            out.append((channel.topic, schema.name, json.loads(schema.data), json.loads(message.data),
                        message.log_time))
    return out


# Foxglove's SDK builds its messages from keyword arguments: nested objects by field name.
NESTED = {"timestamp": lambda d: fm.Timestamp(d["sec"], d["nsec"]),
          "position": lambda d: fm.Vector3(**d), "translation": lambda d: fm.Vector3(**d),
          "orientation": lambda d: fm.Quaternion(**d), "rotation": lambda d: fm.Quaternion(**d),
          "pose": lambda d: fm.Pose(**{k: NESTED[k](v) for k, v in d.items()}),
          "joints": lambda js: [fm.JointState(**j) for j in js],
          "level": lambda v: getattr(fm.LogLevel, ["Unknown", "Debug", "Info", "Warning", "Error", "Fatal"][v])}
BYTES = {"data"}
OURS = {"mode", "fault", "state", "vx", "wz"}        # documented extra fields of ours


def foxglove_accepts(schema_name: str, obj: dict) -> None:
    cls = getattr(fm, schema_name.removeprefix("foxglove."))
    kwargs = {}
    for k, v in obj.items():
        if k in OURS or (k == "joints" and schema_name == "foxglove.PoseInFrame"):
            continue
        kwargs[k] = base64.b64decode(v) if k in BYTES else NESTED[k](v) if k in NESTED else v
    cls(**kwargs).encode()


def test_every_message_validates_and_foxglove_builds_the_official_types(tmp_path):
    src = tmp_path / "session.mcap"
    write_recording(src, session())
    summary = export_foxglove(src)
    assert summary.output == tmp_path / "foxglove" / "session.mcap"
    assert summary.complete and summary.skipped == 0
    exported = read_export(summary.output)
    assert summary.messages == len(exported) == 13       # 11 messages, + 2 transforms
    for topic, name, schema, obj, _ in exported:
        jsonschema.validate(obj, schema)
        assert schema["title"] == name
        if name.startswith("foxglove."):
            foxglove_accepts(name, obj)
    by_topic = {(t, n): o for t, n, _, o, _ in exported if t != "/tf"}
    assert set(n for _, n in by_topic) == {
        "foxglove.JointStates", "foxglove.PoseInFrame", "foxglove.RawImage", "foxglove.CompressedImage",
        "foxglove.CameraCalibration", "foxglove.LaserScan", "foxglove.Log", "asibot.Sonar",
        "asibot.GripperState"}


def test_values_survive_the_conversion(tmp_path):
    src = tmp_path / "session.mcap"
    write_recording(src, session())
    out = read_export(export_foxglove(src, tmp_path / "out.mcap").output)
    msg = {(t, n): o for t, n, _, o, _ in out if t != "/tf"}
    tf = {o["child_frame_id"]: o for t, _, _, o, _ in out if t == "/tf"}
    stamp = {"sec": T0 // 10**9, "nsec": T0 % 10**9}

    joints = msg[keys.arm_state(ROBOT), "foxglove.JointStates"]
    assert joints["timestamp"] == stamp
    assert joints["joints"] == [{"name": "q1", "position": 0.1, "velocity": 0.0},
                                {"name": "q2", "position": -0.2, "velocity": 0.5}]
    assert joints["mode"] == "position"

    # The tool pose: the point's convention (Rz(azimuth) Ry Rz) as a quaternion.
    cart = msg[keys.cart_state(ROBOT), "foxglove.PoseInFrame"]
    assert cart["frame_id"] == "asibot-sim/base"
    q = cart["pose"]["orientation"]
    assert matrix_of_quaternion([q["w"], q["x"], q["y"], q["z"]]) == pytest.approx(
        point_rotation(0.5, 0.5, math.pi / 2, 0.3))

    odom = msg[keys.base_odom(BASE), "foxglove.PoseInFrame"]
    assert odom["frame_id"] == "pioneer-sim/odom" and odom["pose"]["position"] == {"x": 1.0, "y": 2.0, "z": 0.0}
    assert odom["pose"]["orientation"] == pytest.approx({"x": 0, "y": 0, "z": math.sqrt(.5), "w": math.sqrt(.5)})
    assert tf["pioneer-sim/base"]["parent_frame_id"] == "pioneer-sim/odom"
    assert tf["pioneer-sim/front_optical"]["parent_frame_id"] == "pioneer-sim/base"
    assert tf["pioneer-sim/front_optical"]["rotation"] == {"x": -0.5, "y": 0.5, "z": -0.5, "w": 0.5}

    front = msg[keys.camera_depth(BASE, "front"), "foxglove.RawImage"]
    assert (front["encoding"], front["width"], front["height"], front["step"]) == ("32FC1", 4, 3, 16)
    assert np.frombuffer(base64.b64decode(front["data"]), "<f4").reshape(3, 4)[2, 3] == pytest.approx(11 / 4)
    assert front["frame_id"] == "pioneer-sim/front_optical"
    back = msg[keys.camera_depth(BASE, "back"), "foxglove.RawImage"]
    assert (back["encoding"], back["step"]) == ("16UC1", 8)
    assert np.frombuffer(base64.b64decode(back["data"]), "<u2")[-1] == 2750

    rgb = msg[keys.camera_rgb(BASE, "rgb"), "foxglove.CompressedImage"]
    assert base64.b64decode(rgb["data"]) == b"\xff\xd8 not really \xff\xd9" and rgb["format"] == "jpeg"

    info = msg[keys.camera_info(BASE, "front"), "foxglove.CameraCalibration"]
    assert info["K"] == [2.0, 0, 1.5, 0, 2.5, 1.0, 0, 0, 1] and len(info["P"]) == 12

    scan = msg[keys.scan(BASE), "foxglove.LaserScan"]
    assert (scan["start_angle"], scan["end_angle"]) == (-1.0, 1.0)
    assert scan["ranges"] == [1.0, 6.0, 2.0, 6.0, 3.0]          # no return: beyond range_max

    log = msg["events", "foxglove.Log"]
    assert (log["level"], log["message"]) == (3, "[estop] Emergency stop engaged.")

    sonar = msg[keys.base_sonar(BASE), "asibot.Sonar"]
    assert sonar["ranges"] == [1.0, None]                       # JSON has no NaN


def test_log_time_is_kept_and_publish_time_is_the_message_stamp(tmp_path):
    src = tmp_path / "session.mcap"
    write_recording(src, session()[:1])
    with open(export_foxglove(src).output, "rb") as f:
        [(_, _, message)] = list(make_reader(f).iter_messages())
    assert (message.log_time, message.publish_time) == (T0, T0)


def test_a_bad_message_is_skipped_and_the_rest_exported(tmp_path):
    src = tmp_path / "session.mcap"
    bad = m.pack({"_type": "ArmState", "names": ["q1"], "positions": "oops", "velocities": [], "stamp": T0})
    write_recording(src, [(keys.arm_state(ROBOT), bad), (keys.arm_state(ROBOT), b"\xc1 not msgpack")] + session())
    summary = export_foxglove(src)
    assert summary.skipped == 2 and summary.messages == 13


def test_a_recording_whose_writer_was_killed_exports_up_to_its_last_chunk(tmp_path):
    src = tmp_path / "crashed.mcap"
    write_recording(src, session() * 3, finish=False)
    data = src.read_bytes()
    src.write_bytes(data[: len(data) // 2])           # killed while writing a chunk
    summary = export_foxglove(src)
    assert not summary.complete
    assert 0 < summary.messages < 3 * 13
    assert len(read_export(summary.output)) == summary.messages


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
    assert f"wrote 13 messages on 12 topics to {tmp_path / 'foxglove' / 'session.mcap'}" in out
    assert "foxglove.RawImage" in out
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
