"""Who may do what on the bus once it leaves one machine: the router's access control.

On loopback every process on the machine is trusted, so `sim` and `emulated` run an open
router. A robot on a network is not: a laptop that joins must not be able to publish joint
commands or release an estop. So the router can require a user and password (Zenoh's
`usrpwd` authentication) and apply Zenoh's own `access_control`, both built here from the
key catalogue (`asibot.keys`), so no key is spelled by hand twice:

- `driver` (arm and base drivers, the simulator, perception) publishes robot state;
- `controller` (kinematics, nav) publishes commands and holds robots;
- `operator` (web page, AsTeRICS bridge, voice, the `asibot` command, `asibot.client` run by
  hand) engages and releases the estop and calls every RPC;
- `program` (a user's program run by the web page's runner, asibot.web.sandbox) calls the
  kinematics and nav verbs of `asibot.client` and reads; it publishes no command, never
  touches the estop and serves nothing, so a program cannot bypass kinematics or nav;
- `reader` (user `anonymous`, password `anonymous`, public on purpose) reads everything
  and moves nothing.

Permissions are allow lists over a denying default: Zenoh tests whether a rule's key
expression *includes* the one asked for, so a deny list would let a query on `rb/**`
through to `cart/rpc/movl`, while an allow list refuses it.

The credentials live in one private folder (0700, files 0600), made on first use:
`router.passwords` (the router's dictionary) and `<role>.credentials` (`user:password`)
per role, so a machine that only runs the web page gets only `operator.credentials` (and
`ca.pem`, to reach the router over `tls/` across a network: asibot.certificates).
A process presents credentials when `ASIBOT_ACCESS` names that folder; its role is
`ASIBOT_ROLE`, else the one of its bus name (`ROLE_OF`).
"""

from __future__ import annotations

import dataclasses
import os
import secrets
import tempfile
from pathlib import Path
from typing import Callable

from asibot import certificates, keys
from asibot.files import open_private, private_dir

ACCESS_ENV = "ASIBOT_ACCESS"
ROLE_ENV = "ASIBOT_ROLE"
ROLES = ("driver", "controller", "operator", "program", "reader")
ANONYMOUS = ("anonymous", "anonymous")   # the reader's login: public, it moves nothing
DICTIONARY = "router.passwords"

#: The role of each bus name (a service's NAME, or the `asibot` subcommand's); any other is a reader.
ROLE_OF = {
    "arm_driver": "driver", "base_driver": "driver", "sim": "driver", "perception": "driver",
    "kinematics": "controller", "nav": "controller",
    "web": "operator", "asterics_bridge": "operator", "voice": "operator", "client": "operator",
    "estop": "operator", "release": "operator", "reset-fault": "operator", "reset-world": "operator",
}

_ANY = "ANY--"   # a valid chunk no real name uses, swapped for '*' afterwards (as keys.every_robot)


def _every(key_of: Callable[..., str], *names: str) -> str:
    """`key_of` for any name in each '*' argument: `_every(keys.voice_events, "*")` is
    `voice/events/*`. Robot keys go through `keys.every_robot`."""
    key = key_of(*(_ANY if n == "*" else n for n in names))
    return "/".join("*" if part == _ANY else part for part in key.split("/"))


def _robots(*key_ofs: Callable[..., str], names: tuple[str, ...] = ()) -> list[str]:
    return [keys.every_robot(k, *names) for k in key_ofs]


# What each role may send to the router, as (messages, key expressions).
_READ = [
    (("declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"), [keys.EVERYTHING]),
    # Latched values answer `subscribe(..., latest=True)`; queries elsewhere could reach an RPC.
    (("query",), _robots(keys.estop, keys.nav_map)),
    (("liveliness_token",), [keys.ALL_SERVICES]),
    (("put", "delete"), [keys.ALL_HEALTH]),
]
_KEEP_ESTOP = (("declare_queryable", "reply"), _robots(keys.estop))   # EStopState keeps it alive

_DRIVER = [
    (("put", "delete"), _robots(keys.arm_state, keys.gripper_state, keys.base_odom, keys.base_sonar,
                                keys.base_bumpers, keys.base_battery, keys.sim_truth, keys.scan,
                                keys.events)
     + _robots(keys.camera_depth, keys.camera_rgb, keys.camera_info, names=("*",))),
    (("liveliness_token",), _robots(keys.driver_alive)),
    (("declare_queryable", "reply"), _robots(keys.driver_rpc, keys.perception_rpc, names=("*",))),
    _KEEP_ESTOP,
]
_CONTROLLER = [
    (("put", "delete"), _robots(keys.arm_command, keys.gripper_command, keys.base_cmd_vel,
                                keys.cart_state, keys.nav_pose, keys.nav_map, keys.nav_path,
                                keys.nav_status, keys.events)),
    (("liveliness_token",), _robots(keys.controller_alive, keys.base_controller_alive, names=("*",))),
    (("declare_queryable", "reply"), _robots(keys.cart_rpc, keys.nav_rpc, names=("*",))
     + _robots(keys.nav_map)),
    (("query",), _robots(keys.driver_rpc, keys.perception_rpc, names=("*",))),
    _KEEP_ESTOP,
]
_SERVED_BY_OPERATORS = ([keys.tasks_rpc(v) for v in keys.RPC_VERBS_TASKS]
                        + [keys.voice_rpc(v) for v in keys.RPC_VERBS_VOICE]
                        + _robots(keys.look_rpc, names=("*",)))
_OPERATOR = [
    (("put", "delete"), _robots(keys.estop, keys.events)
     + [keys.ALL_VOICE_AUDIO, keys.voice_heard(), _every(keys.voice_events, "*")]),
    (("declare_queryable", "reply"), _robots(keys.estop) + _SERVED_BY_OPERATORS),
    (("query",), _robots(keys.cart_rpc, keys.nav_rpc, keys.driver_rpc, keys.perception_rpc,
                         names=("*",)) + _SERVED_BY_OPERATORS),
]
#: The verbs `asibot.client` calls (CartesianClient, NavClient): what a user's program needs.
#: Not `pointer` (the page's handheld pointer) nor `jog` (its step buttons), not nav's settings,
#: maps on disk or localize.
PROGRAM_CART_VERBS = ("stat", "inv", "fwd", "movj", "movl", "movv", "movjv", "relj", "stop", "wait",
                      "tool", "act", "home")
PROGRAM_NAV_VERBS = ("goto", "cancel", "result", "status", "places", "save_place", "rename_place",
                     "remove_place", "save_position", "recall_position", "drive", "turn", "primitive",
                     "settings", "set_pose", "map_start", "map_stop", "map_save")
_PROGRAM = [
    (("query",), _robots(*(lambda r, v=v: keys.cart_rpc(r, v) for v in PROGRAM_CART_VERBS))
     + _robots(*(lambda r, v=v: keys.nav_rpc(r, v) for v in PROGRAM_NAV_VERBS))
     + _robots(*(lambda r, v=v: keys.look_rpc(r, v) for v in keys.RPC_VERBS_LOOK))),
]
_GRANTS = {"reader": _READ, "driver": _READ + _DRIVER, "controller": _READ + _CONTROLLER,
           "operator": _READ + _OPERATOR, "program": _READ + _PROGRAM}
_EVERY_MESSAGE = ["put", "delete", "declare_subscriber", "query", "declare_queryable", "reply",
                  "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"]


def username(role: str) -> str:
    """The Zenoh user name of `role`: the role's own name, `anonymous` for the reader."""
    return ANONYMOUS[0] if role == "reader" else role


#: The links of the machine's own services and of other machines (the router listens on these);
#: a program's session comes through PROGRAM_LINK, and has the program role's rights only.
SERVICE_LINKS = ("tcp", "tls")
PROGRAM_LINK = "unixsock-stream"
#: Where a router listens for programs (`unixsock-stream/<path>`): set by compose and `asibot
#: up`; else `program_endpoint` derives it from the router's own endpoint.
PROGRAM_ROUTER_ENV = "ASIBOT_PROGRAM_ROUTER"


def access_control(logins: bool = True) -> dict:
    """Zenoh's `access_control` section: a denying default, then each role's allow list.

    Every session that comes through the programs' socket (`PROGRAM_LINK`) has the program
    role's rights, whatever login it gives, on an open router too (issue 51: a program took
    the base from nav and released the page's estop). With `logins`, each other session has
    its login's role; without, an open router, every other session may do everything.
    What the router sends out (egress) is never filtered: what a session may not ask for,
    it is never sent.
    """
    rules: list[dict] = [{"id": "receive", "messages": _EVERY_MESSAGE, "flows": ["egress"],
                          "permission": "allow", "key_exprs": [keys.EVERYTHING]}]
    subjects: list[dict] = []
    policies: list[dict] = []

    def grant(name: str, grants: list, subject: dict) -> None:
        ids = []
        for i, (messages, key_exprs) in enumerate(grants):
            ids.append(f"{name}-{i}")
            rules.append({"id": ids[-1], "messages": list(messages), "flows": ["ingress"],
                          "permission": "allow", "key_exprs": sorted(set(key_exprs))})
        subjects.append({"id": name, **subject})
        policies.append({"id": name, "rules": ["receive", *ids], "subjects": [name]})

    if logins:
        for role, grants in _GRANTS.items():
            grant(role, grants, {"usernames": [username(role)], "link_protocols": list(SERVICE_LINKS)})
    else:
        grant("open", [(_EVERY_MESSAGE, [keys.EVERYTHING])], {"link_protocols": list(SERVICE_LINKS)})
    grant("programs-socket", _GRANTS["program"], {"link_protocols": [PROGRAM_LINK]})
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}


def program_endpoint(router: str) -> str:
    """Where the router on `router` listens for programs: $ASIBOT_PROGRAM_ROUTER, else a
    socket named after the router's port in this user's runtime folder."""
    explicit = os.environ.get(PROGRAM_ROUTER_ENV, "")
    if explicit:
        return explicit
    first = router.split(",")[0]
    port = first.rsplit(":", 1)[-1] if ":" in first else "router"
    return f"{PROGRAM_LINK}/{Path(tempfile.gettempdir()) / f'asibot-{os.getuid()}' / f'programs-{port}.sock'}"


def program_socket(endpoint: str) -> Path:
    """The socket file of a programs endpoint (`unixsock-stream/<path>`)."""
    prefix = PROGRAM_LINK + "/"
    if not endpoint.startswith(prefix):
        raise ValueError(f"{endpoint!r}: the programs' endpoint is {prefix}<path of a socket>, "
                         f"set in ${PROGRAM_ROUTER_ENV}")
    return Path(endpoint[len(prefix):])


# ---------------------------------------------------------------- credentials

def default_folder() -> Path:
    """$ASIBOT_ACCESS, else $XDG_CONFIG_HOME/asibot/access, else ~/.config/asibot/access."""
    env = os.environ.get(ACCESS_ENV, "")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CONFIG_HOME", "")
    base = Path(xdg) if xdg and os.path.isabs(xdg) else Path.home() / ".config"
    return base / "asibot" / "access"


def _write_private(path: Path, text: str) -> None:
    with open_private(path, "xb") as f:
        f.write(text.encode())


def ensure_credentials(folder: Path | str | None = None) -> Path:
    """Make the credentials folder with a random password per role and the router's TLS
    certificate from a CA of its own (asibot.certificates), once; return it.

    Existing files are kept (other machines already hold copies of them). The folder is
    0700 and the files 0600 (the router's dictionary holds every password), but `ca.pem`,
    which every client gets.
    """
    folder = (Path(folder) if folder else default_folder()).absolute()   # children run elsewhere
    private_dir(folder)
    dictionary = folder / DICTIONARY
    if not dictionary.exists():
        logins = {role: secrets.token_urlsafe(24) for role in ROLES if role != "reader"}
        for role, password in logins.items():
            _write_private(folder / f"{role}.credentials", f"{username(role)}:{password}\n")
        lines = [f"{username(r)}:{p}" for r, p in logins.items()] + [":".join(ANONYMOUS)]
        _write_private(dictionary, "\n".join(lines) + "\n")
    else:
        # A folder from before a role existed (`program`) gets it; the router reads its
        # dictionary when it starts, so restart it.
        users = {line.partition(":")[0] for line in dictionary.read_text().splitlines()}
        for role in ROLES:
            if role != "reader" and username(role) not in users:
                password = secrets.token_urlsafe(24)
                if not (folder / f"{role}.credentials").exists():
                    _write_private(folder / f"{role}.credentials", f"{username(role)}:{password}\n")
                else:
                    password = (folder / f"{role}.credentials").read_text().strip().partition(":")[2]
                with open(dictionary, "a") as f:
                    f.write(f"{username(role)}:{password}\n")
    certificates.ensure_router_certificate(folder)   # for tls/: logins cross a network encrypted
    return folder


def router_dictionary(folder: Path | str) -> Path:
    """The router's `user:password` file in `folder`; says how to make it when it is missing."""
    path = Path(folder) / DICTIONARY
    if not path.is_file():
        raise ValueError(f"{path} does not exist: access control needs the router's passwords there. "
                         f"Make them on the robot with `{ACCESS_ENV}={folder} python -m asibot.access` "
                         f"(or `asibot up --access`), or point {ACCESS_ENV} at the folder that has them.")
    return path


def role_of(bus_name: str) -> str:
    """This process's role: $ASIBOT_ROLE, else the role of its bus name, else `reader`."""
    role = os.environ.get(ROLE_ENV) or ROLE_OF.get(bus_name, "reader")
    if role not in ROLES:
        raise ValueError(f"{ROLE_ENV}={role!r} is not a role: use one of {', '.join(ROLES)}")
    return role


@dataclasses.dataclass(frozen=True)
class Login:
    user: str
    password: str


def login(bus_name: str) -> Login | None:
    """The user and password a session named `bus_name` presents, or None when
    $ASIBOT_ACCESS is unset (an open router refuses sessions that present any).

    A folder without this role's file gives the anonymous reader: it reads, moves nothing.
    """
    if not os.environ.get(ACCESS_ENV):
        return None
    role = role_of(bus_name)
    if role == "reader":
        return Login(*ANONYMOUS)
    path = default_folder() / f"{role}.credentials"
    try:
        user, sep, password = path.read_text().strip().partition(":")
    except FileNotFoundError:
        return Login(*ANONYMOUS)
    if not sep or not user or not password:
        raise ValueError(f"{path} is not `user:password` on one line: copy it again from the "
                         "robot's credentials folder")
    return Login(user, password)


def may(role: str, message: str, key: str) -> bool:
    """Whether the router lets `role` send `message` ("put", "query", ...) on `key`: the same
    allow lists it applies, tested the way Zenoh tests them (a rule's expression includes `key`)."""
    import zenoh   # the bus's own dependency; only asked once access control is on

    wanted = zenoh.KeyExpr(key)
    return any(message in messages and any(zenoh.KeyExpr(e).includes(wanted) for e in exprs)
               for messages, exprs in _GRANTS[role])


def _a(role: str) -> str:
    return f"an {role}" if role[0] in "aeiou" else f"a {role}"


_DOING = {"put": "publishing", "query": "calling", "declare_queryable": "serving"}


def refusal(bus_name: str, message: str, key: str) -> str | None:
    """The sentence for what the router would refuse a session named `bus_name`, or None when
    it allows it or runs without access control ($ASIBOT_ACCESS unset).

    The router drops what it refuses without a word: a call would just find nobody, and a
    publisher would publish into the void. Saying so, and who may, is the user's only clue.
    """
    found = login(bus_name)
    if found is None:
        return None
    role = "reader" if found.user == ANONYMOUS[0] else role_of(bus_name)
    if may(role, message, key):
        return None
    # `program` is the runner's to give, not a role to run something with by hand.
    able = [r for r in ROLES if r != "program" and may(r, message, key)]
    if able:
        how = (f"only {' or '.join(_a(r) for r in able)} may: run it with {ROLE_ENV}={able[0]} and "
               f"{default_folder() / (able[0] + '.credentials')} in place")
    else:
        how = "no role may (the keys of a replay under --prefix, or a misspelt key)"
    return (f"The router's access control refuses {_DOING.get(message, message)} {key} to "
            f"{found.user!r} ({role}, from {ACCESS_ENV}={default_folder()}); {how}.")


def signed_in_as(bus_name: str) -> str:
    """' as <user>' for the user a session named `bus_name` logs in with, '' on an open router:
    the part of an estop's `by` that the router vouches for."""
    found = login(bus_name)
    return f" as {found.user}" if found else ""


if __name__ == "__main__":
    # Before `docker compose up` with access control: make the folder, say where it is.
    print(ensure_credentials())
