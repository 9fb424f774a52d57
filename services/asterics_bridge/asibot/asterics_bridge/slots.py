"""Who gets one of the TCP port's slots, and whose slot a newcomer takes when there is none.

The bridge serves `Limits.max_clients` TCP clients at once, and at most `Limits.per_address`
from one address other than this machine's own. On loopback every local program has the same
address (127.0.0.1), so a share per address would only shrink what they all share: local
programs (`LOOPBACK`, any 127.0.0.0/8 or ::1 peer) have no share of their own, only the total.

A full bridge (or a full share) does not turn a newcomer away while a slot is merely held: the
connection that has been silent the longest makes room (`room_for`), so clients that spoke once
and then wait cannot lock out the one who needs the robot now. Who goes first:
- a connection that has not yet sent a whole frame or line (it proved nothing), then
- the one whose last whole frame or line (a NetConnection keepalive counts) is the oldest;
- never one whose command waits or runs (its answer is due);
- a newcomer over its address's share takes the slot of its own address's connection; one
  over the total takes the slot of the address holding the most, so one machine cannot push
  the others out.
Only when every candidate is busy is the newcomer turned away (`servers` still obeys a stop it
sends first).
"""

from __future__ import annotations

import ipaddress
from collections import Counter
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

from asibot.asterics_bridge.limits import Limits

#: The address every local program is counted under.
LOOPBACK = "this machine"


class Holder(Protocol):
    """What the choice needs to know of a connected client."""
    group: str          # its address (`group_of`)
    spoke: bool         # a whole frame or line came from it
    heard: float        # when the last whole frame or line came (its connection, before any), monotonic s

    @property
    def busy(self) -> bool:
        """A command of it waits or runs."""
        ...


H = TypeVar("H", bound=Holder)


@dataclass(frozen=True)
class Room(Generic[H]):
    """The verdict for a newcomer: a slot (after closing `victim`, when one is named), or
    `refusal`, the sentence it is told. `limit` is which bound was reached: "full", "address",
    or "" (a free slot)."""
    victim: H | None = None
    refusal: str | None = None
    limit: str = ""


def group_of(host: str) -> str:
    """The address a peer of `host` is counted under: LOOPBACK for every local program (IPv4
    127.0.0.0/8, ::1, and IPv4-mapped forms of them), else the address itself."""
    try:
        ip = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:          # not an IP (a Unix socket): counted as itself
        return host
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        ip = ip.ipv4_mapped
    return LOOPBACK if ip.is_loopback else str(ip)


def room_for(group: str, holders: Collection[H], limits: Limits) -> Room[H]:
    """Whether a newcomer of `group` gets a slot among `holders` (the clients connected now),
    and whose slot it takes (see the module's docstring)."""
    own = sum(1 for h in holders if h.group == group)
    if group != LOOPBACK and own >= limits.per_address:
        victim = _longest_idle([h for h in holders if h.group == group])
        return Room(victim, None if victim else (
            f"{group} holds {own} connections to the bridge already, the most one address may, and each of them "
            "has a command under way; close one of them, or try again in a moment."), "address")
    if len(holders) >= limits.max_clients:
        held = Counter(h.group for h in holders)
        most = max(held.values())
        victim = _longest_idle(holders, lambda h: held[h.group] < most)
        return Room(victim, None if victim else (
            f"the bridge serves {limits.max_clients} clients at most, and each of them has a command under way; "
            "try again in a moment."), "full")
    return Room()


def _longest_idle(holders: Collection[H], spared: Callable[[H], bool] = lambda h: False) -> H | None:
    """The holder to close first: not busy; of those, the ones `spared` says not to touch last;
    then one that never spoke; then the one silent the longest. None when all are busy."""
    idle = [h for h in holders if not h.busy]
    return min(idle, key=lambda h: (spared(h), h.spoke, h.heard), default=None)
