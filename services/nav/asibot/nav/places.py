"""Named places ("the fridge", "the desk") and the thesis's saved position.

The world's places file (services/sim/asibot/sim/worlds/<world>_places.yaml: frame map, places: name ->
{x, y, theta}) gives the first list. Once the user adds, renames or removes a place, the
whole list lives in the user's file (<data>/nav/<robot>/places.yaml, same format plus an
optional `saved_position`), written atomically: a crash leaves the old file whole. The
world file is never written.

Names are what people say: letters of any language, digits, spaces, and - _ ' . (the
seed's "charging station"), starting with a letter or digit. Path characters (/ \\), control
characters and names longer than 40 characters are refused with a sentence, as is a second place whose name differs only in
case or spacing. Lookups ignore case and extra spaces, and an unknown name gets a "did you
mean" from the known ones.
"""

from __future__ import annotations

import difflib
import re
from importlib import resources
from pathlib import Path
from typing import NamedTuple

import yaml

from asibot.errors import quote
from asibot.nav.errors import NavError
from asibot.files import data_dir, private_dir, write_atomic
from asibot.nav.geometry import Pose, as_pose
from asibot.nav.grid import GridInfo

MAX_NAME = 40
#: Places kept for one robot (its file stays small: at most a few tens of KiB).
MAX_PLACES = 200
MAX_FILE_BYTES = 256 * 1024
_ALLOWED = " -_'."


class Place(NamedTuple):
    name: str
    pose: Pose


def key(name: str) -> str:
    """How names compare: case and runs of spaces do not matter."""
    return " ".join(name.split()).casefold()


def check_name(name: object) -> str:
    """The name, tidied (outer spaces dropped, inner runs of spaces made one), or NavError."""
    if not isinstance(name, str):
        raise NavError(f"A place name must be text; got {quote(name)}.")
    tidy = " ".join(name.split())
    if not tidy:
        raise NavError("A place needs a name, for example 'fridge' or 'by the window'.")
    if len(tidy) > MAX_NAME:
        raise NavError(f"The place name {quote(tidy, 30)} is {len(tidy)} characters long; use at most {MAX_NAME}.")
    bad = sorted({c for c in tidy if not (c.isalnum() or c in _ALLOWED)})
    if bad or not tidy[0].isalnum():
        shown = " ".join(repr(c) for c in bad[:5]) if bad else f"its first character {tidy[0]!r}"
        raise NavError(f"The place name {quote(tidy, 30)} cannot be used because of {shown}: use letters, "
                       "digits, spaces and - _ ' . (starting with a letter or digit).")
    return tidy


def world_places_file(world: str = "apartment") -> Path:
    """The world's places, shipped with the sim's package data (asibot.sim.worlds)."""
    return Path(str(resources.files("asibot.sim") / "worlds" / f"{world}_places.yaml"))


def user_places_file(robot: str) -> Path:
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}", robot):
        raise NavError(f"{quote(robot)} is not a robot id (letters, digits, - and _).")
    return data_dir() / "nav" / robot / "places.yaml"


def _read(path: Path) -> tuple[dict[str, Pose], Pose | None]:
    try:
        if path.stat().st_size > MAX_FILE_BYTES:
            raise NavError(f"The places file {path} is too large to be a list of places.")
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise NavError(f"Cannot read the places file {path}: {exc.strerror or exc}.") from None
    except (yaml.YAMLError, UnicodeDecodeError):
        raise NavError(f"The places file {path} is not valid YAML; fix or remove it.") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("places", {}), dict):
        raise NavError(f"The places file {path} must have 'places:' with name: {{x, y, theta}} entries.")
    if doc.get("frame", "map") != "map":
        raise NavError(f"The places file {path} is in frame {quote(doc.get('frame'))}; only 'map' is known.")
    places: dict[str, Pose] = {}
    for name, p in (doc.get("places") or {}).items():
        try:
            tidy = check_name(str(name))
            places[tidy] = as_pose(p, f"place {tidy!r}")
        except NavError as exc:
            raise NavError(f"The places file {path}: {exc.message}") from None
    saved = doc.get("saved_position")
    return places, (as_pose(saved, "saved position") if saved is not None else None)


def _dump(places: dict[str, Pose], saved: Pose | None) -> bytes:
    def entry(p: Pose) -> dict[str, float]:
        return {"x": round(p.x, 4), "y": round(p.y, 4), "theta": round(p.theta, 4)}
    doc: dict[str, object] = {"frame": "map", "places": {n: entry(p) for n, p in places.items()}}
    if saved is not None:
        doc["saved_position"] = entry(saved)
    head = "# Named places of this robot, in the map frame (m, rad); written by asibot.nav.places.\n"
    return (head + yaml.safe_dump(doc, sort_keys=False, allow_unicode=True, default_flow_style=None)).encode()


class Places:
    def __init__(self, user_file: Path, world_file: Path | None = None, info: GridInfo | None = None) -> None:
        """`user_file` (may not exist yet) wins over `world_file`; `info` bounds the poses."""
        self.user_file = Path(user_file)
        self.world_file = world_file
        self.info = info
        if self.user_file.exists():
            self._places, self._saved = _read(self.user_file)
        elif world_file is not None and Path(world_file).exists():
            self._places, self._saved = _read(Path(world_file))
            self._saved = None
        else:
            self._places, self._saved = {}, None

    @classmethod
    def for_robot(cls, robot: str, world: str = "apartment", info: GridInfo | None = None) -> "Places":
        return cls(user_places_file(robot), world_places_file(world), info)

    # ---------------------------------------------------------------------------- queries

    def list(self) -> list[Place]:
        return [Place(n, p) for n, p in sorted(self._places.items(), key=lambda kv: key(kv[0]))]

    def find(self, name: str) -> str | None:
        k = key(name) if isinstance(name, str) else None
        return next((n for n in self._places if key(n) == k), None)

    def get(self, name: object) -> Place:
        if not isinstance(name, str) or not name.strip():
            raise NavError(f"Say which place: one of {self._known()}.")
        found = self.find(name)
        if found is None:
            close = difflib.get_close_matches(key(name), [key(n) for n in self._places], n=1, cutoff=0.6)
            hint = f" Did you mean {self.find(close[0])!r}?" if close else ""
            raise NavError(f"I know no place called {quote(name.strip(), 40)}.{hint} Known places: {self._known()}.")
        return Place(found, self._places[found])

    def _known(self) -> str:
        return ", ".join(p.name for p in self.list()) or "none yet (save one with 'save this place')"

    # -------------------------------------------------------------------------- changes

    def _check_pose(self, pose: object, what: str) -> Pose:
        p = as_pose(pose, what)
        if self.info is not None and not self.info.contains(p.x, p.y):
            raise NavError(f"The {what} ({p.x:.2f}, {p.y:.2f}) is outside the map ({self.info.bounds()}).")
        return p

    def add(self, name: object, pose: object, replace: bool = False) -> Place:
        """Save a place (the robot's current pose, for "save this place")."""
        tidy = check_name(name)
        p = self._check_pose(pose, f"pose of {tidy!r}")
        existing = self.find(tidy)
        if existing is not None and not replace:
            raise NavError(f"There is already a place called {existing!r}; rename or remove it first, "
                           "or save it again to move it.")
        if existing is None and len(self._places) >= MAX_PLACES:
            raise NavError(f"There are already {len(self._places)} places, the most I keep ({MAX_PLACES}), so "
                           f"{tidy!r} was not saved: remove one you no longer use first (Remove on the Base page, "
                           "or remove_place).")
        places = dict(self._places)
        if existing is not None:
            places.pop(existing)
        places[tidy] = p
        self._commit(places, self._saved)
        return Place(tidy, p)

    def rename(self, old: object, new: object) -> Place:
        src = self.get(old)
        tidy = check_name(new)
        other = self.find(tidy)
        if other is not None and other != src.name:
            raise NavError(f"There is already a place called {other!r}; choose another name.")
        places = {(tidy if n == src.name else n): p for n, p in self._places.items()}
        self._commit(places, self._saved)
        return Place(tidy, src.pose)

    def remove(self, name: object) -> Place:
        src = self.get(name)
        places = {n: p for n, p in self._places.items() if n != src.name}
        self._commit(places, self._saved)
        return src

    def save_position(self, pose: object) -> Pose:
        """The thesis's "save position": one slot, overwritten each time."""
        p = self._check_pose(pose, "position to save")
        self._commit(self._places, p)
        return p

    def recall_position(self) -> Pose:
        """The thesis's "recall position": where `save_position` was last called."""
        if self._saved is None:
            raise NavError("No position is saved yet; save one first ('save position').")
        return self._saved

    def _commit(self, places: dict[str, Pose], saved: Pose | None) -> None:
        """Write first, then change memory: a failed write changes nothing."""
        private_dir(self.user_file.parent)
        write_atomic(self.user_file, _dump(places, saved))
        self._places, self._saved = places, saved
