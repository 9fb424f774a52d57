"""The Task Creator's tasks on the bus: other services (the AsTeRICS bridge, voice) launch a
task by name as the Launcher does, and every robot's users hear how it went.

The web service owns the program runner (one program at a time, with its limits), so it is
the one that serves `keys.tasks_rpc(...)`; a second runner elsewhere could start a second
program on the same arm. When a task's program ends, an Event on the robot's `events` says
how ("Give me the red can: done", or the runner's sentence), for the page, the bridge's
clients and the spoken feedback alike.
"""

from __future__ import annotations

import logging
from typing import Any, Callable

from asibot import keys, verbs
from asibot.bus import Bus, Publisher
from asibot.errors import RpcError
from asibot.messages import Event
from asibot.verbs import Field, Text, Verb
from asibot.web.runner import ProgramRunner, RunResult
from asibot.web.userdata import MAX_NAME, UserData, UserDataError
from asibot.web.userdata.favourites import task_key

log = logging.getLogger("asibot.web.tasks")

#: The verbs of `keys.tasks_rpc`. Whether the task exists and the robot is live are the
#: desk's checks, with their own sentences.
VERBS = {
    "list": Verb(doc="the Task Creator's tasks: name, program, the words that launch each and the robot it "
                     "runs on (\"\": the one that launches it)"),
    "launch": Verb({"task": Field(Text("a task name", longest=MAX_NAME), required=True),
                    "robot": Field(Text("a robot id"), required=True)},
                   doc="start a task's program on its own robot (`robot` for a task that names none), "
                       "as the Launcher's button does"),
    "stop": Verb(doc="stop the running program"),
    "status": Verb(doc="the running program, and how the last one ended"),
}


class TaskDesk:
    """Serves list / launch / stop / status of the tasks in `data` through `runner`.

    `is_live(robot)` says whether a robot is on the bus (the fleet knows); a task is launched
    only on a live one."""

    def __init__(self, bus: Bus, data: UserData, runner: ProgramRunner, is_live: Callable[[str], bool]) -> None:
        self.bus, self.data, self.runner, self.is_live = bus, data, runner, is_live
        self._events: dict[str, Publisher[Event]] = {}
        verbs.serve(bus, keys.tasks_rpc, VERBS, {"list": self._list, "launch": self._launch,
                                                 "stop": self._stop, "status": self._status})

    def launch(self, name: str, robot: str) -> dict:
        """Start task `name` on its own robot, or on `robot` for a task that names none (the
        Launcher's button, a tile, a word and the bridge all come here): a task taught on the
        kitchen arm never runs on the Pioneer because the page commanded it at the time."""
        task = self.data.task(name)
        robot = task.robot or robot
        if not self.is_live(robot):
            raise RpcError("unavailable", f"{task.name} runs on {robot}, which is not connected; start it with "
                                          "`asibot up`." if task.robot else
                                          f"Robot {robot!r} is not connected; start it with `asibot up`.")
        path = self.data.program_file(task.program)
        try:
            self.runner.start(path, robot, name=task.name)
        except RuntimeError as exc:
            raise RpcError("busy", f"{str(exc)[:1].upper()}{str(exc)[1:]}.") from None
        self.tell(robot, "info", "task_started", f"{task.name}: started")
        self.data.favourites.used(task_key(task.name))
        return {"task": task.name, "program": task.program, "robot": robot}

    def finished(self, result: RunResult) -> None:
        """The runner's `on_exit`: tell the robot's users how the task ended."""
        if result.robot:
            text = f"{result.program}: done" if result.ok else f"{result.program}: {result.reason}"
            self.tell(result.robot, "info" if result.ok else "warning",
                      "task_done" if result.ok else "task_failed", text)

    def tell(self, robot: str, level: str, code: str, text: str) -> None:
        try:
            pub = self._events.get(robot) or self._events.setdefault(
                robot, self.bus.publisher(keys.events(robot), Event))
            pub.put(Event(level=level, code=code, text=text))
        except Exception as exc:   # telling must never break a run or a launch
            log.warning("could not tell %s about its task: %s", robot, exc)

    # --- the RPC verbs ---------------------------------------------------------------------
    def _list(self, a: Any) -> dict:
        return {"tasks": [{"name": t.name, "program": t.program, "words": list(t.words), "robot": t.robot}
                          for t in self.data.tasks()]}

    def _launch(self, a: Any) -> dict:
        try:
            return self.launch(a.task, a.robot)
        except UserDataError as exc:
            raise RpcError("bad_request", str(exc)) from None

    def _stop(self, a: Any) -> dict:
        self.runner.stop("stopped from another program")
        return {}

    def _status(self, a: Any) -> dict:
        return self.runner.status()
