"""The latched estop outlives whoever engaged it: every process that obeys it keeps serving it.

`asibot estop`, a program's `CartesianClient.estop()` or a web page latch
`EStop(engaged=True)` on `rb/<robot>/estop`, and the first two exit soon after. A latch is
served by the process that latched it, so when that process ended, a driver, controller or
UI started later learned nothing, and took the robot for released. So every process that
obeys the estop (the drivers, the sim, the kinematics service) follows it with `EStopState`,
which keeps serving the newest state it received (`Bus.latch(..., publish=False)`): the
state lives as long as any of them runs, and a subscriber with `latest=True` gets the
newest of the copies (by stamp).

A restarted driver learns the state from the controller, and a restarted controller from
the driver. When all of them ended (the whole stack stopped), the state is gone with them:
the stack starts released, which moves nothing by itself (a robot moves only on a new
motion request). Hardware that must stay stopped across a restart of its software keeps a
physical estop in its power circuit; this one is a software latch.

`who()` names the person and program that engage or release it (`EStop.by`), and `latch`
signs the message with the sender's key (asibot.safety.identity). A release counts only signed:
one that is not (a stranger's, or one that borrows another's name and cannot sign for it)
is ignored by every process that follows the estop, and the drivers' events name a release
by what its sender said and the key that signed it (`named`). An engage counts signed or not:
stopping needs no proof.
"""

from __future__ import annotations

import getpass
import logging
import os
import socket
import sys
import threading
from typing import Any, Callable

from asibot import access, keys
from asibot.safety import identity
from asibot.safety.identity import Identity
from asibot.messages import EStop

log = logging.getLogger(__name__)


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
    """Engage or release the estop of `robot`: the EStop signed by `sender`, latched on `bus`."""
    msg = sender.sign(EStop(engaged=engaged, reason=reason, by=by), context(robot))
    bus.latch(keys.estop(robot), msg)
    return msg


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


class EStopState:
    """Follow the estop of `robot` on `bus`: `on_change(msg)` for every newer EStop (the
    latched one first), and keep serving the newest, so it outlives its sender. A release
    that is not signed is ignored, and given to `on_refused(msg, why)`.

    A state older than the one held (by stamp: two latches answered, or a sample that
    overtook the latched answer) is ignored, and so is the same one twice (the latched
    answer and the sample of one latch).
    """

    def __init__(self, bus: Any, robot: str, on_change: Callable[[EStop], None],
                 on_refused: Callable[[EStop, str], None] | None = None) -> None:
        self.key = keys.estop(robot)
        self.context = context(robot)
        self._on_refused = on_refused
        self._bus = bus
        self._on_change = on_change
        self._lock = threading.Lock()
        self.state: EStop | None = None
        bus.subscribe(self.key, EStop, self._on_estop, latest=True)

    @property
    def engaged(self) -> bool:
        state = self.state
        return state is not None and state.engaged

    def _on_estop(self, msg: EStop) -> None:
        why = None if msg.engaged else identity.refusal(self.context, msg)
        if why is not None:
            log.warning("ignored a release of the estop (%s): %s", named(msg) or "anonymous", why)
            if self._on_refused is not None:
                self._on_refused(msg, why)
            return
        with self._lock:
            if self.state is not None and (msg.stamp < self.state.stamp or msg == self.state):
                return
            self.state = msg
        try:
            self._bus.latch(self.key, msg, publish=False)
        except Exception:  # a closing bus: the other keepers serve it
            log.debug("could not keep the estop state of %s", self.key, exc_info=True)
        self._on_change(msg)
