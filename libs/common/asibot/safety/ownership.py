"""Ownership of motion: one controller at a time moves each part of a robot.

Without it any process on the router could publish `arm/command` or `cmd_vel` and the
driver obeyed (issue 10, finding 1): a replay, a fuzzer or a second kinematics service
moved the arm while the user's `stop()` answered ok. The rule, kept by every driver (the
CANopen arm driver, the ARCOS base driver, the sim):

- A controller announces itself with a liveliness token whose key names it, an identity new
  at every start that carries its public key (`asibot.safety.identity`), so a restarted controller
  is a new one. The arm and its gripper
  are driven by the kinematics service, on `keys.controller_alive(robot, id)`
  (`rb/<robot>/controller/alive/<id>`); a mobile base by the program that drives it (the nav
  service, a teleop program, a test) on `keys.base_controller_alive(robot, id)`
  (`rb/<robot>/base/controller/alive/<id>`). `announce` does both steps.
- A part is held by the controller that came alive first among those alive, as its driver
  saw them (by id for those it found alive at its own start). It holds the part until its
  token vanishes (the process ended, crashed or lost the router); then the oldest of the
  others alive takes over, if any.
- Every command carries its sender's id (`ArmCommand.controller`, `GripperCommand.controller`,
  `Twist.controller`), a sequence number and a signature by that id's key (`Controller.put`).
  A driver obeys only the holder's, signed by the holder's key, newer than the last it obeyed:
  any other command (another controller's, one that borrows the holder's id, a replayed or
  anonymous one) is refused whole with an Event, rate-limited like every refusal
  (`asibot.safety.events.EventThrottle`), and moves nothing.
- A person driving comes first (twist_mux's priorities): a controller's `priority` follows
  from its name (`priority`): nav's goals are `AUTONOMOUS`, every other controller (a
  joystick, a teleop program) `TELEOP`. A controller of higher priority than the holder takes
  the part with its first command (signed and new, as the holder's must be) and keeps it while
  it commands at least every `TAKEOVER_HOLD` s and stays alive; then the part goes back to
  the oldest alive. Controllers of the same priority wait in line as above. A controller
  that was overtaken hears it (`Holder.on_change`, as the driver does) and ends its own
  motion: nav ends its goal with a sentence the user sees.
- Stopping needs no ownership: the estop stops every part whoever engages it, and the
  kinematics `stop` verb (`CartesianClient.stop()`) makes the holder command a hold,
  whoever moved the arm. A change of holder, or its loss, stops the part and re-arms it
  (`asibot.safety.arming`): a stream still running from before does not move it.

Anyone on the router may still announce a controller (keeping strangers off the router is
the router's job, `asibot.access`): while another of the same or a higher priority holds a
part, a newcomer only waits in line; a newcomer of higher priority (any name but nav's) takes
the base from nav, as a person's joystick must. Nobody can send commands as the holder, on the
open router too.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Callable, Iterable

from asibot.safety import identity
from asibot import keys
from asibot.errors import RpcError
from asibot.safety.events import CommandRefused
from asibot.safety.identity import Identity

#: The parts of a robot that have a holder: the arm with its gripper, and the mobile base.
PARTS = ("arm", "base")

#: Priorities (twist_mux's): a person driving takes a part from a program driving on its own.
AUTONOMOUS, TELEOP = 0, 10
#: The controllers, by name, that drive on their own: every other one is a person's (TELEOP).
AUTONOMOUS_NAMES = frozenset({"nav"})
#: s a controller that took a part by priority keeps it after its last command (a joystick's
#: hand resting a moment is still driving), as twist_mux's per-input timeout.
TAKEOVER_HOLD = 2.0


def priority(controller: str) -> int:
    """The priority of a controller id ("<name>-<key>", asibot.safety.identity): by its name."""
    name, sep, _ = controller.rpartition("-")
    return AUTONOMOUS if (name if sep else controller) in AUTONOMOUS_NAMES else TELEOP


def token_key(robot: str, part: str, controller: str) -> str:
    """The liveliness key on which `controller` announces itself for `part` of `robot`."""
    if part == "arm":
        return keys.controller_alive(robot, controller)
    if part == "base":
        return keys.base_controller_alive(robot, controller)
    raise ValueError(f"part must be one of {', '.join(PARTS)}, not {part!r}")


def pattern(robot: str, part: str) -> str:
    """The pattern of every controller token of `part` of `robot`."""
    token_key(robot, part, "x")  # says what a wrong part is
    return keys.controllers_alive(robot) if part == "arm" else keys.base_controllers_alive(robot)


class Controller:
    """A controller of `part` of `robot`: its identity, and the commands it signs and sends."""

    def __init__(self, robot: str, part: str, name: str = "controller") -> None:
        token_key(robot, part, "x")  # says what a wrong part is
        self.robot, self.part = robot, part
        self.identity = Identity(name)
        self.id = self.identity.id
        self.context = context(robot, part)

    def sign(self, cmd: Any) -> Any:
        """`cmd` named, numbered and signed as this controller's."""
        return self.identity.sign(cmd, self.context)

    def put(self, publisher: Any, cmd: Any) -> None:
        """Sign `cmd` and publish it; in sequence order whichever thread sends."""
        self.identity.put(publisher, cmd, self.context)

    def announce(self, bus: Any) -> Any:
        """The liveliness token that makes this controller alive on `bus` (see above)."""
        return bus.announce(token_key(self.robot, self.part, self.id))

    def __repr__(self) -> str:
        return f"Controller({identity.short(self.id)!r} of the {self.part} of {self.robot})"


def context(robot: str, part: str) -> str:
    """What a command's signature is for: "<robot>/<part>" (asibot.safety.identity)."""
    return f"{robot}/{part}"


def announce(bus: Any, robot: str, part: str = "arm", name: str = "controller") -> Controller:
    """Announce a new controller of `part` of `robot` on `bus`; its `put` signs every command it
    sends. It holds the part if no other controller does (see above)."""
    controller = Controller(robot, part, name)
    controller.announce(bus)
    return controller


class NotHolder(CommandRefused):
    """A command from a sender that does not hold the part: refused whole, nothing moves."""

    code = "not_holder"


class NotSigned(CommandRefused):
    """A command that names the holder but its key did not sign it: someone else's."""

    code = "not_signed"


class Replayed(CommandRefused):
    """A command the holder signed, but not newer than one already obeyed: a copy played again."""

    code = "replayed"


class Holder:
    """Which controller holds `part` of `robot` now, from the liveliness of its controllers and
    the commands that take the part by priority (see above).

    `update(key, alive)` is a `bus.watch` callback (`follow` wires it); `refusal(cmd)` judges
    each command; `tick()`, called now and then, gives the part back once a controller that
    took it has gone quiet. `on_change(holder)` is called, outside the lock, with the new
    holder or None whenever it changes, by any of the three.
    """

    def __init__(self, robot: str, part: str = "arm",
                 on_change: Callable[[str | None], None] | None = None,
                 hold: float = TAKEOVER_HOLD, clock: Callable[[], float] = time.monotonic) -> None:
        self.pattern = pattern(robot, part)
        self.robot, self.part = robot, part
        self.context = context(robot, part)
        self.hold, self.clock = hold, clock
        self._on_change = on_change
        self._alive: list[str] = []          # ids in the order they came alive
        self._obeyed: dict[tuple[str, str], int] = {}   # (id, type) -> newest sequence number
        self._taken: tuple[str, float] | None = None    # who took the part by priority, last command
        self._told: str | None = None         # the holder on_change last heard of
        self._lock = threading.Lock()

    def _holder(self, now: float) -> str | None:
        """The holder at `now` (under the lock): the one that took the part while it keeps it,
        else the oldest alive."""
        if self._taken is not None:
            who, last = self._taken
            if who in self._alive and now - last <= self.hold:
                return who
            self._taken = None
        return self._alive[0] if self._alive else None

    def _changed(self, now: float) -> tuple[bool, str | None]:
        """(whether the holder changed since on_change last heard, the holder), under the lock."""
        after = self._holder(now)
        changed, self._told = after != self._told, after
        return changed, after

    def _tell(self, changed: bool, holder: str | None) -> None:
        if changed and self._on_change is not None:
            self._on_change(holder)

    @property
    def current(self) -> str | None:
        with self._lock:
            return self._holder(self.clock())

    @property
    def taker(self) -> str | None:
        """The controller that holds the part by priority (a person overtook the oldest), or None."""
        with self._lock:
            holder = self._holder(self.clock())
            return holder if self._taken is not None else None

    @property
    def alive(self) -> list[str]:
        """The controllers alive, the oldest first (the holder first, unless one took the part)."""
        with self._lock:
            return list(self._alive)

    def follow(self, bus: Any) -> Any:
        """Learn the controllers alive now, then follow them (ask before watching: a zenoh
        liveliness query just after a liveliness subscriber may answer nothing)."""
        for key in bus.alive(self.pattern):
            self.update(key, True)
        return bus.watch(self.pattern, self.update)

    def update(self, key: str, alive: bool) -> None:
        controller = keys.controller_of(key)
        if controller is None:
            return
        with self._lock:
            if alive and controller not in self._alive:
                self._alive.append(controller)
            elif not alive and controller in self._alive:
                self._alive.remove(controller)
                for seen in [k for k in self._obeyed if k[0] == controller]:
                    del self._obeyed[seen]
            changed, holder = self._changed(self.clock())
        self._tell(changed, holder)

    def tick(self) -> None:
        """Give the part back once a controller that took it has been quiet for `hold` s."""
        with self._lock:
            changed, holder = self._changed(self.clock())
        self._tell(changed, holder)

    def refusal(self, cmd: Any) -> CommandRefused | None:
        """None when `cmd` may move the part: the holder's, or one that takes the part by
        priority (signed by its sender's key, newer than the last obeyed of its type, either
        way); otherwise the refusal, with its sentence. Call it once per command: a command it
        lets through counts as obeyed."""
        controller = cmd.controller
        what = f"the {self.part} of {self.robot}"
        with self._lock:
            now = self.clock()
            holder = self._holder(now)
            takes = (controller != holder and controller in self._alive
                     and (holder is None or priority(controller) > priority(holder)))
            if controller and (controller == holder or takes):
                why = self._signed_and_new(cmd, controller, f"{'holds' if controller == holder else 'may take'} {what}")
                if why is not None:
                    return why
                if takes or (self._taken is not None and self._taken[0] == controller):
                    self._taken = (controller, now)
                changed, holder = self._changed(now)
            else:
                changed = False
        if controller and controller == holder:
            self._tell(changed, holder)
            return None
        if holder is None:
            holds = f"no controller holds {what} (none is alive)"
        else:
            holds = f"controller {holder!r} holds {what}"
        sender = f"from controller {controller!r}" if controller else "without a controller identity"
        return NotHolder("not_holder", f"it came {sender}, and {holds}; only the controller that holds "
                                       "a robot moves it (see asibot.safety.ownership)")

    def _signed_and_new(self, cmd: Any, controller: str, role: str) -> CommandRefused | None:
        """Under the lock: why `cmd` is not `controller`'s own new command, or None (then it
        counts as obeyed). `role`: "holds the arm of asibot"."""
        why = identity.refusal(self.context, cmd)
        if why is not None:
            return NotSigned("not_signed", f"it names controller {identity.short(controller)}, which {role}, "
                                           f"but {why}; a controller's commands are signed by its own key "
                                           "(see asibot.safety.identity)")
        seen = (controller, type(cmd).__name__)
        if cmd.seq <= self._obeyed.get(seen, 0):
            return Replayed("replayed", f"{identity.short(controller)} signed it, but it is not newer "
                                        f"than a {type(cmd).__name__} already obeyed (number {cmd.seq}): "
                                        "a copy played again")
        self._obeyed[seen] = cmd.seq
        return None


def holders_status(holders: Iterable[Holder]) -> dict:
    """What a driver's `status` says of who holds its parts and who may: {"holders": {"arm": id},
    "controllers": {"arm": [ids alive, the oldest first]}}, with "" for a part no controller
    holds. `HoldWait` reads it."""
    holders = list(holders)
    return {"holders": {h.part: h.current or "" for h in holders},
            "controllers": {h.part: h.alive for h in holders}}


class HoldWait:
    """Once per driver: wait until the robot's driver names `controller` as the holder of `part`.

    A controller's first command can reach the driver a few ms before its liveliness token
    does. Refused then, it makes the whole motion "a stream that began before this controller
    took hold" (asibot.safety.arming): a movj right after a start did nothing, and a drive primitive
    would be lost the same way. So a controller calls `wait` before its first motion request,
    and `forget` when a driver comes (back), since that driver learns who holds anew.
    A driver that does not say who holds `part` (no status verb, or no holder of that part
    in it) is not waited for. A controller of higher priority than the holder (a person's
    joystick while nav holds the base) waits until the driver knows it is alive: its first
    command then takes the part.
    """

    def __init__(self, bus: Any, robot: str, part: str, controller: str, poll: float = 0.01) -> None:
        token_key(robot, part, controller)  # says what a wrong part is
        self.bus, self.robot, self.part, self.controller, self.poll = bus, robot, part, controller, poll
        self.held = False

    def forget(self, *_: Any) -> None:
        """The driver changed: wait again before the next motion (a `bus.watch` callback)."""
        self.held = False

    def wait(self, deadline: float) -> bool:
        """Until `deadline` (time.monotonic): True once the driver names us, or does not say."""
        while not self.held:
            try:
                status = self.bus.call(keys.driver_rpc(self.robot, "status"),
                                       timeout=max(0.05, min(0.5, deadline - time.monotonic())))
            except RpcError:
                return False   # no driver answers: the motion request says so itself
            holders, alive = status.get("holders"), status.get("controllers")
            holder = holders.get(self.part) if isinstance(holders, dict) else None
            known = alive.get(self.part, []) if isinstance(alive, dict) else []
            takes = (isinstance(holder, str) and self.controller in known
                     and priority(self.controller) > priority(holder))
            if holder is None or holder == self.controller or takes:
                self.held = True
            elif time.monotonic() >= deadline:
                return False
            else:
                time.sleep(self.poll)
        return True
