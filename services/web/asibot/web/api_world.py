"""The world half of the API: what the robots' depth cameras see, touch to reach, and the
camera calibration walk-through (asibot.web.world does the work; this module maps HTTP onto it).

The point cloud is binary (world.CLOUD_HEADER: a count, float32 x y z, uint8 r g b), so the
3D view reads it into typed arrays with no parsing, a few times a second; everything else is
JSON. No route moves the arm: a touch answers with poses and their joints, which the page
shows as the ghost, and the arm moves only when the person confirms it with an ordinary move.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Request, Response
from pydantic import Field

from asibot.web.models import Number, RobotId, Strict
from asibot.web.routing import known, off_loop, web_of

router = APIRouter(prefix="/api")

CameraName = Annotated[str, Path(pattern=r"^[A-Za-z0-9_][A-Za-z0-9_.\-]{0,63}$", description="a camera's name")]
Pixel = Annotated[Number, Field(ge=0, le=10000, description="image pixels from the picture's top-left corner")]


class Spot(Strict):
    """A spot of a camera's picture, in its image pixels (u across, v down)."""
    u: Pixel
    v: Pixel


@router.get("/robots/{robot}/depth-cameras", summary="the robot's depth cameras: picture size and where their pose comes from")
def depth_cameras(robot: RobotId, request: Request) -> dict:
    return {"cameras": web_of(request).world.listing(robot)}


@router.get("/robots/{robot}/cameras/{name}/cloud", response_class=Response,
            summary="what a depth camera sees, as coloured points in the robot's frame (binary: uint32 N, "
                    "N x 3 float32 x y z in m, N x 3 uint8 r g b)")
async def cloud(robot: RobotId, name: CameraName, request: Request) -> Response:
    count, body, version = await off_loop(web_of(request).world.cloud, robot, name)
    # The page asks a few times a second and names the cloud it has; the same cloud again (a
    # still world) is a 304, and the page draws nothing again (ETag, If-None-Match: RFC 9110).
    tag = f'"{version}"'
    headers = {"Cache-Control": "no-store", "ETag": tag}
    if request.headers.get("if-none-match") == tag:
        return Response(status_code=304, headers=headers)
    return Response(body, media_type="application/octet-stream", headers={**headers, "X-Point-Count": str(count)})


@router.post("/robots/{robot}/cameras/{name}/touch",
             summary="what is at a spot of the camera's picture, and the poses that go above it and reach it")
async def touch(robot: RobotId, name: CameraName, body: Spot, request: Request) -> dict:
    web = web_of(request)
    touched = await off_loop(web.world.touch, known(web, robot), name, body.u, body.v)
    # The name a point kept from it is given unless the person types one: "red-object-1".
    thing = f"{touched['colour']} object" if touched["colour"] and touched["found"]["kind"] == "object" else ""
    touched["name"] = web.data.suggest_point_name(touched["reach"]["point"], place=thing)
    return touched


# --- calibration ---------------------------------------------------------------------------------
@router.get("/robots/{robot}/cameras/{name}/calibration", summary="the marks touched so far and the solved pose")
def calibration(robot: RobotId, name: CameraName, request: Request) -> dict:
    return web_of(request).world.calibration(robot, name)


@router.post("/robots/{robot}/cameras/{name}/calibration/spot",
             summary="a calibration mark touched in the picture: where the camera sees it (read now, "
                     "while the fingertips do not hide it)")
async def see_mark(robot: RobotId, name: CameraName, body: Spot, request: Request) -> dict:
    web = web_of(request)
    return await off_loop(web.world.see_mark, known(web, robot), name, body.u, body.v)


@router.post("/robots/{robot}/cameras/{name}/calibration/marks",
             summary="the fingertips are on the mark touched last: pair the two")
async def add_mark(robot: RobotId, name: CameraName, request: Request) -> dict:
    web = web_of(request)
    return await off_loop(web.world.add_mark, known(web, robot), name)


@router.post("/robots/{robot}/cameras/{name}/calibration/solve",
             summary="solve the camera's pose from the marks (kept and used from then on), with its residual in mm")
async def solve(robot: RobotId, name: CameraName, request: Request) -> dict:
    return await off_loop(web_of(request).world.solve, robot, name)


@router.delete("/robots/{robot}/cameras/{name}/calibration",
               summary="forget the marks and the solved pose (the camera's own pose is used again)")
async def clear(robot: RobotId, name: CameraName, request: Request) -> dict:
    return await off_loop(web_of(request).world.clear, robot, name)
