"""The user-files half of the API: points, programs (and the Python reference of the clients they
use), words, tasks, icons, and running programs.

The files live in one data folder (`asibot.web.userdata`, in the seed's own formats); this
module only maps HTTP onto it. Capturing a point reads the arm's newest state from the
fleet, so it works while the arm moves.
"""

from __future__ import annotations

import dataclasses
from typing import Annotated, Literal

from fastapi import APIRouter, File, Request, Response, UploadFile
from fastapi.responses import FileResponse
from pydantic import Field, StrictInt, StrictStr

from asibot import keys
from asibot.errors import RpcError
from asibot.messages import LISTEN_SECONDS, MAX_LISTEN_SECONDS, MIN_LISTEN_SECONDS
from asibot.web import reference
from asibot.web.models import Level, Number, RobotId, Strict
from asibot.web.routing import known, off_loop, web_of

router = APIRouter(prefix="/api")

#: Largest uploaded icon and imported zip, bytes (the server also caps every body; app.py).
ICON_LIMIT = 2 * 1024 * 1024
IMPORT_LIMIT = 20 * 1024 * 1024

Name = Annotated[StrictStr, Field(min_length=1, max_length=200)]


class Capture(Strict):
    name: Name | None = Field(None, description="the point's name; suggested (point-1, ...) when left out")


class KeepPoint(Strict):
    """A point to keep, as a touch proposed it: [x, y, z, rot(y'), rot(z'')] (m, deg)."""
    values: Annotated[list[Number], Field(min_length=5, max_length=5)]
    name: Name | None = Field(None, description="the point's name; suggested (above-can, point-3, ...) when left out")


class Rename(Strict):
    name: Name


class GoTo(Strict):
    kind: Literal["movj", "movl"] = "movj"
    level: Level = 3


class NewProgram(Strict):
    name: Name


class ProgramText(Strict):
    text: Annotated[StrictStr, Field(max_length=256 * 1024)]


class Run(Strict):
    robot: RobotId


class RunProgram(Run):
    minutes: Annotated[StrictInt, Field(ge=1, le=240, description="the run's time limit (default 10 minutes)")] | None = None


class Word(Strict):
    text: Name


class Learn(Strict):
    """Learn how the user says `word` from what the page's microphone hears next."""
    word: Name
    page: Annotated[StrictStr, Field(pattern=r"^[0-9a-f]{8}$", description="the listening page's id (its hello)")]
    seconds: Annotated[Number, Field(ge=MIN_LISTEN_SECONDS, le=MAX_LISTEN_SECONDS)] = LISTEN_SECONDS


class TaskBody(Strict):
    program: Name
    words: Annotated[list[Name], Field(max_length=20)] = []
    icon: Name
    robot: Annotated[str, Field(pattern=f"^{keys.ROBOT_ID_PATTERN}$")] | None = Field(
        None, description="the robot the task runs on, whatever the page commands when it is launched; "
                          "left out: whichever robot launches it (a task of the original ASIBOT)")


def _as_json(obj) -> dict:
    return dataclasses.asdict(obj)


# --- points ------------------------------------------------------------------------------------
@router.get("/points", summary="the taught points")
def points(request: Request) -> dict:
    data = web_of(request).data
    return {"points": [_as_json(p) for p in data.points()], "suggested": data.suggest_point_name()}


@router.get("/robots/{robot}/suggested-point-name",
            summary="the name a capture would take now: at a place, above or near a taught point, or point-N")
def suggested_point_name(robot: RobotId, request: Request) -> dict:
    web = web_of(request)
    known(web, robot)
    return {"name": web.data.suggest_point_name(web.fleet.point(robot), web.fleet.place(robot))}


@router.post("/robots/{robot}/capture", summary="capture the arm's current point (works while it moves)")
def capture(robot: RobotId, body: Capture, request: Request) -> dict:
    web = web_of(request)
    known(web, robot)
    here = web.fleet.point(robot)
    if here is None:
        raise RpcError("unavailable", f"No position from {robot} yet: is its kinematics service running?")
    name = body.name or web.data.suggest_point_name(here, web.fleet.place(robot))
    return _as_json(web.data.add_point(name, here))


@router.post("/points", summary="keep a point a touch proposed (the arm does not move)")
def keep_point(body: KeepPoint, request: Request) -> dict:
    data = web_of(request).data
    values = [float(v) for v in body.values]
    point = data.add_point(body.name or data.suggest_point_name(values), values)
    return {"name": point.name, "values": point.values}


@router.post("/points/{name}/rename", summary="rename a point")
def rename_point(name: str, body: Rename, request: Request) -> dict:
    return _as_json(web_of(request).data.rename_point(name, body.name))


@router.delete("/points/{name}", summary="delete a point")
def delete_point(name: str, request: Request) -> dict:
    web_of(request).data.delete_point(name)
    return {}


@router.post("/robots/{robot}/points/{name}/go", summary="move the arm to a taught point")
async def go_to_point(robot: RobotId, name: str, body: GoTo, request: Request) -> dict:
    web = web_of(request)
    known(web, robot)
    point = web.data.point(name)
    return await off_loop(web.motion.move, robot, body.kind, point.values, level=body.level)


# --- programs ----------------------------------------------------------------------------------
@router.get("/programs", summary="the user's programs")
def programs(request: Request) -> dict:
    return {"programs": web_of(request).data.programs()}


@router.post("/programs", summary="a new program from the template")
def new_program(body: NewProgram, request: Request) -> dict:
    return {"name": body.name, "text": web_of(request).data.new_program(body.name)}


@router.get("/programs/{name}", summary="a program's text")
def read_program(name: str, request: Request) -> dict:
    data = web_of(request).data
    return {"name": name, "text": data.read_program(name),
            "versions": [_as_json(v) for v in data.versions(name)]}


@router.put("/programs/{name}", summary="save a program (the previous version is kept)")
def save_program(name: str, body: ProgramText, request: Request) -> dict:
    data = web_of(request).data
    data.save_program(name, body.text)
    return {"name": name, "problems": [_as_json(p) for p in data.check_program(body.text)]}


@router.post("/programs/{name}/rename", summary="rename a program")
def rename_program(name: str, body: Rename, request: Request) -> dict:
    web_of(request).data.rename_program(name, body.name)
    return {"name": body.name}


@router.delete("/programs/{name}", summary="delete a program (kept in the trash)")
def delete_program(name: str, request: Request) -> dict:
    web_of(request).data.delete_program(name)
    return {}


@router.get("/storage", summary="how much the program store keeps (programs, icons, versions, trash) of its limit, in bytes")
def storage(request: Request) -> dict:
    return web_of(request).data.usage().as_json()


@router.delete("/trash", summary="empty the trash: deleted programs, their versions and steps, and deleted tasks go for good")
def empty_trash(request: Request) -> dict:
    data = web_of(request).data
    emptied = data.empty_trash()
    return {"emptied": emptied.items, "freed": emptied.bytes, "storage": data.usage().as_json()}


@router.get("/client-reference",
            summary="the Program tab's Python reference: the clients' methods, signatures and docstrings (asibot.client)")
def client_reference() -> dict:
    # Not under /programs/: that is where a program named "reference" is read.
    return reference.build()


@router.post("/check", summary="syntax check of a program's text")
def check(body: ProgramText, request: Request) -> dict:
    return {"problems": [_as_json(p) for p in web_of(request).data.check_program(body.text)]}


@router.post("/programs/{name}/versions/{version}/restore", summary="bring back a previous version")
def restore(name: str, version: str, request: Request) -> dict:
    return {"name": name, "text": web_of(request).data.restore_version(name, version)}


# --- running -----------------------------------------------------------------------------------
def _start(web, program: str, robot: str, minutes: int | None = None) -> dict:
    known(web, robot)
    path = web.data.program_file(program)
    try:
        web.runner.start(path, robot, name=program, wall_seconds=None if minutes is None else minutes * 60.0)
    except RuntimeError as exc:
        raise RpcError("busy", str(exc)) from None
    return web.runner.status()


@router.post("/programs/{name}/run", summary="run a program on a robot, in its own process")
def run_program(name: str, body: RunProgram, request: Request) -> dict:
    return _start(web_of(request), name, body.robot, body.minutes)


@router.post("/run/stop", summary="stop the running program (and the arm)")
async def stop_program(request: Request) -> dict:
    web = web_of(request)
    await off_loop(web.runner.stop)
    return web.runner.status()


@router.get("/run", summary="the running (or last) program, its output, and the walls programs run in here")
def run_status(request: Request) -> dict:
    runner = web_of(request).runner
    return {**runner.status(), "output": [list(o) for o in runner.output()],
            "confinement": runner.sandbox.confinement()}


# --- words -------------------------------------------------------------------------------------
@router.get("/words", summary="the recorded words and phrases")
def words(request: Request) -> dict:
    return {"words": web_of(request).data.words()}


@router.post("/words", summary="add a word or phrase")
def add_word(body: Word, request: Request) -> dict:
    return {"word": web_of(request).data.add_word(body.text)}


@router.delete("/words/{text}", summary="delete a word or phrase")
def delete_word(text: str, request: Request) -> dict:
    web_of(request).data.delete_word(text)
    return {}


@router.post("/voice/learn", summary="learn how the user says a word: from what the page's microphone hears next")
def learn_word(body: Learn, request: Request) -> dict:
    return web_of(request).voice.learn(body.word, body.page, body.seconds)


@router.post("/voice/forget", summary="forget how the user says a word (the dictionary's pronunciation stays)")
def forget_word(body: Word, request: Request) -> dict:
    return web_of(request).voice.forget(body.text)


@router.get("/voice/learned", summary="the words learned by saying them, with their phones")
def learned_words(request: Request) -> dict:
    web = web_of(request)
    return web.voice.learned(web.data.words())


# --- tasks -------------------------------------------------------------------------------------
@router.get("/tasks", summary="the tasks the Launcher shows")
def tasks(request: Request) -> dict:
    return {"tasks": [_as_json(t) for t in web_of(request).data.tasks()]}


@router.put("/tasks/{name}", summary="create or change a task: program + words + icon")
def save_task(name: str, body: TaskBody, request: Request) -> dict:
    return _as_json(web_of(request).data.save_task(name, body.program, body.words, body.icon, body.robot or ""))


@router.delete("/tasks/{name}", summary="delete a task")
def delete_task(name: str, request: Request) -> dict:
    web_of(request).data.delete_task(name)
    return {}


@router.post("/tasks/{name}/launch", summary="launch a task's program: on its own robot, else on `robot`")
def launch(name: str, body: Run, request: Request) -> dict:
    web = web_of(request)
    web.tasks.launch(name, body.robot)
    return web.runner.status()


# --- icons -------------------------------------------------------------------------------------
@router.get("/icons", summary="the icons a task can have")
def icons(request: Request) -> dict:
    return {"icons": [_as_json(i) for i in web_of(request).data.icons()]}


@router.get("/icons/{name}", summary="one icon's image")
def icon(name: str, request: Request) -> FileResponse:
    path = web_of(request).data.icon_file(name)
    # Uploaded images are served as images only, never sniffed into HTML.
    return FileResponse(path, headers={"X-Content-Type-Options": "nosniff",
                                       "Content-Security-Policy": "default-src 'none'; style-src 'unsafe-inline'"})


@router.post("/icons", summary="upload an icon (PNG, JPEG, GIF or WebP, up to 2 MiB)")
async def upload_icon(request: Request, file: UploadFile = File(...)) -> dict:
    data = await file.read(ICON_LIMIT + 1)
    if len(data) > ICON_LIMIT:
        raise RpcError("bad_request", f"An icon may be up to {ICON_LIMIT // (1024 * 1024)} MiB; this one is larger.")
    return {"name": web_of(request).data.add_icon(file.filename or "icon", data)}


# --- the seed's files --------------------------------------------------------------------------
@router.get("/export.zip", summary="every user file in the seed's formats, as a zip")
def export(request: Request) -> Response:
    return Response(web_of(request).data.export_zip(), media_type="application/zip",
                    headers={"Content-Disposition": 'attachment; filename="asibot-user-files.zip"'})


@router.post("/import", summary="load an ASIBOT user's files (a zip of the seed's user folder)")
async def import_files(request: Request, file: UploadFile = File(...)) -> dict:
    data = await file.read(IMPORT_LIMIT + 1)
    if len(data) > IMPORT_LIMIT:
        raise RpcError("bad_request", f"An import may be up to {IMPORT_LIMIT // (1024 * 1024)} MiB; this one is larger.")
    return _as_json(await off_loop(web_of(request).data.import_zip, data))

