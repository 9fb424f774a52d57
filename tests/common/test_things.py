"""Taught things found again (asibot.things, issue 52: a taught pick remembers what, not where),
on synthetic kitchen scenes with known answers: the red can taught where it stands, then moved,
taken away, put far off, or joined by another red can."""

from __future__ import annotations

import re

import pytest

from asibot import depth, things
from asibot.things import Seen, Thing

from .scenes import BLUE, CAN_R, CAN_TOP, CAN_XY, COUNTER, GREEN, GREY, RED, Scene, kitchen_info

CAN_HEIGHT = CAN_TOP - COUNTER
Cylinder = tuple[float, float, float, float, float]


def can(x: float, y: float, height: float = CAN_HEIGHT) -> Cylinder:
    return (x, y, CAN_R, COUNTER, COUNTER + height)


def box(x: float, y: float, height: float, size: float = 0.07) -> tuple[float, float, float, float, float, float]:
    return (x - size / 2, y - size / 2, COUNTER, x + size / 2, y + size / 2, COUNTER + height)


#: A green box 9 cm tall near the can and a blue one 24 cm tall further off, on the counter
#: before a white wall: what stays put while the can comes and goes.
OTHERS = dict(boxes=[box(0.25, 0.25, 0.09), box(0.3, -0.25, 0.24)], box_colours=[GREEN, BLUE], wall=-0.3)


def look(cans: list[Cylinder], others: dict | None = None, noise: float = 0.002) -> list[Seen]:
    """What the kitchen camera sees of red `cans` among OTHERS (or `others`: {} for a bare counter)."""
    info = kitchen_info()
    scene = Scene(cylinders=list(cans), cylinder_colours=[RED] * len(cans), **(OTHERS if others is None else others))
    return things.objects_in_view(scene.depth(info, noise=noise), scene.rgb(info), info,
                                  depth.pose_matrix(info.pose), "kitchen")


@pytest.fixture(scope="module")
def taught() -> Thing:
    """The red can as teaching keeps it: touched where it stands (CAN_XY), measured, named."""
    red = [s for s in look([can(*CAN_XY)]) if s.colour == "red"]
    assert len(red) == 1
    return Thing("red can", "red", red[0].found.height, red[0].found.width, red[0].found.centre)


def seen(colour: str, x: float, y: float, height: float, width: float = 2 * CAN_R, camera: str = "kitchen") -> Seen:
    """An object as objects_in_view would report it, without rendering a scene."""
    found = depth.Touched((x, y, COUNTER + height), "object", COUNTER + height, (x, y, COUNTER + height / 2),
                          height, width, COUNTER, 100)
    return Seen(colour, found, camera)


# --- seeing -------------------------------------------------------------------------------------
def test_objects_in_view_finds_the_red_can_and_the_green_box_with_their_sizes():
    info = kitchen_info()
    scene = Scene(cylinders=[can(*CAN_XY)], cylinder_colours=[RED], boxes=[box(0.3, -0.2, 0.09)],
                  box_colours=[GREEN], wall=-0.3)
    found = things.objects_in_view(scene.depth(info, noise=0.002), scene.rgb(info), info,
                                   depth.pose_matrix(info.pose), "kitchen")
    by_colour = {s.colour: s for s in found}
    assert set(by_colour) == {"green", "red"} and len(found) == 2
    red, green = by_colour["red"], by_colour["green"]
    assert red.camera == "kitchen" and red.found.kind == "object"
    assert red.found.height == pytest.approx(CAN_HEIGHT, abs=0.01)
    assert red.found.width == pytest.approx(2 * CAN_R, abs=0.015)
    assert red.found.centre[:2] == pytest.approx(CAN_XY, abs=0.01)
    assert red.words() == "a red object 12 cm tall"
    assert green.found.height == pytest.approx(0.09, abs=0.01)
    assert green.found.centre[:2] == pytest.approx([0.3, -0.2], abs=0.015)
    assert green.words() == "a green object 9 cm tall"


def test_grey_things_and_the_counter_are_not_seen_nor_anything_without_a_matching_picture():
    info = kitchen_info()
    scene = Scene(cylinders=[can(*CAN_XY)], cylinder_colours=[RED], boxes=[box(0.3, -0.2, 0.09)],
                  box_colours=[GREY], wall=-0.3)
    image, rgb, pose = scene.depth(info), scene.rgb(info), depth.pose_matrix(info.pose)
    assert [s.colour for s in things.objects_in_view(image, rgb, info, pose)] == ["red"]
    assert things.objects_in_view(image, None, info, pose) == []
    assert things.objects_in_view(image, rgb[::2, ::2], info, pose) == []
    with pytest.raises(depth.DepthError, match="wait for the next frame"):
        things.objects_in_view(image[:100], rgb[:100], info, pose)


def test_two_red_cans_one_behind_the_other_in_one_colour_blob_are_both_seen():
    # Seen from the camera (at +x), the far can shows above the near one: one red blob.
    found = look([can(*CAN_XY), can(CAN_XY[0] - 0.15, CAN_XY[1])], others={})
    assert [s.colour for s in found] == ["red", "red"]
    xs = sorted(s.found.centre[0] for s in found)
    assert xs == pytest.approx([CAN_XY[0] - 0.15, CAN_XY[0]], abs=0.015)


# --- finding the taught thing again -------------------------------------------------------------
def test_the_can_moved_12_cm_is_found_where_it_stands_now(taught):
    assert taught.where[:2] == pytest.approx(CAN_XY, abs=0.01)
    best = things.choose(taught, look([can(CAN_XY[0], CAN_XY[1] + 0.12)]))
    assert best is not None and best.colour == "red"
    assert best.found.centre[:2] == pytest.approx([CAN_XY[0], CAN_XY[1] + 0.12], abs=0.01)
    assert things.moved(taught, best) == pytest.approx(0.12, abs=0.01)


def test_a_can_that_is_gone_is_not_found_and_the_user_hears_what_is_there(taught):
    everything = look([])
    assert things.choose(taught, everything) is None
    assert things.not_found(taught, everything) == ("I looked for the red can and see a green object 9 cm tall and "
                                                    "a blue object 24 cm tall, but no red can.")
    assert things.not_found(taught, look([], others={})) == "I looked for the red can and see nothing standing there."


def test_a_can_further_than_the_search_radius_is_not_taken_for_it(taught, monkeypatch):
    """The kitchen camera sees less than the radius (1.2 m, the counter in the arm's reach) around
    the can: the rule is checked with a radius of 0.5 m and the can 0.8 m away."""
    monkeypatch.setattr(things, "SEARCH_RADIUS", 0.5)
    everything = look([can(CAN_XY[0], CAN_XY[1] - 0.8)])
    assert any(s.colour == "red" for s in everything)
    assert things.choose(taught, everything) is None
    said = things.not_found(taught, everything)
    assert said.startswith("I looked for the red can and see a red object 12 cm tall, 0.80 m from where the red can "
                           "was taught, a green object 9 cm tall and a blue object 24 cm tall")
    assert said.endswith(", but no red can.")


def test_a_taller_red_thing_where_the_can_stood_is_not_the_can(taught):
    everything = look([can(*CAN_XY, height=0.3)])
    assert things.choose(taught, everything) is None
    assert things.not_found(taught, everything) == ("I looked for the red can and see a red object 30 cm tall, taller "
                                                    "than the red can, a green object 9 cm tall and a blue object 24 "
                                                    "cm tall, but no red can.")


@pytest.mark.parametrize("reverse", [False, True])
@pytest.mark.parametrize("case", ["size", "place"])
def test_of_two_red_cans_the_one_of_its_size_or_nearer_its_place_is_chosen(taught, case, reverse):
    if case == "size":
        # A can 3 cm taller where it stood (still within the height slack), and one of its
        # size 30 cm off: the size wins over the place.
        right, wrong = can(CAN_XY[0], CAN_XY[1] + 0.3), can(*CAN_XY, height=CAN_HEIGHT + 0.03)
    else:
        right, wrong = can(CAN_XY[0], CAN_XY[1] + 0.1), can(CAN_XY[0], CAN_XY[1] + 0.35)
    everything = look([right, wrong])
    assert sum(s.colour == "red" for s in everything) == 2
    best = things.choose(taught, everything[::-1] if reverse else everything)
    assert best is not None and best.found.centre[:2] == pytest.approx(right[:2], abs=0.015)


@pytest.mark.parametrize("other, fits", [
    (dict(), True),
    (dict(colour="orange"), False),
    (dict(height=0.145), True),            # +25 %: within 30 %
    (dict(height=0.165), False),
    (dict(height=0.02), False),
    (dict(width=0.09), True),              # +0.024 m: within max(0.03, 40 %)
    (dict(width=0.1), False),
    (dict(y=0.5 + 0.45), True),
    (dict(x=0.4, y=0.5 + 0.4), True),      # 0.57 m away: on the counter still
    (dict(x=0.9, y=0.5 + 0.9), False),     # 1.27 m away
])
def test_choose_takes_only_its_colour_about_its_size_within_the_search_radius(other, fits):
    thing = Thing("red can", "red", 0.12, 0.066, (0.0, 0.5, 0.02))
    args = dict(colour="red", x=0.0, y=0.5, height=0.12, width=0.066) | other
    candidate = seen(**args)
    assert (things.choose(thing, [candidate]) is candidate) is fits


def test_what_is_said_when_nothing_fits_names_each_object_once_and_only_a_few():
    thing = Thing("red can", "red", 0.12, 0.066, (0.0, 0.5, 0.02))
    # Two cameras see the same short red object; a wide one stands far off.
    two_views = [seen("red", 0.0, 0.52, 0.05), seen("red", 0.01, 0.52, 0.05, camera="arm")]
    assert things.not_found(thing, two_views) == ("I looked for the red can and see a red object 5 cm tall, shorter "
                                                  "than the red can, but no red can.")
    assert things.not_found(thing, two_views + [seen("green", 0.3, 0.0, 0.09)]) == (
        "I looked for the red can and see a red object 5 cm tall, shorter than the red can, and a green object 9 cm "
        "tall, but no red can.")
    far_and_wide = seen("red", 0.0, -0.8, 0.12, width=0.2)
    assert "a red object 12 cm tall, wider than the red can and 1.30 m from where it was taught" in \
        things.not_found(thing, [far_and_wide])
    many = [seen(c, 0.1 * i, 0.0, 0.1) for i, c in enumerate(["green", "blue", "yellow", "purple", "orange"])]
    said = things.not_found(thing, many)
    assert said.endswith(", a yellow object 10 cm tall and 2 more things, but no red can.")
    assert said.count("object") == things.MENTIONED
    assert things.not_found(Thing("mug", "white", 0.1, 0.08, (0.0, 0.5, 0.0)), many) == \
        "I looked for the mug, but I find things only by a bright colour, and it is white."


def test_moved_is_the_horizontal_distance_from_where_it_was_taught():
    thing = Thing("red can", "red", 0.12, 0.066, (0.0, 0.5, 0.02))
    assert things.moved(thing, seen("red", 0.3, 0.9, 0.3)) == pytest.approx(0.5)
    assert seen("orange", 0, 0, 0.1).words() == "an orange object 10 cm tall"


# --- a thing's JSON -------------------------------------------------------------------------------
GOOD = {"name": "red can", "colour": "red", "height": 0.12, "width": 0.066, "where": [0.0, 0.5, 0.02]}


def test_a_thing_goes_to_json_and_back():
    thing = Thing.from_json(GOOD)
    assert thing == Thing("red can", "red", 0.12, 0.066, (0.0, 0.5, 0.02))
    assert thing.as_json() == GOOD and Thing.from_json(thing.as_json()) == thing
    assert Thing.from_json(GOOD | {"name": "  the blue mug "}).name == "the blue mug"
    assert set(things.COLOURS) == {"red", "orange", "yellow", "green", "blue", "purple", "white", "grey", "black"}


@pytest.mark.parametrize("change, says", [
    ({"name": ""}, "name is 1 to 40 printable characters"),
    ({"name": "   "}, "name is 1 to 40"),
    ({"name": "x" * 41}, "name is 1 to 40"),
    ({"name": "red\ncan"}, "name is 1 to 40 printable"),
    ({"name": 7}, "name is"),
    ({"colour": "crimson"}, "colour is one of red, orange, yellow, green, blue, purple, white, grey, black; "
                            "got 'crimson'"),
    ({"colour": None}, "colour is one of"),
    ({"height": 0.001}, "height is a number of metres from 0.005 to 1.0; got 0.001"),
    ({"height": 2}, "height is a number of metres"),
    ({"height": True}, "height is a number"),
    ({"height": "0.1"}, "height is a number"),
    ({"width": float("nan")}, "width is a number of metres"),
    ({"width": -0.05}, "width is a number"),
    ({"where": [0, 0]}, "where is 3 numbers"),
    ({"where": [0, 0, float("inf")]}, "where is 3 numbers"),
    ({"where": [6, 0, 0]}, "within 5 m of the robot"),
    ({"where": [0, False, 0]}, "where is 3 numbers"),
    ({"where": "0 0 0"}, "where is 3 numbers"),
    ({"where": None}, "where is 3 numbers"),
    ({"colour": ...}, "has no colour"),
    ({"color": "red"}, "has no field 'color'"),
])
def test_a_thing_with_a_bad_field_is_refused_with_a_sentence_naming_it(change, says):
    data = {k: v for k, v in (GOOD | change).items() if v is not ...}
    with pytest.raises(ValueError, match=f"^(A thing|The thing).*{re.escape(says)}"):
        Thing.from_json(data)


def test_a_thing_that_is_not_an_object_is_refused():
    with pytest.raises(ValueError, match="A thing is a JSON object with its name, colour, height, width and where"):
        Thing.from_json(["red can"])


def _escape(text: str) -> str:
    import re
    return re.escape(text)
