"""The kinematics service for one robot: RPC verbs on cart/rpc/<verb>, a control loop that
sends joint references with velocity feed-forward on arm/command, and cart/state.

User-facing points, joints and tool frames are in the seed's units (m and deg,
docs/asibot-conventions.md "Kinematics") and are converted to SI here, at the edge; the
Controller and the bus messages are SI only.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from typing import Any, Callable

import numpy as np

from asibot import keys
from asibot.errors import RpcError
from asibot.messages import ArmCommand, ArmState, CartState, EStop, Event, GripperCommand, GripperState
from asibot.runtime import Service
from asibot.timing import Ticker

from .controller import MOVV, POINTER, Controller
from .pointer import PointerInput, pointer_velocity

log = logging.getLogger(__name__)

#: cart/state rate, Hz (the web UI needs 20 Hz or more; the seed streamed FK every 20 ms,
#: docs/asibot-conventions.md "Control states").
STATE_RATE = 50.0
#: Longest a single `wait` RPC blocks; the client loops for longer waits.
MAX_WAIT = 10.0
#: Longest `act` waits for the fingers to stop, s (a full stroke takes about 1 s).
GRIP_TIMEOUT = 3.0
#: The fingers have stopped when they moved less than this (m) during GRIP_STILL seconds.
GRIP_STILL_M, GRIP_STILL = 0.0005, 0.3
#: How long a request waits for the arm driver to show up before refusing, s: just after
#: `asibot up` the driver's first state may be a moment behind the first user command.
DRIVER_GRACE = 2.0
#: Verbs that need a live driver and its measured joints.
NEEDS_DRIVER = ("stat", "movj", "movl", "movv", "relj", "home", "pointer")


def numbers(req: dict, name: str, size: int) -> np.ndarray:
    """A list of `size` finite numbers from the request, or bad_request naming the field."""
    value = req.get(name)
    if not isinstance(value, (list, tuple)) or len(value) != size or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value):
        raise RpcError("bad_request", f"'{name}' must be a list of {size} finite numbers; got {value!r}.")
    return np.asarray(value, float)


def optional_number(req: dict, name: str) -> float | None:
    value = req.get(name)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise RpcError("bad_request", f"'{name}' must be a positive number; got {value!r}.")
    return float(value)


class KinematicsServer(Service):
    """Wires one Controller to the bus. `model` and `spec` come from the robot catalog."""

    def __init__(self, bus: Any, robot: str, model: Any, spec: Any, rate: float = 100.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not rate > 0:
            raise ValueError("--rate must be positive (Hz)")
        self.bus, self.robot, self.model, self.spec = bus, robot, model, spec
        self.rate, self.clock = rate, clock
        self.ctl = Controller(model, spec)
        self.n = len(spec.joint_names)
        self._stop = threading.Event()
        self.ticker = Ticker(rate, stop=self._stop)
        self.cmd_pub = bus.publisher(keys.arm_command(robot), ArmCommand, express=True)  # no batching: latency
        self.state_pub = bus.publisher(keys.cart_state(robot), CartState)
        self.grip_pub = bus.publisher(keys.gripper_command(robot), GripperCommand)
        self.events = bus.publisher(keys.events(robot), Event)
        bus.subscribe(keys.arm_state(robot), ArmState, self._on_arm_state)
        bus.subscribe(keys.estop(robot), EStop, self._on_estop, latest=True)
        self._grip: GripperState | None = None
        self._grip_changed = threading.Condition()
        bus.subscribe(keys.gripper_state(robot), GripperState, self._on_gripper)
        bus.watch(keys.driver_alive(robot), self._on_driver)
        verbs = {"stat": self.stat, "inv": self.inv, "fwd": self.fwd, "movj": self.movj, "movl": self.movl,
                 "movv": self.movv, "relj": self.relj, "stop": self.stop, "wait": self.wait,
                 "tool": self.tool, "act": self.act, "home": self.home, "pointer": self.pointer}
        for verb, handler in verbs.items():
            bus.serve(keys.cart_rpc(robot, verb), self._after_driver(handler) if verb in NEEDS_DRIVER else handler)
        bus.announce(keys.controller_alive(robot))
        self._loop = threading.Thread(target=self._run, name="control-loop", daemon=True)
        self._loop.start()

    def _after_driver(self, handler: Callable[[dict], dict]) -> Callable[[dict], dict]:
        def run(req: dict) -> dict:
            deadline = time.monotonic() + DRIVER_GRACE
            while not (self.ctl.driver_alive and self.ctl.q is not None) and time.monotonic() < deadline:
                time.sleep(0.02)
            return handler(req)
        return run

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
        if not alive:
            text = "The arm driver disappeared" + ("; the motion was stopped." if was_moving else ".")
            log.warning(text)
            self.events.put(Event(level="error" if was_moving else "warning", code="driver_lost", text=text))

    # --- the loop -----------------------------------------------------------------------
    def _send(self) -> None:
        """One control step: the reference for now, if any, goes to the driver."""
        ref = self.ctl.tick(self.clock())
        if ref is not None and self.ctl.driver_alive:
            self.cmd_pub.put(ArmCommand(mode="position", values=ref.positions, velocities=ref.velocities))

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
    def _point_in(self, req: dict, name: str = "point") -> np.ndarray:
        return np.asarray(self.model.from_user_point(numbers(req, name, self.model.pose_size)), float)

    def _point_out(self, pose: np.ndarray) -> list[float]:
        return [float(v) for v in self.model.to_user_point(np.asarray(pose, float))]

    def _joints_in(self, req: dict, name: str = "joints") -> np.ndarray:
        return np.radians(numbers(req, name, self.n))

    def _describe(self, pose: np.ndarray) -> str:
        return "[" + ", ".join(f"{v:.3f}" for v in self._point_out(pose)) + "]"

    def _measured(self) -> np.ndarray:
        if self.ctl.q is None:
            raise RpcError("unavailable", "No arm state received yet; start the driver or the sim for "
                                          f"{self.robot}.")
        return self.ctl.q.copy()

    # --- verbs --------------------------------------------------------------------------
    def stat(self, req: dict) -> dict:
        q = self._measured()
        return {"state": self.ctl.state, "point": self._point_out(self.model.fwd(q)),
                "joints": np.degrees(q).tolist(), "estop": self.ctl.estop, "fault": self.ctl.fault}

    def inv(self, req: dict) -> dict:
        pose = self._point_in(req)
        guess = self.ctl.q if self.ctl.q is not None else np.zeros(self.n)
        return {"joints": np.degrees(self.model.inv(pose, guess)).tolist()}

    def fwd(self, req: dict) -> dict:
        return {"point": self._point_out(self.model.fwd(self._joints_in(req)))}

    def movj(self, req: dict) -> dict:
        """Joint-space move to a point (via IK) or to joints (deg)."""
        if ("point" in req) == ("joints" in req):
            raise RpcError("bad_request", "movj needs either 'point' [x, y, z, rot(y'), rot(z'')] or 'joints' (deg).")
        if "point" in req:
            pose = self._point_in(req)
            q = np.asarray(self.model.inv(pose, self._measured()), float)
        else:
            q = self._joints_in(req)
        return self._movj_to(q, req)

    def _movj_to(self, q: np.ndarray, req: dict) -> dict:
        T = self.ctl.movj(q, self.clock(), duration=optional_number(req, "duration"),
                          speed=optional_number(req, "speed"))
        self._send()
        return {"duration": T}

    def relj(self, req: dict) -> dict:
        return self._movj_to(self._measured() + self._joints_in(req), req)

    def home(self, req: dict) -> dict:
        return self._movj_to(np.asarray(self.spec.home, float), req)

    def movl(self, req: dict) -> dict:
        pose = self._point_in(req)
        T = self.ctl.movl(pose, self.clock(), duration=optional_number(req, "duration"),
                          speed=optional_number(req, "speed"), describe=self._describe)
        self._send()
        return {"duration": T}

    def movv(self, req: dict) -> dict:
        """Stream a velocity in user units (m/s, deg/s); repeat within 200 ms to keep moving."""
        v = np.asarray(self.model.from_user_point(numbers(req, "velocity", self.model.pose_size)), float)
        self.ctl.stream(v, self.clock(), MOVV)
        self._send()
        return {}

    def pointer(self, req: dict) -> dict:
        cmd = PointerInput.from_request(req)
        if not cmd.deadman:
            if self.ctl.state == POINTER:
                self.ctl.stop()
                self._send()
            return {"state": self.ctl.state}
        if self.model.pose_size != 5:
            raise RpcError("bad_request", "The pointer mode needs the ASIBOT 5-element pose.")
        pose = np.asarray(self.model.fwd(self._measured()), float)
        self.ctl.stream(pointer_velocity(pose, cmd), self.clock(), POINTER)
        self._send()
        return {"state": self.ctl.state}

    def stop(self, req: dict) -> dict:
        self.ctl.stop()
        self._send()
        return {}

    def wait(self, req: dict) -> dict:
        """Wait for the planned motion (movj/movl) to end, at most MAX_WAIT s per call.

        Replies done=False if it is still running; raises the reason if it ended early.
        """
        timeout = optional_number(req, "timeout") or MAX_WAIT
        done = self.ctl.wait(min(timeout, MAX_WAIT))
        if done and self.ctl.outcome is not None:
            raise self.ctl.outcome
        return {"done": done, "state": self.ctl.state}

    def tool(self, req: dict) -> dict:
        """Attach a tool frame (the seed's `tool`): 'tool' is [x, y, z, rx, ry, rz] in m and deg,
        the offset and rotation vector (axis times angle) of the tool point from the flange
        (the ASIBOT) or the approach frame (other arms). Absent, null or all zeros removes it."""
        tool = req.get("tool")
        if tool is None:
            self.model.set_tool(None)
            return {}
        try:
            tool = numbers(req, "tool", 6)  # user units, like points
        except RpcError:
            raise RpcError("bad_request", "'tool' must be [x, y, z, rx, ry, rz] in m and deg (6 finite numbers), "
                                          f"or null to remove it; got {req['tool']!r}.") from None
        self.model.set_tool(tool[:3].tolist() + np.radians(tool[3:]).tolist())
        return {}

    def act(self, req: dict) -> dict:
        """Gripper: action "open" or "close" (the seed's acog/accg). Returns once the fingers
        stop, at the end of their stroke or on an object, with the opening and whether the
        gripper holds something, so a program can check its grasp."""
        action = req.get("action")
        if action not in ("open", "close"):
            raise RpcError("bad_request", f"'action' must be open or close; got {action!r}.")
        if self.ctl.estop:
            raise RpcError("estop", "The emergency stop is engaged; release it before using the gripper.")
        with self._grip_changed:
            # Just after start-up the first report may still be on its way.
            self._grip_changed.wait_for(lambda: self._grip is not None, timeout=1.0)
            if self._grip is None:
                raise RpcError("unavailable", f"No gripper reports for {self.robot}: its driver has no "
                                              "gripper, or is not running.")
        opening = float(self.spec.gripper_max_opening) if action == "open" else 0.0
        self.grip_pub.put(GripperCommand(opening=opening))
        state = self._gripper_settled(opening)
        return {"opening": state.opening, "holding": state.holding}

    def _gripper_settled(self, target: float) -> GripperState:
        """The gripper state once the fingers reach `target` or stop moving (on an object)."""
        start = time.monotonic()
        window: list[tuple[float, float]] = []
        with self._grip_changed:
            while True:
                self._grip_changed.wait(0.05)
                now, state = time.monotonic(), self._grip
                window = [(t, o) for t, o in window if now - t <= GRIP_STILL] + [(now, state.opening)]
                spread = max(o for _, o in window) - min(o for _, o in window)
                if abs(state.opening - target) < 0.002 or now - start > GRIP_TIMEOUT:
                    return state
                if now - start > GRIP_STILL and spread < GRIP_STILL_M:
                    return state

    # --- lifecycle ----------------------------------------------------------------------
    def health(self) -> dict:
        return {"state": self.ctl.state, "driver": self.ctl.driver_alive, "jitter": self.ticker.stats()}

    def close(self) -> None:
        self.ctl.stop()
        self._stop.set()
        self._loop.join(timeout=1.0)
