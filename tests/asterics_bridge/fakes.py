"""Test doubles serving the real RPC keys with the real services' reply shapes:
nav (services/nav/asibot/nav/service.py and pilot.py), kinematics (services/kinematics/asibot/kinematics/server.py), the
Task Creator's tasks (keys.tasks_rpc, served by the web service)."""

from __future__ import annotations

import threading

from asibot import keys
from asibot import messages as m
from asibot.errors import RpcError

PLACES = {"fridge": [8.7, 1.0, 0.0], "shelf": [2.0, 6.8, 1.5708], "desk": [8.5, 6.5, 1.5708],
          "charging station": [0.75, 1.5, 3.1416]}
NAV_PRIMITIVES = ("forward", "backward", "turn left", "turn right", "turn left 90", "turn right 90", "turn around",
                  "curve forward left", "curve forward right", "curve backward left", "curve backward right", "stop")


class Recorder:
    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.calls: list[tuple[str, dict]] = []

    def serve(self, bus, key, verbs) -> None:
        """Answer `key(verb)` for each verb with the method `_<verb>`, recording every call."""
        for verb in verbs:
            bus.serve(key(verb), self._handler(verb))

    def _handler(self, verb: str):
        def handle(req: dict) -> dict:
            with self._lock:
                self.calls.append((verb, dict(req)))
            reply = getattr(self, "_" + verb)(req)
            self.answered()
            return reply
        return handle

    def answered(self) -> None:
        """After every answer (nav publishes its status)."""

    def verbs(self) -> list[str]:
        with self._lock:
            return [v for v, _ in self.calls]

    def requests(self, verb: str) -> list[dict]:
        with self._lock:
            return [r for v, r in self.calls if v == verb]

    def clear(self) -> None:
        with self._lock:
            self.calls.clear()


class FakeNav(Recorder):
    """nav's verbs for one robot; a primitive publishes a Twist on base_cmd_vel (as nav's loop
    would) and a NavStatus, as nav does after every RPC."""

    def __init__(self, bus, robot: str, twist: bool = True) -> None:
        super().__init__()
        self.bus, self.robot = bus, robot
        self.state, self.text, self.driving, self.place = "idle", "", "", ""
        self.speed, self.width, self.goal_id = 2, 3, 0
        self.saved: list[float] | None = None
        self.refuse: RpcError | None = None     # the next motion is refused with this
        self._status = bus.publisher(keys.nav_status(robot), m.NavStatus)
        self._cmd = bus.publisher(keys.base_cmd_vel(robot), m.Twist) if twist else None
        self.serve(bus, lambda verb: keys.nav_rpc(robot, verb),
                   ("primitive", "settings", "goto", "save_position", "recall_position", "places", "status", "cancel"))

    def answered(self) -> None:
        self.publish_status()

    def publish_status(self) -> None:
        self._status.put(m.NavStatus(goal_id=self.goal_id, state=self.state, text=self.text, place=self.place,
                                     driving=self.driving, speed=self.speed, width=self.width))

    def finish(self, state: str = "succeeded", text: str = "forward: done") -> None:
        """The motion ends by itself (an obstacle, the goal reached)."""
        self.state, self.text, self.driving = state, text, ""
        self.publish_status()

    def _refused(self) -> None:
        if self.refuse is not None:
            exc, self.refuse = self.refuse, None
            raise exc

    def _primitive(self, req: dict) -> dict:
        name = req.get("name")
        if name not in NAV_PRIMITIVES:
            raise RpcError("bad_request", f"{name!r} is not a driving primitive; use one of {', '.join(NAV_PRIMITIVES)}.")
        if name == "stop":
            self.state, self.text, self.driving = ("canceled" if self.state == "active" else self.state), "stopped", ""
            if self._cmd:
                self._cmd.put(m.Twist(vx=0.0, wz=0.0, controller="nav"))
            return {"text": "stopped"}
        self._refused()
        text = f"{name}, until you say stop" if req.get("continuous") else f"{name}, 1.00 m"
        self.state, self.text, self.driving = "active", text, text
        if self._cmd:
            self._cmd.put(m.Twist(vx=0.2 if "backward" not in name else -0.2, wz=0.0, controller="nav"))
        return {"text": text}

    def _settings(self, req: dict) -> dict:
        change = req.get("change")
        if change not in ("faster", "slower", "wider", "narrower"):
            raise RpcError("bad_request", f"{change!r} is not a setting change; use one of faster, slower, wider, narrower.")
        which = "speed" if change in ("faster", "slower") else "width"
        delta = 1 if change in ("faster", "wider") else -1
        setattr(self, which, min(5, max(1, getattr(self, which) + delta)))
        return {"text": f"{which} {getattr(self, which)} of 5", "speed": self.speed, "width": self.width}

    def _goto(self, req: dict) -> dict:
        place = req.get("place")
        if place not in PLACES:
            raise RpcError("bad_request", f"There is no place {place!r}; known places: {', '.join(PLACES)}.")
        self._refused()
        self.goal_id += 1
        self.state, self.place, self.text = "active", place, f"driving to {place}, 8.0 m left"
        return {"goal_id": self.goal_id, "place": place, "goal": PLACES[place], "text": self.text}

    def _save_position(self, req: dict) -> dict:
        self.saved = [1.0, 1.5, 0.0]
        return {"pose": self.saved}

    def _recall_position(self, req: dict) -> dict:
        if self.saved is None:
            raise RpcError("bad_request", "No position is saved yet; save one first.")
        self.goal_id += 1
        self.state, self.place, self.text = "active", "the saved position", "driving to the saved position"
        return {"goal_id": self.goal_id, "place": "the saved position", "goal": self.saved, "text": self.text}

    def _places(self, req: dict) -> dict:
        return {"places": [{"name": n, "pose": p} for n, p in PLACES.items()]}

    def _status(self, req: dict) -> dict:
        return {"goal_id": self.goal_id, "state": self.state, "text": self.text, "place": self.place, "goal": [],
                "distance": 0.0, "eta": 0.0, "recoveries": 0, "driving": self.driving, "localised": True,
                "speed": self.speed, "width": self.width, "pose": [1.0, 1.5, 0.0]}

    def _cancel(self, req: dict) -> dict:
        self.state = "canceled"
        return {"goal_id": self.goal_id, "state": self.state, "text": "canceled", "place": self.place,
                "distance": 0.0, "recoveries": 0}


class FakeArm(Recorder):
    """kinematics' verbs for one arm: a tip point that movl moves at once, a gripper."""

    REACH = 0.8   # m from the base: farther is unreachable

    def __init__(self, bus, robot: str, point=(0.3, 0.0, 0.4, 90.0, 0.0)) -> None:
        super().__init__()
        self.point = list(point)
        self.opening, self.holding = 0.08, False
        self.serve(bus, lambda verb: keys.cart_rpc(robot, verb), ("stat", "movl", "home", "act", "stop"))

    def _stat(self, req: dict) -> dict:
        return {"state": "idle", "point": list(self.point), "joints": [0.0] * 5, "estop": False, "fault": ""}

    def _movl(self, req: dict) -> dict:
        point = req["point"]
        if sum(v * v for v in point[:3]) ** 0.5 > self.REACH:
            raise RpcError("unreachable", "The point is unreachable at 100 % of the path: "
                                          "it is farther than the arm reaches.")
        self.point = list(point)
        return {"duration": 0.5}

    def _home(self, req: dict) -> dict:
        self.point = [0.3, 0.0, 0.4, 90.0, 0.0]
        return {"duration": 2.0}

    def _act(self, req: dict) -> dict:
        if req.get("action") == "close":
            self.opening, self.holding = 0.02, True
        else:
            self.opening, self.holding = 0.08, False
        return {"opening": self.opening, "holding": self.holding}

    def _stop(self, req: dict) -> dict:
        return {}


class FakeTasks(Recorder):
    """The Task Creator's verbs as the web service serves them."""

    def __init__(self, bus, tasks=("give me the red can", "drink")) -> None:
        super().__init__()
        self.tasks = list(tasks)
        self.serve(bus, keys.tasks_rpc, ("list", "launch", "stop"))

    def _list(self, req: dict) -> dict:
        return {"tasks": [{"name": t, "program": t.replace(" ", "_") + ".py", "words": [t]} for t in self.tasks]}

    def _launch(self, req: dict) -> dict:
        if req.get("task") not in self.tasks:
            raise RpcError("bad_request", f"There is no task {req.get('task')!r}.")
        return {"task": req["task"], "program": req["task"].replace(" ", "_") + ".py", "robot": req["robot"]}

    def _stop(self, req: dict) -> dict:
        return {}
