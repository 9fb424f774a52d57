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
- Stopping needs no ownership: the estop stops every part whoever engages it, and the
  kinematics `stop` verb (`CartesianClient.stop()`) makes the holder command a hold,
  whoever moved the arm. A change of holder, or its loss, stops the part and re-arms it
  (`asibot.safety.arming`): a stream still running from before does not move it.

Anyone on the router may still announce a controller (keeping strangers off the router is
the router's job, `asibot.access`): while another holds a part, a newcomer only waits in line,
and nobody can send commands as the holder, on the open router too.
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
    """Which controller holds `part` of `robot` now, from the liveliness of its controllers.

    `update(key, alive)` is a `bus.watch` callback (`follow` wires it); `on_change(holder)`
    is called, outside the lock, with the new holder or None when it changes.
    """

    def __init__(self, robot: str, part: str = "arm",
                 on_change: Callable[[str | None], None] | None = None) -> None:
        self.pattern = pattern(robot, part)
        self.robot, self.part = robot, part
        self.context = context(robot, part)
        self._on_change = on_change
        self._alive: list[str] = []          # ids in the order they came alive
        self._obeyed: dict[tuple[str, str], int] = {}   # (id, type) -> newest sequence number
        self._lock = threading.Lock()

    @property
    def current(self) -> str | None:
        with self._lock:
            return self._alive[0] if self._alive else None

    @property
    def alive(self) -> list[str]:
        """The controllers alive, in the order they hold the part (the holder first)."""
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
            before = self._alive[0] if self._alive else None
            if alive and controller not in self._alive:
                self._alive.append(controller)
            elif not alive and controller in self._alive:
                self._alive.remove(controller)
                for seen in [k for k in self._obeyed if k[0] == controller]:
                    del self._obeyed[seen]
            after = self._alive[0] if self._alive else None
        if after != before and self._on_change is not None:
            self._on_change(after)

    def refusal(self, cmd: Any) -> CommandRefused | None:
        """None when the holder sent `cmd` (its id, signed by its key, newer than the last
        obeyed of its type); otherwise the refusal, with its sentence. Call it once per
        command: a command it lets through counts as obeyed."""
        controller = cmd.controller
        holder = self.current
        what = f"the {self.part} of {self.robot}"
        if controller and controller == holder:
            why = identity.refusal(self.context, cmd)
            if why is not None:
                return NotSigned("not_signed", f"it names controller {identity.short(controller)}, which holds "
                                               f"{what}, but {why}; a controller's commands are signed by "
                                               "its own key (see asibot.safety.identity)")
            seen = (controller, type(cmd).__name__)
            with self._lock:
                if cmd.seq <= self._obeyed.get(seen, 0):
                    return Replayed("replayed", f"{identity.short(controller)} signed it, but it is not newer "
                                                f"than a {type(cmd).__name__} already obeyed (number {cmd.seq}): "
                                                "a copy played again")
                self._obeyed[seen] = cmd.seq
            return None
        if holder is None:
            holds = f"no controller holds {what} (none is alive)"
        else:
            holds = f"controller {holder!r} holds {what}"
        sender = f"from controller {controller!r}" if controller else "without a controller identity"
        return NotHolder("not_holder", f"it came {sender}, and {holds}; only the controller that holds "
                                       "a robot moves it (see asibot.safety.ownership)")


def holders_status(holders: Iterable[Holder]) -> dict:
    """What a driver's `status` says of who holds its parts: {"holders": {"arm": id}}, with
    "" for a part no controller holds. `HoldWait` reads it."""
    return {"holders": {h.part: h.current or "" for h in holders}}


class HoldWait:
    """Once per driver: wait until the robot's driver names `controller` as the holder of `part`.

    A controller's first command can reach the driver a few ms before its liveliness token
    does. Refused then, it makes the whole motion "a stream that began before this controller
    took hold" (asibot.safety.arming): a movj right after a start did nothing, and a drive primitive
    would be lost the same way. So a controller calls `wait` before its first motion request,
    and `forget` when a driver comes (back), since that driver learns who holds anew.
    A driver that does not say who holds `part` (no status verb, or no holder of that part
    in it) is not waited for.
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
            holders = status.get("holders")
            holder = holders.get(self.part) if isinstance(holders, dict) else None
            if holder is None or holder == self.controller:
                self.held = True
            elif time.monotonic() >= deadline:
                return False
            else:
                time.sleep(self.poll)
        return True
