"""The name a capture proposes: where the arm is, in the words the user already taught.

A name that says where a point is helps when the program is written later ("above-can" says
more than "point-7"). So a capture proposes, in this order:
1. `<place>-N` when the robot's base stands at one of nav's named places (the Pioneer at the
   fridge: "fridge-1");
2. `<point>-2` when the tool is where a taught point is, `above-<point>` when it is straight
   above one (an approach point), `<thing>` straight below `above-<thing>` (down from the
   approach point is at the thing), or `near-<point>` when it is close to one (the nearest of
   those the user named, if several), with the user's separator (`above_can` gives `near_can`);
3. `point-N`, the first free number, as the seed did.
A suggestion is never a name already taken; the user can always type another.
"""

from __future__ import annotations

import math
import re
from typing import Iterable, Sequence

#: Within this of a taught point (m, tool positions) the capture is that point again.
SAME_M = 0.01
#: Within this of a taught point (m, tool positions) the capture is "near" it.
NEAR_M = 0.15
#: "Above": at least this much higher (m) and within this much sideways (m).
ABOVE_MIN_M, ABOVE_SIDEWAYS_M = 0.02, 0.03

_UNSAFE = re.compile(r"[^A-Za-z0-9_.-]+")
#: A relation the user wrote, with the separator they chose ("above-can", "above_can").
_RELATION = re.compile(r"^(above|near)([-_])(.+)$")
_GENERIC = re.compile(r"point-\d+")


def _as_name(words: str) -> str:
    """A place's words as a point-name token: "charging station" -> "charging-station"."""
    name = _UNSAFE.sub("-", words.strip()).strip("-.")
    return name if name and name[0].isalpha() else f"p-{name}" if name else "point"


def _free(stem: str, taken: set[str], numbered: bool) -> str:
    """`stem` itself when free (unless `numbered`), else `stem-2`, `stem-3`... (`stem-1`... when numbered)."""
    if not numbered and stem not in taken:
        return stem
    n = 1 if numbered else 2
    while f"{stem}-{n}" in taken:
        n += 1
    return f"{stem}-{n}"


def nearest(here: Sequence[float], points: Iterable[tuple[str, Sequence[float]]]) -> tuple[str, float] | None:
    """The taught point whose position is nearest the tool's, with its distance (m)."""
    best: tuple[str, float] | None = None
    for name, values in points:
        d = math.dist(here[:3], values[:3])
        if best is None or d < best[1]:
            best = (name, d)
    return best


def suggest(taken: Iterable[str], points: Iterable[tuple[str, Sequence[float]]] = (),
            here: Sequence[float] | None = None, place: str = "") -> str:
    """The name to propose for a capture at `here` (a point, m and deg) with the base at `place`."""
    taken = set(taken)
    if place:
        return _free(_as_name(place), taken, numbered=True)
    if here is not None:
        # Only names the user chose say something: "near-point-3" would not.
        points = [(n, v) for n, v in points if not _GENERIC.fullmatch(n)]
        found = nearest(here, points)
        if found is not None and found[1] <= NEAR_M:
            name, distance = found
            if distance <= SAME_M:           # taught again where it was: "above-can-2"
                return _free(name, taken, numbered=False)
            values = dict(points)[name]
            sideways = math.dist(here[:2], values[:2])
            rise = here[2] - values[2]
            written = _RELATION.match(name)
            relation, sep, thing = written.groups() if written else ("", "-", name)
            if relation == "above" and rise <= -ABOVE_MIN_M and sideways <= ABOVE_SIDEWAYS_M:
                return _free(thing, taken, numbered=False)   # down from "above_can": at the can
            rel = "above" if rise >= ABOVE_MIN_M and sideways <= ABOVE_SIDEWAYS_M else "near"
            # Near "above-can" is still about the can: no "above-above-can"; "_" stays "_".
            return _free(f"{rel}{sep}{thing}", taken, numbered=False)
    return _free("point", taken, numbered=True)
