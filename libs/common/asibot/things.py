"""What a taught thing is, and how to find it again in a depth camera's view (issue 52: a taught
pick remembers what, not where).

A pick taught by touching a thing in a camera's picture keeps what was touched: the carer's name
for it, its colour and its size as the camera measured them (depth.object_at, depth.colour_name)
and where it stood then. Things get moved, so when the pick runs the thing is looked for again:
every coloured object standing in view is measured the same way, and the one of the same colour
and about the same size, nearest to where it was taught, is the one to pick. When none is, the
user hears what the cameras saw instead, in words. Plain numpy/cv2 geometry: no bus.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, Sequence

import cv2
import numpy as np

from asibot import depth
from asibot.messages import CameraInfo

#: A pixel is colourful enough to seed on from this HSV saturation (OpenCV's 0-255; about a
#: third): a grey counter, a white wall and their shading stay below it.
MIN_SATURATION = 80
#: ... and from this HSV value (brightness, 0-255): in the dark, hue is noise.
MIN_VALUE = 50
#: A colour blob smaller than this, pixels (after opening), is speckle or a label, not a thing
#: to pick; the kitchen camera sees the 6.6 cm can as about 70 pixels at 320 x 240.
MIN_PIXELS = 20
#: Seeds tried in one colour blob at most: two things of one colour that touch in the picture
#: make one blob, and each object found in it leaves the rest to seed again.
MAX_SEEDS = 6

#: A taught thing is looked for this far (horizontally, m) from where it was taught: anywhere
#: on the counter within the arm's reach (bench_pick put the can 0.58 m away, and 0.5 m missed
#: it), not carried across the room, where another like it is likelier. Of two alike, the one
#: nearer the taught place wins (DISTANCE_WEIGHT).
SEARCH_RADIUS = 1.2
#: Its height may differ from the taught one by this much (m) or this share of it, whichever is
#: more: object_at measures a height to a few mm, but a can stands on a coaster or a lid is off.
HEIGHT_SLACK, HEIGHT_SHARE = 0.03, 0.30
#: Its width, more loosely: a width across the line of sight changes as a box is turned or the
#: camera looks from elsewhere, and is a whole pixel coarse (7 mm at 1.6 m for the kitchen's).
WIDTH_SLACK, WIDTH_SHARE = 0.03, 0.40
#: A relative width mismatch counts half as much as a height one in the score, for the same reasons.
WIDTH_WEIGHT = 0.5
#: Score per metre from where it was taught: small, 10 cm weighs as much as a 5 % height mismatch,
#: so the better size wins, and of two alike the one nearer the taught place.
DISTANCE_WEIGHT = 0.5

#: The colour names depth.colour_name gives, so the ones a taught thing can have.
COLOURS: tuple[str, ...] = tuple(dict.fromkeys([name for _, name in depth.HUES] + ["white", "grey", "black"]))
#: Colours objects_in_view cannot seed on (no saturation): a thing of these is never found again.
COLOURLESS = ("white", "grey", "black")
#: A thing's name is at most this many characters: a few words a carer says.
NAME_LENGTH = 40
#: Heights and widths of a thing the arm could pick, m.
SMALLEST, LARGEST = 0.005, 1.0
#: A thing was taught within this distance of the robot's base, m: further is a wrong frame or unit.
WHERE_LIMIT = 5.0
#: Objects two cameras see this close together (m, horizontally, same colour) are said once.
SAME_PLACE = 0.05
#: not_found mentions this many objects at most, then "and N more".
MENTIONED = 3

_FIELDS = ("name", "colour", "height", "width", "where")


def _number(value: Any) -> bool:
    """A finite real number; a bool is not one, though Python counts it an int."""
    return (isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
            and math.isfinite(float(value)))


def _quote(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


@dataclass(frozen=True)
class Thing:
    """A taught thing: what to look for when the pick runs, not a place to go to."""

    name: str                              # the carer's words, "red can"
    colour: str                            # one of COLOURS, as depth.colour_name named it when taught
    height: float                          # m, as depth.object_at measured it when taught
    width: float                           # m, across the camera's line of sight when taught
    where: tuple[float, float, float]      # its centre when taught, robot frame, m

    def __post_init__(self) -> None:
        # Checked here, not only in from_json, so that every Thing (one made when teaching too)
        # is one that can be looked for.
        name = self.name
        if not isinstance(name, str) or not name.strip() or len(name.strip()) > NAME_LENGTH or not name.isprintable():
            raise ValueError(f"A thing's name is 1 to {NAME_LENGTH} printable characters, the words you call it "
                             f"(\"red can\"); got {_quote(name)}.")
        if self.colour not in COLOURS:
            raise ValueError(f"A thing's colour is one of {', '.join(COLOURS)}; got {_quote(self.colour)}.")
        for field_name in ("height", "width"):
            value = getattr(self, field_name)
            if not _number(value) or not SMALLEST <= float(value) <= LARGEST:
                raise ValueError(f"A thing's {field_name} is a number of metres from {SMALLEST} to {LARGEST:.1f}; "
                                 f"got {_quote(value)}.")
        where: Any = self.where.tolist() if isinstance(self.where, np.ndarray) else self.where
        if (isinstance(where, (str, bytes, dict)) or not isinstance(where, Sequence) or len(where) != 3
                or not all(_number(c) for c in where) or math.hypot(*(float(c) for c in where)) > WHERE_LIMIT):
            raise ValueError(f"A thing's where is 3 numbers, its x y z in metres within {WHERE_LIMIT:.0f} m of the "
                             f"robot; got {_quote(where)}.")
        object.__setattr__(self, "name", name.strip())
        object.__setattr__(self, "height", float(self.height))
        object.__setattr__(self, "width", float(self.width))
        object.__setattr__(self, "where", tuple(float(c) for c in where))

    @classmethod
    def from_json(cls, data: Any) -> "Thing":
        """The thing a saved program or a request describes; ValueError says which field is wrong."""
        if not isinstance(data, dict):
            raise ValueError(f"A thing is a JSON object with its {', '.join(_FIELDS[:-1])} and {_FIELDS[-1]}; "
                             f"got {_quote(data)}.")
        for key in _FIELDS:
            if key not in data:
                raise ValueError(f"The thing has no {key}.")
        for key in data:
            if key not in _FIELDS:
                raise ValueError(f"A thing has no field {_quote(key)}; it has {', '.join(_FIELDS)}.")
        return cls(**{key: data[key] for key in _FIELDS})

    def as_json(self) -> dict[str, Any]:
        r = lambda v: round(float(v), 4)   # noqa: E731
        return {"name": self.name, "colour": self.colour, "height": r(self.height), "width": r(self.width),
                "where": [r(c) for c in self.where]}


@dataclass(frozen=True)
class Seen:
    """An object standing in one camera's view, what a taught thing is compared with."""

    colour: str | None       # depth.colour_name of its pixels
    found: depth.Touched     # what depth.object_at measured (kind "object")
    camera: str              # the camera that saw it

    def words(self) -> str:
        """It in the user's words, "a red object 12 cm tall" (as the web's describe says a touch)."""
        article = "an" if self.colour is None or self.colour[0] in "aeiou" else "a"
        return f"{article} {self.colour + ' ' if self.colour else ''}object {self.found.height * 100:.0f} cm tall"


def objects_in_view(depth_image: np.ndarray, rgb: np.ndarray | None, info: CameraInfo, camera_pose: np.ndarray,
                    camera: str = "") -> list[Seen]:
    """Every coloured object standing in a camera's view (depth image, the RGB picture registered
    with it, its CameraInfo and its 4x4 pose in the robot's frame), measured as a touch would be.

    Seeds come from colour, not depth: the picture's colourful pixels (HSV saturation and value
    high enough), opened 3x3 against speckle, in blobs of at least MIN_PIXELS; each blob is
    touched (depth.object_at) at its pixel with a depth nearest its middle, and what rises above
    its support is an object. So grey, white and black things, and things too dark to tell, are
    not found: a taught thing of those colours cannot be looked for again. Without a picture, or
    with one of another size than the depth, nothing is found ([]); a depth image of another
    size than `info` is a depth.DepthError."""
    depth.check_size(depth_image, info)
    if rgb is None or rgb.ndim != 3 or rgb.shape[:2] != depth_image.shape or rgb.shape[2] < 3:
        return []
    hsv = cv2.cvtColor(np.ascontiguousarray(rgb[..., :3], dtype=np.uint8), cv2.COLOR_RGB2HSV)
    colourful = ((hsv[..., 1] >= MIN_SATURATION) & (hsv[..., 2] >= MIN_VALUE)).astype(np.uint8)
    colourful = cv2.morphologyEx(colourful, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(colourful, connectivity=8)
    has_depth = depth_image > 0
    rim = np.ones((3, 3), np.uint8)
    taken = np.zeros(depth_image.shape, bool)      # the pixels of the objects found so far
    seen: list[Seen] = []
    for label in range(1, count):
        if stats[label, cv2.CC_STAT_AREA] < MIN_PIXELS:
            continue
        left = (labels == label) & has_depth & ~taken
        for _ in range(MAX_SEEDS):
            rows, cols = np.nonzero(left)
            if len(rows) < MIN_PIXELS:
                break
            k = int(np.argmin((rows - rows.mean()) ** 2 + (cols - cols.mean()) ** 2))
            try:
                found = depth.object_at(depth_image, info, camera_pose, int(cols[k]), int(rows[k]))
            except depth.DepthError:
                break
            if found.kind != "object" or found.region is None or not found.region.any():
                break      # a coloured surface (a placemat, a tray's floor): nothing stands there
            seen.append(Seen(depth.colour_name(rgb, found.region), found, camera))
            taken |= found.region
            # Its rim too: the strip at its foot, within ABOVE_SUPPORT of the counter, is not in
            # its region, and seeded again would only touch the counter.
            left &= ~cv2.dilate(found.region.astype(np.uint8), rim, iterations=2).astype(bool)
    return seen


def moved(thing: Thing, seen: Seen) -> float:
    """How far (m, horizontally) the thing stands from where it was taught."""
    return math.hypot(seen.found.centre[0] - thing.where[0], seen.found.centre[1] - thing.where[1])


def _unlike(thing: Thing, seen: Seen) -> list[str]:
    """Why a seen object of the thing's colour is not it, in words ("taller than the red can");
    [] when it may be."""
    size = []
    height, width = seen.found.height - thing.height, seen.found.width - thing.width
    if abs(height) > max(HEIGHT_SLACK, HEIGHT_SHARE * thing.height):
        size.append("taller" if height > 0 else "shorter")
    if abs(width) > max(WIDTH_SLACK, WIDTH_SHARE * thing.width):
        size.append("wider" if width > 0 else "narrower")
    why = [f"{' and '.join(size)} than the {thing.name}"] if size else []
    away = moved(thing, seen)
    if away > SEARCH_RADIUS:
        why.append(f"{away:.2f} m from where {'it' if size else 'the ' + thing.name} was taught")
    return why


def _score(thing: Thing, seen: Seen) -> float:
    return (abs(seen.found.height - thing.height) / thing.height
            + WIDTH_WEIGHT * abs(seen.found.width - thing.width) / thing.width
            + DISTANCE_WEIGHT * moved(thing, seen))


def choose(thing: Thing, seen: Sequence[Seen]) -> Seen | None:
    """The seen object that is the taught thing: its colour, about its size (HEIGHT_*, WIDTH_*)
    and within SEARCH_RADIUS of where it was taught; of several, the best by size mismatch with a
    small weight on the distance. None when none may be it (then say `not_found`)."""
    fits = [s for s in seen if s.colour == thing.colour and not _unlike(thing, s)]
    return min(fits, key=lambda s: _score(thing, s), default=None)


def not_found(thing: Thing, seen: Sequence[Seen]) -> str:
    """What the user hears when `choose` found nothing: what was seen instead, and of the ones of
    the thing's colour why they are not it ("a red object 30 cm tall, taller than the red can")."""
    if thing.colour in COLOURLESS:
        return f"I looked for the {thing.name}, but I find things only by a bright colour, and it is {thing.colour}."
    # The thing's colour first, then the nearest to where it was taught; once each, though two
    # cameras see it.
    ordered = sorted(seen, key=lambda s: (s.colour != thing.colour, moved(thing, s)))
    distinct: list[Seen] = []
    for s in ordered:
        if not any(s.colour == d.colour and math.dist(s.found.centre[:2], d.found.centre[:2]) < SAME_PLACE
                   for d in distinct):
            distinct.append(s)
    if not distinct:
        return f"I looked for the {thing.name} and see nothing standing there."
    said: list[tuple[str, bool]] = []      # (words, whether they end in a reason)
    for s in distinct[:MENTIONED]:
        why = _unlike(thing, s) if s.colour == thing.colour else []
        said.append((s.words() + "".join(", " + w for w in why[:1]) + "".join(" and " + w for w in why[1:]),
                     bool(why)))
    if len(distinct) > MENTIONED:
        more = len(distinct) - MENTIONED
        said.append((f"{more} more thing{'s' if more > 1 else ''}", False))
    listed = said[0][0]
    for i, (words, _) in enumerate(said[1:], 1):
        # A reason is set off by commas: "a red object 30 cm tall, taller than the red can, and ..."
        last = i == len(said) - 1
        listed += (", and " if said[i - 1][1] else " and ") if last else ", "
        listed += words
    return f"I looked for the {thing.name} and see {listed}, but no {thing.name}."
