"""Our messages as Foxglove messages: one function per message type, shared by the export (a
recording to an MCAP file) and the live view (the bus to a WebSocket server), so a session
looks the same in Foxglove recorded or live.

A message with a well-known Foxglove schema becomes that (protobuf, binary: an image's bytes
stay bytes), so the 3D, Image, Log and Plot panels understand it:

| our message | topic: Foxglove schema (protobuf)                               | on key/extra (JSON)   |
|-------------|-----------------------------------------------------------------|-----------------------|
| ArmState    | key: foxglove.JointStates                                       | mode, fault           |
| CartState   | key: foxglove.PoseInFrame (tool, in the arm's base frame)       | state, joints         |
| Odometry    | key: foxglove.Odometry; /tf: foxglove.FrameTransform odom->base |                       |
| DepthImage  | key: foxglove.RawImage (32FC1 metres, 16UC1 mm)                 |                       |
| RgbImage    | key: foxglove.CompressedImage (jpeg)                            |                       |
| CameraInfo  | key: foxglove.CameraCalibration; /tf: base->camera mount        |                       |
| LaserScan   | key: foxglove.LaserScan (no return: beyond range_max)           |                       |
| NavMap      | key: foxglove.Grid (int8 occupancy, map frame)                  | name                  |
| NavPose     | key: foxglove.PoseInFrame; key/particles: foxglove.PosesInFrame | covariance, localised |
| NavPath     | key: foxglove.PosesInFrame (map frame)                          | goal_id, length       |
| Event       | key: foxglove.Log ("[code] text")                               |                       |
| AudioChunk  | key: foxglove.RawAudio (pcm-s16)                                |                       |

What a well-known schema has no place for goes beside it on `<key>/extra`, as JSON under
`asibot.<Type>.extra`. Every other message keeps its own fields as JSON under an
`asibot.<Type>` schema built from its dataclass (`jsonable`), so no topic is lost.
"""

from __future__ import annotations

from typing import Any, Callable, Union

import numpy as np
from foxglove import messages as fm

from asibot import keys, messages
from asibot.errors import MessageError
from asibot.messages import REGISTRY, TYPE_FIELD
from asibot.poses import point_rotation, quaternion_wxyz, yaw_quaternion_wxyz
from asibot.recorder import frames
from asibot.recorder.jsonable import Json, extra, whole

#: What one message becomes on one topic: a well-known Foxglove message, or JSON.
Message = Union[fm.FoxgloveMessage, Json]
Out = list[tuple[str, Message]]

LEVELS = {"debug": fm.LogLevel.Debug, "info": fm.LogLevel.Info, "warning": fm.LogLevel.Warning,
          "error": fm.LogLevel.Error, "fatal": fm.LogLevel.Fatal}
#: The samples of an AudioChunk, by its `sample` field.
SAMPLES: dict[str, np.dtype] = {"int16": np.dtype("<i2"), "float32": np.dtype("<f4")}


def _time(ns: int) -> fm.Timestamp:
    ns = max(int(ns), 0)
    return fm.Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def _vector(v: Any) -> fm.Vector3:
    return fm.Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _quaternion(q_wxyz: Any) -> fm.Quaternion:
    return fm.Quaternion(x=float(q_wxyz[1]), y=float(q_wxyz[2]), z=float(q_wxyz[3]), w=float(q_wxyz[0]))


def _planar(x: float, y: float, theta: float) -> fm.Pose:
    """A pose in a plane (m, m, rad), as Foxglove's 3D pose."""
    return fm.Pose(position=_vector([x, y, 0.0]), orientation=_quaternion(yaw_quaternion_wxyz(theta)))


def _array(m: dict, type_name: str, field: str, ndim: int, columns: int | None = None) -> np.ndarray:
    """An array field with the shape the conversion needs, or the MessageError that says not."""
    a = np.asarray(m[field])
    if a.ndim != ndim or (columns is not None and a.shape[1] < columns):
        want = f"N x {columns}" if columns else "H x W" if ndim == 2 else f"{ndim}-D"
        raise MessageError(type_name, field, f"expected an {want} array, got shape {a.shape}")
    return a


def arm_state(key: str, m: dict) -> Out:
    velocities = m["velocities"] or [None] * len(m["names"])
    joints = [fm.JointState(name=n, position=p, velocity=v)
              for n, p, v in zip(m["names"], m["positions"], velocities)]
    return [(key, fm.JointStates(timestamp=_time(m["stamp"]), joints=joints)),
            (f"{key}/extra", extra("ArmState", m, ("mode", "fault")))]


def cart_state(key: str, m: dict) -> Out:
    pose = list(m["pose"])
    if len(pose) != 5:
        raise MessageError("CartState", "pose", f"expected x, y, z and two rotations, got {len(pose)} values")
    rot = quaternion_wxyz(point_rotation(pose[0], pose[1], pose[3], pose[4]))
    tool = fm.Pose(position=_vector(pose), orientation=_quaternion(rot))
    return [(key, fm.PoseInFrame(timestamp=_time(m["stamp"]), frame_id=frames.arm(key), pose=tool)),
            (f"{key}/extra", extra("CartState", m, ("state", "joints")))]


def odometry(key: str, m: dict) -> Out:
    t, here = _time(m["stamp"]), _planar(m["x"], m["y"], m["theta"])
    return [
        (key, fm.Odometry(timestamp=t, frame_id=frames.odom(key), body_frame_id=frames.base(key), pose=here,
                          linear_velocity=fm.Vector3(x=float(m["vx"])),
                          angular_velocity=fm.Vector3(z=float(m["wz"])))),
        (frames.TF_TOPIC, fm.FrameTransform(timestamp=t, parent_frame_id=frames.odom(key),
                                            child_frame_id=frames.base(key),
                                            translation=_vector([m["x"], m["y"], 0.0]),
                                            rotation=_quaternion(yaw_quaternion_wxyz(m["theta"])))),
    ]


def depth_image(key: str, m: dict) -> Out:
    depth = _array(m, "DepthImage", "depth", 2)
    if depth.dtype.kind == "f":
        depth, encoding = depth.astype("<f4", copy=False), "32FC1"
    else:
        depth, encoding = depth.astype("<u2", copy=False), "16UC1"
    h, w = depth.shape
    return [(key, fm.RawImage(timestamp=_time(m["stamp"]), frame_id=frames.camera(key), width=w, height=h,
                              encoding=encoding, step=w * depth.itemsize,
                              data=np.ascontiguousarray(depth).tobytes()))]


def rgb_image(key: str, m: dict) -> Out:
    return [(key, fm.CompressedImage(timestamp=_time(m["stamp"]), frame_id=frames.camera(key),
                                     data=bytes(m["jpeg"]), format="jpeg"))]


def camera_info(key: str, m: dict) -> Out:
    t, frame = _time(m["stamp"]), frames.camera(key)
    fx, fy, cx, cy = (float(m[k]) for k in ("fx", "fy", "cx", "cy"))
    pose = list(m["pose"])
    if len(pose) != 7:
        raise MessageError("CameraInfo", "pose", f"expected x, y, z, qw, qx, qy, qz, got {len(pose)} values")
    calibration = fm.CameraCalibration(
        timestamp=t, frame_id=frame, width=m["width"], height=m["height"], distortion_model="plumb_bob",
        D=[0.0] * 5, K=[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0], R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        P=[fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0])
    mount = fm.FrameTransform(timestamp=t, parent_frame_id=frames.base(key), child_frame_id=frame,
                              translation=_vector(pose[:3]), rotation=_quaternion(pose[3:7]))
    return [(key, calibration), (frames.TF_TOPIC, mount)]


def laser_scan(key: str, m: dict) -> Out:
    ranges = np.asarray(m["ranges"], float).ravel()
    start, step = float(m["angle_min"]), float(m["angle_increment"])
    # Out-of-range beams are "no return": Foxglove draws nothing for a range beyond range_max.
    ranges = np.where(np.isfinite(ranges), ranges, float(m["range_max"]) + 1.0)
    return [(key, fm.LaserScan(timestamp=_time(m["stamp"]), frame_id=frames.base(key),
                               pose=_planar(0.0, 0.0, 0.0), start_angle=start,
                               end_angle=start + step * max(len(ranges) - 1, 0), ranges=ranges.tolist()))]


def nav_map(key: str, m: dict) -> Out:
    cells = _array(m, "NavMap", "data", 2).astype(np.int8, copy=False)
    origin = list(m["origin"]) + [0.0] * (3 - len(m["origin"]))
    res = float(m["resolution"])
    occupancy = fm.PackedElementField(name="occupancy", offset=0, type=fm.PackedElementFieldNumericType.Int8)
    grid = fm.Grid(timestamp=_time(m["stamp"]), frame_id=frames.map_(key), pose=_planar(*origin[:3]),
                   column_count=cells.shape[1], cell_size=fm.Vector2(x=res, y=res), row_stride=cells.shape[1],
                   cell_stride=1, fields=[occupancy], data=np.ascontiguousarray(cells).tobytes())
    return [(key, grid), (f"{key}/extra", extra("NavMap", m, ("name",)))]


def nav_pose(key: str, m: dict) -> Out:
    t, frame = _time(m["stamp"]), frames.map_(key)
    out: Out = [(key, fm.PoseInFrame(timestamp=t, frame_id=frame, pose=_planar(m["x"], m["y"], m["theta"])))]
    particles = _array(m, "NavPose", "particles", 2, columns=3)
    if len(particles):
        poses = [_planar(*p[:3]) for p in particles.tolist()]
        out.append((f"{key}/particles", fm.PosesInFrame(timestamp=t, frame_id=frame, poses=poses)))
    return out + [(f"{key}/extra", extra("NavPose", m, ("covariance", "localised")))]


def nav_path(key: str, m: dict) -> Out:
    points = _array(m, "NavPath", "points", 2, columns=2) if np.size(m["points"]) else np.zeros((0, 2))
    poses = [_planar(x, y, 0.0) for x, y in points[:, :2].tolist()]
    return [(key, fm.PosesInFrame(timestamp=_time(m["stamp"]), frame_id=frames.map_(key), poses=poses)),
            (f"{key}/extra", extra("NavPath", m, ("goal_id", "length")))]


def event(key: str, m: dict) -> Out:
    return [(key, fm.Log(timestamp=_time(m["stamp"]), level=LEVELS.get(m["level"], fm.LogLevel.Unknown),
                         message=f"[{m['code']}] {m['text']}", name=keys.robot_of(key) or key))]


def audio_chunk(key: str, m: dict) -> Out:
    sample, channels = SAMPLES.get(m["sample"]), int(m["channels"])
    if sample is None:
        raise MessageError("AudioChunk", "sample", f"expected int16 or float32, got {m['sample']!r}")
    if channels < 1:
        raise MessageError("AudioChunk", "channels", f"expected 1 or more, got {channels}")
    data = bytes(m["data"])
    if len(data) % (sample.itemsize * channels):
        raise MessageError("AudioChunk", "data", f"{len(data)} bytes are not whole {m['sample']} frames")
    samples = np.frombuffer(data, sample)
    if sample.kind == "f":      # Foxglove plays 16-bit PCM only
        samples = np.round(np.clip(samples, -1.0, 1.0) * 32767)
    return [(key, fm.RawAudio(timestamp=_time(m["stamp"]), data=samples.astype("<i2").tobytes(), format="pcm-s16",
                              sample_rate=int(m["rate"]), number_of_channels=channels))]


CONVERTERS: dict[str, Callable[[str, dict], Out]] = {
    "ArmState": arm_state, "CartState": cart_state, "Odometry": odometry, "DepthImage": depth_image,
    "RgbImage": rgb_image, "CameraInfo": camera_info, "LaserScan": laser_scan, "NavMap": nav_map,
    "NavPose": nav_pose, "NavPath": nav_path, "Event": event, "AudioChunk": audio_chunk,
}


def convert(key: str, body: Any) -> Out:
    """The Foxglove messages (topic, message) one message of ours on `key` becomes.

    A typed message is validated first, so a bad message is refused (MessageError) and the
    ones around it still shown, instead of something Foxglove cannot draw.
    """
    type_name = body.get(TYPE_FIELD) if isinstance(body, dict) else None
    if type_name not in REGISTRY:
        return [(key, whole(type_name if isinstance(type_name, str) else None, body))]
    msg = messages.to_dict(messages.from_dict(REGISTRY[type_name], body))
    converter = CONVERTERS.get(type_name)
    return converter(key, msg) if converter is not None else [(key, whole(type_name, msg))]
