"""The Foxglove frame of each message, from its key alone.

Our messages carry no frame (an image does not say which camera took it), so the export and
the live view name frames after the key: `<robot>/odom`, `<robot>/base`, `<robot>/map`,
`<robot>/<camera>_optical`. Every message of a robot then hangs off the same tree, and a
camera's images, calibration and transform always agree.
"""

from __future__ import annotations

from asibot import keys, robots

#: The topic of every frame transform (odometry, camera mounts), as Foxglove expects.
TF_TOPIC = "/tf"


def robot_of(key: str) -> str:
    """The robot whose frames a message is in; keys outside `rb/<robot>/` hang off "world"."""
    return keys.robot_of(key) or "world"


def camera(key: str) -> str:
    return f"{robot_of(key)}/{keys.camera_of(key) or 'camera'}_optical"


def base(key: str) -> str:
    return f"{robot_of(key)}/base"


def odom(key: str) -> str:
    return f"{robot_of(key)}/odom"


def map_(key: str) -> str:
    """The frame of nav's map, path and localisation: its own root (nav publishes no map ->
    odom transform), so a 3D panel shows them with this as its display frame."""
    return f"{robot_of(key)}/map"


def arm(key: str) -> str:
    """The frame Cartesian poses are in: the arm's base, which is the robot's on the ASIBOT."""
    robot = robot_of(key)
    spec = robots.get(robot) if robot in robots.ids() else None
    return f"{robot}/{spec.base_link}" if spec is not None and spec.has_base else base(key)
