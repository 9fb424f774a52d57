"""The seed's handheld-pointer mode (docs/asibot-conventions.md, "Pointer mode": streaming
fwd/bkwd/rot): the arm tracks a virtual point in front of the tool; the device gives the
orientation, a three-way input moves forward / holds / moves backward, and nothing moves
unless the dead-man input is held.

Request of RPC verb `pointer` (the web UI sends it at about 20 Hz; each one keeps the motion
alive for 200 ms):
  deadman   bool   required; False stops the arm at once
  direction str    "forward" | "hold" | "backward" (default "hold")
  yaw       float  azimuth rate, deg/s, positive turns the arm counter-clockwise (default 0, at most 360)
  pitch     float  device pitch, deg: the wanted rot(y') of the tool (default: keep; -180..180)
  speed     float  translation speed along the tool axis, m/s (default 0.05, max 0.1)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import requests

#: Default translation speed, m/s (trajectoryRefSpeed, docs/asibot-conventions.md "Control states").
DEFAULT_SPEED = requests.POINTER_SPEED
MAX_SPEED = requests.MAX_POINTER_SPEED
#: How fast the tool pitch follows the device, 1/s (reaches it in about half a second).
PITCH_GAIN = 2.0
DIRECTIONS = dict(zip(requests.POINTER_DIRECTIONS, (1.0, 0.0, -1.0)))


@dataclass
class PointerInput:
    deadman: bool
    direction: str = "hold"
    yaw: float = 0.0
    pitch: float | None = None
    speed: float = DEFAULT_SPEED

    @classmethod
    def from_request(cls, req: dict) -> "PointerInput":
        """Validate a request (the `pointer` entry of asibot.kinematics.requests, like every
        verb); bad input raises bad_request naming the field and its allowed range."""
        return cls(**vars(requests.POINTER.parse("pointer", req)))


def pointer_motion(pose: np.ndarray, cmd: PointerInput) -> tuple[np.ndarray, float]:
    """SI velocity of the ASIBOT 5-pose [x, y, z, rot(y'), rot(z'')] for one pointer input, and
    the rate at which the whole point turns about the base axis (rad/s, counter-clockwise).

    The tool axis is Rz(azimuth)·Ry(rot(y')) applied to z; forward moves along it (towards
    the virtual point), backward away from it. The yaw rate turns the whole point about the
    base axis, as the seed's dRotZ did; it is a turn and not a velocity, so the controller
    turns the point exactly: a velocity tangent to the circle, integrated step by step, spirals
    outwards (5 cm over a quarter turn at 10 Hz).
    """
    x, y, z, pitch = (float(v) for v in pose[:4])
    azimuth = math.atan2(y, x)
    axis = np.array([math.cos(azimuth) * math.sin(pitch), math.sin(azimuth) * math.sin(pitch), math.cos(pitch)])
    v = np.zeros(len(pose))
    v[:3] = axis * cmd.speed * DIRECTIONS[cmd.direction]
    if cmd.pitch is not None:
        v[3] = PITCH_GAIN * (math.radians(cmd.pitch) - pitch)
    return v, math.radians(cmd.yaw)
