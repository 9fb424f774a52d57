"""The latched estop: an engage always counts, and only a release the follower saw after it clears it.

`asibot estop`, a program's `CartesianClient.estop()` or a web page latch
`EStop(engaged=True)` on `rb/<robot>/estop`, and the first two exit soon after. A latch is
served by the process that latched it, so when that process ended, a driver, controller or
UI started later learned nothing, and took the robot for released. So every process that
follows the estop (the drivers, the sim, kinematics, nav, the web page, the AsTeRICS bridge)
follows it with `EStopState` (one robot) or `EStopStates` (every robot), which keep serving
the state they hold (`Bus.latch(..., publish=False)`): it lives as long as any of them runs.

Who decides, and by whose clock (issue 51). A sender chooses its stamp, so a stamp never
decides: a release stamped ten years ahead once outranked every later engage, and an engage
stamped ahead could never be released. The rule (`Rule`), in every follower:

- an engage always counts, whatever its stamp, sender or signature: stopping needs no proof;
- a release counts only signed (asibot.safety.identity), naming who released (`by`), stamped
  within `MAX_SKEW_S` of the follower's own clock, and newer (by its sender's sequence number)
  than anything that sender sent before; it then clears the engages this follower received
  before it, in the follower's own order of arrival;
- a follower that starts later asks every keeper (`Bus.subscribe(..., on_latched=...)`): one
  copy engaged is enough to start engaged; it starts released only when no keeper holds an
  engage and a copy is a signed release not stamped ahead.

A refused release, and an engage stamped far from the follower's clock (it counts all the
same), are told (`on_refused`, `on_skewed`): the drivers make them Events. Whoever can put on
the key can thus stop a robot and keep a restarted one stopped, never move one.

A restarted driver learns the state from the controller, and a restarted controller from
the driver. When all of them ended (the whole stack stopped), the state is gone with them:
the stack starts released, which moves nothing by itself (a robot moves only on a new
motion request). Hardware that must stay stopped across a restart of its software keeps a
physical estop in its power circuit; this one is a software latch.

`who()` names the person and program that engage or release it (`EStop.by`), `latch` signs
the message with the sender's key, and the drivers' events name a release by what its sender
said and the key that signed it (`named`).
"""

from __future__ import annotations

import getpass
import logging
import os
import socket
import sys
import threading
import time
import weakref
from typing import Any, Callable

from asibot import access, keys
from asibot.safety import identity
from asibot.safety.identity import Identity
from asibot.messages import EStop

log = logging.getLogger(__name__)

#: How far an estop's stamp may be from a follower's clock, s. A release outside it is
#: refused: an old one played again, or a sender whose clock is wrong. Processes that
#: follow the estop share one machine or a LAN kept in time (NTP: milliseconds); messages
#: take milliseconds even on a loaded machine.
MAX_SKEW_S = 5.0


def who(program: str | None = None, login_of: str | None = None) -> str:
    """"user@host (program, pid N)": who engages or releases an estop from this process; with
    `login_of` (the bus session's name) and a router that checks logins, " as <login>" too:
    the part the router vouches for (asibot.access)."""
    try:
        user = getpass.getuser()
    except Exception:  # no user name in some containers
        user = f"uid {os.getuid()}" if hasattr(os, "getuid") else "someone"
    program = program or os.path.basename(sys.argv[0] or "") or "python"
    login = access.signed_in_as(login_of) if login_of else ""
    return f"{user}@{socket.gethostname()} ({program}, pid {os.getpid()}){login}"


def context(robot: str) -> str:
    """What an estop's signature is for (asibot.safety.identity)."""
    return f"{robot}/estop"


def latch(bus: Any, robot: str, sender: Identity, engaged: bool, reason: str = "", by: str = "") -> EStop:
    """Engage or release the estop of `robot`: the EStop signed by `sender`, latched on `bus`.

    The process then follows the estop too (if it did not already), so the copy it serves is
    the state by the rule, not its own last word: a voice "stop" a page released later must
    not start a restarted driver stopped (a newcomer starts stopped when one copy is engaged)."""
    if not _follows(bus, keys.estop(robot)):
        EStopStates(bus, lambda robot, msg: None)
    msg = sender.sign(EStop(engaged=engaged, reason=reason, by=by), context(robot))
    bus.latch(keys.estop(robot), msg)
    return msg


#: The key patterns each bus's followers cover, so `latch` adds one only where none is.
_FOLLOWED: "weakref.WeakKeyDictionary[Any, set[str]]" = weakref.WeakKeyDictionary()
_FOLLOWED_LOCK = threading.Lock()


def _follows(bus: Any, key: str) -> bool:
    with _FOLLOWED_LOCK:
        patterns = _FOLLOWED.get(bus, set())
    return key in patterns or keys.every_robot(keys.estop) in patterns


def refused_text(msg: EStop, why: str) -> str:
    """The drivers' Event for a release that did not count."""
    return (f"A release of the emergency stop ({named(msg) or 'anonymous'}) was ignored: {why}. The robot "
            "stays stopped; release it from the page, `asibot release` or a program's release().")


def named(msg: EStop) -> str:
    """Who engaged or released it, for the drivers' sentences: what its sender said, and the
    key that signed it ("alice@home (asibot release, pid 8), key asibot-release-mfrgg2lt");
    "" when it says nothing and is not signed."""
    key = f"key {identity.short(msg.signer)}" if msg.signer and msg.signature else ""
    return ", ".join(filter(None, (msg.by, key or ("unsigned" if msg.by else ""))))


def _seconds(skew_s: float) -> str:
    skew = abs(skew_s)
    if skew >= 2 * 86_400:
        return f"{skew / 86_400:,.0f} days"
    return f"{skew:,.0f} s" if skew >= 10 else f"{skew:.1f} s"


class Rule:
    """One robot's estop as one follower holds it: by the follower's own clock and order of
    arrival, never by the sender's stamp (the module's rules). Plain, for tests: no bus."""

    def __init__(self, robot: str, clock: Callable[[], int] = time.time_ns) -> None:
        self.context = context(robot)
        self.clock = clock
        self.state: EStop | None = None
        self._seq: dict[str, int] = {}     # the newest sequence number counted, by signer

    def skew_s(self, msg: EStop) -> float:
        """How far ahead of this follower's clock `msg` is stamped, s (behind: negative)."""
        return (msg.stamp - self.clock()) / 1e9

    def receive(self, msg: EStop) -> tuple[bool, str | None]:
        """Apply one EStop as it arrives: (whether the state changed, why a release was
        refused or None)."""
        if msg == self.state:               # the latched answer and the sample of one latch
            return False, None
        if not msg.engaged:
            why = self.release_refusal(msg, live=True)
            if why is not None:
                return False, why
        self._counted(msg)
        return True, None

    def prime(self, copies: list[EStop]) -> tuple[EStop | None, list[tuple[EStop, str]]]:
        """Start from every keeper's copy: engaged when one is; released when one is a release
        that counts. (The state taken or None, [(copy, why refused)])."""
        engaged = [m for m in copies if m.engaged]
        if engaged:
            self._counted(engaged[0])
            return engaged[0], []
        refused: list[tuple[EStop, str]] = []
        for msg in copies:
            why = self.release_refusal(msg, live=False)
            if why is None:
                self._counted(msg)
                return msg, refused
            refused.append((msg, why))
        return None, refused

    def release_refusal(self, msg: EStop, live: bool) -> str | None:
        """None when release `msg` counts; otherwise why not, as the end of a sentence. A
        latched copy (`live=False`) may be old: it says what a keeper holds."""
        why = identity.refusal(self.context, msg)
        if why is not None:
            return why
        if not msg.by.strip():
            return "it does not say who released it"
        skew = self.skew_s(msg)
        if skew > MAX_SKEW_S:
            return (f"it is stamped {_seconds(skew)} ahead of this robot's clock (a release counts only "
                    "as it is sent: set the sender's clock)")
        if live and skew < -MAX_SKEW_S:
            return (f"it is stamped {_seconds(skew)} in the past (a release counts only as it is sent: "
                    "an old one played again, or the sender's clock to set)")
        last = self._seq.get(msg.signer)
        if last is not None and msg.seq <= last:
            return f"its sender sent it before (number {msg.seq}, after {last}): played again"
        return None

    def _counted(self, msg: EStop) -> None:
        if msg.signer and msg.signature:
            self._seq[msg.signer] = max(msg.seq, self._seq.get(msg.signer, 0))
        self.state = msg


class EStopStates:
    """Follow the estop of every robot matching `pattern` on `bus` by the module's rules, and
    keep serving the state held of each, so it outlives its sender.

    `on_change(robot, msg)` hears each state taken (the first one from the keepers), in order;
    `on_refused(robot, msg, why)` each release that did not count; `on_skewed(robot, msg, text)`
    each engage stamped more than MAX_SKEW_S from this clock (it counts all the same).
    """

    def __init__(self, bus: Any, on_change: Callable[[str, EStop], None], *,
                 pattern: str = keys.every_robot(keys.estop),
                 on_refused: Callable[[str, EStop, str], None] | None = None,
                 on_skewed: Callable[[str, EStop, str], None] | None = None,
                 clock: Callable[[], int] = time.time_ns) -> None:
        self._bus = bus
        self._on_change = on_change
        self._on_refused = on_refused
        self._on_skewed = on_skewed
        self._clock = clock
        self._lock = threading.Lock()
        self._rules: dict[str, Rule] = {}
        with _FOLLOWED_LOCK:
            _FOLLOWED.setdefault(bus, set()).add(pattern)
        bus.subscribe(pattern, EStop, self._receive, with_key=True, on_latched=self._prime)

    def state(self, robot: str) -> EStop | None:
        rule = self._rules.get(robot)
        return rule.state if rule is not None else None

    def engaged(self, robot: str) -> bool:
        state = self.state(robot)
        return state is not None and state.engaged

    def _rule(self, robot: str) -> Rule:
        rule = self._rules.get(robot)
        if rule is None:
            rule = self._rules[robot] = Rule(robot, self._clock)
        return rule

    def _prime(self, copies: list[tuple[str, EStop]]) -> None:
        by_robot: dict[str, list[EStop]] = {}
        for key, msg in copies:
            robot = keys.robot_of(key)
            if robot is not None:
                by_robot.setdefault(robot, []).append(msg)
        for robot, held in by_robot.items():
            with self._lock:
                taken, refused = self._rule(robot).prime(held)
            for msg, why in refused:
                self._refused(robot, msg, why)
            if taken is not None:
                self._took(robot, taken)

    def _receive(self, key: str, msg: EStop) -> None:
        robot = keys.robot_of(key)
        if robot is None:
            return
        with self._lock:
            changed, why = self._rule(robot).receive(msg)
        if why is not None:
            self._refused(robot, msg, why)
        elif changed:
            self._took(robot, msg)

    def _refused(self, robot: str, msg: EStop, why: str) -> None:
        log.warning("ignored a release of the estop of %s (%s): %s", robot, named(msg) or "anonymous", why)
        if self._on_refused is not None:
            self._on_refused(robot, msg, why)

    def _took(self, robot: str, msg: EStop) -> None:
        skew = self._rules[robot].skew_s(msg)
        if msg.engaged and abs(skew) > MAX_SKEW_S and self._on_skewed is not None:
            self._on_skewed(robot, msg, skewed_text(msg, skew))
        try:
            self._bus.latch(keys.estop(robot), msg, publish=False)
        except Exception:  # a closing bus: the other keepers serve it
            log.debug("could not keep the estop state of %s", robot, exc_info=True)
        self._on_change(robot, msg)


def skewed_text(msg: EStop, skew_s: float) -> str:
    """The drivers' Event for an engage stamped far from their clock."""
    where = "ahead of" if skew_s > 0 else "behind"
    return (f"An emergency stop ({named(msg) or 'anonymous'}) is stamped {_seconds(skew_s)} {where} this "
            "robot's clock. It counts: a stop always does. Set that sender's clock.")


class EStopState:
    """Follow the estop of one `robot` (EStopStates' rules): `on_change(msg)` for each state
    taken, `on_refused(msg, why)` for each release that did not count, `on_skewed(msg, text)`
    for an engage stamped far from this clock."""

    def __init__(self, bus: Any, robot: str, on_change: Callable[[EStop], None],
                 on_refused: Callable[[EStop, str], None] | None = None,
                 on_skewed: Callable[[EStop, str], None] | None = None,
                 clock: Callable[[], int] = time.time_ns) -> None:
        self.key = keys.estop(robot)
        self.robot = robot
        self._states = EStopStates(
            bus, lambda robot, msg: on_change(msg), pattern=self.key, clock=clock,
            on_refused=None if on_refused is None else (lambda robot, msg, why: on_refused(msg, why)),
            on_skewed=None if on_skewed is None else (lambda robot, msg, text: on_skewed(msg, text)))

    @property
    def state(self) -> EStop | None:
        return self._states.state(self.robot)

    @property
    def engaged(self) -> bool:
        return self._states.engaged(self.robot)
