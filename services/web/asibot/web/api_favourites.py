"""The person's tasks and places, most used first (or in the carer's order): what Home offers
one level deep, so one switch, a touch or a glance reaches the usual ones at once.

Uses are counted where they happen (a task launched by any page, the voice or the AsTeRICS
bridge, in TaskDesk; a place gone to from a page, in api_base); the order is kept in the
user's folder (userdata/favourites.py).
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Request
from pydantic import Field, StrictStr

from asibot.client import NavClient
from asibot.errors import RpcError
from asibot.web.models import Strict
from asibot.web.routing import off_loop, web_of
from asibot.web.userdata.favourites import MAX_KEY, MAX_KEYS, place_key, task_key

router = APIRouter(prefix="/api")

#: A robot's nav answers its places at once; one that does not is left out, not waited for.
PLACES_TIMEOUT = 2.0

Key = Annotated[StrictStr, Field(min_length=1, max_length=MAX_KEY)]


class Order(Strict):
    """The carer's order of the person's items, by key ("task:<task>", "place:<robot>/<place>");
    what it leaves out follows by use. An empty list: by use alone."""
    order: Annotated[list[Key], Field(max_length=MAX_KEYS)]


def _places(request: Request) -> tuple[list[dict], list[str]]:
    """Every named place of every connected mobile robot, and a sentence per robot that did not say."""
    web = web_of(request)
    items, notes = [], []
    for view in web.fleet.views():
        if not view.get("has_base"):
            continue
        robot = view["id"]
        try:
            places = NavClient.on(web.motion.bus, robot, timeout=PLACES_TIMEOUT).places()
        except RpcError as exc:
            notes.append(f"The places of {robot} are not known now: {exc}")
            continue
        items += [{"key": place_key(robot, name), "kind": "place", "robot": robot, "name": name} for name in places]
    return items, notes


def favourites(request: Request) -> dict:
    web = web_of(request)
    items = [{"key": task_key(t.name), "kind": "task", "name": t.name, "icon": t.icon, "robot": t.robot}
             for t in web.data.tasks()]
    places, notes = _places(request)
    items += places
    usage = web.data.favourites.read()
    by_key = {item["key"]: item for item in items}
    ranked = [dict(by_key[k], uses=usage.uses.get(k, 0)) for k in usage.rank(list(by_key))]
    return {"items": ranked, "order": usage.order, "notes": notes}


@router.get("/favourites", summary="the person's tasks and places, in the carer's order, then most used first")
async def get_favourites(request: Request) -> dict:
    return await off_loop(favourites, request)


@router.put("/favourites/order", summary="the carer's order of the person's tasks and places (empty: by use)")
async def set_order(body: Order, request: Request) -> dict:
    web = web_of(request)
    await off_loop(web.data.favourites.set_order, body.order)
    return await off_loop(favourites, request)
