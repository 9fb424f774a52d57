"""What every RPC verb of the kinematics server accepts: its table of verbs (`asibot.verbs`).

`verbs(n_joints)` is the table: verb -> `Verb` (its fields, each a `Field` with a validator,
and whether it needs a live driver). The server serves exactly the verbs of this table
(`asibot.verbs.serve`), so a verb cannot be served unchecked.

Ranges are wide enough for every arm of the catalog and narrow enough that the arithmetic
after them stays finite and small: a point farther than `MAX_DISTANCE` is not a typo of a
reachable one but a unit mistake, and a movl to a distant point that passes these checks is
refused by the planner's reach check of its end point, before any path is sampled.

Units are the user's (m and deg), as in the client and the seed.
"""

from __future__ import annotations

from asibot import jog
from asibot.verbs import Field, Flag, Number, Numbers, OneOf, Verb, Whole

#: Largest coordinate of a point, m: far beyond any arm, small enough to square.
MAX_DISTANCE = 1e6
#: Largest angle of a point (rot(y'), rot(z'')), deg: one turn either way.
MAX_POINT_ANGLE = 360.0
#: Largest joint value or joint step (fwd, movj joints, relj, jog), deg: two turns either way.
#: A jog step of x, y or z takes the same number in m: far beyond any arm, refused by the reach
#: check of the step's end point.
MAX_JOINT = 720.0
#: Longest movement a request may ask for, s.
MAX_DURATION = 600.0
#: movj/relj/home speed: a fraction of each joint's maximum speed.
MIN_JOINT_SPEED, MAX_JOINT_SPEED = 0.01, 1.0
#: movl speed, m/s.
MIN_LINEAR_SPEED, MAX_LINEAR_SPEED = 0.001, 1.0
#: movv: largest linear (m/s) and angular (deg/s) velocity.
MAX_VELOCITY, MAX_ANGULAR_VELOCITY = 2.0, 360.0
#: tool frame: largest offset (m) and rotation-vector component (deg).
MAX_TOOL_OFFSET, MAX_TOOL_ANGLE = 5.0, 360.0
#: Longest `wait` a request may ask for, s (the server waits at most MAX_WAIT per call anyway).
MAX_WAIT_REQUEST = 3600.0
#: pointer: the device's yaw rate (deg/s) and pitch (deg), and the speed along the tool (m/s).
MAX_POINTER_YAW, MAX_POINTER_PITCH = 360.0, 180.0
POINTER_SPEED, MAX_POINTER_SPEED = 0.05, 0.1
POINTER_DIRECTIONS = ("forward", "hold", "backward")
#: Longest a single `wait` RPC blocks, s (its default timeout); the client loops for longer waits.
MAX_WAIT = 10.0


def point(names: tuple[str, ...] = ("x", "y", "z", "rot(y')", "rot(z'')")) -> Numbers:
    """A user point [x, y, z, rot(y'), rot(z'')] in m and deg."""
    distance, angle = Number(-MAX_DISTANCE, MAX_DISTANCE, "m"), Number(-MAX_POINT_ANGLE, MAX_POINT_ANGLE, "deg")
    return Numbers(names, (distance,) * 3 + (angle,) * (len(names) - 3))


def joints(n: int) -> Numbers:
    """n joint values (or steps) in deg."""
    return Numbers(tuple(f"q{i + 1}" for i in range(n)), (Number(-MAX_JOINT, MAX_JOINT, "deg"),) * n)


DURATION = Field(Number(0.0, MAX_DURATION, "s", open_low=True))
JOINT_SPEED = Field(Number(MIN_JOINT_SPEED, MAX_JOINT_SPEED, "of the maximum joint speed"))

#: The pointer verb's fields (asibot.kinematics.pointer.PointerInput is built from them).
POINTER = Verb({
    "deadman": Field(Flag(), required=True),
    "direction": Field(OneOf(POINTER_DIRECTIONS), default="hold"),
    "yaw": Field(Number(-MAX_POINTER_YAW, MAX_POINTER_YAW, "deg/s"), default=0.0),
    "pitch": Field(Number(-MAX_POINTER_PITCH, MAX_POINTER_PITCH, "deg")),
    "speed": Field(Number(0.0, MAX_POINTER_SPEED, "m/s", open_low=True), default=POINTER_SPEED),
}, needs_driver=True, doc="one reading of a handheld pointer: the tool follows it while the dead-man is held")


def verbs(n_joints: int) -> dict[str, Verb]:
    """Every verb of cart/rpc/<verb> and what it accepts, for an arm of `n_joints` joints."""
    p, q = point(), joints(n_joints)
    velocity = Numbers(("vx", "vy", "vz", "w rot(y')", "w rot(z'')"),
                       (Number(-MAX_VELOCITY, MAX_VELOCITY, "m/s"),) * 3
                       + (Number(-MAX_ANGULAR_VELOCITY, MAX_ANGULAR_VELOCITY, "deg/s"),) * 2)
    joint_velocity = Numbers(tuple(f"w q{i + 1}" for i in range(n_joints)),
                             (Number(-MAX_ANGULAR_VELOCITY, MAX_ANGULAR_VELOCITY, "deg/s"),) * n_joints)
    tool = Numbers(("x", "y", "z", "rx", "ry", "rz"),
                   (Number(-MAX_TOOL_OFFSET, MAX_TOOL_OFFSET, "m"),) * 3
                   + (Number(-MAX_TOOL_ANGLE, MAX_TOOL_ANGLE, "deg"),) * 3)
    return {
        "stat": Verb(needs_driver=True, doc="where the arm is: state, point, joints, estop, fault"),
        "inv": Verb({"point": Field(p, required=True)}, doc="the joints that put the tool at a point; nothing moves"),
        "fwd": Verb({"joints": Field(q, required=True)}, doc="the point the tool is at for some joints; nothing moves"),
        "movj": Verb({"point": Field(p), "joints": Field(q), "duration": DURATION, "speed": JOINT_SPEED},
                     needs_driver=True, doc="a joint-space move to a point or to joints"),
        "movl": Verb({"point": Field(p, required=True), "duration": DURATION,
                      "speed": Field(Number(MIN_LINEAR_SPEED, MAX_LINEAR_SPEED, "m/s"))}, needs_driver=True,
                     doc="a straight line of the tool to a point"),
        "movv": Verb({"velocity": Field(velocity, required=True)}, needs_driver=True,
                     doc="stream a velocity of the tool; again within 200 ms to keep moving"),
        "movjv": Verb({"velocity": Field(joint_velocity, required=True)}, needs_driver=True,
                      doc="stream joint velocities; again within 200 ms to keep moving"),
        "relj": Verb({"joints": Field(q, required=True), "duration": DURATION, "speed": JOINT_SPEED},
                     needs_driver=True, doc="a joint-space move by some joint steps from here"),
        "home": Verb({"duration": DURATION, "speed": JOINT_SPEED}, needs_driver=True,
                     doc="a joint-space move to the arm's home posture"),
        "stop": Verb(strict=False, doc="stop the arm, whoever moved it"),
        "wait": Verb({"timeout": Field(Number(0.0, MAX_WAIT_REQUEST, "s", open_low=True), default=MAX_WAIT)},
                     doc="wait until the motion ends and the arm has caught up with its end (done), or the timeout passes"),
        "tool": Verb({"tool": Field(tool, also="or null to remove it")},
                     doc="attach a tool frame: points are the tool point's from then on"),
        "act": Verb({"action": Field(OneOf(("open", "close")), required=True)},
                    doc="open or close the gripper; answers once the fingers stopped, and whether it holds"),
        "pointer": POINTER,
        # One step of one axis (the page's step buttons): a joint (movj) or a coordinate of the
        # point (movl) by a signed step, at one of the page's speed levels.
        "jog": Verb({"axis": Field(OneOf(jog.axes(n_joints)), required=True),
                     "step": Field(Number(-MAX_JOINT, MAX_JOINT, "deg (m for x, y, z)"), required=True),
                     "level": Field(Whole(1, len(jog.SPEED_LEVELS)), required=True)}, needs_driver=True,
                    doc="one step of one axis, added to the previous step's target while it moves"),
    }
