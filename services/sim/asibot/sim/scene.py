"""Build one MuJoCo model from a world (MJCF data) and a robot of the catalog (URDF).

Why MjSpec: the arm is loaded from the very URDF that kinematics and the browser use
(libs/common/models), attached at the world's site "arm_mount", and only what the URDF
cannot say (position servos, gripper servos, weld constraints for grasping, gravity
compensation) is added here in code. Geometry is never copied by hand.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import mujoco
import numpy as np

from asibot import robots

WORLDS_DIR = Path(str(resources.files("asibot.sim") / "worlds"))
WORLDS = {robots.get(rid).world: rid for rid in robots.ids() if robots.get(rid).world}
"""World name -> the robot id it hosts (one process per world), from the robot catalogue."""
ARM_PREFIX = "arm/"
ROBOT_GROUP = 2
"""Geom group of the robot's own base/station: ray sensors ignore it (see worlds/*.xml)."""

ARM_KP = 400.0        # N m / rad: stiff position servo, like a drive's position loop
ARM_KV = 20.0         # N m s / rad: about critical damping with the armature below
ARM_ARMATURE = 0.1    # kg m^2: reflected rotor inertia of a geared drive; also keeps 2 ms steps stable
FINGER_KP = 300.0     # N / m (prismatic) or N m / rad (revolute)
FINGER_FORCE = 15.0   # N: grip force limit


@dataclass
class Gripper:
    """Finger joints of the arm and how a joint value maps to the opening between fingers."""
    qpos: np.ndarray          # qpos addresses of the finger joints
    actuators: np.ndarray     # actuator ids, one per finger joint
    closed: np.ndarray        # joint values with the fingers together
    opened: np.ndarray        # joint values at the maximum opening
    max_opening: float        # m
    geoms: list[set[int]]     # collision geoms of each finger
    _last: tuple[float, np.ndarray] = field(default=(math.nan, np.zeros(0)), init=False, repr=False)

    def joint_values(self, opening: float) -> np.ndarray:
        """The finger joints' values at `opening` (m), asked every physics step: the last answer
        is kept, as the opening changes only when the gripper is commanded."""
        if opening != self._last[0]:
            f = min(max(opening / self.max_opening, 0.0), 1.0)
            values = self.closed + f * (self.opened - self.closed)
            values.flags.writeable = False                 # shared by every step that asks
            self._last = (opening, values)
        return self._last[1]

    def opening(self, qpos: np.ndarray) -> float:
        span = self.opened - self.closed
        f = np.mean((qpos[self.qpos] - self.closed) / np.where(span == 0, 1, span))
        return float(np.clip(f, 0.0, 1.0) * self.max_opening)


@dataclass
class Base:
    """The mobile base's planar joints, actuators and sensors."""
    body: int
    qpos: np.ndarray          # x, y, yaw
    dof: np.ndarray
    actuators: np.ndarray     # velocity actuators x, y, yaw
    bumpers_front: list[int]
    bumpers_rear: list[int]
    sonar_sites: list[int]


@dataclass
class Scene:
    """A compiled world with the indices the simulation needs."""
    world: str
    robot_id: str
    model: mujoco.MjModel
    joint_names: list[str]
    arm_qpos: np.ndarray
    arm_dof: np.ndarray
    arm_actuators: np.ndarray
    arm_base_body: int
    tool_body: int
    gripper: Gripper
    objects: dict[str, tuple[int, int, int]]   # name -> (body id, weld equality id, qpos address)
    robot_bodies: set[int]
    cameras: list[str]
    base: Base | None = None
    robot_geomgroup: np.ndarray = field(default_factory=lambda: np.array([1, 1, 0, 1, 1, 1], np.uint8))


def world_path(world: str) -> Path:
    if world not in WORLDS:
        raise ValueError(f"unknown world {world!r}; choose one of {', '.join(WORLDS)}")
    return WORLDS_DIR / f"{world}.xml"


def _subtree(model: mujoco.MjModel, root: int) -> set[int]:
    out = {root}
    for b in range(root + 1, model.nbody):
        if int(model.body_parentid[b]) in out:
            out.add(b)
    return out


def build(world: str, robot) -> Scene:
    """Compile `world` with the arm of `robot` (an asibot.robots.RobotSpec) attached."""
    spec = mujoco.MjSpec.from_file(str(world_path(world)))
    arm = mujoco.MjSpec.from_file(str(robot.urdf_path))
    arm_joint_set = set(robot.joint_names)
    missing = arm_joint_set - {j.name for j in arm.joints}
    if missing:
        raise ValueError(f"{robot.urdf_path} lacks the joints {sorted(missing)} of robot {robot.robot_id}; "
                         "the URDF and asibot.robots disagree")
    for body in arm.bodies:
        if body.name != "world":
            body.gravcomp = 1.0  # the drives hold the arm's weight, as the real servo loops do
    fingers = [j.name for j in arm.joints if j.name not in arm_joint_set]  # names before attach prefixes them
    if not fingers:
        fingers = _add_fingers(arm, robot.tool_link, float(robot.gripper_max_opening))
    for j in arm.joints:
        if j.name in arm_joint_set:
            j.armature = ARM_ARMATURE
            j.damping = [0.5, 0.0, 0.0]  # N m s / rad (MuJoCo 4: linear term first)
    mount = spec.site("arm_mount")
    spec.attach(arm, prefix=ARM_PREFIX, site=mount)
    # Neighbouring links overlap at their joints and the base link sits on its mount: those
    # touches are bearings and bolts, not collisions. (MuJoCo's parent filter does not apply
    # to bodies welded to the world, such as a docked arm's base link.)
    # Coarse URDF collision shapes also overlap one link further, so grandparents are excluded
    # too; links further apart still collide with each other.
    for body in spec.bodies:
        if not body.name.startswith(ARM_PREFIX):
            continue
        up = body.parent
        for _ in range(2):
            if up is None or up.name == "world":
                break
            spec.add_exclude(bodyname1=up.name, bodyname2=body.name)
            up = up.parent
    for i, name in enumerate(robot.joint_names):
        act = spec.add_actuator(name=ARM_PREFIX + name, target=ARM_PREFIX + name,
                                trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=ARM_KP, kv=ARM_KV)
        act.forcelimited = True
        act.forcerange = [-200.0, 200.0]
    for j in fingers:
        act = spec.add_actuator(name=ARM_PREFIX + j, target=ARM_PREFIX + j,
                                trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=FINGER_KP, kv=FINGER_KP * 0.05)
        act.forcelimited = True
        act.forcerange = [-FINGER_FORCE, FINGER_FORCE]
    tool_name = ARM_PREFIX + robot.tool_link
    free_bodies = [b.name for b in spec.bodies if any(j.type == mujoco.mjtJoint.mjJNT_FREE for j in b.joints)]
    for name in free_bodies:
        spec.add_equality(type=mujoco.mjtEq.mjEQ_WELD, name=f"grasp_{name}", name1=tool_name,
                          name2=name, objtype=mujoco.mjtObj.mjOBJ_BODY, active=False,
                          solref=[0.01, 1.0])
    model = spec.compile()
    return _index(world, robot, model, [ARM_PREFIX + j for j in fingers], free_bodies)


FINGER_LENGTH = 0.06


def _add_fingers(arm: mujoco.MjSpec, tool_link: str, max_opening: float) -> list[str]:
    """A parallel-jaw gripper on the tool link, for URDFs that model the arm only.

    Each finger slides along the tool's y axis from the centre to max_opening / 2 and reaches
    FINGER_LENGTH along the tool's z axis (away from the arm); opening = 2 x slide.
    """
    tool = arm.body(tool_link)
    if tool is None:
        raise ValueError(f"the URDF has no link {tool_link!r} to carry the gripper")
    names = []
    for side, sign in (("left", 1.0), ("right", -1.0)):
        body = tool.add_body(name=f"sim_finger_{side}")
        body.gravcomp = 1.0
        joint = body.add_joint(name=f"sim_finger_{side}_joint", type=mujoco.mjtJoint.mjJNT_SLIDE,
                               axis=[0.0, sign, 0.0], range=[0.0, max_opening / 2])
        joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        body.add_geom(name=f"sim_finger_{side}", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.01, 0.005, FINGER_LENGTH / 2],
                      pos=[0.0, sign * 0.005, FINGER_LENGTH / 2], mass=0.05, rgba=[0.2, 0.2, 0.2, 1.0])
        names.append(joint.name)
    return names


def _index(world: str, robot, model: mujoco.MjModel, finger_joints: list[str], free_bodies: list[str]) -> Scene:
    def jid(name: str) -> int:
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)

    arm_j = [jid(ARM_PREFIX + n) for n in robot.joint_names]
    arm_base = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, ARM_PREFIX + robot.base_link)
    tool = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, ARM_PREFIX + robot.tool_link)
    if arm_base < 0 or tool < 0:
        raise ValueError(f"base_link {robot.base_link!r} or tool_link {robot.tool_link!r} is not a link of "
                         f"{robot.urdf_path}")
    gripper = _gripper(model, robot, finger_joints)
    objects = {}
    for name in free_bodies:
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        e = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, f"grasp_{name}")
        objects[name] = (b, e, int(model.jnt_qposadr[model.body_jntadr[b]]))
    base = None
    robot_root = arm_base
    if robot.has_base:
        base = _base(model)
        robot_root = base.body
    robot_bodies = _subtree(model, robot_root)
    cameras = [model.camera(i).name for i in range(model.ncam)]
    return Scene(
        world=world, robot_id=robot.robot_id, model=model, joint_names=list(robot.joint_names),
        arm_qpos=np.array([model.jnt_qposadr[j] for j in arm_j]),
        arm_dof=np.array([model.jnt_dofadr[j] for j in arm_j]),
        arm_actuators=np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, ARM_PREFIX + n)
                                for n in robot.joint_names]),
        arm_base_body=arm_base, tool_body=tool, gripper=gripper, objects=objects,
        robot_bodies=robot_bodies, cameras=cameras, base=base)


def _gripper(model: mujoco.MjModel, robot, finger_joints: list[str]) -> Gripper:
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in finger_joints]
    lo = np.array([model.jnt_range[j][0] for j in ids])
    hi = np.array([model.jnt_range[j][1] for j in ids])
    qpos = np.array([model.jnt_qposadr[j] for j in ids])
    bodies = [int(model.jnt_bodyid[j]) for j in ids]
    subtrees = [_subtree(model, b) for b in bodies]  # a finger may carry a fingertip link
    geoms = [{g for g in range(model.ngeom) if int(model.geom_bodyid[g]) in sub} for sub in subtrees]
    # Which end of the range is "open"? Measure how far apart the finger geoms are at both
    # ends (geoms, not bodies: a revolute finger's body origin does not move).
    data = mujoco.MjData(model)
    gids = [g for gs in geoms for g in gs]

    def spread(values: np.ndarray) -> float:
        data.qpos[:] = model.qpos0
        data.qpos[qpos] = values
        mujoco.mj_kinematics(model, data)
        pts = data.geom_xpos[gids]
        return float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))

    closed, opened = (lo, hi) if spread(hi) >= spread(lo) else (hi, lo)
    acts = np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in finger_joints])
    return Gripper(qpos=qpos, actuators=acts, closed=closed, opened=opened,
                   max_opening=float(robot.gripper_max_opening), geoms=geoms)


def _base(model: mujoco.MjModel) -> Base:
    def named(kind: mujoco.mjtObj, name: str) -> int:
        i = mujoco.mj_name2id(model, kind, name)
        if i < 0:
            raise ValueError(f"the world has no {name!r}; a mobile robot needs it")
        return i

    joints = [named(mujoco.mjtObj.mjOBJ_JOINT, n) for n in ("base_x", "base_y", "base_yaw")]
    geom_names = [model.geom(g).name for g in range(model.ngeom)]
    return Base(
        body=int(model.jnt_bodyid[joints[0]]),
        qpos=np.array([model.jnt_qposadr[j] for j in joints]),
        dof=np.array([model.jnt_dofadr[j] for j in joints]),
        actuators=np.array([named(mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in ("base_x", "base_y", "base_yaw")]),
        bumpers_front=[g for g, n in enumerate(geom_names) if n.startswith("bumper_front_")],
        bumpers_rear=[g for g, n in enumerate(geom_names) if n.startswith("bumper_rear_")],
        sonar_sites=[named(mujoco.mjtObj.mjOBJ_SITE, f"sonar_{i}") for i in range(16)],
    )
