"""The robot half of the API: what the Connection Manager, the jog tabs and the 3D view call.

Every action is one POST with a small JSON body, answered with JSON; the live state comes
over the WebSocket (live.py). The request models are the API's description (FastAPI shows
them at /docs), so the page never guesses a field or a unit.
"""

from __future__ import annotations

import threading
from typing import Annotated, Literal

from fastapi import APIRouter, Request
from fastapi.responses import StreamingResponse
from pydantic import Field, StrictBool, StrictInt

from asibot import robots
from asibot.errors import RpcError
from asibot.web.cameras import BOUNDARY, mjpeg
from asibot.web.models import Direction, Level, Number, RobotId, Strict
from asibot.web.routing import known, off_loop, web_of

router = APIRouter(prefix="/api")


class Step(Strict):
    """One jog step: a joint (0 for the first) or a point axis (0-4: x, y, z, rot(y'), rot(z''))."""
    space: Literal["joint", "cartesian"]
    axis: StrictInt
    direction: Direction
    level: Level = 3
    step: Annotated[Number, Field(gt=0, le=90)] | None = Field(
        None, description="step size in m (x, y, z) or deg; default the seed's 5 deg / 0.10 m / 15 deg")


class Move(Strict):
    """The seed's movj/movl forms: absolute or relative, to a point or (movj) to joint values."""
    kind: Literal["movj", "movl"]
    values: Annotated[list[Number], Field(min_length=1, max_length=8)]
    relative: StrictBool = False
    joints: StrictBool = False
    level: Level = 3


class Target(Strict):
    """A point [x, y, z, rot(y'), rot(z'')] (m, deg) whose joints the 3D view shows as a ghost."""
    point: Annotated[list[Number], Field(min_length=5, max_length=5)]


class Grip(Strict):
    close: StrictBool


class Speed(Strict):
    level: Level = 3


@router.get("/robots", summary="every connected robot and its live state")
def list_robots(request: Request) -> list[dict]:
    return web_of(request).fleet.views()


@router.get("/robots/{robot}", summary="one robot's live state")
def get_robot(robot: RobotId, request: Request) -> dict:
    web = web_of(request)
    return web.fleet.view(known(web, robot))


@router.get("/robots/{robot}/model", summary="the robot's arm model for the 3D view")
def get_model(robot: RobotId, request: Request) -> dict:
    try:
        spec = robots.get(robot)
    except KeyError as exc:
        raise RpcError("bad_request", exc.args[0][0].upper() + exc.args[0][1:] + ".") from None
    return {"urdf": spec.urdf_path.read_text(), "joint_names": spec.joint_names,
            "base_link": spec.base_link, "tool_link": spec.tool_link}


@router.post("/robots/{robot}/step", summary="jog one step")
async def step(robot: RobotId, body: Step, request: Request) -> dict:
    web = web_of(request)
    known(web, robot)
    if body.space == "joint":
        return await off_loop(web.motion.step_joint, robot, body.axis, body.direction, body.level, body.step)
    return await off_loop(web.motion.step_axis, robot, body.axis, body.direction, body.level, body.step)


@router.post("/robots/{robot}/move", summary="movj or movl, absolute or relative")
async def move(robot: RobotId, body: Move, request: Request) -> dict:
    web = web_of(request)
    known(web, robot)
    return await off_loop(web.motion.move, robot, body.kind, body.values, relative=body.relative,
                      joints=body.joints, level=body.level)


@router.post("/robots/{robot}/inv", summary="the joints that reach a point (nothing moves)")
async def inverse(robot: RobotId, body: Target, request: Request) -> dict:
    web = web_of(request)
    known(web, robot)
    joints = await off_loop(web.motion.inverse, robot, body.point)
    return {"joints": joints, "names": robots.get(robot).joint_names}


@router.post("/robots/{robot}/home", summary="go to the home position")
async def home(robot: RobotId, body: Speed, request: Request) -> dict:
    web = web_of(request)
    return await off_loop(web.motion.home, known(web, robot), body.level)


@router.post("/robots/{robot}/stop", summary="stop the arm's motion")
async def stop(robot: RobotId, request: Request) -> dict:
    web = web_of(request)
    return await off_loop(web.motion.stop, known(web, robot))


@router.post("/robots/{robot}/gripper", summary="open or close the gripper")
async def gripper(robot: RobotId, body: Grip, request: Request) -> dict:
    web = web_of(request)
    return await off_loop(web.motion.grip, known(web, robot), body.close)


@router.post("/robots/{robot}/estop", summary="engage this robot's emergency stop")
async def estop_one(robot: RobotId, request: Request) -> dict:
    web = web_of(request)
    await off_loop(web.motion.estop, robot)
    await off_loop(web.runner.stop, "stopped by the emergency stop")
    return {"engaged": True}


@router.post("/estop", summary="emergency stop of every connected robot and the running program")
async def estop_all(request: Request) -> dict:
    web = web_of(request)
    stopped = web.fleet.ids()
    for robot in stopped:
        await off_loop(web.motion.estop, robot)
    await off_loop(web.runner.stop, "stopped by the emergency stop")
    return {"robots": stopped}


@router.post("/robots/{robot}/release", summary="release the emergency stop")
async def release(robot: RobotId, request: Request) -> dict:
    web = web_of(request)
    await off_loop(web.motion.release, known(web, robot))
    return {"engaged": False}


@router.post("/release", summary="release the emergency stop of every connected robot that has it engaged")
async def release_all(request: Request) -> dict:
    web = web_of(request)
    engaged = [view["id"] for view in web.fleet.views() if view["estop"]["engaged"]]
    for robot in engaged:
        await off_loop(web.motion.release, robot)
    return {"robots": engaged}


@router.post("/robots/{robot}/reset_fault", summary="ask the driver to clear a fault")
async def reset_fault(robot: RobotId, request: Request) -> dict:
    web = web_of(request)
    return await off_loop(web.motion.reset_fault, known(web, robot))


@router.post("/robots/{robot}/reset_world", summary="simulation only: put the world back as it started")
async def reset_world(robot: RobotId, request: Request) -> dict:
    web = web_of(request)
    known(web, robot)
    status = web.runner.status()
    if status["running"] and status["robot"] == robot:
        raise RpcError("busy", f"{status['program']} is running on {robot}: stop it before putting the world back.")
    await off_loop(web.motion.reset_world, robot)
    return {"world": robots.get(robot).world}


@router.get("/robots/{robot}/cameras", summary="the robot's cameras that are sending images")
def cameras(robot: RobotId, request: Request) -> dict:
    return {"cameras": web_of(request).cameras.names(robot)}


@router.get("/robots/{robot}/cameras/{name}.mjpg", summary="a camera's images as an MJPEG stream")
def camera_stream(robot: RobotId, name: str, request: Request) -> StreamingResponse:
    try:
        frames = web_of(request).cameras.frames(robot, name, threading.Event())
    except KeyError as exc:
        raise RpcError("unavailable", exc.args[0]) from None
    return StreamingResponse(mjpeg(frames), media_type=f"multipart/x-mixed-replace; boundary={BOUNDARY}",
                             headers={"Cache-Control": "no-store"})
