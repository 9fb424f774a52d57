"""`asibot nav ...`: send a mobile robot somewhere, drive it, and manage its places, from a shell.

    asibot nav goto fridge              # waits until it arrives (or says why not); Ctrl-C cancels
    asibot nav goto 3.0,-2.5,90 --no-wait   # x, y in m, heading in degrees
    asibot nav drive 1.0 | turn -90 | primitive "turn left 90" | stop | cancel
    asibot nav places | save-place "sofa" | rename-place sofa couch | remove-place couch
    asibot nav status
    asibot nav map start | stop | save home [--use]   # map a new home while driving it

The robot is --robot, else $ASIBOT_ROBOT, else pioneer-sim. Every refusal prints the nav
service's sentence and exits with 2, as the other commands do. Every angle typed or printed
here is in degrees; poses go to nav in radians (NavClient.goto), converted at this edge only.
Ctrl-C while the robot moves stops it (cancels the goal), then exits 130 like any Ctrl-C.
"""

from __future__ import annotations

import argparse
import math
import os
from typing import Callable, Sequence

from asibot import driving, keys
from asibot.bus import Bus
from asibot.client import NavClient
from asibot.errors import AsibotError, RpcError

DEFAULT_ROBOT = "pioneer-sim"


def _numbers(text: str) -> list[float] | None:
    """The numbers of "x,y,theta", or None when `text` is a name (a place may be called "4b")."""
    try:
        return [float(v) for v in text.split(",")] if "," in text else None
    except ValueError:
        return None


def _target(text: str) -> str | list[float]:
    """A place's name, or x,y,theta as people type it (m, m, degrees) made the pose nav takes
    (m, m, rad). A wrong list of numbers is refused here, as argparse refuses any bad value."""
    numbers = _numbers(text)
    if numbers is None:
        return text
    if len(numbers) != 3 or not all(math.isfinite(v) for v in numbers):
        raise argparse.ArgumentTypeError(
            f"give a place's name or x,y,theta (m, m, degrees) such as 1.5,-2,90, not {text!r}")
    x, y, theta = numbers
    return [x, y, math.radians(theta)]


def _pose(pose: Sequence[float]) -> str:
    """A pose from nav (m, m, rad) as people read it: the heading in degrees."""
    return f"({pose[0]:.2f}, {pose[1]:.2f}, {math.degrees(pose[2]):.0f} degrees)"


def _show(status: dict) -> str:
    pose = status.get("pose")
    where = f" at {_pose(pose)}" if pose else ""
    mapping = f"\n{status['mapping']}" if status.get("mapping") else ""
    return f"{status['state']}: {status['text']}{where}{mapping}"


def _wait_or_stop(robot: str, wait: Callable[[], dict], stop: Callable[[], object]) -> None:
    """Wait for the motion to end; on Ctrl-C stop the robot first (a person who interrupts a
    waiting command means the robot too), then let the interrupt end the command."""
    try:
        print(f"{robot}: {wait()['text']}")
    except KeyboardInterrupt:
        stop()
        print(f"{robot}: stopped on Ctrl-C")
        raise


def cmd_nav(args: argparse.Namespace) -> int:
    chosen = args.robot or os.environ.get("ASIBOT_ROBOT")
    robot = chosen or DEFAULT_ROBOT
    try:
        base = NavClient(robot)
    except RpcError as exc:
        there = [] if chosen or exc.code != "unavailable" else _nav_robots()
        if not there or robot in there:
            raise
        # The default robot is absent (the emulated and real profiles run `pioneer`): name the
        # mobile robots whose nav is there, so that the next command is the right one.
        again = " or ".join(f"`asibot nav --robot {r} {args.verb} ...`" for r in there)
        raise RpcError("unavailable", f"No nav service answers for {robot!r} (the default robot); nav runs "
                                      f"for {', '.join(map(repr, there))}: {again}, or set ASIBOT_ROBOT.") from None
    with base:
        return _nav(args, robot, base)


def _nav_robots() -> list[str]:
    """The robots whose nav service is alive on the bus (none when the bus cannot be reached)."""
    try:
        with Bus("nav", wait=2.0) as bus:
            alive = bus.alive(keys.ALL_SERVICES)
    except AsibotError:
        return []
    return sorted({instance for service, instance in map(keys.parse_service, alive) if service == "nav"})


def _nav(args: argparse.Namespace, robot: str, base: NavClient) -> int:
    """The verb, on a robot whose nav answers."""
    verb = args.verb
    if verb == "goto":
        gid = base.goto(args.target)
        if args.no_wait:
            print(f"{robot}: goal {gid} started")
            return 0
        _wait_or_stop(robot, lambda: base.wait(gid), lambda: base.cancel(gid))
    elif verb in ("drive", "turn", "primitive"):
        call = {"drive": lambda: base.drive(args.amount), "turn": lambda: base.turn(args.amount),
                "primitive": lambda: base.primitive(args.name)}[verb]
        print(f"{robot}: {call()}")
        if not args.no_wait:
            _wait_or_stop(robot, base.wait, base.stop)
    elif verb == "stop":
        base.stop()
        print(f"{robot}: stopped")
    elif verb == "cancel":
        print(f"{robot}: {base.cancel()['text']}")
    elif verb == "status":
        print(f"{robot}: {_show(base.status())}")
    elif verb == "places":
        for name, (x, y, th) in base.places().items():
            print(f"{name:24s} x {x:6.2f}  y {y:6.2f}  theta {math.degrees(th):4.0f} degrees")
    elif verb == "save-place":
        pose = base.save_place(args.name, replace=args.replace)
        print(f"{robot}: saved {args.name!r} at {_pose(pose)}")
    elif verb == "rename-place":
        base.rename_place(args.name, args.new_name)
        print(f"{robot}: {args.name!r} is now {args.new_name!r}")
    elif verb == "remove-place":
        base.remove_place(args.name)
        print(f"{robot}: {args.name!r} removed")
    elif verb == "map":
        if args.action == "save":
            print(f"{robot}: {base.map_save(args.name, use=args.use)['text']}")
        else:
            print(f"{robot}: {base.map_start() if args.action == 'start' else base.map_stop()}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    nav = sub.add_parser("nav", help="send a mobile robot to a place, drive it, manage its places")
    nav.add_argument("--robot", help=f"the robot (default $ASIBOT_ROBOT or {DEFAULT_ROBOT})")
    verbs = nav.add_subparsers(dest="verb", required=True)
    g = verbs.add_parser("goto", help="go to a named place or to x,y,theta (m, m, degrees; e.g. -1,2,90)")
    g.add_argument("target", type=_target, help="a place's name, or x,y,theta (m, m, degrees)")
    g.add_argument("--no-wait", action="store_true", help="return once the goal is accepted")
    for name, what, unit in (("drive", "drive straight", "m, negative: backwards"),
                             ("turn", "turn in place", "degrees, positive: left")):
        d = verbs.add_parser(name, help=f"{what} ({unit})")
        d.add_argument("amount", type=float, help=unit)
        d.add_argument("--no-wait", action="store_true")
    pr = verbs.add_parser("primitive", help=f"a driving primitive: {', '.join(driving.PRIMITIVES)}")
    pr.add_argument("name")
    pr.add_argument("--no-wait", action="store_true")
    verbs.add_parser("stop", help="stop whatever drives the robot")
    verbs.add_parser("cancel", help="cancel the running goal")
    verbs.add_parser("status", help="the latest goal or drive and where the robot is")
    verbs.add_parser("places", help="list the named places")
    sp = verbs.add_parser("save-place", help="save the place where the robot stands")
    sp.add_argument("name")
    sp.add_argument("--replace", action="store_true", help="move an existing place here")
    rn = verbs.add_parser("rename-place", help="rename a place")
    rn.add_argument("name")
    rn.add_argument("new_name")
    rm = verbs.add_parser("remove-place", help="remove a place")
    rm.add_argument("name")
    mp = verbs.add_parser("map", help="map a new home: start, drive the robot everywhere, save NAME --use")
    actions = mp.add_subparsers(dest="action", required=True)
    actions.add_parser("start", help="start a new map where the robot stands (then drive it around)")
    actions.add_parser("stop", help="stop mapping (the map is kept until saved or a new start)")
    sv = actions.add_parser("save", help="save the map as NAME.yaml + NAME.pgm in your maps folder")
    sv.add_argument("name")
    sv.add_argument("--use", action="store_true", help="localise and navigate on it from now on")
    nav.set_defaults(func=cmd_nav)
