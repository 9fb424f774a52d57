"""The key catalog: every Zenoh key expression of the stack, spelled once.

Services never write key strings by hand; they call these functions, so a renamed key is
one edit here and a typo is a NameError instead of a silent, empty subscription.
"""

from __future__ import annotations

from typing import Callable

import re

_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.\-]*$")
#: A robot id as the page, the API and the user's files accept it: a key chunk of 1 to 64 characters.
ROBOT_ID_PATTERN = r"[A-Za-z0-9_][A-Za-z0-9_.\-]{0,63}"

RPC_VERBS_CART = (
    "stat", "inv", "fwd", "movj", "movl", "movv", "movjv", "relj", "stop", "wait", "tool", "act",
    "home", "pointer", "jog",
)
RPC_VERBS_NAV = ("goto", "cancel", "result", "status", "places", "save_place", "rename_place", "remove_place",
                 "save_position", "recall_position", "drive", "turn", "primitive", "settings", "set_pose",
                 "localize", "save_map", "map_start", "map_stop", "map_save")
RPC_VERBS_PERCEPTION = ("find",)
RPC_VERBS_LOOK = ("find",)
RPC_VERBS_TASKS = ("list", "launch", "stop", "status")
RPC_VERBS_VOICE = ("status", "settings", "learn", "forget", "learned")


def _chunk(value: str, what: str) -> str:
    """Validate one key chunk: no wildcards, separators or empty names sneak into a key."""
    if not isinstance(value, str) or not _NAME.match(value):
        raise ValueError(
            f"{what} {value!r} is not a valid name: use letters, digits, '_', '-' or '.', "
            "without '/' or wildcards"
        )
    return value


def robot(robot_id: str) -> str:
    """Prefix of everything that belongs to one robot."""
    return f"rb/{_chunk(robot_id, 'robot id')}"


def arm_state(robot_id: str) -> str:
    return f"{robot(robot_id)}/arm/state"


def arm_command(robot_id: str) -> str:
    return f"{robot(robot_id)}/arm/command"


def gripper_state(robot_id: str) -> str:
    return f"{robot(robot_id)}/gripper/state"


def gripper_command(robot_id: str) -> str:
    return f"{robot(robot_id)}/gripper/command"


def base_cmd_vel(robot_id: str) -> str:
    return f"{robot(robot_id)}/base/cmd_vel"


def base_odom(robot_id: str) -> str:
    return f"{robot(robot_id)}/base/odom"


def base_sonar(robot_id: str) -> str:
    return f"{robot(robot_id)}/base/sonar"


def base_bumpers(robot_id: str) -> str:
    return f"{robot(robot_id)}/base/bumpers"


def base_battery(robot_id: str) -> str:
    return f"{robot(robot_id)}/base/battery"


def camera_depth(robot_id: str, name: str) -> str:
    return f"{robot(robot_id)}/camera/{_chunk(name, 'camera name')}/depth"


def camera_rgb(robot_id: str, name: str) -> str:
    return f"{robot(robot_id)}/camera/{_chunk(name, 'camera name')}/rgb"


def camera_info(robot_id: str, name: str) -> str:
    return f"{robot(robot_id)}/camera/{_chunk(name, 'camera name')}/info"


def scan(robot_id: str) -> str:
    return f"{robot(robot_id)}/scan"


def cart_state(robot_id: str) -> str:
    return f"{robot(robot_id)}/cart/state"


def cart_rpc(robot_id: str, verb: str) -> str:
    return f"{robot(robot_id)}/cart/rpc/{_chunk(verb, 'verb')}"


def driver_rpc(robot_id: str, verb: str) -> str:
    """Driver-level verbs (status, reset_fault; sim-only helpers such as reset_world)."""
    return f"{robot(robot_id)}/driver/rpc/{_chunk(verb, 'verb')}"


def driver_alive(robot_id: str) -> str:
    """Liveliness of whatever implements the driver contract for this robot."""
    return f"{robot(robot_id)}/driver/alive"


def controller_alive(robot_id: str, controller: str) -> str:
    """Liveliness of one controller of the arm and its gripper (the kinematics service), named
    by its identity: the drivers obey only the one that holds the robot (asibot.safety.ownership) and
    stop the arm when it vanishes."""
    return f"{robot(robot_id)}/controller/alive/{_chunk(controller, 'controller id')}"


def controllers_alive(robot_id: str) -> str:
    """Pattern of the liveliness tokens of every controller of the arm of `robot_id`."""
    return f"{robot(robot_id)}/controller/alive/*"


def base_controller_alive(robot_id: str, controller: str) -> str:
    """Liveliness of one controller of the mobile base (the nav service, a teleop program, a
    test), named by its identity: the drivers obey only the one that holds the base."""
    return f"{robot(robot_id)}/base/controller/alive/{_chunk(controller, 'controller id')}"


def base_controllers_alive(robot_id: str) -> str:
    """Pattern of the liveliness tokens of every controller of the base of `robot_id`."""
    return f"{robot(robot_id)}/base/controller/alive/*"


def sim_truth(robot_id: str) -> str:
    """Sim-only ground-truth base pose, kept apart from the (noisy) odometry."""
    return f"{robot(robot_id)}/sim/truth"


def nav_pose(robot_id: str) -> str:
    return f"{robot(robot_id)}/nav/pose"


def nav_map(robot_id: str) -> str:
    return f"{robot(robot_id)}/nav/map"


def nav_path(robot_id: str) -> str:
    return f"{robot(robot_id)}/nav/path"


def nav_status(robot_id: str) -> str:
    return f"{robot(robot_id)}/nav/status"


def nav_rpc(robot_id: str, verb: str) -> str:
    return f"{robot(robot_id)}/nav/rpc/{_chunk(verb, 'verb')}"


def perception_rpc(robot_id: str, verb: str) -> str:
    """Perception's verbs (`find`: where a coloured object is, in the robot's base frame)."""
    return f"{robot(robot_id)}/perception/rpc/{_chunk(verb, 'verb')}"


def look_rpc(robot_id: str, verb: str) -> str:
    """Looking with a robot's cameras for a thing a carer taught (`find`: where it stands now,
    and the grasp from there: asibot.things), answered by the web service, which keeps the
    cameras' pictures and calibrations."""
    return f"{robot(robot_id)}/look/rpc/{_chunk(verb, 'verb')}"


def tasks_rpc(verb: str) -> str:
    """The Task Creator's tasks, served by the web service (which owns the program runner):
    `list` the tasks, `launch` one by name on a robot, `stop` the running program, its `status`."""
    if verb not in RPC_VERBS_TASKS:
        raise ValueError(f"tasks verb {verb!r} is not one of {', '.join(RPC_VERBS_TASKS)}")
    return f"tasks/rpc/{verb}"


def voice_audio(source: str) -> str:
    """Microphone audio for the voice service (`AudioChunk`), one key per source: a web page
    publishes its microphone as `web-<page id>`; each source is its own stream (own resampler,
    own voice activity detection), forgotten after 2 s without a chunk."""
    return f"voice/audio/{_chunk(source, 'audio source')}"


def voice_events(source: str) -> str:
    """What the voice service says about one source's audio (`Event`): a chunk refused and
    why (`bad_audio`, `format_changed`), audio arriving faster than it is heard (`audio_overflow`),
    the source forgotten after a silence (`source_forgotten`), too many sources (`too_many_sources`)."""
    return f"voice/events/{_chunk(source, 'audio source')}"


def voice_heard() -> str:
    """Every utterance the voice service cut from any source, what it heard in it and what it
    did (`VoiceHeard`): for the Speech tab and the logs."""
    return "voice/heard"


def voice_rpc(verb: str) -> str:
    """The voice service's verbs: `status` (the words listened for, the sources, the settings),
    `settings`, `learn` / `forget` / `learned` (the user's own pronunciations of their words)."""
    if verb not in RPC_VERBS_VOICE:
        raise ValueError(f"voice verb {verb!r} is not one of {', '.join(RPC_VERBS_VOICE)}")
    return f"voice/rpc/{verb}"


def voice_source_of(key: str) -> str | None:
    """The source of a `voice/audio/<source>` key; None for any other key."""
    parts = key.split("/") if isinstance(key, str) else []
    if len(parts) == 3 and parts[:2] == ["voice", "audio"] and _NAME.match(parts[2]):
        return parts[2]
    return None


def estop(robot_id: str) -> str:
    return f"{robot(robot_id)}/estop"


def events(robot_id: str) -> str:
    return f"{robot(robot_id)}/events"


def service(service_name: str, instance: str) -> str:
    """Liveliness token of one running service instance."""
    return f"svc/{_chunk(service_name, 'service name')}/{_chunk(instance, 'instance')}"


def health(service_name: str, instance: str) -> str:
    return f"health/{_chunk(service_name, 'service name')}/{_chunk(instance, 'instance')}"


ALL_SERVICES = "svc/**"
ALL_HEALTH = "health/**"
ALL_DRIVERS = "rb/*/driver/alive"
ALL_CONTROLLERS = "rb/*/controller/alive/*"
ALL_VOICE_AUDIO = "voice/audio/*"


def every_robot(key_of_robot: Callable[..., str], *names: str) -> str:
    """The pattern matching one kind of key on every robot: `every_robot(arm_state)` is
    `rb/*/arm/state` and `every_robot(camera_rgb, "*")` is `rb/*/camera/*/rgb`, so a
    subscriber to all robots spells no key by hand either."""
    any_ = "ANY--"  # a valid chunk no real name uses, swapped for '*' afterwards
    key = key_of_robot(any_, *(any_ if n == "*" else n for n in names))
    if not key.startswith(robot(any_) + "/"):
        raise ValueError(f"{key_of_robot.__name__} does not build a robot key")
    return "/".join("*" if part == any_ else part for part in key.split("/"))
EVERYTHING = "**"

#: What, after `rb/<robot>/`, moves a robot or changes what it may do (besides every RPC).
_COMMAND_RESTS = ("arm/command", "gripper/command", "base/cmd_vel", "estop")


# ---------------------------------------------------------------- parsing
# The inverse of the functions above, for code that meets keys it did not build (status,
# recordings, exports). Wildcard patterns are not keys: they parse as nothing.

def parse_service(key: str) -> tuple[str, str]:
    """Split `svc/<service>/<instance>` into its two names."""
    parts = key.split("/")
    if len(parts) != 3 or parts[0] != "svc":
        raise ValueError(f"{key!r} is not a service liveliness key (svc/<service>/<instance>)")
    return parts[1], parts[2]


def parse_robot(key: str) -> tuple[str, str]:
    """Split `rb/<robot>/<rest>` into the robot id and the rest after it.

    `parse_robot("rb/asibot/arm/state") == ("asibot", "arm/state")`; the bare prefix
    `rb/<robot>` gives an empty rest. Raises ValueError for any other key.
    """
    parts = key.split("/", 2) if isinstance(key, str) else []
    if len(parts) < 2 or parts[0] != "rb" or not _NAME.match(parts[1]):
        raise ValueError(f"{key!r} is not a robot key (rb/<robot>/...)")
    return parts[1], parts[2] if len(parts) == 3 else ""


def robot_of(key: str) -> str | None:
    """The robot id of a `rb/<robot>/...` key; None for keys that belong to no robot."""
    try:
        return parse_robot(key)[0]
    except ValueError:
        return None


def controller_of(key: str) -> str | None:
    """The controller id of a controller's liveliness key (arm or base); None for other keys."""
    try:
        _, rest = parse_robot(key)
    except ValueError:
        return None
    parts = rest.split("/")
    if parts[:-1] in (["controller", "alive"], ["base", "controller", "alive"]) and _NAME.match(parts[-1]):
        return parts[-1]
    return None


def camera_of(key: str) -> str | None:
    """The camera name of `rb/<robot>/camera/<name>/<stream>` (depth, rgb, info); None otherwise."""
    try:
        _, rest = parse_robot(key)
    except ValueError:
        return None
    parts = rest.split("/")
    if len(parts) == 3 and parts[0] == "camera" and _NAME.match(parts[1]) and parts[2]:
        return parts[1]
    return None


def is_command(key: str) -> bool:
    """Whether publishing on `key` can move a robot or change what it may do: its commands,
    its estop and every RPC, and the voice service's microphone audio (a recorded "stop" or a
    task's words would act again). Tools that republish (replay) keep off these near live drivers."""
    if voice_source_of(key) is not None:
        return True
    try:
        _, rest = parse_robot(key)
    except ValueError:
        return False
    return rest in _COMMAND_RESTS or "/rpc/" in f"/{rest}/"
