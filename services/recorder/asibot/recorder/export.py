"""Export a recording so Foxglove (or Lichtblick) opens it: JSON messages, foxglove.* schemas.

Recordings are msgpack, which Foxglove cannot decode (reference middleware.md 0.7), so the
export rewrites every message as JSON in a new MCAP file. Messages with a Foxglove meaning
get its schema, so the 3D, Image, Log and Plot panels understand them:

| our message | topic                | foxglove schema                                   |
|-------------|----------------------|---------------------------------------------------|
| ArmState    | same key             | foxglove.JointStates (+ mode, fault)              |
| CartState   | same key             | foxglove.PoseInFrame (tool pose, arm base frame)  |
| Odometry    | same key, and /tf    | foxglove.PoseInFrame, foxglove.FrameTransform     |
| DepthImage  | same key             | foxglove.RawImage (32FC1 metres, 16UC1 mm)         |
| RgbImage    | same key             | foxglove.CompressedImage (jpeg)                   |
| CameraInfo  | same key, and /tf    | foxglove.CameraCalibration, foxglove.FrameTransform |
| LaserScan   | same key             | foxglove.LaserScan                                |
| Event       | same key             | foxglove.Log                                      |

Everything else keeps its own fields under an `asibot.<Type>` JSON schema built from the
message dataclass, so no topic is lost. Bytes become base64 (as Foxglove's JSON expects),
numpy arrays lists, and non-finite numbers null (JSON has no NaN).
"""

from __future__ import annotations

import base64
import dataclasses
import json
import math
import os
import threading
import typing
from pathlib import Path
from typing import Any, Callable

import msgpack
import numpy as np
from mcap.writer import CompressionType, Writer

from asibot import keys, messages, robots
from asibot.errors import MessageError
from asibot.messages import REGISTRY, TYPE_FIELD, decode_any
from asibot.poses import point_rotation, quaternion_wxyz, yaw_quaternion_wxyz
from asibot.recorder.reader import Reading, check_recording

TF_TOPIC = "/tf"
LEVELS = {"debug": 1, "info": 2, "warning": 3, "error": 4, "fatal": 5}


@dataclasses.dataclass
class ExportSummary:
    source: Path
    output: Path
    messages: int = 0          # messages written
    skipped: int = 0           # payloads that were not MessagePack, or not a valid message
    schemas: dict[str, str] = dataclasses.field(default_factory=dict)   # topic -> schema name
    complete: bool = True      # False when the source ended in a truncated chunk
    live: bool = False         # the source was being written when the export began
    stopped: bool = False      # a follow was ended by `stop` (Ctrl-C), not by the writer


# ---------------------------------------------------------------- JSON schemas
_TIME = {"type": "object", "title": "time",
         "properties": {"sec": {"type": "integer", "minimum": 0},
                        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}
_VEC3 = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
_QUAT = {"type": "object", "properties": {k: {"type": "number"} for k in "xyzw"}}
_POSE = {"type": "object", "properties": {"position": _VEC3, "orientation": _QUAT}}
_BYTES = {"type": "string", "contentEncoding": "base64"}
_NUMBERS = {"type": "array", "items": {"type": "number"}}


def _schema(title: str, **properties: Any) -> dict:
    return {"title": title, "type": "object", "properties": properties}


FOXGLOVE_SCHEMAS: dict[str, dict] = {
    "foxglove.JointStates": _schema(
        "foxglove.JointStates", timestamp=_TIME,
        joints={"type": "array", "items": {"type": "object", "properties": {
            "name": {"type": "string"}, "position": {"type": "number"}, "velocity": {"type": "number"}}}}),
    "foxglove.PoseInFrame": _schema("foxglove.PoseInFrame", timestamp=_TIME, frame_id={"type": "string"},
                                    pose=_POSE),
    "foxglove.FrameTransform": _schema(
        "foxglove.FrameTransform", timestamp=_TIME, parent_frame_id={"type": "string"},
        child_frame_id={"type": "string"}, translation=_VEC3, rotation=_QUAT),
    "foxglove.RawImage": _schema(
        "foxglove.RawImage", timestamp=_TIME, frame_id={"type": "string"}, width={"type": "integer"},
        height={"type": "integer"}, encoding={"type": "string"}, step={"type": "integer"}, data=_BYTES),
    "foxglove.CompressedImage": _schema("foxglove.CompressedImage", timestamp=_TIME,
                                        frame_id={"type": "string"}, data=_BYTES, format={"type": "string"}),
    "foxglove.CameraCalibration": _schema(
        "foxglove.CameraCalibration", timestamp=_TIME, frame_id={"type": "string"}, width={"type": "integer"},
        height={"type": "integer"}, distortion_model={"type": "string"}, D=_NUMBERS, K=_NUMBERS,
        R=_NUMBERS, P=_NUMBERS),
    "foxglove.LaserScan": _schema(
        "foxglove.LaserScan", timestamp=_TIME, frame_id={"type": "string"}, pose=_POSE,
        start_angle={"type": "number"}, end_angle={"type": "number"}, ranges=_NUMBERS, intensities=_NUMBERS),
    "foxglove.Log": _schema(
        "foxglove.Log", timestamp=_TIME, level={"type": "integer", "minimum": 0, "maximum": 5},
        message={"type": "string"}, name={"type": "string"}, file={"type": "string"},
        line={"type": "integer", "minimum": 0}),
}


def _json_type(tp: Any) -> dict:
    """JSON schema of one dataclass field annotation."""
    origin = typing.get_origin(tp)
    if tp is float:
        return {"type": ["number", "null"]}
    if tp is int:
        return {"type": "integer"}
    if tp is bool:
        return {"type": "boolean"}
    if tp is str:
        return {"type": "string"}
    if tp is bytes:
        return dict(_BYTES)
    if tp is np.ndarray:
        return {"type": "array"}
    if origin is list:
        (item,) = typing.get_args(tp) or (Any,)
        return {"type": "array", "items": _json_type(item)}
    if origin is dict or tp is dict:
        return {"type": "object"}
    return {}


def message_schema(type_name: str) -> dict:
    """`asibot.<Type>`: the JSON schema of one of our message types, from its dataclass."""
    cls = REGISTRY.get(type_name)
    if cls is None:
        return {"title": f"asibot.{type_name}", "type": "object"}
    hints = typing.get_type_hints(cls)
    return _schema(f"asibot.{type_name}", **{f.name: _json_type(hints[f.name]) for f in dataclasses.fields(cls)})


# ---------------------------------------------------------------- conversions
def _time(ns: int) -> dict:
    ns = max(int(ns), 0)
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _xyz(v: Any) -> dict:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _xyzw(q_wxyz: Any) -> dict:
    return {"x": float(q_wxyz[1]), "y": float(q_wxyz[2]), "z": float(q_wxyz[3]), "w": float(q_wxyz[0])}


def _robot_of(key: str) -> str:
    """The robot whose frames a message is in; keys outside `rb/<robot>/` hang off "world"."""
    return keys.robot_of(key) or "world"


def _camera_frame(key: str) -> str:
    """`<robot>/<camera>_optical`, from the key alone, so the images (which carry no frame)
    and the calibration and transform of their camera always agree."""
    return f"{_robot_of(key)}/{keys.camera_of(key) or 'camera'}_optical"


def _base_frame(key: str) -> str:
    return f"{_robot_of(key)}/base"


def _arm_frame(key: str) -> str:
    """The frame Cartesian poses are in: the arm's base, which is the robot's on the ASIBOT."""
    robot = _robot_of(key)
    spec = robots.get(robot) if robot in robots.ids() else None
    return f"{robot}/{spec.base_link}" if spec is not None and spec.has_base else _base_frame(key)


Out = list[tuple[str, str, dict]]          # (topic, schema name, JSON object)


def _arm_state(key: str, m: dict) -> Out:
    joints = [{"name": n, "position": p, "velocity": v}
              for n, p, v in zip(m["names"], m["positions"], m["velocities"] or [math.nan] * len(m["names"]))]
    return [(key, "foxglove.JointStates",
             {"timestamp": _time(m["stamp"]), "joints": joints, "mode": m.get("mode", ""),
              "fault": m.get("fault", "")})]


def _cart_state(key: str, m: dict) -> Out:
    pose = list(m["pose"])
    if len(pose) != 5:
        return []
    rot = quaternion_wxyz(point_rotation(pose[0], pose[1], pose[3], pose[4]))
    return [(key, "foxglove.PoseInFrame",
             {"timestamp": _time(m["stamp"]), "frame_id": _arm_frame(key),
              "pose": {"position": _xyz(pose), "orientation": _xyzw(rot)},
              "state": m["state"], "joints": list(m["joints"])})]


def _odometry(key: str, m: dict) -> Out:
    robot = _robot_of(key)
    t, here, rot = _time(m["stamp"]), [m["x"], m["y"], 0.0], _xyzw(yaw_quaternion_wxyz(m["theta"]))
    return [
        (key, "foxglove.PoseInFrame", {"timestamp": t, "frame_id": f"{robot}/odom",
                                       "pose": {"position": _xyz(here), "orientation": rot},
                                       "vx": m.get("vx", 0.0), "wz": m.get("wz", 0.0)}),
        (TF_TOPIC, "foxglove.FrameTransform", {"timestamp": t, "parent_frame_id": f"{robot}/odom",
                                               "child_frame_id": _base_frame(key),
                                               "translation": _xyz(here), "rotation": rot}),
    ]


def _depth(key: str, m: dict) -> Out:
    depth = np.asarray(m["depth"])
    if depth.ndim != 2:
        raise MessageError("DepthImage", "depth", f"expected an H x W image, got shape {depth.shape}")
    if depth.dtype.kind == "f":
        depth, encoding = depth.astype("<f4", copy=False), "32FC1"
    else:
        depth, encoding = depth.astype("<u2", copy=False), "16UC1"
    h, w = depth.shape
    return [(key, "foxglove.RawImage",
             {"timestamp": _time(m["stamp"]), "frame_id": _camera_frame(key), "width": w, "height": h,
              "encoding": encoding, "step": w * depth.itemsize, "data": np.ascontiguousarray(depth).tobytes()})]


def _rgb(key: str, m: dict) -> Out:
    return [(key, "foxglove.CompressedImage",
             {"timestamp": _time(m["stamp"]), "frame_id": _camera_frame(key), "data": m["jpeg"], "format": "jpeg"})]


def _camera_info(key: str, m: dict) -> Out:
    t, frame = _time(m["stamp"]), _camera_frame(key)
    fx, fy, cx, cy = (float(m[k]) for k in ("fx", "fy", "cx", "cy"))
    pose = list(m["pose"])
    calibration = {
        "timestamp": t, "frame_id": frame, "width": m["width"], "height": m["height"],
        "distortion_model": "plumb_bob", "D": [0.0] * 5,
        "K": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        "R": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "P": [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    }
    return [(key, "foxglove.CameraCalibration", calibration),
            (TF_TOPIC, "foxglove.FrameTransform", {"timestamp": t, "parent_frame_id": _base_frame(key),
                                                   "child_frame_id": frame, "translation": _xyz(pose[:3]),
                                                   "rotation": _xyzw(pose[3:7])})]


def _laser_scan(key: str, m: dict) -> Out:
    ranges = np.asarray(m["ranges"], float).ravel()
    start, step = float(m["angle_min"]), float(m["angle_increment"])
    # Out-of-range beams are "no return": Foxglove draws nothing for a range beyond range_max.
    ranges = np.where(np.isfinite(ranges), ranges, float(m["range_max"]) + 1.0)
    return [(key, "foxglove.LaserScan",
             {"timestamp": _time(m["stamp"]), "frame_id": _base_frame(key),
              "pose": {"position": _xyz([0, 0, 0]), "orientation": _xyzw([1, 0, 0, 0])},
              "start_angle": start, "end_angle": start + step * max(len(ranges) - 1, 0),
              "ranges": ranges.tolist(), "intensities": []})]


def _event(key: str, m: dict) -> Out:
    return [(key, "foxglove.Log",
             {"timestamp": _time(m["stamp"]), "level": LEVELS.get(m["level"], 0),
              "message": f"[{m['code']}] {m['text']}", "name": keys.robot_of(key) or key,
              "file": "", "line": 0})]


CONVERTERS: dict[str, Callable[[str, dict], Out]] = {
    "ArmState": _arm_state, "CartState": _cart_state, "Odometry": _odometry, "DepthImage": _depth,
    "RgbImage": _rgb, "CameraInfo": _camera_info, "LaserScan": _laser_scan, "Event": _event,
}


def convert(key: str, body: Any) -> Out:
    """The JSON messages (topic, schema, object) one recorded message becomes.

    A typed message is validated first, so a recording with a bad message exports the ones
    around it and reports the bad one instead of writing something Foxglove cannot draw.
    """
    type_name = body.get(TYPE_FIELD) if isinstance(body, dict) else None
    if type_name in REGISTRY:
        msg = messages.to_dict(messages.from_dict(REGISTRY[type_name], body))
        if type_name in CONVERTERS:
            return CONVERTERS[type_name](key, msg)
        return [(key, f"asibot.{type_name}", msg)]
    return [(key, f"asibot.{type_name or 'untyped'}", body if isinstance(body, dict) else {"value": body})]


# ---------------------------------------------------------------- JSON encoding
def _plain(v: Any) -> Any:
    """A JSON-ready copy: bytes -> base64, arrays -> lists, NaN/inf -> null."""
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, (bytes, bytearray, memoryview)):
        return base64.b64encode(bytes(v)).decode("ascii")
    if isinstance(v, np.ndarray):
        return _plain(v.tolist())
    if isinstance(v, np.generic):
        return _plain(v.item())
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, msgpack.ExtType):
        return {"ext": v.code, "data": base64.b64encode(v.data).decode("ascii")}
    return v


def to_json(obj: dict) -> bytes:
    return json.dumps(_plain(obj), separators=(",", ":"), allow_nan=False).encode()


# ---------------------------------------------------------------- the export
def default_output(source: Path) -> Path:
    """`recordings/foxglove/<name>.mcap`: beside the recordings, not among them."""
    return source.parent / "foxglove" / source.name


def export_foxglove(source: Path | str, output: Path | str | None = None, *, follow: bool = False,
                    stop: threading.Event | None = None) -> ExportSummary:
    """Write `output` (default: `default_output(source)`) and summarise it.

    A recording still being written is exported as it was when the export began; with
    `follow`, the export goes on with what the recorder appends until it closes the file or
    `stop` is set. The output appears atomically: a crash leaves no half-written file under
    its name, and the source recording is never touched.
    """
    source = Path(source)
    check_recording(source)
    output = Path(output) if output is not None else default_output(source)
    if output.resolve() == source.resolve():
        raise ValueError(f"the export would overwrite the recording {source}; choose another output file")
    summary = ExportSummary(source, output)
    output.parent.mkdir(parents=True, exist_ok=True)
    tmp = output.with_name(f".{output.name}.partial")
    try:
        with open(tmp, "wb") as f:
            writer = Writer(f, compression=CompressionType.ZSTD)
            writer.start(profile="", library="asibot export")
            schema_ids: dict[str, int] = {}
            channel_ids: dict[str, int] = {}
            records = Reading(source, follow=follow, stop=stop)
            for rec in records:
                try:
                    out = convert(rec.key, decode_any(rec.payload))
                except MessageError:
                    summary.skipped += 1
                    continue
                for topic, schema, obj in out:
                    if schema not in schema_ids:
                        body = FOXGLOVE_SCHEMAS.get(schema) or message_schema(schema.removeprefix("asibot."))
                        schema_ids[schema] = writer.register_schema(schema, "jsonschema", json.dumps(body).encode())
                    if topic not in channel_ids:
                        channel_ids[topic] = writer.register_channel(topic, "json", schema_ids[schema])
                        summary.schemas[topic] = schema
                    stamp = obj.get("timestamp")
                    publish = stamp["sec"] * 1_000_000_000 + stamp["nsec"] if stamp else rec.log_time
                    writer.add_message(channel_ids[topic], log_time=rec.log_time, data=to_json(obj),
                                       publish_time=publish)
                    summary.messages += 1
            writer.finish()
            f.flush()
            os.fsync(f.fileno())
        summary.complete, summary.live, summary.stopped = records.complete, records.live, records.stopped
        os.replace(tmp, output)
    finally:
        tmp.unlink(missing_ok=True)
    return summary

