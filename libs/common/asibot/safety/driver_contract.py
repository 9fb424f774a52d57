"""The bus side of the driver contract, written once for every driver.

The CANopen arm driver, the ARCOS base driver and the simulation each move a robot in their
own way; what they promise on the bus is the same, and it lives here (python-can's shape: one
small contract, a backend behind it):

- a command (`arm/command`, `gripper/command`, `cmd_vel`) is obeyed only from the controller
  that holds its part, signed by it, newer than the last (`asibot.safety.ownership`); another
  controller's command is noted for re-arming (`asibot.safety.arming`), a forged one is not;
- every refusal (a stranger's command, a malformed message, a value beyond a limit, a stream
  from before a recovery) is answered with an Event in one sentence shape per command, at
  most one a second per reason (`asibot.safety.events.EventThrottle`), and moves nothing;
- the estop is followed and kept served after its sender exits (`asibot.safety.estop`); a release
  that is not signed is refused with an Event;
- a part taken by priority goes back when its taker goes quiet (`Holder.tick`, every
  `TICK_S`), with the same stop and re-arming as any change of holder;
- `status` says who holds each part beside what the driver says of itself; `reset_fault` and
  the driver's own verbs (a table of `asibot.verbs`, beside `VERBS`) are served, each request
  checked by its table; `driver_alive` is announced last, once all of it answers.

A driver service makes its `DriverContract` first (its Events go out from then on), then the
driver, then `serve`s what the driver obeys, as `command(name, obey, heard)`s.
"""

from __future__ import annotations

import functools
import logging
import threading
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping

from asibot.safety import estop
from asibot import keys
from asibot.safety.estop import EStopState
from asibot.safety.events import CommandRefused, EventThrottle, refusal_reason
from asibot.messages import ArmCommand, EStop, Event, GripperCommand, Twist
from asibot.safety.ownership import Holder, NotHolder, holders_status
from asibot.verbs import Handler, Verb, serve as serve_verbs

log = logging.getLogger(__name__)

#: s between two looks at whether a part taken by priority goes back (asibot.safety.ownership)
TICK_S = 0.1


@dataclass(frozen=True)
class Kind:
    """A kind of command: its key, its message, the part that obeys it and what a refusal says."""

    key: Callable[[str], str]
    message: type
    part: str
    refused: str


#: The verbs every driver serves on `keys.driver_rpc`; a driver may add its own beside them.
VERBS = {
    "status": Verb(doc="what the driver says of itself (mode, fault, estop...), its robot and who holds each part"),
    "reset_fault": Verb(doc="clear a fault (re-initialise what failed); refused with the driver's sentence "
                            "while it is still there"),
}

KINDS = {
    "arm": Kind(keys.arm_command, ArmCommand, "arm", "Arm command refused, the arm keeps its previous motion"),
    "gripper": Kind(keys.gripper_command, GripperCommand, "arm",
                    "Gripper command refused, the gripper keeps its previous opening"),
    "cmd_vel": Kind(keys.base_cmd_vel, Twist, "base", "Base command refused, the base keeps its previous motion"),
}


@dataclass(frozen=True)
class Command:
    """A kind of command a driver obeys: `obey(msg)` moves the robot or raises ValueError or
    CommandRefused with the driver's sentence; `heard(controller)` notes another controller's
    command, so that its stream does not move the part the moment it takes hold."""

    name: str
    obey: Callable[[Any], object]
    heard: Callable[[str], None] | None = None

    @property
    def kind(self) -> Kind:
        return KINDS[self.name]


def command(name: str, obey: Callable[[Any], object], heard: Callable[[str], None] | None = None) -> Command:
    """A `Command` of kind `name` (one of KINDS), checked at once."""
    if name not in KINDS:
        raise ValueError(f"a driver obeys {', '.join(KINDS)} commands, not {name!r}")
    return Command(name, obey, heard)


class DriverContract:
    """One robot's driver on the bus: its events from the start, then (`serve`) the commands
    it obeys, the estop and its verbs.

    Made before the driver, so that the driver's own Events (`event`) have a way out from its
    first moment; `serve` then wires the rest, and announces the driver alive last.
    """

    def __init__(self, bus: Any, robot: str) -> None:
        self.bus, self.robot = bus, robot
        self.events = bus.publisher(keys.events(robot), Event)
        self.refusals = EventThrottle(self.events.put)
        self.commands: list[Command] = []
        self.holders: dict[str, Holder] = {}
        self.not_holder = 0          # commands refused because they were not the holder's
        self.rejected = 0            # every command refused, for whatever reason
        self._status: Callable[[], dict] = dict
        self.estop: EStopState | None = None
        self._closed = threading.Event()

    def serve(self, commands: Iterable[Command], *,
              on_holder: Callable[[str, str | None], None],
              on_estop: Callable[[bool, str, str], None],
              status: Callable[[], dict], reset_fault: Callable[[], dict],
              verbs: Mapping[str, Verb] | None = None, handlers: Mapping[str, Handler] | None = None) -> None:
        """Obey `commands` from their holders; `on_holder(part, id)` hears each change of a
        part's holder, `on_estop(engaged, reason, by)` each newer estop state; `status()` is the
        driver's own status, `reset_fault()` clears a fault (raising RpcError with the sentence
        when it cannot). `verbs` are the driver's own verbs (the sim's `reset_world`, the
        emulated bus's `inject_fault`), answered by `handlers` with the checked arguments."""
        verbs, handlers = verbs or {}, handlers or {}
        if set(verbs) & set(VERBS):    # a driver cannot answer for the contract
            raise ValueError(f"a driver's own verbs cannot be {', '.join(sorted(set(verbs) & set(VERBS)))}")
        bus, robot = self.bus, self.robot
        self.commands = list(commands)
        self._status = status
        parts = sorted({c.kind.part for c in self.commands}, key=("arm", "base").index)
        self.holders = {part: Holder(robot, part, on_change=functools.partial(on_holder, part))
                        for part in parts}
        for holder in self.holders.values():
            holder.follow(bus)
        self.estop = EStopState(bus, robot, lambda msg: on_estop(msg.engaged, msg.reason, estop.named(msg)),
                                self._release_refused, self._estop_skewed)
        for c in self.commands:
            bus.subscribe(c.kind.key(robot), c.kind.message, self._receiver(c), with_key=True,
                          on_reject=lambda key, exc, c=c: self.refuse(c.name, exc))
        serve_verbs(bus, lambda verb: keys.driver_rpc(robot, verb), {**VERBS, **verbs},
                    {"status": lambda args: self.status(), "reset_fault": lambda args: reset_fault(), **handlers})
        self._ticking = threading.Thread(target=self._tick, name=f"holders-{robot}", daemon=True)
        self._ticking.start()
        bus.announce(keys.driver_alive(robot))

    def _tick(self) -> None:
        """Give a part back once the controller that took it by priority went quiet
        (`Holder.tick`), within a tenth of a second."""
        while not self._closed.wait(TICK_S):
            for holder in list(self.holders.values()):
                holder.tick()

    def _receiver(self, c: Command) -> Callable[[str, Any], None]:
        holder = self.holders[c.kind.part]

        def receive(key: str, msg: Any) -> None:
            refused = holder.refusal(msg)
            if refused is not None:     # not the holder's: never obeyed
                self.not_holder += 1
                if c.heard is not None and isinstance(refused, NotHolder):   # a forged one says nothing
                    c.heard(msg.controller)                                   # of the holder's stream
                self.refuse(c.name, refused)
                return
            try:
                c.obey(msg)
            except (ValueError, CommandRefused) as exc:   # the driver's sentence
                # During an estop a command is refused by the stop, not for what it says:
                # counted and logged, not an Event a second while a stream runs into it.
                if self.estop is not None and self.estop.engaged and not isinstance(exc, CommandRefused):
                    self.rejected += 1
                    log.debug("ignored a %s command: %s", c.name, exc)
                else:
                    self.refuse(c.name, exc)
        return receive

    def refuse(self, name: str, exc: Exception) -> None:
        """Answer a refused command of kind `name` with an Event (at most one a second per reason)."""
        self.rejected += 1
        level, code = (exc.level, exc.code) if isinstance(exc, CommandRefused) else ("error", "bad_command")
        text = f"{KINDS[name].refused}: {str(exc).rstrip('.')}."
        if self.refusals.event(level, code, text, reason=f"{name}:{refusal_reason(exc)}"):
            log.warning("%s", text)

    def _release_refused(self, msg: EStop, why: str) -> None:
        self.refusals.event("warning", "release_refused", estop.refused_text(msg, why), reason="estop:release")

    def _estop_skewed(self, msg: EStop, text: str) -> None:
        self.refusals.event("warning", "estop_clock", text, reason="estop:clock")

    def event(self, level: str, code: str, text: str) -> None:
        """Publish one of the driver's own Events (a fault, a recovery, the estop)."""
        self.events.put(Event(level=level, code=code, text=text))

    def status(self) -> dict:
        """The driver's status with the robot's id and who holds each of its parts."""
        return {"robot": self.robot, **self._status(), **holders_status(self.holders.values())}

    def health(self) -> dict:
        """The contract's part of the driver's health: holders and refusals."""
        holders = {f"holder_{part}" if len(self.holders) > 1 else "holder": h.current or ""
                   for part, h in self.holders.items()}
        return {**holders, "not_holder": self.not_holder, "commands_rejected": self.rejected}

    def close(self) -> None:
        self._closed.set()
        self.refusals.close()
