"""The kinematics service for one robot: RPC verbs on cart/rpc/<verb>, a control loop that
sends joint references with velocity feed-forward on arm/command, and cart/state.

User-facing points, joints and tool frames are in the seed's units (m and deg,
docs/asibot-conventions.md "Kinematics") and are converted to SI here, at the edge; the
Controller and the bus messages are SI only.

Every request is checked by one table, asibot.kinematics.requests: the server serves exactly
its verbs, and each handler receives the checked arguments (a namespace), never the raw map.
A movj or movl is planned without holding the controller (see asibot.kinematics.controller),
so `stop`, `stat` and cart/state are answered while a long path is checked. A `jog` step is a
movj or movl whose target the controller keeps while it runs, so that steps touched in a row
add up here, in the service that moves the arm, whoever sends them.

The server is the controller of the arm and gripper of its robot (asibot.safety.ownership): it
announces itself with a new identity at every start, and every command it sends carries it.
It keeps the estop state served after its sender exits (asibot.safety.estop), so a driver restarted
meanwhile learns it.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from typing import Any, Callable

import numpy as np

from asibot import keys, verbs
from asibot.jog import STEP_LINEAR_SPEED, axes as jog_axes, speed_fraction
from asibot.safety import ownership
from asibot.errors import RpcError
from asibot.safety.estop import EStopState
from asibot.messages import ArmCommand, ArmState, CartState, EStop, Event, GripperCommand, GripperState
from asibot.runtime import Service
from asibot.timing import Ticker
from asibot.verbs import Verb

from . import requests
from .controller import MOVJ, MOVJV, MOVL, MOVV, POINTER, Controller
from .pointer import PointerInput, pointer_motion
from .requests import MAX_WAIT

log = logging.getLogger(__name__)

#: cart/state rate, Hz (the web UI needs 20 Hz or more; the seed streamed FK every 20 ms,
#: docs/asibot-conventions.md "Control states").
STATE_RATE = 50.0
#: Longest `act` waits for the fingers to start moving after its command, s: a loaded
#: machine or a slow driver may take a while to pass the command on.
GRIP_START_TIMEOUT = 1.5
#: Longest `act` waits in all for the fingers to move and stop, s (a full stroke takes about
#: 1 s); below the client's 5 s call timeout, so the caller gets the server's sentence.
GRIP_TIMEOUT = 4.0
#: The fingers move when they moved more than this (m) from where they were at the command,
#: and have stopped when they moved less than this during GRIP_STILL seconds.
GRIP_STILL_M, GRIP_STILL = 0.0005, 0.3
#: The fingers are at their target within this, m.
GRIP_AT_TARGET = 0.002
#: How long a request waits for the arm driver to show up before refusing, s: just after
#: `asibot up` the driver's first state may be a moment behind the first user command.
DRIVER_GRACE = 2.0


class KinematicsServer(Service):
    """Wires one Controller to the bus. `model` and `spec` come from the robot catalog."""

    def __init__(self, bus: Any, robot: str, model: Any, spec: Any, rate: float = 100.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not rate > 0:
            raise ValueError("--rate must be positive (Hz)")
        self.bus, self.robot, self.model, self.spec = bus, robot, model, spec
        self.rate, self.clock = rate, clock
        self.ctl = Controller(model, spec, started=clock())
        #: This controller's identity, which signs every command it sends (asibot.safety.ownership).
        self.me = ownership.Controller(robot, "arm", "kinematics")
        self.controller = self.me.id
        self.n = len(spec.joint_names)
        #: The names of the jog's axes: the n joints, then the point's coordinates.
        self._jog_axes = jog_axes(self.n)
        #: One jog step at a time: each adds to the target of the one before.
        self._jog_lock = threading.Lock()
        self._stop = threading.Event()
        self.ticker = Ticker(rate, stop=self._stop)
        self.cmd_pub = bus.publisher(keys.arm_command(robot), ArmCommand, express=True)  # no batching: latency
        self.state_pub = bus.publisher(keys.cart_state(robot), CartState)
        self.grip_pub = bus.publisher(keys.gripper_command(robot), GripperCommand)
        self.events = bus.publisher(keys.events(robot), Event)
        bus.subscribe(keys.arm_state(robot), ArmState, self._on_arm_state)
        self.estop = EStopState(bus, robot, self._on_estop)
        self._grip: GripperState | None = None
        self._grip_changed = threading.Condition()
        bus.subscribe(keys.gripper_state(robot), GripperState, self._on_gripper)
        #: Before the first motion for each driver: wait until it names us the holder.
        self.hold = ownership.HoldWait(bus, robot, "arm", self.controller)
        bus.watch(keys.driver_alive(robot), self._on_driver)
        # The table of requests is the list of verbs: each is served by the method of its name,
        # which receives the checked arguments.
        self.verbs = requests.verbs(self.n)
        verbs.serve(bus, lambda verb: keys.cart_rpc(robot, verb), self.verbs,
                    {verb: getattr(self, verb) for verb in self.verbs}, before=self._before)
        self.me.announce(bus)
        self._loop = threading.Thread(target=self._run, name="control-loop", daemon=True)
        self._loop.start()

    def _before(self, verb: str, spec: Verb, args: object) -> None:
        """Before a verb that needs the driver: wait a moment for it and for its holder."""
        if spec.needs_driver:
            deadline = time.monotonic() + DRIVER_GRACE
            while not (self.ctl.driver_alive and self.ctl.q is not None) and time.monotonic() < deadline:
                time.sleep(0.02)
            self.hold.wait(deadline)

    # --- bus inputs ---------------------------------------------------------------------
    def _on_arm_state(self, msg: ArmState) -> None:
        self.ctl.on_arm_state(msg.positions, msg.fault)

    def _on_estop(self, msg: EStop) -> None:
        self.ctl.on_estop(msg.engaged, msg.reason)

    def _on_gripper(self, msg: GripperState) -> None:
        with self._grip_changed:
            self._grip = msg
            self._grip_changed.notify_all()

    def _on_driver(self, key: str, alive: bool) -> None:
        was_moving = self.ctl.state != "not_controlling"
        self.ctl.on_driver(alive)
        self.hold.forget()    # a driver that comes (back) learns who holds the arm anew
        if not alive:
            text = "The arm driver disappeared" + ("; the motion was stopped." if was_moving else ".")
            log.warning(text)
            self.events.put(Event(level="error" if was_moving else "warning", code="driver_lost", text=text))

    # --- the loop -----------------------------------------------------------------------
    def _send(self) -> None:
        """One control step: the reference for now, if any, goes to the driver."""
        ref = self.ctl.tick(self.clock())
        if ref is not None and self.ctl.driver_alive:
            self.me.put(self.cmd_pub, ArmCommand(mode="position", values=ref.positions,
                                                 velocities=ref.velocities))

    def _run(self) -> None:
        every = max(1, int(round(self.rate / STATE_RATE)))
        for i, _ in enumerate(self.ticker):
            try:
                self._send()
                if i % every == 0 and self.ctl.q is not None:
                    q = self.ctl.q
                    self.state_pub.put(CartState(state=self.ctl.state, pose=np.asarray(self.model.fwd(q)).tolist(),
                                                 joints=q.tolist()))
            except Exception:
                log.exception("control tick failed; holding")

    # --- unit conversion at the edge ----------------------------------------------------
    def _point_in(self, point: np.ndarray) -> np.ndarray:
        return np.asarray(self.model.from_user_point(point), float)

    def _point_out(self, pose: np.ndarray) -> list[float]:
        return [float(v) for v in self.model.to_user_point(np.asarray(pose, float))]

    def _describe(self, pose: np.ndarray) -> str:
        return "[" + ", ".join(f"{v:.3f}" for v in self._point_out(pose)) + "]"

    def _measured(self) -> np.ndarray:
        if self.ctl.q is None:
            raise RpcError("unavailable", "No arm state received yet; start the driver or the sim for "
                                          f"{self.robot}.")
        return self.ctl.q.copy()

    # --- verbs: each takes the arguments checked by its entry in requests.verbs ----------
    def stat(self, a: Any) -> dict:
        q = self._measured()
        return {"state": self.ctl.state, "point": self._point_out(self.model.fwd(q)),
                "joints": np.degrees(q).tolist(), "estop": self.ctl.estop, "fault": self.ctl.fault}

    def inv(self, a: Any) -> dict:
        guess = self.ctl.q if self.ctl.q is not None else np.zeros(self.n)
        return {"joints": np.degrees(self.model.inv(self._point_in(a.point), guess)).tolist()}

    def fwd(self, a: Any) -> dict:
        return {"point": self._point_out(self.model.fwd(np.radians(a.joints)))}

    def movj(self, a: Any) -> dict:
        """Joint-space move to a point (via IK) or to joints (deg)."""
        if (a.point is None) == (a.joints is None):
            raise RpcError("bad_request", "movj needs either 'point' [x, y, z, rot(y'), rot(z'')] or 'joints' (deg).")
        if a.point is not None:
            q = np.asarray(self.model.inv(self._point_in(a.point), self._measured()), float)
        else:
            q = np.radians(a.joints)
        return self._movj_to(q, a)

    def _movj_to(self, q: np.ndarray, a: Any) -> dict:
        return self._start(self.ctl.plan_movj(q, duration=a.duration, speed=a.speed))

    def _start(self, planned: Any) -> dict:
        """Start a motion planned without the controller's lock, at the time it starts."""
        T = self.ctl.start(planned, self.clock())
        self._send()
        return {"duration": T}

    def relj(self, a: Any) -> dict:
        return self._movj_to(self._measured() + np.radians(a.joints), a)

    def home(self, a: Any) -> dict:
        return self._movj_to(np.asarray(self.spec.home, float), a)

    def movl(self, a: Any) -> dict:
        return self._start(self.ctl.plan_movl(self._point_in(a.point), duration=a.duration, speed=a.speed,
                                              describe=self._describe))

    def movv(self, a: Any) -> dict:
        """Stream a velocity in user units (m/s, deg/s); repeat within 200 ms to keep moving."""
        self.ctl.stream(np.asarray(self.model.from_user_point(a.velocity), float), self.clock(), MOVV)
        self._send()
        return {}

    def movjv(self, a: Any) -> dict:
        """Stream joint velocities in deg/s (hold-to-move of one joint); repeat within 200 ms."""
        self.ctl.stream(np.radians(np.asarray(a.velocity, float)), self.clock(), MOVJV)
        self._send()
        return {}

    def pointer(self, a: Any) -> dict:
        cmd = PointerInput(**vars(a))
        if not cmd.deadman:
            if self.ctl.state == POINTER:
                self.ctl.stop()
                self._send()
            return {"state": self.ctl.state}
        if self.model.pose_size != 5:
            raise RpcError("bad_request", "The pointer mode needs the ASIBOT 5-element pose.")
        pose = np.asarray(self.model.fwd(self._measured()), float)
        velocity, turn = pointer_motion(pose, cmd)
        self.ctl.stream(velocity, self.clock(), POINTER, turn=turn)
        self._send()
        return {"state": self.ctl.state}

    def jog(self, a: Any) -> dict:
        """One jog step (the page's step buttons): `axis` (a joint q1 ... or a coordinate of
        the point) moves by the signed `step` (deg; m for x, y, z) at speed `level`: a movj at
        that fraction of the joints' speeds, or a movl at that fraction of STEP_LINEAR_SPEED.

        Steps add up: a step touched while the previous one still moves goes on from that
        step's target, not from where the arm is (the arm does not stop short), as a pendant's
        jog buttons do; after the end of a step, a stop, the estop or a motion of another verb
        it starts where the arm is. The running motion is stopped and the step starts from
        there, as a movj or movl would after a stop. A step refused (a limit, out of reach, a
        line through a singularity) answers the same sentence as that movj or movl and changes
        nothing: it is checked before the running step is stopped, which goes on to its target.
        Replies the duration and the step's target: `joints` (deg) or `point`."""
        i = self._jog_axes.index(a.axis)
        joint = i < self.n
        fraction = speed_fraction(a.level)
        with self._jog_lock:
            base, running = self.ctl.jog_from(MOVJ if joint else MOVL)
            # The step is added in the user's units, as the page shows the axis.
            if joint:
                user = np.degrees(base)
                user[i] += a.step
                target, speed = np.radians(user), fraction
            else:
                user = np.asarray(self._point_out(base), float)
                user[i - self.n] += a.step
                target, speed = self._point_in(user), STEP_LINEAR_SPEED * fraction
            if running:
                if joint:
                    self.ctl.check_joint_limits(target)
                else:
                    self.ctl.check_line(target, speed=speed, describe=self._describe)
                self.ctl.stop()      # plan_movj/plan_movl refuse "busy" while a motion runs
                self._send()
            planned = (self.ctl.plan_movj(target, speed=speed) if joint
                       else self.ctl.plan_movl(target, speed=speed, describe=self._describe))
            reply = self._start(dataclasses.replace(planned, jog=target))
        return {**reply, ("joints" if joint else "point"): user.tolist()}

    def stop(self, a: Any) -> dict:
        self.ctl.stop()
        self._send()
        return {}

    def wait(self, a: Any) -> dict:
        """Wait for the planned motion (movj/movl) to end, at most MAX_WAIT s per call.

        Replies done=False if it is still running; raises the reason if it ended early.
        """
        done = self.ctl.wait(min(a.timeout, MAX_WAIT))
        if done and self.ctl.outcome is not None:
            raise self.ctl.outcome
        return {"done": done, "state": self.ctl.state}

    def tool(self, a: Any) -> dict:
        """Attach a tool frame (the seed's `tool`): 'tool' is [x, y, z, rx, ry, rz] in m and deg,
        the offset and rotation vector (axis times angle) of the tool point from the flange
        (the ASIBOT) or the approach frame (other arms). Absent, null or all zeros removes it."""
        if a.tool is None:
            self.model.set_tool(None)
        else:
            self.model.set_tool(a.tool[:3].tolist() + np.radians(a.tool[3:]).tolist())
        return {}

    def act(self, a: Any) -> dict:
        """Gripper: action "open" or "close" (the seed's acog/accg). Returns once the fingers
        have moved and stopped, at the end of their stroke or on an object, with the opening
        and whether the gripper holds something, so a program can check its grasp."""
        if self.ctl.estop:
            raise RpcError("estop", "The emergency stop is engaged; release it before using the gripper.")
        with self._grip_changed:
            # Just after start-up the first report may still be on its way.
            self._grip_changed.wait_for(lambda: self._grip is not None, timeout=1.0)
            if self._grip is None:
                raise RpcError("unavailable", f"No gripper reports for {self.robot}: its driver has no "
                                              "gripper, or is not running.")
            before = self._grip
        opening = float(self.spec.gripper_max_opening) if a.action == "open" else 0.0
        self.me.put(self.grip_pub, GripperCommand(opening=opening))
        state = self._gripper_settled(opening, before)
        return {"opening": state.opening, "holding": state.holding}

    def _gripper_settled(self, target: float, before: GripperState) -> GripperState:
        """The gripper state once the fingers, commanded to `target`, have started to move and
        stopped again (at the target or on an object). Not a fixed delay: a loaded machine or a
        slow driver may start the fingers late, and a report that they have not moved yet
        must not pass for "stopped". Answers at once when they are at the target already, or
        closing while they hold something. Refuses with `timeout` when they do not start
        within GRIP_START_TIMEOUT or have not stopped GRIP_TIMEOUT after the command."""
        closing = target < before.opening
        start = time.monotonic()
        moved_at: float | None = None
        window: list[tuple[float, float]] = []
        with self._grip_changed:
            while True:
                self._grip_changed.wait(0.05)
                now, state = time.monotonic(), self._grip
                if state is None:
                    raise RuntimeError("the gripper state was cleared; _on_gripper only ever replaces it")
                if abs(state.opening - target) < GRIP_AT_TARGET:
                    return state
                if self.ctl.estop:  # the driver stops the fingers and refuses their commands
                    raise RpcError("estop", "The emergency stop was engaged while the gripper moved "
                                            f"(opening {state.opening:.3f} m); release it, then try again.")
                if moved_at is None:
                    if closing and state.holding:
                        return state
                    # Towards the target: fingers still finishing an earlier stroke have not started.
                    if (before.opening - state.opening if closing else state.opening - before.opening) > GRIP_STILL_M:
                        moved_at = now
                    elif now - start > GRIP_START_TIMEOUT:
                        raise RpcError("timeout", f"The gripper did not start to move within {GRIP_START_TIMEOUT:g} s "
                                                  f"of the command (opening {state.opening:.3f} m); check its driver, "
                                                  "then try again.")
                    continue
                window = [(t, o) for t, o in window if now - t <= GRIP_STILL] + [(now, state.opening)]
                spread = max(o for _, o in window) - min(o for _, o in window)
                if now - moved_at > GRIP_STILL and spread < GRIP_STILL_M:
                    return state
                if now - start > GRIP_TIMEOUT:
                    raise RpcError("timeout", f"The gripper was still moving {GRIP_TIMEOUT:g} s after the command "
                                              f"(opening {state.opening:.3f} m); check its driver, then try again.")

    # --- lifecycle ----------------------------------------------------------------------
    def health(self) -> dict:
        return {"state": self.ctl.state, "driver": self.ctl.driver_alive, "controller": self.controller,
                "jitter": self.ticker.stats()}

    def close(self) -> None:
        self.ctl.stop()
        self._stop.set()
        self._loop.join(timeout=1.0)
