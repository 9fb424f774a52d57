"""What the route modules share: the `Web` a request works with, the robot it must find
connected, and bus calls kept off the event loop."""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING, Any, Callable, TypeVar

from fastapi import Request

from asibot.errors import RpcError

if TYPE_CHECKING:   # app.py builds the routes from these modules, so it cannot be imported here
    from asibot.web.app import Web

T = TypeVar("T")


def web_of(request: Request) -> Web:
    return request.app.state.web


def known(web: Web, robot: str) -> str:
    """The robot must be on the bus (a live driver or controller) for the page to command it."""
    if robot not in web.fleet.ids():
        live = ", ".join(web.fleet.ids()) or "none"
        raise RpcError("unavailable", f"Robot {robot!r} is not connected (live robots: {live}). "
                                      "Start it with `asibot up`, then choose it in the Connection Manager.")
    return robot


async def off_loop(fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """Bus calls block for up to a few seconds: keep them off the event loop."""
    return await asyncio.to_thread(fn, *args, **kwargs)
