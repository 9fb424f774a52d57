"""The robot catalog: one source of truth for joint names, limits, speeds and models.

Drivers, the simulation and the kinematics service all read it, so that a limit is
changed in one place. Numbers: ASIBOT from docs/asibot-conventions.md, "Kinematics"
(limits +-360/+-135 deg, 25 deg/s maxVel of the real drives, home all zeros); Katana
300 6M180 from docs/katana.md (limits and vel_enc2rad(180) speeds).
"""

from __future__ import annotations
from importlib import resources

import math
from dataclasses import dataclass, field
from pathlib import Path

MODELS = Path(str(resources.files("asibot.models")))


@dataclass(frozen=True)
class RobotSpec:
    """What every service needs to know about one robot's arm (SI units: rad, rad/s, m)."""

    robot_id: str
    arm: str
    urdf_path: Path
    joint_names: list[str]
    lower: list[float]
    upper: list[float]
    max_velocity: list[float]
    home: list[float]
    base_link: str
    tool_link: str
    gripper_max_opening: float
    solver: str
    has_base: bool
    #: The simulated world that hosts this robot ("kitchen"); "" for a real robot.
    world: str = ""
    extra: dict = field(default_factory=dict)
    #: How far beyond the tool point the fingertips' centre is, along the tool's z, m: the
    #: middle of what closes on an object (a grasp puts it there).
    finger_length: float = 0.0
    #: How far beyond the tool point the fingers end, along the tool's z, m: what touches a
    #: mark when a person puts "the fingertips on it" (the camera calibration).
    fingertip_reach: float = 0.0
    #: How far below an object's top the fingertips close on it when they grasp it, m.
    grip_depth: float = 0.03


_D = math.pi / 180.0


def _asibot(robot_id: str, solver: str = "asibot", world: str = "") -> RobotSpec:
    lim = [360 * _D, 135 * _D, 135 * _D, 135 * _D, 360 * _D]
    return RobotSpec(
        robot_id=robot_id, arm="asibot", urdf_path=MODELS / "asibot.urdf",
        joint_names=[f"q{i}" for i in range(1, 6)],
        lower=[-v for v in lim], upper=list(lim),
        max_velocity=[25 * _D] * 5, home=[0.0] * 5,
        base_link="base_link", tool_link="tool", gripper_max_opening=0.08,
        solver=solver, has_base=False, world=world,
        # The worked pick (examples/give_me_the_red_can.py): fingers 4 cm, grip 3 cm below the top.
        # The fingers are 8 cm long (asibot.urdf): they end 4 cm beyond their middle.
        finger_length=0.04, fingertip_reach=0.08, grip_depth=0.03)


KATANA_JOINTS = ["katana_motor1_pan_joint", "katana_motor2_lift_joint", "katana_motor3_lift_joint",
                 "katana_motor4_lift_joint", "katana_motor5_wrist_roll_joint"]


def _katana(robot_id: str, world: str = "") -> RobotSpec:
    return RobotSpec(
        robot_id=robot_id, arm="katana", urdf_path=MODELS / "katana.urdf",
        joint_names=list(KATANA_JOINTS),
        lower=[-3.025528, -0.135228, -2.221804, -2.033309, -2.993240],
        upper=[2.891097, 2.168572, 2.054223, 1.876133, 2.870985],
        max_velocity=[2.208932, 1.190799, 1.190799, 2.208932, 2.208932],
        # A folded, non-singular pose inside every limit.
        home=[0.0, 1.2, -1.0, -0.5, 0.0],
        base_link="katana_base_link", tool_link="katana_gripper_tool_frame",
        gripper_max_opening=0.07, solver="pinocchio", has_base=True, world=world,
        # The tool frame lies between the fingertips already.
        finger_length=0.0, grip_depth=0.03)


_CATALOG = {
    "asibot-sim": _asibot("asibot-sim", world="kitchen"),
    "asibot": _asibot("asibot"),
    "pioneer-sim": _katana("pioneer-sim", world="apartment"),
    "pioneer": _katana("pioneer"),
}


def ids() -> list[str]:
    """All known robot ids."""
    return sorted(_CATALOG)


def get(robot_id: str) -> RobotSpec:
    """The spec of `robot_id`; raises KeyError naming the known ids."""
    try:
        return _CATALOG[robot_id]
    except KeyError:
        raise KeyError(f"unknown robot {robot_id!r}; choose one of {', '.join(ids())}") from None
