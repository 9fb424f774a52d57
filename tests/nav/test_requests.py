"""Every nav verb is checked by one table (asibot.nav.requests): a wrong field is `bad_request`
with the sentence of asibot.verbs, given before nav looks at the base; what a field cannot say
keeps nav's own sentence. The primitives nav drives are the names of asibot.driving."""

from __future__ import annotations

import pytest

from asibot import driving, keys
from asibot.bus import Bus
from asibot.errors import RpcError
from asibot.nav import requests
from asibot.nav.geometry import Pose
from asibot.nav.primitives import PRIMITIVES
from asibot.nav.service import NavService

START = Pose(1.0, 1.5, 0.0)
ROBOT = "pioneer-requests"


def test_the_table_covers_every_nav_verb():
    assert set(requests.VERBS) == set(keys.RPC_VERBS_NAV)
    assert all(spec.doc for spec in requests.VERBS.values())


def test_nav_drives_the_primitives_the_web_and_the_bridge_name():
    assert tuple(PRIMITIVES) == driving.PRIMITIVES
    assert driving.normalise("  Turn   LEFT 90 ") == "turn left 90"


@pytest.fixture
def bus(memory_bus, apartment, world_places):
    bus = Bus("nav", memory_bus)
    svc = NavService(bus, ROBOT, apartment, world_places, START, run_loop=False)
    try:
        yield bus
    finally:
        svc.close()
        bus.close()


@pytest.mark.parametrize("verb, body, sentence", [
    ("goto", {"where": "fridge"}, "goto takes only place, pose; 'where' is not one of them."),
    ("goto", {"pose": [1.0, 1.0, 90]}, "(theta = 90 is outside [-6.28319, 6.28319] rad)."),
    ("drive", {"distance": 12}, "'distance' must be a number in [-10, 10] m; got 12."),
    ("turn", {"angle": True}, "'angle' must be a number in [-360, 360] deg; got True."),
    ("primitive", {"name": "forward", "continuous": "yes"}, "'continuous' must be true or false"),
    ("settings", {"change": "louder"}, "'change' must be faster or slower or wider or narrower"),
    ("result", {}, "result needs 'goal_id': a whole number from 1 to"),
    ("set_pose", {"pose": [1.0, 1.5, 0.0], "cov": [-1, 0, 0]}, "(xx = -1 is outside [0, 100] m^2)."),
    ("save_place", {"name": "x" * 41}, "(it has 41 characters)."),
    ("map_save", {"name": "home", "use": 1}, "'use' must be true or false"),
    ("status", {"verbose": True}, "status takes no arguments; 'verbose' is not one of them."),
])
def test_a_wrong_field_is_refused_with_its_sentence(bus, verb, body, sentence):
    with pytest.raises(RpcError) as err:
        bus.call(keys.nav_rpc(ROBOT, verb), body, timeout=5)
    assert err.value.code == "bad_request" and sentence in err.value.message


@pytest.mark.parametrize("verb, body, sentence", [
    ("drive", {"distance": 0}, "distance must not be 0"),
    ("turn", {"angle": 0.0}, "angle must not be 0"),
    ("goto", {"place": "fridge", "pose": [1.0, 1.0, 0.0]}, "not both"),
    ("map_save", {"name": "../home"}, "A map name is a plain name, not a path"),
])
def test_what_a_field_cannot_say_keeps_navs_sentence(bus, verb, body, sentence):
    with pytest.raises(RpcError) as err:
        bus.call(keys.nav_rpc(ROBOT, verb), body, timeout=5)
    assert err.value.code == "bad_request" and sentence in err.value.message
