"""What every RPC verb of the nav service accepts: its table of verbs (`asibot.verbs`).

`VERBS` is the table: verb -> `Verb` (its fields, each a `Field` with a validator). The
service serves exactly these verbs (`asibot.verbs.serve`), so a verb cannot be served
unchecked, and each handler receives the checked arguments. What one field cannot say is
the handler's to refuse: a place and a pose together, a distance of 0, a place nobody saved.

`needs_driver` marks the verbs that drive the base: while another program holds the base
they are refused at once, and before the first of them for each base driver nav waits a
moment until the driver names it the base's holder (asibot.safety.ownership). The primitive
"stop" is neither refused nor delayed: a stop always stops.

Units are the user's: m and rad for poses (map frame), m for a drive, deg for a turn.
"""

from __future__ import annotations

import math

from asibot import driving
from asibot.verbs import Field, Flag, Number, Numbers, OneOf, Text, Verb, Whole

from asibot.nav.places import MAX_NAME
from asibot.nav.primitives import MAX_STEP, MAX_TURN

#: Largest coordinate of a pose, m: no place in a home, a unit mistake (the map's bounds
#: refuse the rest, with a sentence that gives them).
MAX_COORDINATE = 1e6
#: Largest heading of a pose, rad: one turn either way (90 is a heading in degrees).
MAX_HEADING = 2 * math.pi
#: Goal ids count from 1, one per goal.
MAX_GOAL_ID = 2 ** 31 - 1
#: set_pose's spread: a position variance of 100 m^2 (10 m) covers a home, a heading variance
#: of 10 rad^2 any heading; wider is not a guess (localize looks everywhere).
MAX_POSITION_VARIANCE, MAX_HEADING_VARIANCE = 100.0, 10.0
#: A primitive's name as people write it: the longest is 20 characters, spacing varies.
MAX_PRIMITIVE_NAME = 64

POSE = Numbers(("x", "y", "theta"), (Number(-MAX_COORDINATE, MAX_COORDINATE, "m"),) * 2
               + (Number(-MAX_HEADING, MAX_HEADING, "rad"),))
COVARIANCE = Numbers(("xx", "yy", "theta-theta"), (Number(0.0, MAX_POSITION_VARIANCE, "m^2"),) * 2
                     + (Number(0.0, MAX_HEADING_VARIANCE, "rad^2"),))
PLACE = Text("a place name", MAX_NAME)
MAP_NAME = Text("a map name", MAX_NAME)
PLAIN = "a plain name such as 'home', not a path"
GOAL_ID = Whole(1, MAX_GOAL_ID)

VERBS: dict[str, Verb] = {
    "goto": Verb({"place": Field(PLACE), "pose": Field(POSE)}, needs_driver=True,
                 doc="go to a named place or to a pose of the map (one of the two); the goal's id at once"),
    "cancel": Verb({"goal_id": Field(GOAL_ID)}, doc="cancel the running goal (or goal_id, if it is the one running)"),
    "result": Verb({"goal_id": Field(GOAL_ID, required=True)}, doc="how goal goal_id goes, or how it ended"),
    "status": Verb(doc="the latest goal's or drive's state and sentence, and where the robot is"),
    "places": Verb(doc="the named places, with their poses"),
    "save_place": Verb({"name": Field(PLACE, required=True),
                        "pose": Field(POSE, also="or absent: where the robot stands"),
                        "replace": Field(Flag(), default=False, also="true moves a place of that name")},
                       doc="save a place where the robot stands, or at a pose"),
    "rename_place": Verb({"name": Field(PLACE, required=True), "new_name": Field(PLACE, required=True)},
                         doc="give a place a new name"),
    "remove_place": Verb({"name": Field(PLACE, required=True)}, doc="forget a place"),
    "save_position": Verb(doc="remember where the robot stands, to come back with recall_position"),
    "recall_position": Verb(needs_driver=True, doc="drive back to where save_position was last called"),
    "drive": Verb({"distance": Field(Number(-MAX_STEP, MAX_STEP, "m"), required=True)}, needs_driver=True,
                  doc="drive straight, backwards when negative, stopping before obstacles"),
    "turn": Verb({"angle": Field(Number(-math.degrees(MAX_TURN), math.degrees(MAX_TURN), "deg"), required=True)},
                 needs_driver=True, doc="turn in place, left (counter-clockwise) when positive"),
    "primitive": Verb({"name": Field(Text("a primitive's name", MAX_PRIMITIVE_NAME), required=True,
                                     also=f"one of {', '.join(driving.PRIMITIVES)} (any case)"),
                       "continuous": Field(Flag(), default=False, also="true goes on until stop")},
                      needs_driver=True, doc="one of the driving primitives; stop stops whatever drives the base"),
    "settings": Verb({"change": Field(OneOf(driving.CHANGES), also="or absent: the levels now")},
                     doc="the primitives' speed or width, one level up or down"),
    "set_pose": Verb({"pose": Field(POSE, required=True), "cov": Field(COVARIANCE)},
                     doc="tell localisation where the robot is; a running goal or drive ends"),
    "localize": Verb(doc="forget where the robot is, look everywhere and turn in place (up to twice) until "
                         "found; a running goal or drive ends", needs_driver=True),
    "save_map": Verb({"name": Field(MAP_NAME, default="map", also=PLAIN)},
                     doc="save the map in use as NAME.yaml + NAME.pgm in the user's maps folder"),
    "map_start": Verb(doc="start a new map where the robot stands, to drive it everywhere (goals are refused)"),
    "map_stop": Verb(doc="stop mapping; the map built is kept to be saved, the map in use stays"),
    "map_save": Verb({"name": Field(MAP_NAME, required=True, also=PLAIN),
                      "use": Field(Flag(), default=False, also="true navigates on it from now on")},
                     doc="save the map built as NAME.yaml + NAME.pgm in the user's maps folder"),
}
