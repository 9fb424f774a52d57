"""The jog's speeds and axis names, written once for both of its ends.

The kinematics service's `jog` verb (one step of one axis, asibot.kinematics.server) moves by
them, and the web page draws its speed buttons with them and moves at the same levels when it
holds to move, moves to a point or goes home (asibot.web.motion). They live here, in the
contract both packages import, because the web does not depend on the kinematics package
(and its solvers).
"""

from __future__ import annotations

from asibot.poses import POINT_AXES

#: The five speed levels, slowest first, as fractions of the top speed of what moves: of each
#: joint's maximum speed for a joint step (a movj), of STEP_LINEAR_SPEED for a Cartesian step
#: (a movl).
SPEED_LEVELS: tuple[float, ...] = (0.1, 0.25, 0.5, 0.75, 1.0)


def speed_fraction(level: int) -> float:
    """The fraction of the top speed that `level` (1 to 5) moves at. A level outside them is a
    ValueError here, where the table is, and never wraps round to the top speed (level 0 would
    be SPEED_LEVELS[-1])."""
    if isinstance(level, bool) or not isinstance(level, int) or not 1 <= level <= len(SPEED_LEVELS):
        raise ValueError(f"The speed level must be 1 to {len(SPEED_LEVELS)}; got {level!r}.")
    return SPEED_LEVELS[level - 1]


#: A Cartesian step (a movl) at the top level moves at this linear speed, m/s.
STEP_LINEAR_SPEED = 0.10


def axes(n_joints: int) -> tuple[str, ...]:
    """The axes a jog steps, by name: the joints q1 ... (deg), as requests name joint values,
    then the point's coordinates x, y, z (m), rot(y'), rot(z'') (deg)."""
    return tuple(f"q{i + 1}" for i in range(n_joints)) + tuple(name for name, _ in POINT_AXES)

