"""The name a capture proposes (asibot.web.naming): place, above/near a taught point, point-N."""

from __future__ import annotations

from asibot.web.naming import suggest

CAN = ("can", [0.0, 0.5, 0.09, 180, 0])


def test_nothing_known_gives_the_first_free_number():
    assert suggest([]) == "point-1"
    assert suggest(["point-1", "point-2", "point-4"]) == "point-3"
    assert suggest(["point-1", "can"], [CAN], here=[1.0, 0.0, 1.0, 0, 0]) == "point-2"   # far from the can


def test_straight_above_a_taught_point_is_above_it():
    assert suggest(["can"], [CAN], here=[0.0, 0.5, 0.21, 180, 0]) == "above-can"
    assert suggest(["can", "above-can"], [CAN], here=[0.005, 0.5, 0.19, 180, 0]) == "above-can-2"


def test_where_a_taught_point_is_is_that_point_again():
    assert suggest(["can"], [CAN], here=[0.0, 0.505, 0.09, 180, 0]) == "can-2"


def test_close_beside_or_below_a_taught_point_is_near_it():
    assert suggest(["can"], [CAN], here=[0.08, 0.5, 0.10, 180, 0]) == "near-can"     # beside
    assert suggest(["can"], [CAN], here=[0.0, 0.5, 0.07, 180, 0]) == "near-can"      # 2 cm lower
    cup = ("cup", [0.3, 0.3, 0.1, 180, 0])
    assert suggest(["can", "cup"], [CAN, cup], here=[0.25, 0.32, 0.1, 180, 0]) == "near-cup"  # the nearest


def test_relations_do_not_pile_up_and_generic_names_say_nothing():
    above = ("above-can", [0.0, 0.5, 0.21, 180, 0])
    assert suggest(["can", "above-can"], [CAN, above], here=[0.0, 0.5, 0.31, 180, 0]) == "above-can-2"
    generic = ("point-1", [0.0, 0.5, 0.09, 180, 0])
    assert suggest(["point-1"], [generic], here=[0.0, 0.5, 0.09, 180, 0]) == "point-2"


def test_a_base_at_a_named_place_names_the_point_after_it():
    assert suggest(["can"], [CAN], here=[0.0, 0.5, 0.21, 180, 0], place="fridge") == "fridge-1"
    assert suggest(["fridge-1"], place="fridge") == "fridge-2"
    assert suggest([], place="charging station") == "charging-station-1"
    assert suggest([], place="1st shelf") == "p-1st-shelf-1"


def test_down_from_an_approach_point_is_the_thing_itself_in_the_users_spelling():
    """Seen by hand: `at_can`, 12 cm below `above_can`, was offered `near-above_can`."""
    above = ("above_can", [0.0, 0.5, 0.21, 180, 0])
    assert suggest(["above_can"], [above], here=[0.0, 0.5, 0.09, 180, 0]) == "can"
    assert suggest(["above_can", "can"], [above], here=[0.0, 0.5, 0.09, 180, 0]) == "can-2"
    assert suggest(["above_can"], [above], here=[0.08, 0.5, 0.2, 180, 0]) == "near_can"
    assert suggest(["above-can"], [("above-can", above[1])], here=[0.0, 0.5, 0.1, 180, 0]) == "can"
    # A name without a relation keeps "near-" with a hyphen, whatever is in it.
    shelf = ("top_shelf", [0.0, 0.5, 0.21, 180, 0])
    assert suggest(["top_shelf"], [shelf], here=[0.0, 0.5, 0.1, 180, 0]) == "near-top_shelf"
