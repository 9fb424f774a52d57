"""The nav service on the bus: one instance per robot (`--robot pioneer-sim`).

In: odometry (`keys.base_odom`), the 360-degree scan of the perception service (`keys.scan`),
the estop (`keys.estop`, followed and kept served as every process that obeys it does).
Out: velocity commands on `keys.base_cmd_vel` as the robot's base controller (it announces
itself, `asibot.safety.ownership`, and every Twist carries its identity); `nav/pose` (every cycle
the filter updated, and at `pose_hz`), `nav/map` (latched), `nav/path` (when it changes),
`nav/status` (at `status_hz` and on every change), user Events; the RPC verbs of its table
(asibot.nav.requests) on `keys.nav_rpc`, each handler given the checked arguments. While
mapping (`map_start`), `nav/map` carries the map being built every `map_period` s; `map_save`
writes it under the user's maps folder and, with `use`, makes it the map in use.

The work is in `Pilot` (localisation, goals, primitives, places); this class runs its
control loop at `rate` Hz and moves messages between it and the bus. Nothing is sent to the
base while nothing drives it, so another program can hold the base when nav is idle.
"""

from __future__ import annotations
from importlib import resources

import argparse
import logging
import math
import threading
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Callable

import numpy as np

from asibot.safety import identity, ownership
from asibot import driving, keys, verbs
from asibot import messages as m
from asibot.bus import Bus
from asibot.errors import RpcError, quote
from asibot.safety.estop import EStopState
from asibot.files import data_dir, private_dir
from asibot.runtime import Service, robot_id
from asibot.timing import Ticker
from asibot.verbs import Verb

from asibot.nav import requests
from asibot.nav.errors import NavError
from asibot.nav.geometry import Pose, as_pose
from asibot.nav.grid import OccupancyGrid
from asibot.nav.mapfile import LoadedMap, load_map, save_map
from asibot.nav.pilot import Pilot
from asibot.nav.places import Places, check_name
from asibot.nav.planner import Path as PlannedPath

log = logging.getLogger("asibot.nav")

NAME = "nav"
#: Before the first verb that drives the base for each driver (`needs_driver` in the table),
#: nav waits at most this long (s) until the driver names it the base's holder.
HOLD_GRACE = 2.0
SHIPPED_MAPS = Path(str(resources.files("asibot.maps")))


class NavService(Service):
    """Navigation of one robot on the bus."""

    def __init__(self, bus: Bus, robot: str, loaded: LoadedMap, places: Places, start: Pose, *,
                 rate: float = 15.0, pose_hz: float = 5.0, status_hz: float = 4.0, map_period: float = 2.0,
                 clock: Callable[[], float] = time.monotonic, seed: int | None = None,
                 run_loop: bool = True) -> None:
        self.bus, self.robot, self.loaded, self.clock = bus, robot, loaded, clock
        self.rate, self.pose_period, self.status_period = rate, 1.0 / pose_hz, 1.0 / status_hz
        self.map_period = map_period
        self._lock = threading.Lock()      # the pilot: the loop and the RPC handlers take turns
        self.pilot = Pilot(loaded.grid, places, start, on_event=self._event, seed=seed)
        self._pub_cmd = bus.publisher(keys.base_cmd_vel(robot), m.Twist)
        self._pub_pose = bus.publisher(keys.nav_pose(robot), m.NavPose)
        self._pub_path = bus.publisher(keys.nav_path(robot), m.NavPath)
        self._pub_status = bus.publisher(keys.nav_status(robot), m.NavStatus)
        self._pub_event = bus.publisher(keys.events(robot), m.Event)
        self.me = ownership.announce(bus, robot, "base", "nav")
        self.controller = self.me.id
        # Nav follows who holds the base as the driver does, the commands that take it by
        # priority too (a person at a joystick), so it ends its goal the moment it is overtaken.
        self.holder = ownership.Holder(robot, "base", on_change=self._on_holder)
        self.holder.follow(bus)
        bus.subscribe(keys.base_cmd_vel(robot), m.Twist, self.holder.refusal)
        #: Before the first motion for each driver: wait until it names us the holder.
        self.hold = ownership.HoldWait(bus, robot, "base", self.controller)
        bus.watch(keys.driver_alive(robot), self.hold.forget)
        self._latch_map()
        bus.subscribe(keys.base_odom(robot), m.Odometry, self._on_odom)
        bus.subscribe(keys.scan(robot), m.LaserScan, self._on_scan, maxsize=1)
        self.estop = EStopState(bus, robot, self._on_estop)
        self._serve()
        self.cycles = self.commands = 0
        self.slowest_cycle = 0.0
        self._last_pose = self._last_status = self._last_map = -math.inf
        self._status_sent: tuple | None = None
        self._path_sent: object = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="nav-loop", daemon=True)
        if run_loop:
            self._thread.start()

    # ----------------------------------------------------------------------- inputs
    def _on_odom(self, msg: m.Odometry) -> None:
        with self._lock:
            self.pilot.odometry(self.clock(), msg)

    def _on_scan(self, msg: m.LaserScan) -> None:
        with self._lock:
            self.pilot.scan(self.clock(), msg)

    def _on_estop(self, msg: m.EStop) -> None:
        with self._lock:
            self.pilot.estop(self.clock(), msg.engaged)
        self._publish_status(force=True)

    def _on_holder(self, holder: str | None) -> None:
        if holder is not None and holder != self.controller:
            with self._lock:
                self.pilot.taken_over(self.clock(), identity.short(holder))
            self._publish_status(force=True)

    def _event(self, level: str, code: str, text: str) -> None:
        log.info("event %s/%s: %s", level, code, text)
        self._pub_event.put(m.Event(level=level, code=code, text=text[:1].upper() + text[1:]))

    # ------------------------------------------------------------------------- loop
    def _loop(self) -> None:
        ticker = Ticker(self.rate, stop=self._stop)
        while ticker.wait():
            try:
                self.step()
            except Exception:   # one bad cycle must not end navigation: stop and go on
                log.exception("a nav cycle failed; the base is stopped")
                with self._lock:
                    self.pilot.stop(self.clock())
                self._send(0.0, 0.0)

    def step(self) -> None:
        """One control cycle (the loop calls it at `rate`; tests may call it by hand)."""
        t0 = time.perf_counter()
        now = self.clock()
        self.holder.tick()
        with self._lock:
            cmd = self.pilot.tick(now)
            pose = self.pilot.pose_message() if now - self._last_pose >= self.pose_period else None
            path = self.pilot.status().path
            mapper = self.pilot.mapper if self.pilot.mapping else None
            building = (self.pilot.map_grid() if mapper is not None and mapper.stats.scans
                        and now - self._last_map >= self.map_period else None)
        if building is not None:
            self._last_map = now
            self._latch_map(building, "mapping")
        if cmd is not None:
            self._send(cmd.vx, cmd.wz)
        if pose is not None:
            self._last_pose = now
            self._pub_pose.put(pose)
        if path is not self._path_sent:
            self._path_sent = path
            self._publish_path(path)
        self._publish_status()
        self.cycles += 1
        self.slowest_cycle = max(self.slowest_cycle, time.perf_counter() - t0)

    def _send(self, vx: float, wz: float) -> None:
        if self.holder.current not in (None, self.controller):
            return       # another holds the base: the driver would refuse it, with an Event
        self.commands += 1
        self.me.put(self._pub_cmd, m.Twist(vx=float(vx), wz=float(wz)))

    def _publish_path(self, path: PlannedPath | None) -> None:
        gid = self.pilot.status().goal_id or 0
        if path is None:
            self._pub_path.put(m.NavPath(goal_id=gid, points=np.zeros((0, 2), np.float32)))
        else:
            self._pub_path.put(m.NavPath(goal_id=gid, points=np.asarray(path.points, np.float32),
                                         length=float(path.length)))

    def _publish_status(self, force: bool = False) -> None:
        now = self.clock()
        with self._lock:
            msg = self.pilot.status_message()
        what = (msg.goal_id, msg.state, msg.text, msg.driving, msg.localised, msg.speed, msg.width)
        if force or what != self._status_sent or now - self._last_status >= self.status_period:
            self._status_sent, self._last_status = what, now
            self._pub_status.put(msg)

    def _latch_map(self, grid: OccupancyGrid | None = None, name: str = "") -> None:
        """Latch the map in use (or `grid`, the map being built, under `name`)."""
        if grid is None:
            grid, name = self.loaded.grid, self.loaded.yaml_path.stem
        o = grid.info.origin
        self.bus.latch(keys.nav_map(self.robot), m.NavMap(
            resolution=grid.info.resolution, origin=[o.x, o.y, o.theta], data=grid.data, name=name))

    # -------------------------------------------------------------------------- RPC
    def _serve(self) -> None:
        """Serve every verb of the table (asibot.nav.requests) with its handler below."""
        handlers: dict[str, Callable[[float, SimpleNamespace], dict]] = {
            "goto": self._rpc_goto, "cancel": self._rpc_cancel, "result": self._rpc_result,
            "status": self._rpc_status, "places": self._rpc_places, "save_place": self._rpc_save_place,
            "rename_place": self._rpc_rename_place, "remove_place": self._rpc_remove_place,
            "save_position": self._rpc_save_position, "recall_position": self._rpc_recall_position,
            "drive": self._rpc_drive, "turn": self._rpc_turn, "primitive": self._rpc_primitive,
            "settings": self._rpc_settings, "set_pose": self._rpc_set_pose, "localize": self._rpc_localize,
            "save_map": self._rpc_save_map, "map_start": self._rpc_map_start, "map_stop": self._rpc_map_stop,
            "map_save": self._rpc_map_save,
        }
        verbs.serve(self.bus, lambda verb: keys.nav_rpc(self.robot, verb), requests.VERBS,
                    {verb: self._with_pilot(handle) for verb, handle in handlers.items()}, before=self._before)

    def _with_pilot(self, handle: Callable[[float, SimpleNamespace], dict]) -> verbs.Handler:
        """`handle` holding the pilot (the loop waits meanwhile); every change is told at once."""
        def run(args: SimpleNamespace) -> dict:
            with self._lock:
                reply = handle(self.clock(), args)
            self._publish_status(force=True)
            return reply
        return run

    def _before(self, verb: str, spec: Verb, args: SimpleNamespace) -> None:
        """Before a verb that drives the base (`needs_driver`): refuse it at once while another
        program holds the base, else wait a moment until the base driver names nav its holder.
        A stop is neither refused nor delayed."""
        if not spec.needs_driver or (verb == "primitive" and driving.normalise(args.name) == "stop"):
            return
        holder = self.holder.current
        if holder not in (None, self.controller):
            if holder == self.holder.taker:
                raise RpcError("busy", f"{identity.short(holder)} drives the base of {self.robot} by hand; ask me "
                                       f"again once it has stopped for {ownership.TAKEOVER_HOLD:g} s.")
            raise RpcError("busy", f"Another program drives the base of {self.robot} ({identity.short(holder)}); "
                                   "stop it first.")
        self.hold.wait(time.monotonic() + HOLD_GRACE)

    def _rpc_goto(self, now: float, args: SimpleNamespace) -> dict:
        return self.pilot.goto(now, args.place, args.pose)

    def _rpc_cancel(self, now: float, args: SimpleNamespace) -> dict:
        return self.pilot.cancel(now, args.goal_id)

    def _rpc_result(self, now: float, args: SimpleNamespace) -> dict:
        return self.pilot.result(args.goal_id)

    def _rpc_status(self, now: float, args: SimpleNamespace) -> dict:
        msg = self.pilot.status_message()
        pose = self.pilot.pose()
        return {**{f: getattr(msg, f) for f in msg._fields if f != "stamp"}, "pose": list(pose)}

    def _rpc_places(self, now: float, args: SimpleNamespace) -> dict:
        return {"places": [{"name": p.name, "pose": list(p.pose)} for p in self.pilot.places.list()]}

    def _rpc_save_place(self, now: float, args: SimpleNamespace) -> dict:
        """Save a place: here (no pose), or at a pose; `replace` moves an existing one."""
        pose = as_pose(args.pose, "pose") if args.pose is not None else self._here()
        place = self.pilot.places.add(args.name, pose, replace=args.replace)
        return {"name": place.name, "pose": list(place.pose)}

    def _rpc_rename_place(self, now: float, args: SimpleNamespace) -> dict:
        place = self.pilot.places.rename(args.name, args.new_name)
        return {"name": place.name, "pose": list(place.pose)}

    def _rpc_remove_place(self, now: float, args: SimpleNamespace) -> dict:
        place = self.pilot.places.remove(args.name)
        return {"name": place.name}

    def _rpc_save_position(self, now: float, args: SimpleNamespace) -> dict:
        return {"pose": list(self.pilot.places.save_position(self._here()))}

    def _rpc_recall_position(self, now: float, args: SimpleNamespace) -> dict:
        return self.pilot.recall_position(now)

    def _rpc_drive(self, now: float, args: SimpleNamespace) -> dict:
        """Drive straight `distance` m (negative: backwards), closed-loop, stopping before obstacles."""
        d = args.distance
        if d == 0:
            raise NavError("distance must not be 0; use a positive distance forwards or a negative one backwards.")
        return self.pilot.drive(now, "forward" if d > 0 else "backward", amount=abs(d))

    def _rpc_turn(self, now: float, args: SimpleNamespace) -> dict:
        """Turn in place by `angle` degrees (positive: counter-clockwise)."""
        a = args.angle
        if a == 0:
            raise NavError("angle must not be 0; positive turns left (counter-clockwise), negative right.")
        return self.pilot.drive(now, "turn left" if a > 0 else "turn right", amount=math.radians(abs(a)))

    def _rpc_primitive(self, now: float, args: SimpleNamespace) -> dict:
        return self.pilot.drive(now, driving.normalise(args.name), continuous=args.continuous)

    def _rpc_settings(self, now: float, args: SimpleNamespace) -> dict:
        return self.pilot.settings(args.change)

    def _rpc_set_pose(self, now: float, args: SimpleNamespace) -> dict:
        return self.pilot.set_pose(now, args.pose, args.cov)

    def _rpc_localize(self, now: float, args: SimpleNamespace) -> dict:
        return self.pilot.localize(now)

    def _rpc_save_map(self, now: float, args: SimpleNamespace) -> dict:
        """Write the map in use as map_server YAML + PGM under the user's maps folder."""
        yaml_path, pgm = save_map(self.pilot.grid, self._map_path(args.name), bounded=self.robot)
        return {"yaml": str(yaml_path), "pgm": str(pgm)}

    def _map_path(self, name: str) -> Path:
        """data_dir()/nav/<robot>/maps/<name>.yaml (the folder made); NavError for a path. The
        folder is bounded (mapfile.MAX_MAPS, MAX_MAPS_BYTES): save_map checks it."""
        if "/" in name or "\\" in name or name.startswith("."):
            raise NavError(f"A map name is a plain name, not a path; got {quote(name, 40)}.")
        name = check_name(name)
        folder = data_dir() / "nav" / self.robot / "maps"
        private_dir(folder)
        return folder / f"{name}.yaml"

    def _rpc_map_start(self, now: float, args: SimpleNamespace) -> dict:
        """Start building a new map from the scans while the robot is driven (goals are refused)."""
        return self.pilot.map_start(now)

    def _rpc_map_stop(self, now: float, args: SimpleNamespace) -> dict:
        """Stop mapping; the map is kept to be saved, and the map in use is shown again."""
        reply = self.pilot.map_stop(now)
        self._latch_map()
        return reply

    def _rpc_map_save(self, now: float, args: SimpleNamespace) -> dict:
        """Save the map built (while mapping or after map_stop) as <name>.yaml + .pgm; with `use`,
        localise and navigate on it from now on (mapping ends)."""
        path = self._map_path(args.name)
        summary = self.pilot.mapper.summary() if self.pilot.mapper is not None else ""
        yaml_path, pgm = save_map(self.pilot.map_grid(), path, bounded=self.robot)
        reply = {"yaml": str(yaml_path), "pgm": str(pgm), "text": f"saved the map {path.stem!r} ({summary})"}
        if args.use:
            loaded = load_map(yaml_path)     # what was written, exactly as a restart would read it
            reply["text"] += "; " + self.pilot.use_map(now, loaded.grid)["text"]
            self.loaded = loaded
            self._latch_map()
        return reply

    def _here(self) -> Pose:
        if not self.pilot.localised:
            raise NavError("I am not sure where I am, so I cannot save this place; set my position first.")
        return self.pilot.pose()

    # ---------------------------------------------------------------------- runtime
    def health(self) -> dict:
        s = self.pilot.status_message()
        return {"state": s.state, "localised": s.localised, "mapping": s.mapping, "cycles": self.cycles,
                "commands": self.commands,
                "slowest_cycle_ms": round(self.slowest_cycle * 1000, 1), "holder": self.holder.current}

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=1.0)
        with self._lock:
            driving = self.pilot.status().state == "active" or self.pilot.primitives.active
            self.pilot.stop(self.clock())
        if driving:
            self._send(0.0, 0.0)


# -------------------------------------------------------------------------- command line
def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--map", default=str(SHIPPED_MAPS / "apartment.yaml"),
                   help="map_server YAML of the map (default: the sim apartment's)")
    p.add_argument("--world", default="apartment", help="world whose named places are read (default apartment)")
    p.add_argument("--initial-pose", default="charging station",
                   help="where the robot starts: x,y,theta (m, m, rad) or a place name (default 'charging station')")
    p.add_argument("--rate", type=float, default=15.0, help="control loop, Hz (10-20; default 15)")


def _start_pose(text: str, places: Places) -> Pose:
    parts = text.split(",")
    if len(parts) == 3:
        try:
            return as_pose([float(v) for v in parts], "--initial-pose")
        except (ValueError, NavError):
            pass
    try:
        return places.get(text).pose
    except NavError as exc:
        raise ValueError(f"--initial-pose must be x,y,theta or a place name: {exc.message}") from None


def build(bus: Bus, args: argparse.Namespace) -> NavService:
    robot = robot_id(args, example="pioneer-sim")   # no default: nav would wait for a robot nobody named
    if not 5.0 <= args.rate <= 50.0:
        raise ValueError(f"--rate must be between 5 and 50 Hz; got {args.rate:g}")
    try:
        loaded = load_map(args.map)
    except NavError as exc:
        raise ValueError(exc.message) from None
    try:
        places = Places.for_robot(robot, args.world, loaded.grid.info)
    except NavError as exc:
        raise ValueError(exc.message) from None
    start = _start_pose(args.initial_pose, places)
    if not loaded.grid.info.contains(start.x, start.y):
        raise ValueError(f"--initial-pose ({start.x:.2f}, {start.y:.2f}) is outside the map ({loaded.grid.info.bounds()})")
    return NavService(bus, robot, loaded, places, start, rate=args.rate)
