"""Taught points: points.ini, one point a line, `<name> <x> <y> <z> <rot(y')> <rot(z'')>` (m, deg)."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from asibot.files import write_atomic
from asibot.web import naming
from asibot.web.userdata.errors import AlreadyExists, NotFound, UserDataError
from asibot.web.userdata.folder import Folder, log
from asibot.web.userdata.names import plain_name, quote

POINT_RE = re.compile(r"[A-Za-z][A-Za-z0-9_.-]*")


@dataclass
class Point:
    """A taught Cartesian point: [x, y, z, rot(y'), rot(z'')] in m and deg, base frame."""

    name: str
    values: list[float]


def check_point_name(name: object) -> str:
    """A point name is one token of points.ini (split on spaces), so no spaces."""
    return plain_name("point name", POINT_RE, "letters, digits, _, - and .", name)


def check_values(values: object) -> list[float]:
    """A point is exactly 5 finite numbers; anything else would break a move later."""
    if not isinstance(values, (list, tuple)) or len(values) != 5:
        got = f"{len(values)} values" if isinstance(values, (list, tuple)) else quote(values)
        raise UserDataError(f"A point needs 5 values (x y z in m, rot(y') rot(z'') in deg); got {got}.")
    out = []
    for label, v in zip(("x", "y", "z", "rot(y')", "rot(z'')"), values):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise UserDataError(f"The point's {label} must be a finite number; got {repr(v)[:40]}.")
        out.append(float(v))
    return out


def parse_point(line: str) -> Point:
    parts = line.split()
    if len(parts) != 6:
        raise UserDataError(f"A points.ini line needs a name and 5 numbers; got {len(parts)} fields.")
    try:
        values = [float(p) for p in parts[1:]]
    except ValueError:
        raise UserDataError(f"The point {quote(parts[0])} has a value that is not a number.") from None
    return Point(check_point_name(parts[0]), check_values(values))


class Points:
    """points.ini of one folder."""

    def __init__(self, folder: Folder) -> None:
        self.folder = folder

    def all(self) -> list[Point]:
        """The taught points in file order; a hand-broken line is left out (and logged)."""
        found: dict[str, Point] = {}
        for number, line in enumerate(self.folder.read_lines("points.ini"), 1):
            try:
                p = parse_point(line)
            except UserDataError as e:
                log.warning("points.ini line %d left out: %s", number, e)
                continue
            found.pop(p.name, None)  # the seed appended: a later line with the same name wins
            found[p.name] = p
        return list(found.values())

    def get(self, name: str) -> Point:
        name = check_point_name(name)
        for p in self.all():
            if p.name == name:
                return p
        raise NotFound(f"There is no point named {quote(name)}.")

    def add(self, name: str, values: list[float], replace: bool = False) -> Point:
        """Store a point (a capture); refuse a taken name unless `replace`."""
        name = check_point_name(name)
        values = check_values(values)
        points = self.all()
        if any(p.name == name for p in points):
            if not replace:
                raise AlreadyExists(f"A point named {quote(name)} already exists.")
            points = [p for p in points if p.name != name]
        points.append(Point(name, values))
        self.write(points)
        return points[-1]

    def suggest_name(self, here: list[float] | None = None, place: str = "") -> str:
        """What a capture at `here` (the base at nav's `place`) proposes before the user edits
        it: `naming.suggest` ("fridge-1", "above-can", "point-3")."""
        points = self.all()
        return naming.suggest((p.name for p in points), ((p.name, p.values) for p in points), here, place)

    def rename(self, old: str, new: str) -> Point:
        """Rename a point in place (programs hold its values, not its name)."""
        old, new = check_point_name(old), check_point_name(new)
        points = self.all()
        target = self.get(old)
        if old != new and any(p.name == new for p in points):
            raise AlreadyExists(f"A point named {quote(new)} already exists.")
        for p in points:
            if p.name == old:
                p.name = new
        self.write(points)
        return Point(new, target.values)

    def delete(self, name: str) -> None:
        self.get(name)
        self.write([p for p in self.all() if p.name != name])

    def write(self, points: list[Point]) -> None:
        # repr() is the shortest text that reads back as the same float.
        text = "".join(f"{p.name} {' '.join(repr(v) for v in p.values)}\n" for p in points)
        write_atomic(self.folder.root / "points.ini", text.encode())
