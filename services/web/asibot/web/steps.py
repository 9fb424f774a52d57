"""Programs without Python: a program as a list of steps (move to a point, open or close the
gripper, wait, say, repeat), the "Pick it up" and "Put it down" templates, the sentence that
describes each step on the page, and the seed-format Python program the steps generate.

The steps never run themselves: they are saved beside the program (userdata/steps.py) and make
its `<program>.py`, an ordinary seed-format program (CartesianClient, `simCart.movj(point)`,
literal points), so the runner, the Launcher and a user's existing files stay as they are, and
a carer who later learns Python finds a program that reads like the seed's examples.

A move's "how" may be left to the generator ("auto"): a joint move for travel, and a straight
move only for a short final approach (at most APPROACH_DISTANCE from where the previous move
ended, with the tool turning little), because a straight line is what keeps the fingers off the
object on the last centimetres, while over a long way it risks a singularity or a joint limit.
Any straight move the kinematics refuses is made as a joint move instead, with a notice in the
program's output: the generated program catches the client's RpcError for that case only.

Plain Python (pydantic models, no web framework): the routes validate request bodies with the
models, and the generator is a pure function of the steps and the points' values.
"""

from __future__ import annotations

import keyword
import math
import re
from dataclasses import dataclass, field
from typing import Annotated, Iterable, Literal, Mapping, Sequence, Union

from pydantic import (AfterValidator, BaseModel, ConfigDict, Field, StrictBool, StrictFloat, StrictInt, StrictStr, TypeAdapter,
                      ValidationError, model_validator)

from asibot import things
from asibot.web.userdata.errors import UserDataError
from asibot.web.userdata.names import CONTROL_RE
from asibot.web.userdata.points import check_point_name

#: How far above a point "above <point>" is, m: the fingers clear a can or a cup standing
#: there (the worked example give_me_the_red_can.py goes 0.12 m above its grip).
ABOVE_HEIGHT = 0.12
#: An "auto" move is straight only when it ends at most this far from where the previous move
#: ended, m (a final approach or a lift; ABOVE_HEIGHT fits), and turns the tool at most
#: APPROACH_TURN deg; otherwise it is a joint move.
APPROACH_DISTANCE = 0.15
APPROACH_TURN = 10.0
#: The speed of a move marked "slowly": m/s for a straight move, a fraction of each joint's top
#: speed for a joint move.
SLOW_STRAIGHT = 0.03
SLOW_JOINT = 0.2
#: The RpcError codes of a straight move the kinematics cannot make but a joint move may (a
#: singularity or a configuration change on the way, a joint limit on the way).
STRAIGHT_REFUSALS = ("unreachable", "joint_limit")
#: The RpcError code of a close whose fingers did not settle (asibot.client act: still moving
#: after its time): they push on the side of something, which a checked close counts as nothing.
UNSETTLED = "timeout"
#: Limits that keep a steps program something a person reads: steps in all, and repeats inside
#: repeats.
MAX_STEPS = 200
MAX_DEPTH = 3
MAX_TIMES = 100
MAX_WAIT = 600.0
MAX_SAY = 200
MAX_THING_NAME = 40
#: The client variable of the generated program: the seed's template's; and the one that looks.
CLIENT = "simCart"
LOOK = "look"

Number = StrictFloat | StrictInt   # JSON's `true` is not the number 1 (as in web/models.py)


def _plain_text(text: str) -> str:
    if CONTROL_RE.search(text):
        raise ValueError("the text holds a control character or a line break; write it on one line")
    if not text.strip():
        raise ValueError("the text is empty; write what to say")
    return text


PointName = Annotated[StrictStr, AfterValidator(check_point_name)]


def _taught_thing(data: dict) -> dict:
    try:
        return things.Thing.from_json(data).as_json()
    except ValueError as exc:
        raise ValueError(f"the thing to look for: {exc}") from None


def _thing_name(name: str) -> str:
    if CONTROL_RE.search(name) or not name.strip() or len(name) > MAX_THING_NAME:
        raise ValueError(f"a thing's name is 1 to {MAX_THING_NAME} characters on one line")
    return name


ThingName = Annotated[StrictStr, AfterValidator(_thing_name)]


class _Step(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Move(_Step):
    """Move the tool to a captured point, or to a thing where a Find before found it (its
    grasp), or ABOVE_HEIGHT above either."""
    kind: Literal["move"] = "move"
    point: PointName | None = None
    thing: ThingName | None = None
    how: Literal["auto", "joint", "straight"] = "auto"
    above: StrictBool = False
    slow: StrictBool = False

    @model_validator(mode="after")
    def _one_target(self) -> "Move":
        if (self.point is None) == (self.thing is None):
            raise ValueError("a move goes to a point or to a thing: give one of them")
        return self

    @property
    def target(self) -> str:
        """What it moves to, as the person named it."""
        return self.point if self.point is not None else f"the {self.thing}"


class Find(_Step):
    """Look with the robot's cameras for a thing the carer taught (asibot.things) and keep
    where it stands now, for the moves to it that follow: a pick that repeats what, not where."""
    kind: Literal["find"] = "find"
    thing: Annotated[dict, AfterValidator(_taught_thing)]


class Open(_Step):
    kind: Literal["open"] = "open"


class Close(_Step):
    """Close the gripper; with `check`, the program stops when it holds nothing."""
    kind: Literal["close"] = "close"
    check: StrictBool = True


class Wait(_Step):
    kind: Literal["wait"] = "wait"
    seconds: Annotated[Number, Field(gt=0, le=MAX_WAIT)]


class Say(_Step):
    kind: Literal["say"] = "say"
    text: Annotated[StrictStr, Field(min_length=1, max_length=MAX_SAY), AfterValidator(_plain_text)]


class Repeat(_Step):
    kind: Literal["repeat"] = "repeat"
    times: Annotated[StrictInt, Field(ge=1, le=MAX_TIMES)]
    steps: list[Step] = []


Step = Annotated[Union[Move, Find, Open, Close, Wait, Say, Repeat], Field(discriminator="kind")]
Repeat.model_rebuild()
STEPS = TypeAdapter(list[Step])


def parse(data: object) -> list[Step]:
    """Steps from JSON data (a saved file, a test); a bad step is a UserDataError sentence."""
    try:
        steps = STEPS.validate_python(data)
    except ValidationError as e:
        first = e.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        raise UserDataError(f"The steps are not valid: {where}: {first['msg']}.") from None
    check_shape(steps)
    return steps


def dump(steps: Sequence[Step]) -> list[dict]:
    # A move names its point or its thing, not the other as null.
    return [s.model_dump(exclude_none=True) for s in steps]


def check_shape(steps: Sequence[Step]) -> None:
    """Refuse, with a sentence, steps over MAX_STEPS in all or repeats deeper than MAX_DEPTH."""
    count = 0

    def walk(items: Sequence[Step], depth: int) -> None:
        nonlocal count
        for s in items:
            count += 1
            if isinstance(s, Repeat):
                if depth >= MAX_DEPTH:
                    raise UserDataError(f"A Repeat may hold Repeats only {MAX_DEPTH} deep; "
                                        "take a Repeat out of another one.")
                walk(s.steps, depth + 1)
    walk(steps, 0)
    if count > MAX_STEPS:
        raise UserDataError(f"The program has {count} steps; the most a steps program may have is {MAX_STEPS}. "
                            "Use Repeat for steps that come again, or write it in Python.")


def points_used(steps: Sequence[Step]) -> list[str]:
    """The names of the points the steps move to, in order, each once."""
    out: dict[str, None] = {}
    for s in _flat(steps):
        if isinstance(s, Move) and s.point is not None:
            out.setdefault(s.point, None)
    return list(out)


def check_points(steps: Sequence[Step], points: Mapping[str, Sequence[float]]) -> None:
    """Every point a step moves to must exist, and every thing a step moves to must be looked
    for by a step before it: the refusal names the step and the point or thing."""
    looked: set[str] = set()
    for number, s in _numbered(steps):
        if isinstance(s, Find):
            looked.add(s.thing["name"])
        elif isinstance(s, Move) and s.point is not None and s.point not in points:
            raise UserDataError(f"Step {number} moves to the point {s.point!r}, but there is no point with that "
                                "name: capture it, or choose another point for the step.")
        elif isinstance(s, Move) and s.thing is not None and s.thing not in looked:
            raise UserDataError(f"Step {number} moves to the {s.thing}, but no step before it looks for the "
                                f"{s.thing}: add a step that looks for it first.")


# --- templates ------------------------------------------------------------------------------------
def pick_it_up(point: str) -> list[Step]:
    """The whole pick from one captured point, the grip pose: open, above it (joint), down to it
    (straight, slow), close and check, lift back above it (straight)."""
    point = check_point_name(point)
    return [Open(), Move(point=point, how="joint", above=True), Move(point=point, how="straight", slow=True),
            Close(check=True), Move(point=point, how="straight", above=True)]


def put_it_down(point: str) -> list[Step]:
    """The place at one captured point: above it (joint), down (straight, slow), open, up (straight)."""
    point = check_point_name(point)
    return [Move(point=point, how="joint", above=True), Move(point=point, how="straight", slow=True),
            Open(), Move(point=point, how="straight", above=True)]


def pick_up_thing(thing: Mapping[str, object]) -> list[Step]:
    """The pick of a taught thing wherever it stands: open, look for it, above it (joint), down
    to it (straight, slow), close and check (a close on nothing looks again and tries once more),
    lift back above it (straight)."""
    spec = things.Thing.from_json(dict(thing))
    return [Open(), Find(thing=spec.as_json()), Move(thing=spec.name, how="joint", above=True),
            Move(thing=spec.name, how="straight", slow=True), Close(check=True),
            Move(thing=spec.name, how="straight", above=True)]


TEMPLATES = {"pick_it_up": pick_it_up, "put_it_down": put_it_down}
#: How a program made from a template is named when the person names it not: "pick_up_red-can".
TEMPLATE_PROGRAM_PREFIX = {"pick_it_up": "pick_up", "put_it_down": "put_down", "empty": "steps"}


def program_name(template: str, point: str | None, taken: Iterable[str]) -> str:
    """A free program name for a template's program at `point`: the template and the point
    ("pick_up_red-can"), with a number after it when that is taken ("pick_up_red-can_2")."""
    base = "_".join(filter(None, [TEMPLATE_PROGRAM_PREFIX[template], re.sub(r"[^A-Za-z0-9_-]", "_", point or "")]))
    names, n = set(taken), 2
    name = base
    while name in names:
        name, n = f"{base}_{n}", n + 1
    return name
Template = Literal["pick_it_up", "put_it_down"]


# --- the plan: what each step does, with "auto" resolved ------------------------------------------
@dataclass
class Planned:
    """One step as the page describes it and the program does it."""
    step: Step
    sentence: str
    how: str | None = None              # a move's: "joint" or "straight"
    target: str | None = None           # a move's: "grasp-can" or "above grasp-can"
    values: list[float] | None = None   # a move's target point (None: a thing's, found when it runs)
    at: str | None = None               # a close's: where the gripper closes (the last move's target)
    thing: str | None = None            # a close's: the thing the last move went to, looked for again
    inside: list[Planned] = field(default_factory=list)

    def json(self) -> dict:
        out: dict = {"sentence": self.sentence}
        if self.how is not None:
            out["how"] = self.how
        if isinstance(self.step, Repeat):
            out["steps"] = [p.json() for p in self.inside]
        return out


def target_of(move: Move, points: Mapping[str, Sequence[float]]) -> tuple[str, list[float] | None]:
    """The name and values of where a move goes: the point, or ABOVE_HEIGHT above it; a
    thing's values are found when the program runs (None)."""
    if move.thing is not None:
        return (f"above {move.thing}" if move.above else move.thing), None
    assert move.point is not None
    values = [float(v) for v in points[move.point]]
    if move.above:
        return f"above {move.point}", [values[0], values[1], values[2] + ABOVE_HEIGHT, *values[3:]]
    return move.point, values


def is_approach(start: Sequence[float] | None, end: Sequence[float] | None) -> bool:
    """The auto rule: a short final approach (or lift) from a known start is straight."""
    if start is None or end is None:
        return False
    turn = max(abs((a - b + 180.0) % 360.0 - 180.0) for a, b in zip(start[3:], end[3:]))
    return math.dist(start[:3], end[:3]) <= APPROACH_DISTANCE and turn <= APPROACH_TURN


def plan(steps: Sequence[Step], points: Mapping[str, Sequence[float]]) -> list[Planned]:
    """Each step with its sentence and, for a move, its target and its resolved kind.

    The arm's start is unknown, and so is where it is at the start of a Repeat (the first time,
    where the steps before left it; then, where the Repeat's own steps did), so the first move
    in either place is never "auto" straight."""
    check_points(steps, points)
    last: dict = {"name": None, "values": None, "thing": None}

    def walk(items: Sequence[Step]) -> list[Planned]:
        out = []
        for s in items:
            if isinstance(s, Move):
                name, values = target_of(s, points)
                if s.how != "auto":
                    how = s.how
                elif s.thing is not None:   # its place is found when it runs: straight only near it
                    how = "straight" if last["thing"] == s.thing else "joint"
                else:
                    how = "straight" if is_approach(last["values"], values) else "joint"
                chosen = ", chosen automatically" if s.how == "auto" else ""
                where = f"above {s.target}" if s.above else f"to {s.target}"
                slowly = " slowly" if s.slow else ""
                out.append(Planned(s, f"Move {where}{slowly} ({how} move{chosen})", how, name, values))
                last["name"], last["values"], last["thing"] = name, values, s.thing
            elif isinstance(s, Find):
                t = s.thing
                out.append(Planned(s, f"Look for the {t['name']} (a {t['colour']} object {t['height'] * 100:.0f} cm "
                                      "tall) and find where it stands now"))
            elif isinstance(s, Open):
                out.append(Planned(s, "Open the gripper"))
            elif isinstance(s, Close):
                sentence = "Close the gripper and check it holds something" if s.check else "Close the gripper"
                if s.check and last["thing"] is not None:
                    sentence += f" (if not, look for the {last['thing']} again and try once more)"
                out.append(Planned(s, sentence, at=last["name"], thing=last["thing"]))
            elif isinstance(s, Wait):
                out.append(Planned(s, f"Wait {s.seconds:g} s"))
            elif isinstance(s, Say):
                out.append(Planned(s, f"Say “{s.text}”"))
            else:
                before = dict(last)
                last["name"] = last["values"] = last["thing"] = None
                inside = walk(s.steps)
                if not any(isinstance(p.step, Move) for p in _flat_planned(inside)):
                    last.update(before)
                times = "once" if s.times == 1 else "twice" if s.times == 2 else f"{s.times} times"
                out.append(Planned(s, f"Repeat {times}" + ("" if s.steps else " (no steps inside yet)"),
                                   inside=inside))
        return out
    return walk(steps)


def describe(steps: Sequence[Step], points: Mapping[str, Sequence[float]]) -> list[dict]:
    """The sentences of the steps, as the page lists them (nested for a Repeat's steps)."""
    return [p.json() for p in plan(steps, points)]


# --- the generated program ------------------------------------------------------------------------
_RESERVED = {"os", "sys", "time", "CartesianClient", "LookClient", "RpcError", "robot_name", CLIENT, LOOK,
             "straight", "close_and_check", "close_on_thing", "holds", "up", "give_up", "find", "ABOVE",
             "SLOW_STRAIGHT", "SLOW_JOINT", "print", "range"}


def variable_names(targets: Iterable[str]) -> dict[str, str]:
    """A Python name for each target ("above grasp-can" -> above_grasp_can), each a different one."""
    names: dict[str, str] = {}
    taken = set(_RESERVED)
    for target in targets:
        if target in names:
            continue
        base = re.sub(r"\W", "_", target, flags=re.ASCII)
        if not base or base[0].isdigit():
            base = f"p_{base}"
        if keyword.iskeyword(base):
            base += "_point"
        name, n = base, 2
        while name in taken:
            name, n = f"{base}_{n}", n + 1
        names[target] = name
        taken.add(name)
    return names


def _number(v: float) -> str:
    text = repr(round(float(v), 6))
    return "0.0" if text == "-0.0" else text


HEADER = '''"""{program}: made from steps on the Program page.

Change its steps there ("Steps"), and they write this file again. If you edit this Python
instead, the page says that its steps no longer match it, and keeps both.
Robot: argv[1], ASIBOT_ROBOT, or asibot-sim. Points are the seed's [x, y, z, rot(y'), rot(z'')]
in m and deg, in the arm's base frame; rot(y') = 180 points the gripper straight down.
"""

import os
import sys
{time}
from asibot.client import {clients}
{errors}
robot_name = sys.argv[1] if len(sys.argv) > 1 else os.environ.get("ASIBOT_ROBOT", "asibot-sim")
'''

SLOW = '''
SLOW_STRAIGHT = {slow_straight!r}  # m/s: the speed of a straight move made slowly
SLOW_JOINT = {slow_joint!r}  # a fraction of each joint's top speed: a joint move made slowly
'''

STRAIGHT = '''

def straight(point, name, speed=None):
    """A straight move; one the arm cannot make (a singularity or a joint limit on the way) is
    made as a joint move instead, with a notice."""
    try:
        {client}.movl(point, speed=speed)
    except RpcError as error:
        if error.code not in {refusals!r}:
            raise
        print(f"Notice: the straight move to {{name}} cannot be done ({{error}}); "
              "making it a joint move instead.")
        {client}.movj(point)
    {client}.wait()
'''

GIVE_UP = '''

def give_up(text):
    """End the program with `text` (the page shows it by the task): the arm stays where it is."""
    {client}.close(){close_look}
    sys.exit(text)
'''

CLOSE_AND_CHECK = '''

ABOVE = {above!r}  # m: how far a failed grasp goes back up


def holds():
    """Close the gripper; True when it holds something. Fingers that do not settle (they push
    on the side of something) hold nothing either."""
    try:
        return {client}.grip()
    except RpcError as error:
        if error.code != {unsettled!r}:
            raise
        return False


def up(name):
    """Open the gripper and go straight up ABOVE m from where it closed: never left down at
    the spot, the gripper open around nothing."""
    {client}.grip(close=False)
    here = {client}.stat()
    straight([here[0], here[1], here[2] + ABOVE, here[3], here[4]], f"above {{name}}")


def close_and_check(name):
    """Close the gripper; when it holds nothing, go back up and stop the program."""
    if not holds():
        up(name)
        give_up(f"Nothing in the gripper after closing at {{name}}; the arm went back up, the gripper open.")
'''

FIND = '''

def find(thing):
    """Look for a taught thing with the robot's cameras: (above it, its grasp) where it stands
    now. When it is not there or out of reach, say what the cameras saw, and stop before the
    arm moves towards it."""
    try:
        found = {look}.find(thing)
    except RpcError as error:
        if error.code not in ("not_found", "unreachable"):
            raise
        give_up(error.message)
    print(found["says"])
    return found["above"], found["reach"]
'''

CLOSE_ON_THING = '''

def close_on_thing(thing, places):
    """Close on a thing found where `places` say (above it, its grasp); when the gripper holds
    nothing, go back up, look for it again and try once more. Returns where it is now."""
    name = thing["name"]
    if holds():
        return places
    up(name)
    print(f"Nothing in the gripper at the {{name}}: I look for it again and try once more.")
    places = find(thing)
    {client}.movj(places[0])
    {client}.wait()
    straight(places[1], name, speed=SLOW_STRAIGHT)
    if holds():
        return places
    up(name)
    give_up(f"Nothing in the gripper after two tries at the {{name}}; the arm went back up, the gripper open.")
'''

#: Where a checked close happens when no move came before it in the steps.
NOWHERE = "the start"


def generate(program: str, steps: Sequence[Step], points: Mapping[str, Sequence[float]]) -> str:
    """The seed-format Python program of the steps (see the module doc); `points` maps each point
    name to its values. Refuses (UserDataError) a step that names a point that does not exist.
    It holds only what its steps use: a program without waits does not import time."""
    check_shape(steps)
    planned = plan(steps, points)
    every = list(_flat_planned(planned))
    moves = [p for p in every if p.how is not None]
    finds = [p.step for p in every if isinstance(p.step, Find)]
    checks = any(isinstance(p.step, Close) and p.step.check for p in every)
    on_things = any(isinstance(p.step, Close) and p.step.check and p.thing for p in every)
    straights = any(p.how == "straight" for p in moves) or checks     # a failed grasp goes straight up
    slow = any(isinstance(p.step, Move) and p.step.slow for p in every) or on_things
    taught = {f.thing["name"]: f.thing for f in finds}
    names = variable_names([*(p.target for p in moves if p.target is not None),
                            *(t for n in taught for t in (f"above {n}", n, f"taught {n}"))])
    out = [HEADER.format(program=program,
                         time="import time\n" if any(isinstance(p.step, Wait) for p in every) else "",
                         clients="CartesianClient, LookClient" if finds else "CartesianClient",
                         errors="from asibot.errors import RpcError\n" if straights or checks or finds else "")]
    if any(p.values is not None for p in moves):
        out.append("# The points, as captured: [x, y, z, rot(y'), rot(z'')].")
        seen = set()
        for p in moves:
            if p.values is not None and p.target is not None and p.target not in seen:
                seen.add(p.target)
                higher = f" ({ABOVE_HEIGHT:g} m higher)" if p.target.startswith("above ") else ""
                out.append(f"{names[p.target]} = [{', '.join(_number(v) for v in p.values)}]  # {p.target}{higher}")
    if taught:
        out.append("# What the carer taught: looked for when the program runs, wherever it stands.")
        for name, thing in taught.items():
            out.append(f"{names[f'taught {name}']} = {thing!r}")
    if slow:
        out.append(SLOW.format(slow_straight=SLOW_STRAIGHT, slow_joint=SLOW_JOINT).rstrip("\n"))
    if straights:
        out.append(STRAIGHT.format(client=CLIENT, refusals=STRAIGHT_REFUSALS).rstrip("\n"))
    if checks or finds:
        out.append(GIVE_UP.format(client=CLIENT, close_look=f"\n    {LOOK}.close()" if finds else "").rstrip("\n"))
    if checks:
        out.append(CLOSE_AND_CHECK.format(client=CLIENT, unsettled=UNSETTLED, above=ABOVE_HEIGHT).rstrip("\n"))
    if finds:
        out.append(FIND.format(look=LOOK).rstrip("\n"))
    if on_things:
        out.append(CLOSE_ON_THING.format(client=CLIENT).rstrip("\n"))
    out.append("\n" if straights or checks or finds else "")
    out.append(f"{CLIENT} = CartesianClient()")
    out.append(f'{CLIENT}.open(robot_name)  # "asibot" for the real arm')
    if finds:
        out.append(f"{LOOK} = LookClient()")
        out.append(f"{LOOK}.open(robot_name)  # the robot's cameras, through the web service")
    out.extend(_lines(planned, names, ""))
    out.append('print("done!")')
    out.append(f"{CLIENT}.close()")
    if finds:
        out.append(f"{LOOK}.close()")
    return "\n".join(out) + "\n"


def _lines(planned: Sequence[Planned], names: Mapping[str, str], indent: str) -> list[str]:
    out: list[str] = []
    for p in planned:
        s = p.step
        if isinstance(s, Say):
            # Printed only: a program has no way to speak (the voice service speaks its own
            # feedback, and has no verb that says a program's words).
            out.append(f"{indent}print({s.text!r})")
            continue
        out.append(f"{indent}print({p.sentence!r})")
        if isinstance(s, Move):
            assert p.target is not None
            var = names[p.target]
            if p.how == "straight":
                speed = ", speed=SLOW_STRAIGHT" if s.slow else ""
                out.append(f"{indent}straight({var}, {p.target!r}{speed})")
            else:
                out.append(f"{indent}{CLIENT}.movj({var}{', speed=SLOW_JOINT' if s.slow else ''})")
                out.append(f"{indent}{CLIENT}.wait()")
        elif isinstance(s, Find):
            name = s.thing["name"]
            out.append(f"{indent}{names[f'above {name}']}, {names[name]} = find({names[f'taught {name}']})")
        elif isinstance(s, Open):
            out.append(f"{indent}{CLIENT}.grip(close=False)")
        elif isinstance(s, Close) and s.check and p.thing is not None:
            places = f"{names[f'above {p.thing}']}, {names[p.thing]}"
            out.append(f"{indent}{places} = close_on_thing({names[f'taught {p.thing}']}, ({places}))")
        elif isinstance(s, Close):
            out.append(f"{indent}close_and_check({(p.at or NOWHERE)!r})" if s.check else f"{indent}{CLIENT}.grip()")
        elif isinstance(s, Wait):
            out.append(f"{indent}time.sleep({_number(s.seconds)})")
        elif isinstance(s, Repeat):
            out.append(f"{indent}for _ in range({s.times}):")
            inner = _lines(p.inside, names, indent + "    ")
            out.extend(inner if inner else [f"{indent}    pass  # no steps inside yet"])
    return out


def _flat(steps: Sequence[Step]) -> Iterable[Step]:
    for s in steps:
        yield s
        if isinstance(s, Repeat):
            yield from _flat(s.steps)


def _flat_planned(planned: Sequence[Planned]) -> Iterable[Planned]:
    for p in planned:
        yield p
        yield from _flat_planned(p.inside)


def _numbered(steps: Sequence[Step], prefix: str = "") -> Iterable[tuple[str, Step]]:
    """Each step with its number as the page shows it: 3, or 4.2 for the 2nd step inside step 4."""
    for i, s in enumerate(steps, 1):
        number = f"{prefix}{i}"
        yield number, s
        if isinstance(s, Repeat):
            yield from _numbered(s.steps, f"{number}.")
