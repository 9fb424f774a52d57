"""The Base page's half of the API: send a mobile robot to a place or a point of its map, drive
it with the thesis's primitives, and keep its named places. Each route is one call to the
robot's nav service through `NavClient`, the client the CLI and user programs use; its
refusals reach the page as its sentences.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from fastapi import APIRouter, Request
from pydantic import Field, StrictBool, StrictStr

from asibot import driving
from asibot.client import NavClient
from asibot.errors import RpcError
from asibot.web.models import Number, RobotId, Strict
from asibot.web.routing import known, off_loop, web_of

router = APIRouter(prefix="/api/base")

#: The primitives, and how the page lays out their buttons: as a person faces the way the robot
#: goes (forward on top, the curves beside it, the exact turns below).
DRIVES = driving.PRIMITIVES
DRIVE_ROWS = (("curve forward left", "forward", "curve forward right"),
              ("turn left", "stop", "turn right"),
              ("curve backward left", "backward", "curve backward right"),
              ("turn left 90", "turn around", "turn right 90"))
CHANGES = driving.CHANGES
#: Nav answers at once (a goal runs on after the answer); a slow answer is a stuck service.
NAV_TIMEOUT = 5.0

PlaceName = Annotated[StrictStr, Field(min_length=1, max_length=64, description="a place's name, as the user says it")]


class Goal(Strict):
    """Where to go: a named place, or a point of the map (m, map frame). The robot arrives at a
    point facing the way it came, unless `theta_deg` says otherwise."""
    place: PlaceName | None = None
    x: Number | None = None
    y: Number | None = None
    theta_deg: Number | None = None


class Drive(Strict):
    """One primitive; `continuous` goes on until Stop (or an obstacle), else one step of the width."""
    name: Literal[DRIVES]   # type: ignore[valid-type]  # the primitives' names, known at import only
    continuous: StrictBool = False


class Change(Strict):
    change: Literal[CHANGES]   # type: ignore[valid-type]  # the changes' names, known at import only


class NewPlace(Strict):
    """Save a place where the robot stands now."""
    name: PlaceName
    replace: StrictBool = False


class Rename(Strict):
    new_name: PlaceName


def config() -> dict:
    """What the Base page draws its buttons from."""
    return {"drives": [list(row) for row in DRIVE_ROWS], "changes": list(CHANGES)}


def _nav(request: Request, robot: str) -> NavClient:
    """The nav service of `robot`, over the web's bus."""
    web = web_of(request)
    return NavClient.on(web.motion.bus, known(web, robot), timeout=NAV_TIMEOUT)


@router.get("/{robot}/map", summary="the robot's navigation map (occupancy grid)")
def nav_map(robot: RobotId, request: Request) -> dict:
    found = web_of(request).fleet.map(robot)
    if found is None:
        raise RpcError("unavailable", f"No map from the nav service of {robot!r} yet; is it running "
                                      f"(`asibot up` starts it in the simulation)?")
    return found


@router.post("/{robot}/goto", summary="go to a named place or to a point of the map")
async def goto(robot: RobotId, body: Goal, request: Request) -> dict:
    x, y = body.x, body.y
    target: str | list[float]
    if body.place is not None and (x is None or y is None):
        target = body.place
    elif body.place is not None or x is None or y is None:
        raise RpcError("bad_request", "Say where to go: a place, or a point x and y (m) of the map, not both.")
    else:
        theta = math.radians(body.theta_deg) if body.theta_deg is not None else _facing(request, robot, x, y)
        target = [float(x), float(y), theta]
    # A trip to a named place is counted (Home offers the usual ones first) by trips.py, from
    # nav's status, as the trips the voice and the bridge send.
    return dict(await off_loop(_nav(request, robot).goto_reply, target))


def _facing(request: Request, robot: str, x: float, y: float) -> float:
    """The heading from where the robot is to (x, y): it arrives facing the way it came."""
    nav = web_of(request).fleet.view(known(web_of(request), robot)).get("nav") or {}
    pose = nav.get("pose")
    if not pose or math.hypot(x - pose["x"], y - pose["y"]) < 1e-3:
        return math.radians(pose["theta_deg"]) if pose else 0.0
    return math.atan2(y - pose["y"], x - pose["x"])


@router.post("/{robot}/cancel", summary="cancel the running goal")
async def cancel(robot: RobotId, request: Request) -> dict:
    return dict(await off_loop(_nav(request, robot).cancel))


@router.post("/{robot}/localize", summary="find where the robot is: it turns in place until it knows")
async def localize(robot: RobotId, request: Request) -> dict:
    return {"text": await off_loop(_nav(request, robot).localize)}


@router.post("/{robot}/drive", summary="one of the driving primitives, or stop")
async def drive(robot: RobotId, body: Drive, request: Request) -> dict:
    return {"text": await off_loop(_nav(request, robot).primitive, body.name, body.continuous)}


@router.post("/{robot}/settings", summary="faster, slower, wider or narrower")
async def settings(robot: RobotId, body: Change, request: Request) -> dict:
    return dict(await off_loop(_nav(request, robot).settings, body.change))


@router.get("/{robot}/places", summary="the robot's named places")
async def places(robot: RobotId, request: Request) -> dict:
    places = await off_loop(_nav(request, robot).places)
    return {"places": [{"name": name, "pose": pose} for name, pose in places.items()]}


@router.post("/{robot}/places", summary="save a place where the robot stands")
async def save_place(robot: RobotId, body: NewPlace, request: Request) -> dict:
    return dict(await off_loop(_nav(request, robot).save_place_reply, body.name, None, body.replace))


@router.post("/{robot}/places/{name}/rename", summary="rename a place")
async def rename_place(robot: RobotId, name: str, body: Rename, request: Request) -> dict:
    return dict(await off_loop(_nav(request, robot).rename_place, name, body.new_name))


@router.delete("/{robot}/places/{name}", summary="remove a place")
async def remove_place(robot: RobotId, name: str, request: Request) -> dict:
    return {"name": await off_loop(_nav(request, robot).remove_place, name)}
