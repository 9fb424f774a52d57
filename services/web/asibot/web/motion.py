"""What the page's buttons do to a robot: jog steps, hold-to-move, moves, stop, estop, gripper.

Every motion goes through the robot's kinematics service with a user program's
`CartesianClient`, over the web's bus, so the web page has no privileges a program lacks and the
controller's checks (limits, reach, estop, the 200 ms watchdog of streamed velocities) apply
to it too. Refusals come back as `RpcError` with the controller's sentence for the page.
A jog step is one `jog` request: the kinematics service keeps the previous step's target, so
steps touched in a row add up there, and this module keeps no state of the arm.

What reaches Motion was checked where it came in: a REST body by its pydantic model
(api_robots.py, api_files.py), a page's message where it is read (page_messages.py), and every
request again by the kinematics service's table of verbs. Motion checks only what none of them
knows: the robot's number of joints and axes, and how the values of a move fit together.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

from asibot.safety import estop
from asibot import robots
from asibot.bus import Bus
from asibot.client import CartesianClient, SimClient
from asibot.errors import RpcError
# The speed levels and a Cartesian step's speed are the kinematics `jog` verb's too.
from asibot.jog import SPEED_LEVELS, STEP_LINEAR_SPEED, axes as jog_axes, speed_fraction
from asibot.safety.estop import who
from asibot.safety.identity import Identity
from asibot.poses import POINT_AXES, POINT_AXIS_MEANINGS
from asibot.web.pointer import DeviceReading, PointerMapping

#: Hold-to-move speeds at the top level: linear m/s, angular deg/s, joint deg/s.
HOLD_LINEAR, HOLD_ANGULAR, HOLD_JOINT = 0.10, 20.0, 20.0
#: The seed's jog steps (WebResponder.hpp): 5 deg a joint, 0.10 m and 15 deg a Cartesian axis.
JOINT_STEP, LINEAR_STEP, ANGULAR_STEP = 5.0, 0.10, 15.0
#: Longest RPC wait for a quick verb, s; the gripper takes up to 1.5 + 4 s to report (kinematics `act`).
CALL_TIMEOUT, GRIP_TIMEOUT = 5.0, 8.0
#: How long putting a simulated world back may take (the sim settles it for a moment), s.
RESET_TIMEOUT = 10.0


@dataclass(frozen=True)
class JogSettings:
    """What the page needs to draw its jog controls; sent once, so no unit lives in JavaScript."""

    speed_levels: tuple[float, ...] = SPEED_LEVELS
    joint_step: float = JOINT_STEP
    linear_step: float = LINEAR_STEP
    angular_step: float = ANGULAR_STEP
    hold_linear: float = HOLD_LINEAR
    hold_angular: float = HOLD_ANGULAR
    hold_joint: float = HOLD_JOINT

    def as_json(self) -> dict[str, Any]:
        return {"speed_levels": list(self.speed_levels), "joint_step_deg": self.joint_step,
                "linear_step_m": self.linear_step, "angular_step_deg": self.angular_step,
                "point_axes": [{"name": n, "unit": u, "meaning": POINT_AXIS_MEANINGS.get(n, "")} for n, u in POINT_AXES]}


class Motion:
    """The robot actions of the web page, each one bus call (or two) to the kinematics service.
    It keeps no state of any robot: what must be remembered between calls, the kinematics
    service remembers."""

    def __init__(self, bus: Bus, settings: JogSettings = JogSettings(), who: str = "web page",
                 pointer: PointerMapping | None = None) -> None:
        self.bus = bus
        self.settings = settings
        self.pointer = pointer or PointerMapping()
        self.who = who
        self.me = Identity("web")      # signs the page's estops and releases (asibot.safety.estop)

    def _arm(self, robot: str, timeout: float = CALL_TIMEOUT) -> CartesianClient:
        return CartesianClient.on(self.bus, robot, timeout)

    def _joints(self, robot: str) -> int:
        try:
            return len(robots.get(robot).joint_names)
        except KeyError:
            raise RpcError("bad_request", f"There is no robot {robot!r}; choose one of {', '.join(robots.ids())}.") from None

    # --- jogging --------------------------------------------------------------------------
    def step_joint(self, robot: str, joint: int, direction: int, level: int, step: float | None = None) -> dict:
        """Move one joint (0 for the first) by one step, deg: one `jog` of the kinematics
        service, which adds it to the previous step's target while that one still moves."""
        n = self._joints(robot)
        if not 0 <= joint < n:   # the arm's size, which no request model knows
            raise RpcError("bad_request", f"The joint must be 0 to {n - 1} (this arm has {n}); got {joint!r}.")
        delta = direction * (self.settings.joint_step if step is None else step)
        return self._arm(robot).jog(jog_axes(n)[joint], delta, level)

    def step_axis(self, robot: str, axis: int, direction: int, level: int, step: float | None = None) -> dict:
        """Move the tool one step along (or about) one axis of the point: one `jog` of the
        kinematics service (a movl), which adds it to the previous step's target while that
        one still moves."""
        if not 0 <= axis < len(POINT_AXES):   # the REST model takes any whole number
            raise RpcError("bad_request", f"The axis must be 0 to {len(POINT_AXES) - 1} (x, y, z, rot(y'), rot(z'')); got {axis!r}.")
        if step is None:
            step = self.settings.linear_step if axis < 3 else self.settings.angular_step
        return self._arm(robot).jog(POINT_AXES[axis][0], direction * step, level)

    def hold_velocity(self, space: str, axis: int, direction: int, level: int, n_joints: int) -> list[float]:
        """The velocity one held jog button streams: one axis (or joint) at the level's speed.
        The page's message was checked once, where it was read (asibot.web.page_messages.Hold)."""
        size = n_joints if space == "joint" else len(POINT_AXES)
        if space == "joint":
            top = self.settings.hold_joint
        else:
            top = self.settings.hold_linear if axis < 3 else self.settings.hold_angular
        v = [0.0] * size
        v[axis] = direction * top * speed_fraction(level)
        return v

    def hold(self, robot: str, space: str, axis: int, direction: int, level: int) -> None:
        """One beat of hold-to-move: the page repeats it while the button is held; when the
        beats stop (pointer up, blur, tab closed, network lost) the controller's watchdog stops
        the arm within 200 ms, and the page also sends `stop` at once."""
        v = self.hold_velocity(space, axis, direction, level, self._joints(robot))
        if space == "joint":
            self._arm(robot).movjv(v)
        else:
            self._arm(robot).movv(v)

    def point(self, robot: str, reading: DeviceReading, tool_pitch: float | None) -> None:
        """One reading of a handheld pointer (asibot.web.pointer): the arm follows it while the
        dead-man and a direction are on, and holds still (a `pointer` with the dead-man off, which
        ends the stream at once) otherwise. A bad report never gets here: the page's message
        is refused where it is read, and the refusal stops the pointer's stream."""
        request = self.pointer.request(reading, tool_pitch)
        self._arm(robot).pointer(**(request or {"deadman": False}))

    # --- moves ----------------------------------------------------------------------------
    def move(self, robot: str, kind: str, values: Sequence[float], *, relative: bool = False,
             joints: bool = False, level: int = 3) -> dict:
        """The seed's movj/movl forms (`kind`): to a point (or joints) or by an offset from here;
        {"duration": s}. The kinematics service checks every value; what is checked here is
        how the request's parts fit together, which no request model says."""
        arm, fraction = self._arm(robot), speed_fraction(level)
        if joints:
            if kind != "movj":
                raise RpcError("bad_request", "Joint values move with movj; movl takes a point.")
            if relative:
                return {"duration": arm.relj(values, speed=fraction)}
            return {"duration": arm.movj(joints=values, speed=fraction)}
        if relative:
            here = arm.stat()
            if len(values) != len(here):   # zip would drop the extra numbers silently
                raise RpcError("bad_request", f"An offset needs {len(here)} numbers; got {len(values)}.")
            values = [a + b for a, b in zip(here, values)]
        if kind == "movl":
            return {"duration": arm.movl(values, speed=STEP_LINEAR_SPEED * fraction)}
        return {"duration": arm.movj(values, speed=fraction)}

    def inverse(self, robot: str, point: Sequence[float]) -> list[float]:
        """Joints (deg) that put the tool at `point`; nothing moves."""
        return self._arm(robot).inv(point)

    def home(self, robot: str, level: int = 3) -> dict:
        return {"duration": self._arm(robot).home(speed=speed_fraction(level))}

    def stop(self, robot: str) -> dict:
        self._arm(robot).stop()
        return {}

    def grip(self, robot: str, close: bool) -> dict:
        """{"opening": m, "holding": bool} once the fingers have stopped."""
        return self._arm(robot, GRIP_TIMEOUT).act("close" if close else "open")

    # --- safety ---------------------------------------------------------------------------
    def estop(self, robot: str) -> None:
        """Engage the robot's emergency stop (latched: it holds after this server exits)."""
        estop.latch(self.bus, robot, self.me, True, f"emergency stop from the {self.who}",
                    who(f"the {self.who}", login_of=self.bus.name))

    def release(self, robot: str) -> None:
        estop.latch(self.bus, robot, self.me, False, f"released from the {self.who}",
                    who(f"the {self.who}", login_of=self.bus.name))

    def reset_fault(self, robot: str) -> dict:
        return self._arm(robot).reset_fault()

    def reset_world(self, robot: str) -> None:
        """Put a simulated robot's world back as it started (objects, arm, base); a real robot
        has no world to put back, and says so."""
        world = robots.get(robot).world if robot in robots.ids() else ""
        if not world:
            raise RpcError("bad_request", f"{robot} is a real robot: there is no simulated world to put back.")
        SimClient.on(self.bus, robot, RESET_TIMEOUT).reset_world()
