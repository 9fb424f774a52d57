"""The physics core: one MuJoCo world with its robot, obeying the driver contract's rules.

This class knows nothing about Zenoh: the service (service.py) feeds it commands and reads
its state, and tests drive it directly, stepping as fast as the CPU allows. All times are
simulation time (`data.time`), so the 200 ms watchdog means 200 ms of simulated time in
both real-time and fast mode. Thread-safe: every public method takes the lock.

The sim keeps the driver contract's safety rules like a hardware driver, with the same code:
its arm is a GuardedArm (sim/arm.py) and its base a GuardedBase (sim/base.py), on the sim's
clock. Whose commands it obeys is decided by the service (asibot.safety.ownership); after an
estop release, a fault reset or a change of controller, a stream of arm or base commands from
before moves nothing until it pauses for a watchdog period (asibot.safety.arming).
"""

from __future__ import annotations

import math
import queue
import threading

import mujoco
import numpy as np

from asibot import messages as m
from asibot.safety.events import CommandRefused
from asibot.sim import sensors
from asibot.sim.arm import JointLimits, Notice, SimArm
from asibot.sim.base import BaseDrive, Odometer
from asibot.sim.places import load_places
from asibot.sim.scene import WORLDS, Base, Scene, build

ODOM_PERIOD_S = 0.02
GRASP_CHECK_STEPS = 5
GRIP_SLACK_M = 0.002
"""Commanded opening this much below the measured one means the fingers squeeze something."""
CHARGE_RADIUS_M = 0.5


def world_for(robot_id: str) -> str:
    for world, rid in WORLDS.items():
        if rid == robot_id:
            return world
    raise ValueError(f"no simulated world hosts robot {robot_id!r}; use one of {', '.join(WORLDS.values())}")


class Simulation:
    """One world, one robot; step it, command it, read it."""

    def __init__(self, robot_id: str, world: str | None = None, *,
                 odom_noise: tuple[float, float] = (0.02, 0.05), seed: int | None = None) -> None:
        try:  # the catalog, read when a world is built (tests may stand in for it)
            from asibot import robots
        except ImportError as exc:
            raise RuntimeError("the robot catalog asibot.robots (libs/common/asibot/robots.py) is missing; "
                               "the sim loads the arms from it") from exc
        self.robot = robots.get(robot_id)
        self.world = world or world_for(robot_id)
        if WORLDS[self.world] != robot_id:
            raise ValueError(f"world {self.world!r} hosts {WORLDS[self.world]!r}, not {robot_id!r}")
        self.scene: Scene = build(self.world, self.robot)
        self.model = self.scene.model
        self._dt = float(self.model.opt.timestep)      # read 500 times a second: the model's never changes
        self.data = mujoco.MjData(self.model)
        self.lock = threading.RLock()
        self.notices: "queue.SimpleQueue[Notice]" = queue.SimpleQueue()
        self.limits = JointLimits.of(self.robot.joint_names, self.robot.lower, self.robot.upper,
                                     self.robot.max_velocity)
        held = ("the base is stopped, the arm holds its position, and both ignore motion commands until the "
                "stop is released") if self.scene.base else None     # the arm's Event says it for both
        self.arm = SimArm(self.limits, self.robot.home, self._dt, self._notice, clock=lambda: self.time,
                          lock=self.lock, measured=lambda: self.data.qpos[self.scene.arm_qpos],
                          max_opening=self.scene.gripper.max_opening, held=held)
        self.base = BaseDrive(self._notice, clock=lambda: self.time) if self.scene.base else None
        self.odom = Odometer(noise=odom_noise, seed=seed) if self.scene.base else None
        self.battery = sensors.Battery()
        self.places = load_places(self.world)
        self._odom_acc = 0.0
        self._odom_vx = self._odom_wz = 0.0       # sums over the odometry period
        self._steps = 0
        self.reset_world()

    # ------------------------------------------------------------------ setup
    @property
    def dt(self) -> float:
        return self._dt

    @property
    def time(self) -> float:
        return float(self.data.time)

    @property
    def estop(self) -> bool:
        return self.arm.estop

    def reset_world(self) -> None:
        """Everything back to the MJCF's initial state, arm at home, odometry at zero."""
        with self.lock:
            mujoco.mj_resetData(self.model, self.data)
            home = np.clip(np.asarray(self.robot.home, float), self.limits.lower, self.limits.upper)
            self.data.qpos[self.scene.arm_qpos] = home
            g = self.scene.gripper
            self.arm.gripper_goal = g.max_opening
            self.data.qpos[g.qpos] = g.joint_values(g.max_opening)
            self.data.eq_active[:] = 0
            self.arm.restart(home)
            if self.base is not None:
                self.base.stop()
            if self.odom is not None:
                self.odom.reset()
            self._apply_controls(0.0, 0.0)
            mujoco.mj_forward(self.model, self.data)

    # ------------------------------------------------------------------ commands
    def command_arm(self, cmd: m.ArmCommand) -> bool:
        """Obey an ArmCommand as an arm driver does (asibot.safety.guarded_arm): ValueError or
        CommandRefused (nothing changes) for a bad command, a value beyond a joint's limits or
        max speed, or a stream from before the last recovery; False when ignored (the estop, a fault)."""
        return self.arm.command(cmd.mode, list(cmd.values), list(cmd.velocities), cmd.controller)

    def command_gripper(self, opening: float, controller: str = "") -> bool:
        """Open the fingers to `opening` m (SimArm.command_gripper: an arm driver's gripper)."""
        return self.arm.command_gripper(opening, controller)

    def command_base(self, vx: float, wz: float, controller: str = "") -> bool:
        """As command_arm, for a Twist of `controller` (asibot.safety.guarded_base's rules);
        False when it is ignored (the estop)."""
        with self.lock:
            if self.base is None:
                raise CommandRefused("no_base", f"{self.robot.robot_id} has no mobile base")
            return self.base.command(vx, wz, controller)

    def heard(self, part: str, controller: str) -> None:
        """A command of a controller that does not hold `part` ("arm", "base"; refused by the
        service): noted, so that its stream does not move the part the moment it takes over."""
        if part == "arm":
            self.arm.heard(controller)
        elif self.base is not None:
            self.base.heard(controller)

    def set_estop(self, engaged: bool, reason: str = "", by: str = "") -> None:
        with self.lock:
            released = self.arm.estop and not engaged
            self.arm.set_estop(engaged, reason, by)     # its Event says it for the base too
            if self.base:
                self.base.latch(engaged)
                if released:
                    self.base.recovered("the emergency stop was released" + (f" by {by}" if by else ""))

    def set_controller(self, part: str, holder: str | None) -> None:
        """The controller that holds `part` ("arm", "base") changed (asibot.safety.ownership): stop the
        part if it is moving, and re-arm it for the new holder, if any."""
        with self.lock:
            if part == "arm":
                self.arm.set_controller(holder)
            elif self.base is not None:
                self.base.set_controller(holder)

    def reset_fault(self) -> dict:
        """Clear the arm's fault (asibot.safety.guarded_arm.FaultError when it cannot)."""
        return self.arm.reset_fault()

    def _notice(self, level: str, code: str, text: str) -> None:
        self.notices.put(Notice(level, code, text))

    def set_object_pose(self, name: str, pos: list[float], quat: list[float] | None = None) -> None:
        """Teleport a free object (tests, demos); releases it from the gripper first."""
        with self.lock:
            if name not in self.scene.objects:
                raise KeyError(f"no object {name!r}; objects are {', '.join(self.scene.objects)}")
            if len(pos) != 3 or not all(map(math.isfinite, pos)):
                raise ValueError("pos must be three finite numbers (x, y, z in metres, world frame)")
            q = np.asarray(quat if quat is not None else [1, 0, 0, 0], float)
            if q.shape != (4,) or not np.all(np.isfinite(q)) or np.linalg.norm(q) < 1e-9:
                raise ValueError("quat must be four finite numbers (w, x, y, z), not all zero")
            body, eq, adr = self.scene.objects[name]
            self.data.eq_active[eq] = 0
            self.data.qpos[adr:adr + 3] = pos
            self.data.qpos[adr + 3:adr + 7] = q / np.linalg.norm(q)
            dof = self.model.body_dofadr[body]
            self.data.qvel[dof:dof + 6] = 0
            mujoco.mj_forward(self.model, self.data)

    def set_robot_pose(self, x: float, y: float, theta: float) -> None:
        """Teleport the mobile base (a "kidnapped robot" test): its odometry does not see it,
        as the wheels of a robot carried elsewhere turn not."""
        if self.scene.base is None:
            raise ValueError("this robot has no mobile base to move")
        if not all(math.isfinite(v) for v in (x, y, theta)):
            raise ValueError("x, y and theta must be finite numbers (m, m, rad, map frame)")
        with self.lock:
            b = self.scene.base
            body0 = self.model.body_pos[b.body]
            self.data.qpos[b.qpos] = [x - body0[0], y - body0[1], theta]
            self.data.qvel[b.dof] = 0.0
            mujoco.mj_forward(self.model, self.data)

    # ------------------------------------------------------------------ the step
    def step(self, n: int = 1) -> None:
        """Advance the world by n physics steps (2 ms each)."""
        with self.lock:
            for _ in range(n):
                self._step_once()

    def _step_once(self) -> None:
        d, s, dt = self.data, self.scene, self.dt
        now = d.time
        d.ctrl[s.arm_actuators] = self.arm.step(d.qpos[s.arm_qpos], now)
        d.ctrl[s.gripper.actuators] = s.gripper.joint_values(self.arm.gripper_goal)
        vx = wz = 0.0
        if self.base:
            vx, wz = self.base.step(dt, now)
        self._apply_controls(vx, wz)
        mujoco.mj_step(self.model, d)
        self._steps += 1
        if self.base:
            self._integrate_odometry(dt, vx)
        if self._steps % GRASP_CHECK_STEPS == 0:
            self._update_grasp()

    def _apply_controls(self, vx: float, wz: float) -> None:
        b = self.scene.base
        if b is None:
            return
        yaw = self.data.qpos[b.qpos[2]]
        self.data.ctrl[b.actuators] = (vx * math.cos(yaw), vx * math.sin(yaw), wz)

    def _integrate_odometry(self, dt: float, commanded_vx: float) -> None:
        b, odom = self._mobile_base(), self._odometer()
        qvel, dof = self.data.qvel, b.dof
        yaw = float(self.data.qpos[b.qpos[2]])
        self._odom_vx += float(qvel[dof[0]]) * math.cos(yaw) + float(qvel[dof[1]]) * math.sin(yaw)
        self._odom_wz += float(qvel[dof[2]])
        self._odom_acc += dt
        if self._odom_acc >= ODOM_PERIOD_S - 1e-9:
            vx, wz = self._odom_vx * dt / self._odom_acc, self._odom_wz * dt / self._odom_acc
            odom.update(vx, wz, self._odom_acc)
            x, y, _ = self.truth()
            charging = any(math.hypot(x - px, y - py) < CHARGE_RADIUS_M
                           for name, (px, py, _) in self.places.items() if "charg" in name)
            self.battery.update(self._odom_acc, abs(commanded_vx) / 1.2, charging and abs(vx) < 1e-3)
            self._odom_acc = self._odom_vx = self._odom_wz = 0.0

    # ------------------------------------------------------------------ grasping
    def _touching(self) -> dict[int, set[int]]:
        """Object body -> indices of the fingers touching it."""
        d, s = self.data, self.scene
        bodies = {b: name for name, (b, _, _) in s.objects.items()}
        out: dict[int, set[int]] = {}
        for c in d.contact[: d.ncon]:
            for mine, other in ((c.geom1, c.geom2), (c.geom2, c.geom1)):
                ob = int(self.model.geom_bodyid[other])
                if ob not in bodies:
                    continue
                for i, geoms in enumerate(s.gripper.geoms):
                    if mine in geoms:
                        out.setdefault(ob, set()).add(i)
        return out

    def _update_grasp(self) -> None:
        d, s = self.data, self.scene
        opening = s.gripper.opening(d.qpos)
        held = [eq for (_, eq, _) in s.objects.values() if d.eq_active[eq]]
        goal = self.arm.gripper_goal
        if held and goal > opening + GRIP_SLACK_M:
            d.eq_active[held] = 0          # opening: let go
            return
        if held or goal >= opening - GRIP_SLACK_M:
            return
        nfingers = len(s.gripper.geoms)
        for body, fingers in self._touching().items():
            if len(fingers) == nfingers:
                eq = next(e for (b, e, _) in s.objects.values() if b == body)
                self._weld(s.tool_body, body, eq)
                return

    def _weld(self, tool: int, body: int, eq: int) -> None:
        """Activate the weld keeping the object's current pose relative to the tool."""
        d = self.data
        rt = d.xmat[tool].reshape(3, 3)
        rel_pos = rt.T @ (d.xpos[body] - d.xpos[tool])
        inv = np.zeros(4)
        mujoco.mju_negQuat(inv, d.xquat[tool])
        rel_quat = np.zeros(4)
        mujoco.mju_mulQuat(rel_quat, inv, d.xquat[body])
        data = self.model.eq_data[eq]
        data[0:3] = 0.0
        data[3:6] = rel_pos
        data[6:10] = rel_quat
        data[10] = 1.0
        d.eq_active[eq] = 1

    # ------------------------------------------------------------------ readings
    def _mobile_base(self) -> Base:
        """The scene's base; reading one of an arm-only robot is the caller's mistake."""
        if self.scene.base is None:
            raise ValueError(f"{self.robot.robot_id} has no mobile base")
        return self.scene.base

    def _odometer(self) -> Odometer:
        if self.odom is None:
            raise ValueError(f"{self.robot.robot_id} has no mobile base, hence no odometry")
        return self.odom

    def arm_state(self) -> m.ArmState:
        with self.lock:
            s = self.scene
            return m.ArmState(names=list(s.joint_names),
                              positions=self.data.qpos[s.arm_qpos].tolist(),
                              velocities=self.data.qvel[s.arm_dof].tolist(),
                              mode=self.arm.mode, fault=self.arm.fault)

    def holding(self) -> str:
        """Name of the object in the gripper, or ""."""
        with self.lock:
            for name, (_, eq, _) in self.scene.objects.items():
                if self.data.eq_active[eq]:
                    return name
            return ""

    def gripper_state(self) -> m.GripperState:
        with self.lock:
            return m.GripperState(opening=self.scene.gripper.opening(self.data.qpos),
                                  holding=bool(self.holding()))

    def odometry(self) -> m.Odometry:
        with self.lock:
            o = self._odometer()
            return m.Odometry(x=o.x, y=o.y, theta=o.theta, vx=o.vx, wz=o.wz)

    def truth(self) -> tuple[float, float, float]:
        """Ground-truth base pose in the map (world) frame."""
        with self.lock:
            b = self._mobile_base().body
            r = self.data.xmat[b]
            return (float(self.data.xpos[b][0]), float(self.data.xpos[b][1]), math.atan2(r[3], r[0]))

    def sonar(self) -> m.Sonar:
        with self.lock:
            return m.Sonar(ranges=sensors.sonar_ranges(self.model, self.data, self._mobile_base()),
                           angles=sensors.sonar_angles())

    def bumpers(self) -> m.Bumpers:
        with self.lock:
            front, rear = sensors.bumpers(self.model, self.data, self._mobile_base(), self.scene.robot_bodies)
            return m.Bumpers(front=front, rear=rear)

    def object_position(self, name: str) -> np.ndarray:
        with self.lock:
            return self.data.xpos[self.scene.objects[name][0]].copy()

    def tool_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Tool frame in the arm's base frame: (position, 3x3 rotation)."""
        with self.lock:
            d, s = self.data, self.scene
            rb = d.xmat[s.arm_base_body].reshape(3, 3)
            rt = d.xmat[s.tool_body].reshape(3, 3)
            return rb.T @ (d.xpos[s.tool_body] - d.xpos[s.arm_base_body]), rb.T @ rt

    def status(self) -> dict:
        with self.lock:
            return {"names": list(self.robot.joint_names), "lower": list(self.robot.lower),
                    "upper": list(self.robot.upper), "max_velocity": list(self.robot.max_velocity),
                    "mode": self.arm.mode, "fault": self.arm.fault, "estop": self.estop,
                    "world": self.world, "sim_time": self.time,
                    "objects": list(self.scene.objects), "holding": self.holding(),
                    "gripper_max_opening": self.scene.gripper.max_opening}

    def copy_positions(self, out: mujoco.MjData) -> None:
        """Copy the configuration into another MjData (cameras render from their own copy)."""
        with self.lock:
            out.qpos[:] = self.data.qpos
            out.time = self.data.time
