"""The sim on the bus: the driver contract (docs/foundation-api.md), spoken by a MuJoCo world.

Physics runs on its own thread (2 ms steps, in 10 ms batches paced by the wall clock, or
back to back with `fast`); cameras render on another thread from a private copy of the
configuration, so a slow frame never delays the 100 Hz arm state. All logic lives in
`Simulation`; this class only moves messages between it and the bus, and keeps the two
bus-facing safety rules of a driver: only the controller that holds a part moves it
(asibot.safety.ownership: the arm and gripper, the base), and the estop state is kept served after
its sender exits (asibot.safety.estop). Beside the driver contract's verbs it serves its own
(`VERBS`: tests and demos put its world back or move what is in it).
"""

from __future__ import annotations

import argparse
import collections
import logging
import math
import threading
import time
from dataclasses import dataclass
from typing import Any, TypedDict

import mujoco

from asibot import keys
from asibot import messages as m
from asibot.bus import Bus, Publisher
from asibot.safety.driver_contract import DriverContract, command
from asibot.safety.guarded_arm import FaultError
from asibot.errors import RpcError
from asibot.runtime import Service
from asibot.sim import viewer
from asibot.sim.arm import Notice
from asibot.sim.cameras import Camera
from asibot.sim.scene import WORLDS
from asibot.sim.simulation import Simulation, world_for
from asibot.timing import Ticker
from asibot.verbs import Field, Number, Numbers, Text, Verb

log = logging.getLogger("asibot.sim")

NAME = "sim"

TICK_S = 0.01
"""Physics batch: 5 steps of 2 ms; the arm state goes out once per batch (100 Hz)."""
CATCH_UP_S = 0.05
"""Most simulated time run in one batch to catch up with the wall clock."""
RESET_WAIT_S = 2.0
"""Longest wait for the reset world to be published before reset_world answers anyway."""
CAMERA_KINDS = {"front": ("depth",), "back": ("depth",), "rgb": ("rgb",), "kitchen": ("depth", "rgb")}
"""What each camera of the worlds produces (camera names are those of worlds/*.xml)."""

MAX_WORLD = 100.0
"""Largest world coordinate a request may ask for, m: far beyond every world of worlds/."""
_WORLD = Number(-MAX_WORLD, MAX_WORLD, "m")
_OBJECT = Field(Text("an object name", longest=100), required=True)

#: The sim's own verbs on `keys.driver_rpc`, beside the driver contract's. Which objects there
#: are is the world's: an unknown name is refused by the handler, with the world's objects.
VERBS = {
    "reset_world": Verb(doc="put the world back as it started: objects and arm where they started, "
                            "odometry at zero"),
    "set_object_pose": Verb({
        "name": _OBJECT,
        "pos": Field(Numbers(("x", "y", "z"), (_WORLD,) * 3), required=True),
        "quat": Field(Numbers(("w", "x", "y", "z"), (Number(-1.0, 1.0),) * 4),
                      also="or null for upright; normalised here"),
    }, doc="teleport a free object (world frame), out of the gripper"),
    "object_pose": Verb({"name": _OBJECT}, doc="where an object is: pos, [x, y, z] in m, world frame"),
    "set_robot_pose": Verb({"pose": Field(Numbers(("x", "y", "theta"), (_WORLD, _WORLD,
                                                                        Number(-math.tau, math.tau, "rad"))),
                                          required=True)},
                           doc="teleport the mobile base (map frame); its odometry does not see it, as a robot "
                               "carried elsewhere"),
}


@dataclass
class Options:
    fast: bool = False
    camera_hz: float = 10.0
    width: int = 320
    height: int = 240
    depth_method: str = "render"
    viewer: bool = False
    """Show MuJoCo's viewer on the main thread (needs a DISPLAY)."""


class _CameraPublishers(TypedDict):
    info: Publisher[m.CameraInfo]
    depth: Publisher[m.DepthImage]
    rgb: Publisher[m.RgbImage]


class SimService(Service):
    """Publishes the sim's state and obeys commands, like a hardware driver."""

    def __init__(self, bus: Bus, sim: Simulation, options: Options) -> None:
        self.bus, self.sim, self.opt = bus, sim, options
        rid = sim.robot.robot_id
        self.robot_id = rid
        self.stop_event = threading.Event()
        self.contract = DriverContract(bus, rid)
        self._pub_arm = bus.publisher(keys.arm_state(rid), m.ArmState)
        self._pub_grip = bus.publisher(keys.gripper_state(rid), m.GripperState)
        if sim.base:
            self._pub_odom = bus.publisher(keys.base_odom(rid), m.Odometry)
            self._pub_sonar = bus.publisher(keys.base_sonar(rid), m.Sonar)
            self._pub_bump = bus.publisher(keys.base_bumpers(rid), m.Bumpers)
            self._pub_batt = bus.publisher(keys.base_battery(rid), m.Battery)
            self._pub_truth = bus.publisher(keys.sim_truth(rid), m.Pose2D)
        self._cameras_ready = threading.Event()
        if options.camera_hz <= 0:
            self._cameras_ready.set()
        self._frames = 0                          # camera frames (CameraInfo sent for each camera)
        self._rendered: collections.Counter[str] = collections.Counter()   # pictures rendered, by kind
        self._rtf = 0.0
        self._published = 0                       # physics ticks published, under _tick_done
        self._tick_done = threading.Condition()
        commands = [command("arm", self.sim.command_arm, lambda c: self.sim.heard("arm", c)),
                    command("gripper", lambda cmd: self.sim.command_gripper(cmd.opening, cmd.controller),
                            lambda c: self.sim.heard("arm", c))]
        if sim.base:
            commands.append(command("cmd_vel", lambda cmd: self.sim.command_base(cmd.vx, cmd.wz, cmd.controller),
                                    lambda c: self.sim.heard("base", c)))
        self.contract.serve(
            commands, on_holder=self.sim.set_controller, on_estop=self.sim.set_estop,
            status=self.sim.status, reset_fault=self._reset_fault, verbs=VERBS,
            handlers={"reset_world": self._reset_world, "set_object_pose": self._set_object_pose,
                      "object_pose": self._object_pose, "set_robot_pose": self._set_robot_pose})
        self.holders = self.contract.holders
        self._threads = [threading.Thread(target=self._physics_loop, name="sim-physics", daemon=True)]
        if options.camera_hz > 0:
            self._threads.append(threading.Thread(target=self._camera_loop, name="sim-cameras", daemon=True))
        for t in self._threads:
            t.start()

    # ------------------------------------------------------------------ RPC
    def _reset_fault(self) -> dict:
        try:
            return self.sim.reset_fault()
        except FaultError as exc:
            raise RpcError("fault", str(exc)) from None

    def _reset_world(self, a: Any) -> dict:
        """Reset, then answer once the reset world has been published: a controller asked to
        move right after the answer then plans from where the arm is now, not where it was
        (the arm jumps home; a plan from before the jump would yank it back)."""
        with self._tick_done:
            self.sim.reset_world()
            # the next tick's state may have been read before the reset; the one after is not
            after = self._published + 2
        with self._tick_done:
            self._tick_done.wait_for(lambda: self._published >= after or self.stop_event.is_set(), timeout=RESET_WAIT_S)
        return {}

    def _set_object_pose(self, a: Any) -> dict:
        try:
            self.sim.set_object_pose(a.name, a.pos.tolist(), None if a.quat is None else a.quat.tolist())
        except (KeyError, ValueError) as exc:       # no such object; a quaternion of zeros
            raise RpcError("bad_request", str(exc).strip("'\"")) from None
        return {}

    def _set_robot_pose(self, a: Any) -> dict:
        try:
            self.sim.set_robot_pose(*a.pose.tolist())
        except ValueError as exc:                   # a robot without a base
            raise RpcError("bad_request", str(exc)) from None
        return {}

    def _object_pose(self, a: Any) -> dict:
        if a.name not in self.sim.scene.objects:
            raise RpcError("bad_request", f"no object {a.name!r}; objects are {', '.join(self.sim.scene.objects)}")
        return {"pos": self.sim.object_position(a.name).tolist()}

    # ------------------------------------------------------------------ loops
    def _physics_loop(self) -> None:
        steps = max(1, round(TICK_S / self.sim.dt))
        # Creating GL contexts and the first renders take the GIL for a while: let the cameras
        # warm up first so that real time starts when the physics can keep it.
        self._cameras_ready.wait(timeout=15.0)
        ticker = None if self.opt.fast else Ticker(1.0 / TICK_S, stop=self.stop_event)
        tick = 0
        start_wall, start_sim = time.monotonic(), self.sim.time
        wall0, sim0 = start_wall, start_sim
        try:
            while not self.stop_event.is_set():
                if ticker is None:
                    n = steps
                else:
                    if not ticker.wait():
                        break
                    # Catch up after a late tick (GC, a slow frame) instead of losing sim time;
                    # at most CATCH_UP_S at once so an overloaded machine degrades gracefully.
                    behind = (time.monotonic() - start_wall) - (self.sim.time - start_sim)
                    n = int(round(min(max(behind, 0.0), CATCH_UP_S) / self.sim.dt))
                    if behind > 2 * CATCH_UP_S:  # hopelessly late: resynchronise, do not sprint
                        start_wall, start_sim = time.monotonic(), self.sim.time
                if n > 0:
                    self.sim.step(n)
                tick += 1
                self._publish(tick)
                with self._tick_done:
                    self._published = tick
                    self._tick_done.notify_all()
                if tick % 100 == 0:
                    wall = time.monotonic()
                    self._rtf = (self.sim.time - sim0) / max(wall - wall0, 1e-9)
                    wall0, sim0 = wall, self.sim.time
        except Exception:
            log.exception("the physics loop crashed; stopping the sim")
            self.stop_event.set()

    def _publish(self, tick: int) -> None:
        sim = self.sim
        self._pub_arm.put(sim.arm_state())
        while not sim.notices.empty():
            n: Notice = sim.notices.get()
            self.contract.event(n.level, n.code, n.text)
        if tick % 5 == 0:
            self._pub_grip.put(sim.gripper_state())
        if sim.base is None:
            return
        if tick % 5 == 0:
            self._pub_odom.put(sim.odometry())
            x, y, th = sim.truth()
            self._pub_truth.put(m.Pose2D(x=x, y=y, theta=th))
        if tick % 10 == 0:
            self._pub_sonar.put(sim.sonar())
            self._pub_bump.put(sim.bumpers())
        if tick % 100 == 0:
            self._pub_batt.put(m.Battery(volts=sim.battery.volts))

    def _camera_loop(self) -> None:
        sim, opt = self.sim, self.opt
        robot_body = sim.scene.base.body if sim.scene.base else sim.scene.arm_base_body
        cams = [Camera(sim.model, name, opt.width, opt.height, robot_body)
                for name in sim.scene.cameras if name in CAMERA_KINDS]
        pubs: dict[str, _CameraPublishers] = {}
        for c in cams:
            pubs[c.name] = {"info": self.bus.publisher(keys.camera_info(self.robot_id, c.name), m.CameraInfo),
                            "depth": self.bus.publisher(keys.camera_depth(self.robot_id, c.name), m.DepthImage),
                            "rgb": self.bus.publisher(keys.camera_rgb(self.robot_id, c.name), m.RgbImage)}
        data = mujoco.MjData(sim.model)
        try:
            first = True
            ticker: Ticker | None = None   # made after the first frame, when the cameras are warm
            while first or (ticker is not None and ticker.wait()):
                sim.copy_positions(data)
                # Every image of this frame shows the world as copied now, however long the
                # renders take (30-80 ms each on a loaded machine, one after the other): nav
                # places a scan where the robot was at its stamp.
                stamp = m.now_ns()
                mujoco.mj_kinematics(sim.model, data)
                mujoco.mj_camlight(sim.model, data)
                for c in cams:
                    p = pubs[c.name]
                    p["info"].put(c.info(data, stamp))
                    # A picture nobody subscribes to is not rendered (most of the sim's CPU when
                    # it is: 60 % of a core against 23 % in the kitchen), as a Gazebo camera
                    # sensor is inactive without subscribers. The first frame warms the GL contexts.
                    if "depth" in CAMERA_KINDS[c.name] and (first or p["depth"].matching()):
                        depth, rendered = c.depth_frame(data, opt.depth_method)
                        p["depth"].put(m.DepthImage(depth=depth, stamp=stamp))
                        self._rendered["depth"] += rendered
                    if "rgb" in CAMERA_KINDS[c.name] and (first or p["rgb"].matching()):
                        rgb, rendered = c.rgb_frame(data, stamp)
                        p["rgb"].put(rgb)
                        self._rendered["rgb"] += rendered
                self._frames += 1
                if first:
                    first = False
                    ticker = Ticker(opt.camera_hz, stop=self.stop_event)
                    self._cameras_ready.set()
        except Exception:
            log.exception("the camera loop crashed; cameras stopped (physics keeps running)")
        finally:
            self._cameras_ready.set()
            for c in cams:
                c.close()

    # ------------------------------------------------------------------ runtime hooks
    def run(self, stop: threading.Event) -> None:
        """Block until asked to stop (or the physics thread dies), showing the viewer if asked."""
        if self.opt.viewer:
            viewer.run(self.sim, stop)
            stop.set()
            return
        while not stop.wait(0.2):
            if self.stop_event.is_set():
                raise RuntimeError("the simulation stopped by itself; see the log above")

    def health(self) -> dict:
        return {"world": self.sim.world, "sim_time": round(self.sim.time, 3), "rtf": round(self._rtf, 3),
                "camera_frames": self._frames, "pictures_rendered": dict(self._rendered),
                "estop": self.sim.estop, "arm_mode": self.sim.arm.mode, **self.contract.health()}

    def close(self) -> None:
        self.contract.close()
        self.stop_event.set()
        for t in self._threads:
            t.join(timeout=1.5)


# ---------------------------------------------------------------------- command line
def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"camera size must look like 320x240, not {text!r}") from None
    if not (16 <= w <= 1920 and 16 <= h <= 1080):
        raise argparse.ArgumentTypeError("camera size must be between 16x16 and 1920x1080")
    return w, h


def _noise(text: str) -> tuple[float, float]:
    try:
        lin, ang = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"odometry noise must look like 0.02,0.05, not {text!r}") from None
    if lin < 0 or ang < 0:
        raise argparse.ArgumentTypeError("odometry noise fractions must be >= 0")
    return lin, ang


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--world", choices=sorted(WORLDS), help="world to load (default: the robot's world)")
    p.add_argument("--fast", action="store_true", help="step as fast as possible instead of real time")
    p.add_argument("--viewer", action="store_true", help="open MuJoCo's viewer (needs a DISPLAY)")
    p.add_argument("--camera-hz", type=float, default=10.0, help="camera frame rate; 0 disables cameras")
    p.add_argument("--camera-size", type=_size, default=(320, 240), help="camera resolution WxH")
    p.add_argument("--depth-method", choices=["render", "ray"], default="render",
                   help="depth by OSMesa rendering (default, faster) or by ray casting")
    p.add_argument("--odom-noise", type=_noise, default=(0.02, 0.05),
                   help="odometry noise: linear,angular standard deviation as a fraction of speed")
    p.add_argument("--seed", type=int, default=None, help="seed of the odometry noise")


def build(bus: Bus, args: argparse.Namespace) -> SimService:
    robot = args.robot or (WORLDS[args.world] if args.world else None)
    if robot is None:
        raise ValueError("say which robot to simulate: --robot asibot-sim or --robot pioneer-sim (or --world)")
    world = args.world or world_for(robot)
    sim = Simulation(robot, world, odom_noise=args.odom_noise, seed=args.seed)
    width, height = args.camera_size
    show = args.viewer and viewer.available()
    if args.viewer and not show:
        log.warning("--viewer ignored: no DISPLAY; running headless")
    log.info("simulating %s in the %s world (%s)", robot, world, "fast" if args.fast else "real time")
    return SimService(bus, sim, Options(fast=args.fast, camera_hz=args.camera_hz, width=width,
                                        height=height, depth_method=args.depth_method, viewer=show))
