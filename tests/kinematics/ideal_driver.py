"""An ideal arm driver for tests: an integrator that keeps the driver contract (arm/state at
100 Hz, obeys arm/command in position mode within max velocities, announces driver_alive)."""

from __future__ import annotations

import threading

import numpy as np

from asibot import keys
from asibot.bus import Bus
from asibot.messages import ArmCommand, ArmState, GripperCommand, GripperState
from asibot.timing import Ticker


class IdealDriver:
    def __init__(self, robot: str, spec) -> None:
        self.spec = spec
        self.q = np.asarray(spec.home, float).copy()
        self.target = self.q.copy()
        self.vmax = np.asarray(spec.max_velocity, float)
        self.commands: list[ArmCommand] = []
        self.gripper = 0.0
        self.gripper_target = 0.0
        #: Width of an object between the fingers (m), or None: closing stops on it.
        self.object_width: float | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self.bus = Bus("ideal-driver")
        self.pub = self.bus.publisher(keys.arm_state(robot), ArmState)
        self.grip_pub = self.bus.publisher(keys.gripper_state(robot), GripperState)
        self.bus.subscribe(keys.arm_command(robot), ArmCommand, self._on_command)
        self.bus.subscribe(keys.gripper_command(robot), GripperCommand, self._on_grip)
        self.token = self.bus.announce(keys.driver_alive(robot))
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _on_command(self, cmd: ArmCommand) -> None:
        if cmd.mode == "position" and len(cmd.values) == len(self.q):
            with self._lock:
                self.commands.append(cmd)
                self.target = np.clip(cmd.values, self.spec.lower, self.spec.upper)

    def _on_grip(self, cmd: GripperCommand) -> None:
        self.gripper_target = cmd.opening

    def set_joints(self, q) -> None:
        with self._lock:
            self.q = np.asarray(q, float).copy()
            self.target = self.q.copy()

    def _run(self) -> None:
        ticker = Ticker(100.0, stop=self._stop)
        dt = ticker.period
        for _ in ticker:
            with self._lock:
                step = np.clip(self.target - self.q, -self.vmax * dt, self.vmax * dt)
                self.q = self.q + step
                q, v = self.q.tolist(), (step / dt).tolist()
                # Fingers move at 0.1 m/s and stop on an object.
                floor = self.object_width if self.object_width is not None else 0.0
                target = max(self.gripper_target, floor)
                self.gripper += float(np.clip(target - self.gripper, -0.1 * dt, 0.1 * dt))
                holding = self.object_width is not None and abs(self.gripper - floor) < 1e-6 \
                    and self.gripper_target < floor
            self.pub.put(ArmState(names=list(self.spec.joint_names), positions=q, velocities=v, mode="position"))
            self.grip_pub.put(GripperState(opening=self.gripper, holding=holding))

    def close(self) -> None:
        self._stop.set()
        self.thread.join(timeout=1.0)
        self.bus.close()
