"""Programs without Python, over HTTP: a program's steps (read, save, preview), the templates'
steps, and a new program made straight from a template.

Saving steps writes the program's Python (asibot.web.steps makes it; userdata/steps.py keeps
both and knows whether they still agree). A template's steps are answered, not saved: the page
holds the steps being edited, so they go where the person is adding steps (at the end, or
inside a Repeat) and are saved with the rest, and nothing is written behind their back (an
edited Python is replaced only once they confirm).
"""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Request
from pydantic import Field, StrictBool, StrictStr

from asibot.web import steps as steplib
from asibot.web.models import Strict
from asibot.web.routing import web_of
from asibot.web.userdata import AlreadyExists, NotFound, UserData, UserDataError
from asibot.web.userdata.names import quote

router = APIRouter(prefix="/api")

Name = Annotated[StrictStr, Field(min_length=1, max_length=200)]
StepList = Annotated[list[steplib.Step], Field(max_length=steplib.MAX_STEPS)]


class StepsBody(Strict):
    steps: StepList
    replace_python: StrictBool = Field(False, description="the person confirmed that the steps replace Python "
                                                          "edited since (or a program written in Python)")


class Preview(Strict):
    steps: StepList


class TemplateBody(Strict):
    template: steplib.Template
    point: Name


class NewFromSteps(Strict):
    name: Name | None = Field(None, description="the program's name; when left out, the template's and the "
                                                 "point's or thing's (pick_up_red-can)")
    template: Literal["empty", "pick_it_up", "put_it_down"] = Field(
        description="no steps yet, or a template's steps at `point` (or, to pick it up, of `thing`)")
    point: Name | None = None
    thing: dict | None = Field(None, description="Pick it up: a taught thing (name, colour, height, width, where: "
                                                 "asibot.things), looked for wherever it stands when the program runs")
    if_exists: Literal["number", "ask", "replace"] = Field(
        "number", description="when `name` is left out and the template's name for the point or thing is taken: "
                              "number a new program after it (pick_up_red-can_2); ask (409, code exists: nothing "
                              "is made); or replace that program's steps (teaching a thing again: every task that "
                              "runs it picks up what was taught now; its earlier version is kept)")


def _template(data: UserData, template: str, point: str | None, thing: dict | None = None) -> list[steplib.Step]:
    if template == "empty":
        return []
    if thing is not None:
        if template != "pick_it_up":
            raise UserDataError("Only Pick it up is made from a taught thing; Put it down needs a point.")
        try:
            return steplib.pick_up_thing(thing)
        except ValueError as exc:
            raise UserDataError(f"The thing to pick up is not valid: {exc}") from None
    if point is None:
        raise UserDataError("Choose the point the template is made from.")
    data.point(point)   # NotFound with the point's name
    return steplib.TEMPLATES[template](point)


def _answer(data: UserData, name: str, steps: list[steplib.Step], **more: object) -> dict:
    return {"name": name, "steps": steplib.dump(steps),
            "described": steplib.describe(steps, data.steps.point_values()), **more}


@router.get("/programs/{name}/steps", summary="a program's steps, their sentences, and whether its Python still "
                                              "is the one they made (in_sync); steps null: written in Python")
def read_steps(name: str, request: Request) -> dict:
    data = web_of(request).data
    saved = data.steps.read(name)
    if saved is None:
        return {"name": name, "steps": None, "described": None, "in_sync": False, "points_changed": False}
    try:
        described = steplib.describe(saved.steps, data.steps.point_values())
    except UserDataError:
        described = None    # a point they use is gone: the page shows the steps plainly, a save says which
    return {"name": name, "steps": steplib.dump(saved.steps), "described": described, "in_sync": saved.in_sync,
            "points_changed": data.steps.points_changed(name, saved)}


@router.put("/programs/{name}/steps", summary="save a program's steps and write its Python from them "
                                              "(the Python it replaces is kept as a version)")
def save_steps(name: str, body: StepsBody, request: Request) -> dict:
    data = web_of(request).data
    made = data.steps.save(name, body.steps, replace=body.replace_python)
    return _answer(data, name, made.steps, text=made.text, in_sync=True, points_changed=False)


@router.post("/programs/{name}/steps/preview", summary="the Python and the sentences steps would make "
                                                       "(nothing is saved)")
def preview_steps(name: str, body: Preview, request: Request) -> dict:
    data = web_of(request).data
    return _answer(data, name, body.steps, text=data.steps.preview(name, body.steps))


@router.post("/programs/{name}/steps/template", summary="the steps of a template at a point, for the page to add "
                                                        "to the program's steps (nothing is saved)")
def template_steps(name: str, body: TemplateBody, request: Request) -> dict:
    data = web_of(request).data
    if name not in data.programs():
        raise NotFound(f"There is no program named {quote(name)}.")
    return _answer(data, name, _template(data, body.template, body.point))


@router.post("/step-programs", summary="a new program made of steps: none yet, or a template's at a point")
def new_from_steps(body: NewFromSteps, request: Request) -> dict:
    data = web_of(request).data
    steps = _template(data, body.template, body.point, body.thing)
    named = body.thing.get("name") if body.thing is not None else body.point
    named = named if isinstance(named, str) else None
    if body.name is None and body.if_exists != "number":
        name = steplib.program_name(body.template, named, ())
        if name in data.programs():
            users = [t.name for t in data.tasks() if t.program == name]
            if body.if_exists == "ask":
                ran_by = f", which {_listed(users)} {'runs' if len(users) == 1 else 'run'}" if users else ""
                raise AlreadyExists(f"A program already picks up the {named or 'point'}: {name}{ran_by}. Update it "
                                    "with what you touched now, or make another.")
            made = data.steps.save(name, steps, replace=True)
            return _answer(data, name, made.steps, text=made.text, in_sync=True, points_changed=False,
                           replaced=True, tasks=users)
    name = body.name or steplib.program_name(body.template, named, data.programs())
    made = data.steps.save(name, steps, new=True)
    return _answer(data, name, made.steps, text=made.text, in_sync=True, points_changed=False, replaced=False, tasks=[])


def _listed(names: list[str]) -> str:
    quoted = [f"“{n}”" for n in names]
    return quoted[0] if len(quoted) == 1 else ", ".join(quoted[:-1]) + " and " + quoted[-1]
