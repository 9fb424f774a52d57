"""The user's Python API (README, "Programming the arm"): thin, blocking clients of the
kinematics, nav, tasks, driver and sim RPC verbs, shared by programs, the command line, the web
and the AsTeRICS bridge (`Client.on(bus, robot)` over a service's own bus).

Points are the seed's [x, y, z, rot(y'), rot(z'')] in m and deg, joints in deg. Every call
has a timeout; a refusal raises asibot.errors.RpcError (code + the server's sentence).
"""

from __future__ import annotations

import os
import time
from typing import Mapping, Self, Sequence, TypedDict, cast

from asibot.safety import estop
from asibot import keys
from asibot.bus import Bus
from asibot.errors import RpcError, Timeout
from asibot.messages import LISTEN_SECONDS
from asibot.safety.estop import who
from asibot.safety.identity import Identity

#: Per-call timeout for quick verbs, s.
CALL_TIMEOUT = 5.0
#: A look waits for fresh pictures from every camera of the robot: a second or two when
#: nobody watched them before.
FIND_TIMEOUT = 15.0
#: How often NavClient.wait asks how the goal goes, s.
WAIT_POLL = 0.2


class _ServiceClient:
    """What every client shares: one bus connection and calls with a timeout. `on(bus, ...)`
    borrows a service's own bus (the web's, the bridge's), which `close` leaves open."""

    #: The verb whose answer says the service is there, and its name for `open`'s sentence.
    _probe = ""
    _service = ""

    def __init__(self, timeout: float = CALL_TIMEOUT) -> None:
        self.timeout = timeout
        self._bus: Bus | None = None
        self._owns_bus = True

    def _key(self, verb: str) -> str:
        raise NotImplementedError

    def _not_answering(self) -> str:
        """The sentence of `open` when the service does not answer: how to start it."""
        return f"No {self._service} service answers; start it with `python -m asibot.{self._service}`."

    def _connect(self) -> None:
        """A bus of our own if none is borrowed, and the service answering on it."""
        if self._bus is None:
            self._bus = Bus("client", wait=self.timeout)
        if not self._bus.wait_for(self._key(self._probe), timeout=self.timeout):
            raise RpcError("unavailable", self._not_answering())

    def _connected(self) -> Bus:
        if self._bus is None:
            self._connect()
        assert self._bus is not None
        return self._bus

    def close(self) -> None:
        """Disconnect (a `with` block of the client does it at its end)."""
        if self._bus is not None and self._owns_bus:
            self._bus.close()
        self._bus = None

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _call(self, verb: str, _timeout: float | None = None, **request: object) -> dict:
        bus = self._connected()
        body = {k: list(v) if isinstance(v, (tuple, list)) else v for k, v in request.items() if v is not None}
        return bus.call(self._key(verb), body, timeout=_timeout or self.timeout)


class _Client(_ServiceClient):
    """What the clients of one robot's service share: the robot, and its emergency stop."""

    def __init__(self, robot: str | None = None, timeout: float = CALL_TIMEOUT) -> None:
        super().__init__(timeout)
        self.robot: str | None = None
        self._identity: Identity | None = None
        if robot:
            self.open(robot)

    @property
    def _me(self) -> Identity:
        """Signs this program's estops and releases (asibot.safety.estop); made on first use, as
        a client over a service's bus (the web's, the bridge's) never signs with it."""
        if self._identity is None:
            self._identity = Identity("program")
        return self._identity

    @classmethod
    def on(cls, bus: Bus, robot: str, timeout: float = CALL_TIMEOUT) -> Self:
        """A client of `robot` over a bus its caller owns (a service's: the web, the bridge),
        without waiting for the service: a call while it is not there raises Unavailable.
        `close` leaves that bus open."""
        client = cls(timeout=timeout)
        client._bus, client._owns_bus, client.robot = bus, False, robot.strip("/")
        return client

    def open(self, robot: str) -> bool:
        """Connect to the service of `robot`; raises Unavailable if it does not answer."""
        self.robot = robot.strip("/")
        self._connect()
        return True

    def _not_answering(self) -> str:
        return (f"No {self._service} service answers for robot {self.robot!r}; "
                f"start it with `python -m asibot.{self._service} --robot {self.robot}`.")

    def _connected(self) -> Bus:
        if self._bus is None or self.robot is None:
            raise RpcError("bad_request", "Call open(robot) first.")
        return self._bus

    def _opened(self) -> str:
        """The robot open() connected to."""
        if self.robot is None:
            raise RpcError("bad_request", "Call open(robot) first.")
        return self.robot

    # --- safety: every client can stop its robot -------------------------------------------
    def estop(self, reason: str = "emergency stop from a program") -> None:
        """Engage the robot's emergency stop: it stops at once and refuses every motion until
        release(). The drivers and the controller keep it latched, so it holds after this program
        ends (asibot.safety.estop); their events say who engaged it (this user, program and pid)."""
        bus = self._connected()
        estop.latch(bus, self._opened(), self._me, True, reason, who(login_of=bus.name))

    def release(self, reason: str = "released from a program") -> None:
        """Release the emergency stop. Nothing moves by itself afterwards: the robot moves again
        only on a motion request made after the release. The drivers' events say who released it."""
        bus = self._connected()
        estop.latch(bus, self._opened(), self._me, False, reason, who(login_of=bus.name))

    def reset_fault(self) -> dict:
        """Ask the robot's driver to clear a fault (re-initialise the drive that failed);
        raises RpcError with the driver's sentence when the fault is still there."""
        return self._connected().call(keys.driver_rpc(self._opened(), "reset_fault"), timeout=self.timeout)


class CartesianClient(_Client):
    """`robot = CartesianClient(); robot.open("asibot-sim"); robot.movl(home); robot.wait()`."""

    _probe, _service = "stat", "kinematics"

    def _key(self, verb: str) -> str:
        return keys.cart_rpc(self._opened(), verb)

    # --- the seed's verbs ---------------------------------------------------------------
    def stat(self, res: list | None = None) -> list[float]:
        """Current point; also fills `res` in place like the seed's stat(res)."""
        point = self._call("stat")["point"]
        if res is not None:
            res[:] = point
        return point

    def state(self) -> dict:
        """The whole stat reply: state, point, joints, estop, fault."""
        return self._call("stat")

    def inv(self, point: Sequence[float], res: list | None = None) -> list[float]:
        """The joints (deg) that put the tool at `point`; also fills `res` in place like the seed's inv."""
        joints = self._call("inv", point=point)["joints"]
        if res is not None:
            res[:] = joints
        return joints

    def fwd(self, joints: Sequence[float]) -> list[float]:
        """The point the tool would be at with `joints` (deg)."""
        return self._call("fwd", joints=joints)["point"]

    def movj(self, point: Sequence[float] | None = None, *, joints: Sequence[float] | None = None,
             duration: float | None = None, speed: float | None = None) -> float:
        """Joint-space move to a point (or to `joints`, deg); returns the planned duration."""
        return self._call("movj", point=point, joints=joints, duration=duration, speed=speed)["duration"]

    def movl(self, point: Sequence[float], *, duration: float | None = None, speed: float | None = None) -> float:
        """Straight line to a point, null start/end velocity; speed in m/s."""
        return self._call("movl", point=point, duration=duration, speed=speed)["duration"]

    def relj(self, joints: Sequence[float], *, duration: float | None = None, speed: float | None = None) -> float:
        """Joint-space move by `joints` (deg) from where the arm is; `speed` is a fraction of
        each joint's top speed. Returns the planned duration."""
        return self._call("relj", joints=joints, duration=duration, speed=speed)["duration"]

    def movv(self, velocity: Sequence[float]) -> None:
        """Stream a velocity (m/s, deg/s); send again within 200 ms to keep moving."""
        self._call("movv", velocity=velocity)

    def movjv(self, velocity: Sequence[float]) -> None:
        """Stream joint velocities (deg/s, one per joint); send again within 200 ms to keep moving."""
        self._call("movjv", velocity=velocity)

    def home(self, *, duration: float | None = None, speed: float | None = None) -> float:
        """Joint-space move to the arm's home posture; returns the planned duration."""
        return self._call("home", duration=duration, speed=speed)["duration"]

    def pointer(self, deadman: bool, direction: str = "hold", yaw: float = 0.0, pitch: float | None = None,
                speed: float | None = None) -> None:
        """One reading of a handheld pointer: while `deadman` is held the tool turns at `yaw`
        (deg/s), tilts to `pitch` (deg) and goes "forward" or "backward" along itself at
        `speed` (m/s); send again within 200 ms to keep moving, or with deadman False to stop.
        The page's verb: a program run by the page's runner may not call it (docs/sandbox.md)."""
        self._call("pointer", deadman=deadman, direction=direction, yaw=yaw, pitch=pitch, speed=speed)

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the motion ends. On timeout the motion is stopped and Timeout is raised."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            left = 10.0 if deadline is None else max(0.01, min(10.0, deadline - time.monotonic()))
            if self._call("wait", _timeout=left + 3.0, timeout=left)["done"]:
                return True
            if deadline is not None and time.monotonic() >= deadline:
                self.stop()
                raise Timeout(f"The motion did not finish within {timeout:g} s; it was stopped.")

    def stop(self) -> None:
        """Stop the arm, whoever moved it: its controller ends its motion and tells the driver
        to hold where the arm is."""
        self._call("stop")

    def tool(self, tool: Sequence[float] | None = None) -> None:
        """Attach a tool frame: [x, y, z, rx, ry, rz] in m and deg, like points: the tool point's
        offset from the flange (other arms: from their approach frame) and its rotation as a
        rotation vector (axis times angle in deg). From then on points (stat, inv, movj, movl,
        ...) are the tool point's. None (or all zeros) removes it."""
        self._call("tool", tool=tool)

    def act(self, action: str) -> dict:
        """Gripper "open" or "close"; returns once the fingers have moved and stopped (at once if
        they are there already): {"opening": m, "holding": bool}. RpcError "timeout" when they
        do not start within 1.5 s of the command or are still moving after 4 s."""
        reply = self._call("act", action=action)
        return {"opening": reply["opening"], "holding": reply["holding"]}

    def grip(self, close: bool = True) -> bool:
        """Close (or open) the gripper; True when it holds something afterwards."""
        return self.act("close" if close else "open")["holding"]

    def jog(self, axis: str, step: float, level: int) -> dict:
        """One step of one axis, as the page's step buttons move it: a joint ("q1", "q2", ...)
        by `step` deg (a movj), or a coordinate of the point ("x", "y", "z" by m, "rot(y')",
        "rot(z'')" by deg; a movl), at speed level `level` (1 slowest to 5). A step asked while
        the previous one still moves goes on from that step's target, so steps add up as on a
        pendant. The reply: {"duration": s} and the step's target, "joints" (deg) or "point".
        The page's verb: a program run by the page's runner may not call it (docs/sandbox.md)."""
        return self._call("jog", axis=axis, step=step, level=level)


class LookClient(_Client):
    """Looking with a robot's cameras for a thing a carer taught (asibot.things), answered by
    the web service, which keeps the cameras' pictures and calibrations:
    `LookClient("asibot-sim").find(red_can)`, then move to what it answers."""

    _probe, _service = "find", "web"

    def _key(self, verb: str) -> str:
        return keys.look_rpc(self._opened(), verb)

    def find(self, thing: Mapping[str, object]) -> dict:
        """Where `thing` ({"name", "colour", "height", "width", "where"}: what the carer taught)
        stands now: {"says", "above", "reach", "moved", "seen"}. "above" is the point over it
        and "reach" the grasp, both from where it stands now (m, deg); "moved" how far it is
        from where it was taught (m); "seen" what else the cameras see. RpcError "not_found"
        with what they saw instead, "unreachable" when it stands out of the arm's reach."""
        return self._call("find", FIND_TIMEOUT, thing=dict(thing))


class TasksClient(_Client):
    """The Task Creator's tasks, served by the web service (which runs one program at a time):
    `tasks = TasksClient("asibot-sim"); tasks.launch("Give me the red can")`.

    A task runs on this client's robot; `stop` and `status` are about the running program,
    whichever robot it drives."""

    _probe, _service = "status", "web"

    def _key(self, verb: str) -> str:
        return keys.tasks_rpc(verb)

    def tasks(self) -> list[dict]:
        """Every task: {"name", "program", "words"}, `words` being what a user says to launch it.
        RpcError "internal" when the reply holds no list of tasks (a Task Creator of another
        version)."""
        tasks = self._call("list").get("tasks")
        if not isinstance(tasks, list):
            raise RpcError("internal", "The Task Creator's reply holds no list of tasks.")
        return tasks

    def launch(self, task: str) -> dict:
        """Start the task named `task` on this client's robot, as the Launcher's button does:
        {"task", "program", "robot"}. Raises RpcError "bad_request" for a task that does not
        exist, "busy" while a program runs, "unavailable" when the robot is not connected."""
        reply = self._call("launch", task=task, robot=self._opened())
        return {"task": reply["task"], "program": reply["program"], "robot": reply["robot"]}

    def stop(self) -> None:
        """Stop the running program, if any."""
        self._call("stop")

    def status(self) -> dict:
        """The program runner's state: {"program", "robot", "pid", "running", "started", "last"},
        `last` saying how the previous run ended."""
        return self._call("status")


class VoiceClient(_ServiceClient):
    """The voice service's verbs (one voice service on a machine, so they name no robot):
    `voice = VoiceClient(); voice.learn("give me the red can", source="web-1")`. The first call
    connects (Unavailable when the service does not run)."""

    _probe, _service = "status", "voice"
    #: How much longer than its listening `learn` waits for the answer, s.
    LEARN_MARGIN = 10.0

    @classmethod
    def on(cls, bus: Bus, timeout: float = CALL_TIMEOUT) -> Self:
        """A client over a bus its caller owns (the web's), without waiting for the service."""
        client = cls(timeout=timeout)
        client._bus, client._owns_bus = bus, False
        return client

    def _key(self, verb: str) -> str:
        return keys.voice_rpc(verb)

    def status(self) -> dict:
        """The words listened for, the sources heard, the settings and the words learned."""
        return self._call("status")

    def settings(self, confirm: bool | None = None) -> bool:
        """Whether a task heard is first confirmed by a yes ("Shall I start ...?"), changed first
        when `confirm` is given (kept in the user's data folder)."""
        return self._call("settings", confirm=confirm)["confirm"]

    def learn(self, word: str, *, source: str, seconds: float = LISTEN_SECONDS) -> dict:
        """Learn how the user says `word` from the next thing said on the live audio `source`
        (a page's microphone: "web-<page id>") within `seconds`: {"phrase", "phones", "sayings" kept,
        "matched" (would the recogniser have heard it already), "heard", "dropped", "seconds"}.
        RpcError "timeout" when nothing was said."""
        return self._without_ok(self._call("learn", self.LEARN_MARGIN + seconds, word=word, source=source,
                                        seconds=seconds))

    def learn_recording(self, word: str, data: bytes, rate: int, sample: str = "int16", channels: int = 1) -> dict:
        """Learn how the user says `word` from a recording of it (the AudioChunk fields; quiet
        around the word, a few seconds at most), as `learn` answers."""
        return self._without_ok(self._call("learn", self.LEARN_MARGIN, word=word, data=data, rate=rate,
                                        sample=sample, channels=channels))

    def forget(self, word: str) -> dict:
        """Forget the user's own pronunciations of `word` (the dictionary's stay): {"phrase",
        "forgotten": how many}."""
        return self._without_ok(self._call("forget", word=word))

    def learned(self, words: Sequence[str] = ()) -> dict:
        """{"words": {phrase: [phones, ...]}, "phrases": {word: phrase}}: every phrase learned by
        saying it, and the phrase each of the user's `words` is learned under."""
        return self._without_ok(self._call("learned", words=list(words)))

    @staticmethod
    def _without_ok(reply: dict) -> dict:
        return {k: v for k, v in reply.items() if k != "ok"}


class NavClient(_Client):
    """The nav service's verbs for a mobile robot:
    `base = NavClient("pioneer-sim"); base.goto("fridge"); base.wait()`.

    `goto`, `drive`, `turn` and `primitive` start the motion and return at once (a new one
    replaces the running one); `wait` blocks until it ends and raises RpcError with the
    server's sentence when it did not end where asked ("could not reach fridge: ...")."""

    _probe, _service = "status", "nav"

    class Trip(TypedDict):
        """A goal just started: its id, the place's name as nav knows it ("" for a pose), the
        goal [x, y, theta] (m, m, rad, map frame) and the sentence."""
        goal_id: int
        place: str
        goal: list[float]
        text: str

    class Result(TypedDict):
        """How a goal goes or ended: its state ("active", "succeeded", "aborted", "canceled",
        "preempted", or "idle" before any goal), the sentence, the distance left (m) and the
        recoveries tried."""
        goal_id: int
        state: str
        text: str
        place: str
        distance: float
        recoveries: int

    class Place(TypedDict):
        """A named place as nav keeps it: its name (tidied: single spaces) and pose [x, y, theta]."""
        name: str
        pose: list[float]

    class Levels(TypedDict):
        """The primitives' speed and width levels (1 to 5) and the sentence that says them."""
        text: str
        speed: int
        width: int

    def _key(self, verb: str) -> str:
        return keys.nav_rpc(self._opened(), verb)

    def goto(self, target: str | Sequence[float]) -> int:
        """Go to a named place ("fridge") or a pose (x, y, theta in m, m, rad, map frame);
        returns the goal's id at once."""
        return self.goto_reply(target)["goal_id"]

    def goto_reply(self, target: str | Sequence[float]) -> Trip:
        """`goto`, answering the whole Trip (what a page shows), not only the goal's id."""
        if isinstance(target, str):
            return cast(NavClient.Trip, self._call("goto", place=target))
        return cast(NavClient.Trip, self._call("goto", pose=list(target)))

    def wait(self, goal_id: int | None = None, timeout: float | None = None) -> dict:
        """Block until goal `goal_id` (default: whatever drives the base now) ends; its result
        {"state", "text", ...}. Raises RpcError when it did not succeed: "unreachable" when it
        was aborted, "busy" when it was canceled or replaced; Timeout after `timeout` s (the
        motion goes on: call cancel() to stop it)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            r = self._call("result", goal_id=goal_id) if goal_id is not None else self._call("status")
            if r["state"] not in ("active", "idle") or (r["state"] == "idle" and goal_id is None):
                break
            if deadline is not None and time.monotonic() >= deadline:
                raise Timeout(f"The robot was still on its way after {timeout:g} s ({r['text']}); it goes on.")
            time.sleep(WAIT_POLL)
        if r["state"] in ("succeeded", "idle"):
            return r
        code = "unreachable" if r["state"] == "aborted" else "estop" if "emergency stop" in r["text"] else "busy"
        raise RpcError(code, r["text"][:1].upper() + r["text"][1:])

    def cancel(self, goal_id: int | None = None) -> Result:
        """Cancel the running goal (or `goal_id`, if it is the one running); how it ended."""
        return cast(NavClient.Result, self._call("cancel", goal_id=goal_id))

    def stop(self) -> None:
        """Stop whatever drives the base: a goal or a primitive."""
        self._call("primitive", name="stop")

    def status(self) -> dict:
        """The latest goal's or drive's state and sentence, and the robot's pose."""
        return self._call("status")

    def pose(self) -> list[float]:
        """Where the robot believes it is: x, y, theta (m, m, rad, map frame)."""
        return self._call("status")["pose"]

    def places(self) -> dict[str, list[float]]:
        """The named places: name -> [x, y, theta]."""
        return {p["name"]: p["pose"] for p in self._call("places")["places"]}

    def save_place(self, name: str, pose: Sequence[float] | None = None, replace: bool = False) -> list[float]:
        """Save a place where the robot stands (or at `pose`); `replace` moves an existing one.
        Its pose."""
        return self.save_place_reply(name, pose, replace)["pose"]

    def save_place_reply(self, name: str, pose: Sequence[float] | None = None, replace: bool = False) -> Place:
        """`save_place`, answering the Place as nav keeps it (its name tidied), not only its pose."""
        return cast(NavClient.Place, self._call("save_place", name=name, pose=pose, replace=replace or None))

    def rename_place(self, name: str, new_name: str) -> Place:
        """Give place `name` (any case and spacing) the name `new_name`; the place renamed."""
        return cast(NavClient.Place, self._call("rename_place", name=name, new_name=new_name))

    def remove_place(self, name: str) -> str:
        """Forget place `name` (any case and spacing); its name as nav knew it."""
        return self._call("remove_place", name=name)["name"]

    def drive(self, distance: float) -> str:
        """Drive straight `distance` m (negative: backwards), stopping before obstacles."""
        return self._call("drive", distance=distance)["text"]

    def turn(self, angle: float) -> str:
        """Turn in place by `angle` degrees (positive: left, counter-clockwise)."""
        return self._call("turn", angle=angle)["text"]

    def primitive(self, name: str, continuous: bool = False) -> str:
        """One of the thesis's driving primitives ("forward", "turn left 90", "curve forward
        left", ...); `continuous` goes on until stop()."""
        return self._call("primitive", name=name, continuous=continuous or None)["text"]

    def settings(self, change: str | None = None) -> Levels:
        """One level "faster", "slower", "wider" or "narrower" (asibot.driving.CHANGES) of the
        primitives' speed or width; without `change`, the levels now."""
        return cast(NavClient.Levels, self._call("settings", change=change))

    def save_position(self) -> list[float]:
        """Remember where the robot stands (one position, apart from the named places); its pose."""
        return self._call("save_position")["pose"]

    def recall_position(self) -> Trip:
        """Go back to the position save_position remembered; the trip started."""
        return cast(NavClient.Trip, self._call("recall_position"))

    def set_pose(self, pose: Sequence[float]) -> None:
        """Tell localisation where the robot is (x, y, theta in m, m, rad, map frame)."""
        self._call("set_pose", pose=list(pose))

    def localize(self) -> str:
        """Find where the robot is: it looks everywhere on the map and turns in place (up to
        twice) until it knows; the status's `localised` and an event say how that went."""
        return self._call("localize")["text"]

    def map_start(self) -> str:
        """Start building a new map where the robot stands; drive it (drive, turn, primitive)
        through every room while it maps. Goals are refused until the map is saved and used."""
        return self._call("map_start")["text"]

    def map_stop(self) -> str:
        """Stop mapping; the map is kept to be saved, and the map in use stays."""
        return self._call("map_stop")["text"]

    def map_save(self, name: str, use: bool = False) -> dict:
        """Save the map built as <name>.yaml + <name>.pgm (ROS map_server) in the user's maps
        folder; `use` makes it the map in use at once. {"yaml", "pgm", "text"}."""
        return self._call("map_save", name=name, use=use or None)


class DriverClient(_Client):
    """The driver contract's verbs of one robot, whoever drives it (the CANopen arm driver, the
    ARCOS base driver or the sim): `status`, and what every client has, `reset_fault` and the
    emergency stop. `DriverClient("asibot").status()["estop"]`."""

    _probe = "status"

    def _key(self, verb: str) -> str:
        return keys.driver_rpc(self._opened(), verb)

    def _not_answering(self) -> str:
        # A driver is one of several services: the sentence names them all, not one `python -m`.
        return (f"No driver answers for robot {self.robot!r}; start its driver (arm_driver, base_driver) "
                "or the sim, e.g. with `asibot up`.")

    def status(self) -> dict:
        """What the driver says of itself ("mode", "fault", "estop", ...), its "robot" and who
        holds each part ("holders")."""
        return self._call("status")


class SimClient(_Client):
    """The simulation's own verbs, for tests and demos: put its world back as it started, move
    an object or the mobile base, ask where an object is.
    `sim = SimClient("asibot-sim"); sim.object_pose("red_can")`. Positions are in m, in the
    world frame; the base's pose in the map frame."""

    _probe, _service = "reset_world", "sim"

    def _key(self, verb: str) -> str:
        return keys.driver_rpc(self._opened(), verb)

    def reset_world(self) -> None:
        """Objects and arm where they started, the base too, odometry at zero."""
        self._call("reset_world")

    def object_pose(self, name: str) -> list[float]:
        """Where object `name` is: [x, y, z]."""
        return self._call("object_pose", name=name)["pos"]

    def set_object_pose(self, name: str, pos: Sequence[float], quat: Sequence[float] | None = None) -> None:
        """Teleport object `name` to `pos` [x, y, z], turned by `quat` [w, x, y, z] (default
        upright); it leaves the gripper first."""
        self._call("set_object_pose", name=name, pos=pos, quat=quat)

    def set_robot_pose(self, pose: Sequence[float]) -> None:
        """Teleport the mobile base to `pose` [x, y, theta] (m, m, rad, map frame): its odometry
        does not see it, as the wheels of a robot carried elsewhere turn not."""
        self._call("set_robot_pose", pose=pose)


def default_robot() -> str:
    """The robot a user program drives: ASIBOT_ROBOT or asibot-sim."""
    return os.environ.get("ASIBOT_ROBOT", "asibot-sim")
