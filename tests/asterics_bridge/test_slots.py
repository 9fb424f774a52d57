"""Who gets a TCP slot, and whose slot a newcomer takes (`slots.room_for`), without sockets:
other machines' addresses cannot be made on a test's loopback."""

from dataclasses import dataclass

import pytest

from asibot.asterics_bridge.limits import Limits
from asibot.asterics_bridge.slots import LOOPBACK, group_of, room_for

LIMITS = Limits(max_clients=4, per_address=2)


@dataclass
class Held:
    name: str
    group: str = LOOPBACK
    spoke: bool = True
    heard: float = 0.0
    busy: bool = False


@pytest.mark.parametrize("host, group", [
    ("127.0.0.1", LOOPBACK), ("127.0.0.2", LOOPBACK), ("::1", LOOPBACK), ("::ffff:127.0.0.1", LOOPBACK),
    ("192.0.2.7", "192.0.2.7"), ("::ffff:192.0.2.7", "192.0.2.7"), ("fe80::1%eth0", "fe80::1"),
    ("2001:db8::5", "2001:db8::5"),
])
def test_every_local_program_is_one_group_other_machines_their_own(host, group):
    assert group_of(host) == group


def test_a_free_slot_closes_nobody():
    assert room_for(LOOPBACK, [Held("a"), Held("b", "192.0.2.7")], LIMITS) == room_for(LOOPBACK, [], LIMITS)
    assert room_for(LOOPBACK, [], LIMITS).victim is None and room_for(LOOPBACK, [], LIMITS).refusal is None


def test_local_programs_have_no_share_of_their_own():
    """On loopback every program is 127.0.0.1: a share would only shrink what they all share."""
    room = room_for(LOOPBACK, [Held("a"), Held("b"), Held("c")], LIMITS)
    assert room.victim is None and room.refusal is None


def test_a_full_bridge_closes_the_longest_silent():
    holders = [Held("recent", heard=30.0), Held("oldest", heard=10.0), Held("middle", heard=20.0)]
    room = room_for(LOOPBACK, holders + [Held("busy", heard=0.0, busy=True)], LIMITS)
    assert (room.victim.name, room.refusal, room.limit) == ("oldest", None, "full")


def test_one_that_never_spoke_goes_before_one_that_did():
    holders = [Held("spoke long ago", heard=1.0), Held("mute", spoke=False, heard=50.0), Held("c"), Held("d")]
    assert room_for(LOOPBACK, holders, LIMITS).victim.name == "mute"


def test_another_machine_over_its_share_takes_its_own_slot():
    holders = [Held("local", heard=0.0), Held("r1", "192.0.2.7", heard=5.0), Held("r2", "192.0.2.7", heard=9.0)]
    room = room_for("192.0.2.7", holders, LIMITS)
    assert (room.victim.name, room.limit) == ("r1", "address")
    assert room_for("198.51.100.3", holders, LIMITS) == room_for("198.51.100.3", [], LIMITS)    # another: free


def test_a_full_bridge_takes_the_slot_of_the_address_holding_the_most():
    """A newcomer does not push a machine with one connection out for one with many."""
    holders = [Held("lone", "198.51.100.3", heard=0.0), Held("r1", "192.0.2.7", heard=5.0),
               Held("r2", "192.0.2.7", heard=9.0), Held("local", heard=7.0)]
    assert room_for("203.0.113.9", holders, LIMITS).victim.name == "r1"
    # ... unless the biggest holder's are all busy: then the longest silent of the others
    busy = [Held("lone", "198.51.100.3", heard=0.0), Held("r1", "192.0.2.7", busy=True),
            Held("r2", "192.0.2.7", busy=True), Held("local", heard=7.0)]
    assert room_for("203.0.113.9", busy, LIMITS).victim.name == "lone"


@pytest.mark.parametrize("group, holders, refusal", [
    (LOOPBACK, [Held(str(i), busy=True) for i in range(4)],
     "the bridge serves 4 clients at most, and each of them has a command under way; try again in a moment."),
    ("192.0.2.7", [Held(str(i), "192.0.2.7", busy=True) for i in range(2)],
     "192.0.2.7 holds 2 connections to the bridge already, the most one address may, and each of them has a "
     "command under way; close one of them, or try again in a moment."),
])
def test_only_when_every_one_is_busy_is_a_newcomer_refused(group, holders, refusal):
    room = room_for(group, holders, LIMITS)
    assert room.victim is None and room.refusal == refusal
