"""The `asibot` command: up, status, router, estop, release, reset-fault, replay, export, foxglove, recordings."""

from __future__ import annotations

import argparse
import functools
import importlib.metadata
import json
import logging
import os
import re
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable

from asibot import access, keys
from asibot.safety import estop
from asibot.cli import doctor
from asibot.cli import foxglove as foxglovecli
from asibot.cli import nav as navcli
from asibot.bus import DEFAULT_ROUTER, ROUTER_ENV, Bus, open_router, router_endpoint
from asibot.client import DriverClient, SimClient
from asibot.errors import AsibotError
from asibot.messages import Health
from asibot.runtime import HEALTH_PERIOD
from asibot.safety.estop import who
from asibot.safety.identity import Identity

#: How long a driver may take to clear a fault or to reset its world, s (drives re-initialise).
RESET_TIMEOUT = 10.0
#: The distribution that installs the `asibot` command (libs/cli/pyproject.toml): its version.
DISTRIBUTION = "asibot-cli"
#: How a command ended by Ctrl-C exits: the shell's 128 + SIGINT, whatever the command.
INTERRUPTED = 128 + signal.SIGINT
#: Moves the recordings folder for `asibot up` (compose.yaml gives it to the recorder) and
#: `asibot recordings` alike.
RECORDINGS_ENV = "ASIBOT_RECORDINGS"

_NUMBER = r"\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*"
#: A number or a comma-separated list of them ("-90", "-1,2.5,0", "-1e-3"): a value, never an option.
NUMBERS = re.compile(rf"^{_NUMBER}(?:,{_NUMBER})*$")


class Parser(argparse.ArgumentParser):
    """argparse reading every token that looks like a number or a list of numbers as a value:
    coordinates and angles are often negative ("nav goto -1,2,0"), and no option of ours looks
    like a number. argparse already does this for "-90", not for "-1,2,0" or "-1e3"; its own
    test is this one pattern, so widening it keeps every other rule (subparsers inherit it)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NUMBERS


def _version() -> str:
    try:
        return importlib.metadata.version(DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:  # run from a source tree never installed
        return "unknown (not installed)"


class Stop(threading.Event):
    """Set on SIGINT or SIGTERM, remembering which: Ctrl-C exits 130 as the shell expects, while
    a SIGTERM is how a supervisor (`asibot up`, Docker) ends a service that did nothing wrong."""

    signum: int | None = None

    def exit_code(self) -> int:
        return INTERRUPTED if self.signum == signal.SIGINT else 0


def _connect(name: str, wait: float) -> Bus | None:
    """The bus for a command that reads it, or None after saying why (no router, a refused login)."""
    try:
        return Bus(name, wait=wait)
    except AsibotError as exc:
        print(exc, file=sys.stderr)
        return None


def _stop_on_signals() -> Stop:
    stop = Stop()

    def handler(signum: int, frame: object) -> None:
        if stop.is_set():
            os._exit(INTERRUPTED)   # a second Ctrl-C: the user means it
        stop.signum = signum
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop


def _find_compose() -> Path | None:
    """$ASIBOT_COMPOSE, else the checkout's compose.yaml, found from wherever in it the command
    runs (as git finds .git); None outside any checkout."""
    env = os.environ.get("ASIBOT_COMPOSE")
    if env:
        return Path(env)
    here = Path.cwd().resolve()
    for folder in (here, *here.parents):
        if (folder / "compose.yaml").is_file():
            return folder / "compose.yaml"
    return None


def _compose_path(explicit: str | None) -> Path:
    found = Path(explicit) if explicit else _find_compose()
    if found is None:
        raise SystemExit("asibot up: no compose.yaml here or in a parent folder: run it in the "
                         "repository's checkout, or name the file with --file or ASIBOT_COMPOSE")
    return found


def recordings_folder(root: Path | None = None) -> Path:
    """The one recordings folder of every command: $ASIBOT_RECORDINGS, else `recordings` in the
    checkout `root` (the folder of compose.yaml, whose recorder runs there with `--dir
    recordings`). Without `root`: the checkout `asibot up` would use from here, else this folder
    (recordings copied out of a checkout)."""
    if root is None:
        compose = _find_compose()
        root = compose.resolve().parent if compose else Path.cwd()
    return root / os.environ.get(RECORDINGS_ENV, "recordings")   # an absolute path replaces root


# ---------------------------------------------------------------- router
def cmd_router(args: argparse.Namespace) -> int:
    endpoint = args.listen or os.environ.get("ASIBOT_ROUTER_LISTEN") or router_endpoint()
    credentials = args.access or os.environ.get(access.ACCESS_ENV) or None
    stop = _stop_on_signals()
    session = open_router(endpoint, credentials)
    # The router announces itself like any service, so `asibot status` shows it.
    token = session.liveliness().declare_token(keys.service("router", "main"))
    guarded = f" with access control (logins in {credentials})" if credentials else ""
    print(f"router listening on {endpoint}{guarded}", flush=True)
    stop.wait()
    token.undeclare()
    session.close()
    return stop.exit_code()


# ---------------------------------------------------------------- up
def _use_access(credentials: Path | None) -> None:
    """This process's own session (the launcher's report on the bus) logs in as its services
    do: with the logins `up` uses, and with none on an open router, which refuses any."""
    if credentials is None:
        os.environ.pop(access.ACCESS_ENV, None)
    else:
        os.environ[access.ACCESS_ENV] = str(credentials)


def cmd_up(args: argparse.Namespace) -> int:
    from asibot.cli import compose
    from asibot.cli.launcher import ROUTER_SERVICE, BusReport, Supervisor, wait_for_port

    path = _compose_path(args.file)
    services = compose.select(compose.load(path), args.profile, args.only)
    endpoint = router_endpoint()
    if wait_for_port(endpoint, 0.2):
        print(f"Something already listens on {endpoint}: is another `asibot up` running? "
              f"See `asibot status`, or set {ROUTER_ENV} to another port.", file=sys.stderr)
        return 1
    # Hardware may be reached from other machines: its router admits logins only. `sim` and
    # `emulated` stay open on loopback unless asked (--access, or $ASIBOT_ACCESS set).
    secure = args.access if args.access is not None else (
        args.profile == "real" or bool(os.environ.get(access.ACCESS_ENV)))
    if args.tls and not secure:
        print("--tls lets other machines in: it needs access control (--access, or --profile real)",
              file=sys.stderr)
        return 2
    credentials = access.ensure_credentials() if secure else None
    _use_access(credentials)
    listen = f"{endpoint},tls/{args.tls}" if args.tls else None
    stop = _stop_on_signals()
    sup = Supervisor(services, endpoint, root=path.resolve().parent, access=credentials, listen=listen)
    names = ", ".join(s.name for s in services)
    sup.say("asibot", f"profile {args.profile}: {names}")
    if credentials:
        sup.say("asibot", f"access control on: logins in {credentials} (`{access.ACCESS_ENV}={credentials} "
                          "asibot estop` from another shell); anonymous:anonymous may only read")
    recordings = recordings_folder(path.resolve().parent)
    if args.tls:
        sup.say("asibot", f"other machines: ASIBOT_ROUTER=tls/<this machine>:{args.tls.rsplit(':', 1)[-1]}, "
                          f"with {credentials}/ca.pem and their role's .credentials in their {access.ACCESS_ENV}")
    sup.say("asibot", f"router {endpoint}; recordings in {recordings}; Ctrl-C stops")

    report: list[BusReport] = []

    def on_event(name: str, what: str) -> None:
        url = next(s for s in services if s.name == name).url
        if what == "started" and url:
            def announce() -> None:
                port = url.rsplit(":", 1)[-1].split("/")[0]
                if wait_for_port(f"tcp/127.0.0.1:{port}", 30.0):
                    sup.say("asibot", f"web: {url}")
            threading.Thread(target=announce, daemon=True).start()
        # The restart counts go on the bus while the router is there to carry them.
        if name == ROUTER_SERVICE and what == "ready":
            report.append(BusReport(sup, endpoint))
        if name == ROUTER_SERVICE and what == "stopping":
            for r in report:
                r.close()

    sup.on_event = on_event
    sup.run(stop)
    sup.say("asibot", "stopped")
    return stop.exit_code()


# ---------------------------------------------------------------- status
def _health_reports(bus: Bus) -> dict[str, Health]:
    """One Health of each live service (and of `asibot up`, with its restart counts), by key."""
    health: dict[str, Health] = {}
    bus.subscribe(keys.ALL_HEALTH, Health, lambda k, h: health.__setitem__(k, h), with_key=True)
    time.sleep(HEALTH_PERIOD + 0.2)   # every service reports once a period
    return health


def _launched(health: dict[str, Health]) -> list[dict]:
    """What `asibot up` says of the services it runs (name, pid, restarts, running); [] when
    no `asibot up` runs them (compose, or started by hand)."""
    from asibot.cli.launcher import LAUNCHER, LAUNCHER_INSTANCE

    report = health.get(keys.health(LAUNCHER, LAUNCHER_INSTANCE))
    services = report.details.get("services") if report else None
    return [s for s in services if isinstance(s, dict)] if isinstance(services, list) else []


def _status_rows(alive: list[str], health: dict[str, Health]) -> list[dict]:
    """Each live service, with its health when it reported, and its restart count when the
    `asibot up` running it said (a service and the process up started are told apart by pid)."""
    by_pid = {s.get("pid"): s for s in _launched(health) if s.get("pid")}
    rows = []
    for key in alive:
        service, instance = keys.parse_service(key)
        h = health.get(keys.health(service, instance))
        launched = by_pid.get(h.pid) if h else None
        rows.append({"service": service, "instance": instance,
                     "pid": h.pid if h else None, "uptime": h.uptime if h else None,
                     "rejected": h.rejected if h else None,
                     "launched_as": launched.get("name") if launched else None,
                     "restarts": launched.get("restarts") if launched else None})
    return rows


def _print_status(rows: list[dict]) -> None:
    w = max(len(r["service"]) for r in rows)
    print(f"{'SERVICE':<{w}}  INSTANCE")
    for r in rows:
        line = f"{r['service']:<{w}}  {r['instance']}"
        if r["pid"] is not None:
            line += f"  pid {r['pid']}  up {r['uptime']:.0f} s  rejected {r['rejected']}"
        if r["restarts"] is not None:
            line += f"  restarts {r['restarts']}"
        print(line)


def cmd_status(args: argparse.Namespace) -> int:
    bus = _connect("status", args.wait)
    if bus is None:
        return 1
    with bus:
        health = _health_reports(bus) if args.health or args.json else {}
        alive = bus.alive(keys.ALL_SERVICES)
    rows = _status_rows(alive, health)
    if args.json:
        print(json.dumps({"router": bus.endpoint, "services": rows, "launched": _launched(health)}, indent=2))
    elif rows:
        _print_status(rows)
    else:
        print(f"No services are running on {bus.endpoint}.")
    return 0 if rows else 1


# ---------------------------------------------------------------- safety
def _who() -> str:
    import getpass
    import socket
    try:
        return f"{getpass.getuser()}@{socket.gethostname()}"
    except Exception:  # no user name in some containers
        return socket.gethostname()


def _driver_estop(driver: DriverClient) -> bool | None:
    """What the robot's driver says of its estop; None when it cannot say."""
    try:
        return bool(driver.status().get("estop"))
    except AsibotError:
        return None


def _refused(bus: Bus, robots: list[str]) -> bool:
    """Say so (True) when the router's access control would drop this session's estop."""
    why = next(filter(None, (bus.refusal("put", keys.estop(r)) for r in robots)), None)
    if why is not None:
        print(why, file=sys.stderr)
    return why is not None


def cmd_estop(args: argparse.Namespace) -> int:
    with Bus("estop", wait=args.wait) as bus:
        robots = args.robots or sorted(keys.robot_of(k) or k for k in bus.alive(keys.ALL_DRIVERS))
        if not robots:
            print("No robot is live (no driver is running): there is nothing to stop.", file=sys.stderr)
            return 1
        if _refused(bus, robots):
            return 1
        reason = f"asibot estop by {_who()}"
        by = who("asibot estop", login_of="estop")
        me = Identity("asibot-estop")
        for robot in robots:
            estop.latch(bus, robot, me, True, reason, by)
        code = 0
        for robot in robots:
            engaged = _wait_for(functools.partial(_driver_estop, DriverClient.on(bus, robot, timeout=1.0)), 2.0)
            if engaged:
                print(f"{robot}: stopped; the emergency stop holds until `asibot release {robot}`")
            else:
                print(f"{robot}: the stop was sent, but its driver did not confirm it: check the robot",
                      file=sys.stderr)
                code = 1
    return code


def cmd_release(args: argparse.Namespace) -> int:
    # `by` names the login the router admitted (when it checks logins): a release from a
    # session without the operator's is never delivered, so it is never logged either.
    by = who("asibot release", login_of="release")
    with Bus("release", wait=args.wait) as bus:
        if _refused(bus, [args.robot]):
            return 1
        estop.latch(bus, args.robot, Identity("asibot-release"), False, "asibot release", by)
        driver = DriverClient.on(bus, args.robot, timeout=1.0)
        if _wait_for(lambda: _driver_estop(driver) is False, 2.0):
            print(f"{args.robot}: emergency stop released by {by}; it moves again only on a new motion request")
            return 0
    print(f"{args.robot}: the release was sent, but no driver of {args.robot} confirmed it "
          "(`asibot status` lists the running services)", file=sys.stderr)
    return 1


def cmd_reset_fault(args: argparse.Namespace) -> int:
    """Ask the robot's driver to clear its fault; its sentence on refusal."""
    with Bus(args.command, wait=args.wait) as bus:
        reply = DriverClient.on(bus, args.robot, timeout=RESET_TIMEOUT).reset_fault()
    reply.pop("ok", None)
    print(f"{args.robot}: fault cleared" + (f" {reply}" if reply else ""))
    return 0


def cmd_reset_world(args: argparse.Namespace) -> int:
    """Put a simulated robot's world back as it started."""
    with Bus(args.command, wait=args.wait) as bus:
        SimClient.on(bus, args.robot, timeout=RESET_TIMEOUT).reset_world()
    print(f"{args.robot}: world reset: objects and arm where they started, odometry at zero")
    return 0


def _wait_for(condition: Callable[[], object], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


# ---------------------------------------------------------------- recordings
def cmd_recordings(args: argparse.Namespace) -> int:
    from asibot.recorder.reader import list_recordings

    folder = Path(args.dir) if args.dir else recordings_folder()
    found = list_recordings(folder)
    if not found:
        print(f"No recordings in {folder}/ yet: `asibot up` writes one per session.")
        return 0
    print(f"{'FILE':<40} {'DURATION':>9} {'MESSAGES':>9} {'TOPICS':>6}  NOTE")
    for s in found:
        note = ("not an MCAP file" if s.unreadable else
                "live (being recorded)" if s.live else
                "" if s.complete else "recovered (writer did not finish)")
        print(f"{s.path.name:<40} {s.duration:>8.1f}s {s.messages:>9} {len(s.counts):>6}  {note}")
        if args.verbose:
            for key, n in sorted(s.counts.items()):
                print(f"    {key:<60} {n:>8}  {s.types.get(key, '')}")
    return 0


# ---------------------------------------------------------------- replay
def _readable_recording(path: str) -> bool:
    """True when `path` is an MCAP file; otherwise says why on stderr."""
    from asibot.recorder.reader import NotARecording, check_recording

    if not Path(path).is_file():
        print(f"{path}: no such recording (see `asibot recordings`)", file=sys.stderr)
        return False
    try:
        check_recording(path)
    except NotARecording as exc:
        print(exc, file=sys.stderr)
        return False
    return True


def cmd_replay(args: argparse.Namespace) -> int:
    from asibot.recorder.replay import DEFAULT_EXCLUDE, LiveGuard, replay

    if not _readable_recording(args.file):
        return 1
    if args.prefix is not None:
        try:
            keys.robot(args.prefix)  # a prefix is one key chunk, like a robot id
        except ValueError:
            print(f"--prefix must be one name of letters, digits, '_', '-' or '.', not {args.prefix!r}",
                  file=sys.stderr)
            return 2
    speed = None if args.fast else args.speed
    stop = _stop_on_signals()
    bus = _connect("replay", args.wait)
    if bus is None:
        return 1
    with bus:
        # Ask before watching: zenoh 1.x may answer a liveliness query made just after a
        # liveliness subscriber was declared with nothing.
        live = sorted(keys.robot_of(k) or k for k in bus.alive(keys.ALL_DRIVERS))
        guard = LiveGuard()
        bus.watch(keys.ALL_DRIVERS, guard.on_driver)
        if live and not args.into_live and args.prefix is None:
            print(f"Not replaying: the robots {', '.join(live)} are live (their drivers run), and the "
                  "recording's commands would move them. Stop the stack first, or replay beside it "
                  "with --prefix NAME (keys become NAME/...), or pass --into-live if you mean to drive "
                  "the live robots with the recording.", file=sys.stderr)
            return 2
        if args.into_live and live:
            print(f"warning: replaying INTO the live robots {', '.join(live)}: their recorded commands "
                  "will move them. Ctrl-C stops the replay; `asibot estop` stops the robots.", file=sys.stderr)
        refused: list[str] = []

        def put(key: str, payload: bytes) -> None:
            key = key if args.prefix is None else f"{args.prefix}/{key}"
            why = bus.refusal("put", key)
            if why is not None:   # the router would drop it silently: stop and say so
                refused.append(why)
                stop.set()
                return
            bus.put_raw(key, payload)

        n = replay(args.file, put, speed=speed, only=args.only,
                   exclude=list(DEFAULT_EXCLUDE) + args.exclude, stop=stop,
                   allows=None if (args.into_live or args.prefix is not None) else guard.allows)
        if refused:
            print(f"Not replaying: {refused[0]} Replay into a stack started without access control "
                  "(`asibot up`, or `asibot up --no-access`).", file=sys.stderr)
            return 2
    print(f"replayed {n} messages from {args.file}")
    if guard.held:
        print(f"held back {guard.held} commands because a driver came alive during the replay "
              f"({', '.join(sorted(guard.drivers))})")
    return stop.exit_code()


# ---------------------------------------------------------------- export
def cmd_export(args: argparse.Namespace) -> int:
    from asibot.recorder.export import export_foxglove

    if not _readable_recording(args.file):
        return 1
    stop = _stop_on_signals() if args.follow else None
    try:
        summary = export_foxglove(args.file, args.output, follow=args.follow, stop=stop)
    except OSError as exc:
        print(f"could not write the export ({exc.strerror or exc}): choose a folder you can write to "
              "with -o", file=sys.stderr)
        return 1
    print(f"wrote {summary.messages} messages on {len(summary.schemas)} topics to {summary.output}")
    if args.verbose:
        for topic, schema in sorted(summary.schemas.items()):
            print(f"    {topic:<60} {schema}")
    if summary.skipped:
        print(f"skipped {summary.skipped} messages that were not valid (see the recorder's log)")
    if summary.stopped:
        print("stopped following on Ctrl-C: exported what was recorded until then")
    elif summary.live and not args.follow:
        print("the recording was still being written: exported what it held when the export began "
              "(--follow goes on until the recording ends)")
    elif not summary.complete:
        print("the recording ends in a truncated chunk (its writer did not finish): exported up to there")
    print("open it in Foxglove or Lichtblick: File > Open local file")
    return stop.exit_code() if stop is not None else 0


def _host_port(text: str) -> str:
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise argparse.ArgumentTypeError(f"give HOST:PORT such as 0.0.0.0:7448, not {text!r}")
    return text


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="asibot", description="assistive robot stack")
    p.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = p.add_subparsers(dest="command", required=True)

    up = sub.add_parser("up", help="start the router and a profile's services as local processes")
    up.add_argument("--profile", default="sim", choices=["sim", "emulated", "real"],
                    help="which robots: sim: both MuJoCo worlds (asibot-sim, pioneer-sim; the default); "
                         "emulated: the real drivers against wire-level emulators (asibot, pioneer); "
                         "real: the real drivers on hardware (ASIBOT_ARM_CAN, ASIBOT_PIONEER_PORT)")
    up.add_argument("--only", nargs="+", metavar="NAME", help="start only these services (and their dependencies)")
    up.add_argument("--file", help="compose file (default: compose.yaml in this folder or a parent)")
    up.add_argument("--access", action=argparse.BooleanOptionalAction, default=None,
                    help="router with logins and access control (default: on for --profile real "
                         f"or when ${access.ACCESS_ENV} is set)")
    up.add_argument("--tls", metavar="HOST:PORT", type=_host_port,
                    help="also let other machines in, encrypted, on this address (e.g. 0.0.0.0:7448); "
                         "needs access control")
    up.set_defaults(func=cmd_up)

    st = sub.add_parser("status", help="list the running services")
    st.add_argument("--health", action="store_true", help="also wait for one health report of each")
    st.add_argument("--json", action="store_true",
                    help="machine-readable: each service with its health and, under `asibot up`, its "
                         "restart count (waits for one health report)")
    st.add_argument("--wait", type=float, default=2.0, help="seconds to wait for the router")
    st.set_defaults(func=cmd_status)

    r = sub.add_parser("router", help="run the Zenoh router")
    r.add_argument("--listen", help=f"endpoint (default: $ASIBOT_ROUTER_LISTEN, ${ROUTER_ENV}, {DEFAULT_ROUTER})")
    r.add_argument("--access", metavar="FOLDER",
                   help=f"admit only the logins of FOLDER, with their roles (default: ${access.ACCESS_ENV})")
    r.set_defaults(func=cmd_router)

    rp = sub.add_parser("replay", help="republish a recording on the bus")
    rp.add_argument("file")
    g = rp.add_mutually_exclusive_group()
    g.add_argument("--speed", type=float, default=1.0, help="time scale (2 = twice as fast)")
    g.add_argument("--fast", action="store_true", help="as fast as possible")
    rp.add_argument("--only", action="append", default=[], help="key pattern to replay; repeatable")
    rp.add_argument("--exclude", action="append", default=[], help="key pattern to skip; repeatable")
    rp.add_argument("--wait", type=float, default=2.0, help="seconds to wait for the router")
    live = rp.add_mutually_exclusive_group()
    live.add_argument("--prefix", help="republish every key under PREFIX/ (beside a live stack, moving nothing)")
    live.add_argument("--into-live", action="store_true",
                      help="replay commands into live robots too (they will move as recorded)")
    rp.set_defaults(func=cmd_replay)

    ex = sub.add_parser("export", help="convert a recording for Foxglove (its schemas, binary images)")
    ex.add_argument("file")
    ex.add_argument("--foxglove", action="store_true", default=True,
                    help="Foxglove's well-known schemas, JSON for the rest (the only format, and the default)")
    ex.add_argument("-o", "--output", help="output file (default: foxglove/<name>.mcap beside the recording)")
    ex.add_argument("--follow", action="store_true",
                    help="of a recording being written: go on until it ends (or Ctrl-C), not stop at what it held")
    ex.add_argument("-v", "--verbose", action="store_true", help="list topics and their schemas")
    ex.set_defaults(func=cmd_export)
    foxglovecli.add_parser(sub)

    es = sub.add_parser("estop", help="emergency stop: stop robots now and refuse motion until released")
    es.add_argument("robots", nargs="*", help="robot ids (default: every live robot)")
    es.add_argument("--wait", type=float, default=2.0, help="seconds to wait for the router")
    es.set_defaults(func=cmd_estop)
    rl = sub.add_parser("release", help="release a robot's emergency stop")
    rl.add_argument("robot")
    rl.add_argument("--wait", type=float, default=2.0, help="seconds to wait for the router")
    rl.set_defaults(func=cmd_release)
    for name, func, text in (
            ("reset-fault", cmd_reset_fault, "ask a robot's driver to clear its fault"),
            ("reset-world", cmd_reset_world, "simulated robots only: put the world back as it started (the red can too)")):
        rf = sub.add_parser(name, help=text)
        rf.add_argument("robot")
        rf.add_argument("--wait", type=float, default=2.0, help="seconds to wait for the router")
        rf.set_defaults(func=func)

    navcli.add_parser(sub)
    doctor.add_parser(sub)

    rc = sub.add_parser("recordings", help="list recordings with duration, topics and counts")
    rc.add_argument("dir", nargs="?",
                    help=f"default: ${RECORDINGS_ENV}, else recordings/ in the checkout `asibot up` uses")
    rc.add_argument("-v", "--verbose", action="store_true", help="per-topic counts and types")
    rc.set_defaults(func=cmd_recordings)
    return p


def main(argv: list[str] | None = None) -> int:
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except KeyboardInterrupt:  # Ctrl-C where a command has no handler of its own: no traceback
        return INTERRUPTED
    except BrokenPipeError:  # `asibot recordings -v | head`: the reader has all it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except AsibotError as exc:
        print(f"asibot {args.command}: {exc}", file=sys.stderr)
        return 2
    except ValueError as exc:  # compose errors and bad arguments: a sentence, not a traceback
        print(f"asibot {args.command}: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
