"""Where each camera stands, as the installer measured it: cameras.json in the data folder.

A real camera driver may know nothing of where the camera is fixed, so the page walks the
installer through touching marks with the tool: each mark pairs the point the camera sees
(its optical frame, m) with the fingertips' point then (the arm's base frame, m). Three or
more marks, not in a line, give the camera's pose by a rigid fit (asibot.depth.fit_pose); the
pose and its RMS residual are kept here and used from then on, instead of the camera's own.

    {"asibot/kitchen": {"marks": [{"camera": [x, y, z], "tool": [x, y, z]}, ...],
                        "pose": [x, y, z, qw, qx, qy, qz] or null, "residual_mm": 1.2 or null}}

Plain Python, no web framework and no bus; every write is atomic (asibot.files.write_atomic)
and under the folder's one lock, like the other user files.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

from asibot import depth
from asibot.files import write_atomic
from asibot.web.userdata.errors import UserDataError
from asibot.web.userdata.folder import Folder, log

FILE = "cameras.json"
#: Marks kept per camera: plenty for a good fit, few enough that a stuck page cannot grow the file.
MAX_MARKS = 20


@dataclass
class Calibration:
    """The marks touched so far and the pose solved from them (None before a solve)."""

    marks: list[dict] = field(default_factory=list)      # {"camera": [x y z], "tool": [x y z]}
    pose: list[float] | None = None
    residual_mm: float | None = None

    def as_json(self) -> dict:
        return {"marks": self.marks, "pose": self.pose, "residual_mm": self.residual_mm}


def _triple(value: object) -> list[float] | None:
    if (isinstance(value, list) and len(value) == 3
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)):
        return [float(v) for v in value]
    return None


def _read_entry(entry: object) -> Calibration:
    """One camera's entry of a file that may have been edited by hand: what is broken is left out."""
    if not isinstance(entry, dict):
        return Calibration()
    marks = []
    for mark in entry.get("marks") or []:
        if isinstance(mark, dict) and _triple(mark.get("camera")) and _triple(mark.get("tool")):
            marks.append({"camera": _triple(mark["camera"]), "tool": _triple(mark["tool"])})
    pose, residual = entry.get("pose"), entry.get("residual_mm")
    try:
        if pose is not None:
            depth.pose_matrix(pose)
    except (depth.DepthError, TypeError, ValueError):
        pose = None
    if pose is None or not isinstance(residual, (int, float)) or not math.isfinite(residual):
        pose, residual = None, None
    return Calibration(marks[:MAX_MARKS], pose and [float(v) for v in pose], residual)


class Calibrations:
    """cameras.json of one folder, by (robot, camera)."""

    def __init__(self, folder: Folder) -> None:
        self.folder = folder

    def _all(self) -> dict[str, object]:
        path = self.folder.root / FILE
        if not path.is_file():
            return {}
        try:
            found = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            log.warning("%s left out: it is not JSON (%s)", FILE, exc)
            return {}
        return found if isinstance(found, dict) else {}

    def _write(self, entries: dict[str, object]) -> None:
        write_atomic(self.folder.root / FILE, (json.dumps(entries, indent=1) + "\n").encode())

    def get(self, robot: str, camera: str) -> Calibration:
        with self.folder.lock:
            return _read_entry(self._all().get(f"{robot}/{camera}"))

    def add_mark(self, robot: str, camera: str, seen: list[float], tool: list[float]) -> Calibration:
        """Pair a mark the camera sees with the tool's point; the solved pose stays in use
        until the next solve."""
        seen_ok, tool_ok = _triple(seen), _triple(tool)
        if seen_ok is None or tool_ok is None:
            raise UserDataError("A mark needs a point in the camera and one of the tool, 3 finite numbers each.")
        with self.folder.lock:
            entries = self._all()
            found = _read_entry(entries.get(f"{robot}/{camera}"))
            if len(found.marks) >= MAX_MARKS:
                raise UserDataError(f"There are {MAX_MARKS} marks already, more than a good fit needs: "
                                    "touch Solve, or Start again.")
            found.marks.append({"camera": seen_ok, "tool": tool_ok})
            entries[f"{robot}/{camera}"] = found.as_json()
            self._write(entries)
            return found

    def clear(self, robot: str, camera: str) -> None:
        """Forget the marks and the solved pose: the camera's own pose is used again."""
        with self.folder.lock:
            entries = self._all()
            if entries.pop(f"{robot}/{camera}", None) is not None:
                self._write(entries)

    def solve(self, robot: str, camera: str) -> Calibration:
        """Fit the camera's pose to the marks; refused (nothing changes) with too few marks or
        marks in a line."""
        with self.folder.lock:
            entries = self._all()
            found = _read_entry(entries.get(f"{robot}/{camera}"))
            try:
                fitted, rms = depth.fit_pose([m["camera"] for m in found.marks], [m["tool"] for m in found.marks])
            except depth.DepthError as exc:
                raise UserDataError(str(exc)) from None
            found.pose = [round(v, 6) for v in depth.matrix_pose(fitted)]
            found.residual_mm = round(rms * 1000, 2)
            entries[f"{robot}/{camera}"] = found.as_json()
            self._write(entries)
            return found
