"""Where a camera stands on its robot: `--pose`, else a mounts file (`--mounts`, else the
packaged mounts.toml, the robots' own), else unknown (a zero pose: the web page asks for a
calibration, perception leaves the camera out)."""

from __future__ import annotations

import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from asibot.camera.sources import SourceError
from asibot.poses import quaternion_wxyz

#: What CameraInfo.pose says when nobody knows where the camera stands.
UNKNOWN = [0.0] * 7
#: camera_link (x forward, y left, z up) -> optical frame (x right, y down, z forward).
_LINK_TO_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def packaged() -> Path:
    return Path(str(resources.files("asibot.camera"))) / "mounts.toml"


def from_xyz_rpy(xyz: Sequence[float], rpy_deg: Sequence[float]) -> list[float]:
    """The optical frame's pose of a camera body at `xyz` turned by roll, pitch, yaw (degrees,
    about the fixed x, y, z axes: R = Rz(yaw) Ry(pitch) Rx(roll))."""
    r, p, y = (math.radians(float(v)) for v in rpy_deg)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    rot = rz @ ry @ rx @ _LINK_TO_OPTICAL
    return [float(v) for v in xyz] + quaternion_wxyz(rot)


def check_pose(pose: Sequence[Any], where: str) -> list[float]:
    try:
        values = [float(v) for v in pose]
    except (TypeError, ValueError):
        values = []
    if len(values) != 7 or not all(math.isfinite(v) for v in values):
        raise SourceError(f"{where}: a camera pose is 7 numbers x y z qw qx qy qz (m; the optical frame in the "
                          f"robot's base frame); got {list(pose)!r}")
    norm = math.sqrt(sum(v * v for v in values[3:]))
    if values[3:] != [0.0] * 4 and abs(norm - 1) > 1e-3:
        raise SourceError(f"{where}: the quaternion qw qx qy qz has norm {norm:.4f}; it must be a unit quaternion")
    return values


def pose_of(robot: str, camera: str, path: Path | None = None) -> list[float] | None:
    """The pose the mounts file gives `camera` of `robot`; None when it gives none."""
    path = path or packaged()
    try:
        table = tomllib.loads(path.read_text())
    except OSError as exc:
        raise SourceError(f"--mounts {path}: cannot be read ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise SourceError(f"{path} is not valid TOML: {exc}") from None
    entry = table.get(robot, {}).get(camera)
    if entry is None:
        return None
    where = f"{path} [{robot}.{camera}]"
    if "pose" in entry:
        return check_pose(entry["pose"], where)
    if "xyz" in entry and "rpy" in entry:
        if len(entry["xyz"]) != 3 or len(entry["rpy"]) != 3:
            raise SourceError(f"{where}: xyz is 3 numbers (m), rpy 3 numbers (degrees)")
        return from_xyz_rpy(entry["xyz"], entry["rpy"])
    raise SourceError(f"{where}: give pose = [x, y, z, qw, qx, qy, qz], or xyz = [...] and rpy = [...]")
