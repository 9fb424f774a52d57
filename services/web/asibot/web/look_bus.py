"""Looking for a taught thing, on the bus: `keys.look_rpc(robot, "find")`.

A taught pick remembers what the carer touched (asibot.things), not where it stood, and asks
here when it runs (`asibot.client.LookClient`), so it finds the can where it stands today.
The web service answers because it keeps every camera's pictures and the installer's
calibrations (asibot.web.world); a task's program reaches it with the program role's rights
(asibot.access), as it reaches the kinematics.
"""

from __future__ import annotations

import functools
from typing import Any, Callable

from asibot import keys, robots, things, verbs
from asibot.bus import Bus, Closable
from asibot.errors import RpcError
from asibot.verbs import Field, Map, Verb
from asibot.web.world import World

VERBS = {
    "find": Verb({"thing": Field(Map("a taught thing: name, colour, height, width, where", most=8), required=True)},
                 doc="where a taught thing stands now, and the points above it and to grasp it from there"),
}


def serve(bus: Bus, world: World) -> list[Closable]:
    """Answer `find` for every robot the stack knows."""
    def finder(robot: str) -> Callable[[Any], dict]:
        def find(args: Any) -> dict:
            try:
                thing = things.Thing.from_json(args.thing)
            except ValueError as exc:
                raise RpcError("bad_request", f"The thing to look for is not valid: {exc}") from None
            return world.find(robot, thing)
        return find

    served: list[Closable] = []
    for robot in robots.ids():
        served += verbs.serve(bus, functools.partial(keys.look_rpc, robot), VERBS, {"find": finder(robot)})
    return served
