"""Commands to RPC calls, for every entry alike: `Dispatcher.execute(session, text) -> Reply`.

The dispatcher knows the bus, not sockets. A `Session` is one client's state: the robot it
drives (`robot <id>`, default `--robot`), what `wider`/`narrower` change (the base after a base
word, the arm step after an arm word), the arm step level, its place in the scanning menu,
whether it gave the token. Every word of the vocabulary has its handler in one table, checked
against the vocabulary when the dispatcher is built (`vocab.check_handlers`). Base words go to
the nav service of the robot (`NavClient`), arm words to its kinematics service
(`CartesianClient`), `run` to the Task Creator (`TasksClient`): the clients user programs use,
over the bridge's bus. A refusal comes back as the service's sentence.

Safety:
- a command that does not parse moves nothing (it never reaches an RPC);
- continuous motions (forward, turn left, curves, ...) go on until stop, an obstacle (nav
  stops them) or `longest` s (`expire()`, called periodically, sends stop);
- a client that disconnects, or switches robot, while a base motion it started runs (the
  latest one on that robot, not finished by nav's status) stops that robot.
"""

from __future__ import annotations

import hmac
import itertools
import logging
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Callable, Iterator

from asibot import keys
from asibot.bus import Bus
from asibot.client import CartesianClient, NavClient, TasksClient
from asibot.errors import CODES, RpcError, Unavailable

from asibot.asterics_bridge import vocabulary as vocab
from asibot.asterics_bridge.status import Notice, StatusBoard

log = logging.getLogger("asibot.asterics_bridge")

#: Arm step levels, mm (wider / narrower move one level).
ARM_STEPS_MM = (2, 5, 10, 20, 40)
DEFAULT_ARM_LEVEL = 3
#: Timeout of quick calls; the gripper takes up to 1.5 + 4 s to report (kinematics `act`).
CALL_TIMEOUT, GRIP_TIMEOUT = 3.0, 8.0
DEFAULT_LONGEST = 60.0
DEFAULT_MENU = ("stop", "forward", "turn left", "turn right", "backward", "turn around")
#: NetConnection event port -> command, by default (`--events`).
DEFAULT_EVENTS = {1: "next", 2: "select", 3: "stop"}


@dataclass(frozen=True)
class Reply:
    ok: bool
    text: str = ""
    code: str = "ok"          # ok | not_understood | forbidden | an RpcError code

    def line(self) -> str:
        """For text clients: `ok`, `ok: <detail>` or `error: <sentence>`."""
        if self.ok:
            return f"ok: {self.text}" if self.text else "ok"
        return f"error: {self.text}"

    def frame_text(self) -> str:
        """For NetConnection: `ok`, `ok: <detail>` or the sentence alone."""
        return self.line() if self.ok else self.text


class Session:
    """One client's state. `notify(notice)` is set by its server (called on bus threads)."""

    _ids = itertools.count(1)

    def __init__(self, robot: str, peer: str, authorized: bool) -> None:
        self.id = next(self._ids)
        self.robot, self.peer, self.authorized = robot, peer, authorized
        self.target = vocab.BASE
        self.arm_level = DEFAULT_ARM_LEVEL
        self.menu_index = -1
        self.notify: Callable[[Notice], None] = lambda notice: None

    def __repr__(self) -> str:
        return f"Session({self.id}, {self.peer}, robot={self.robot})"


#: What runs a word: (the client's session, the word's argument or "") -> the reply's text.
Handler = Callable[[Session, str], str]


@dataclass
class _Motion:
    """The latest base motion a client started on a robot."""
    session: Session
    word: str
    started: float        # the dispatcher's clock, s
    stamp: int            # wall clock after nav accepted it, ns (nav status stamps compare with it)
    continuous: bool


class Dispatcher:
    def __init__(self, bus: Bus, robot: str, *, longest: float = DEFAULT_LONGEST, token: str | None = None,
                 menu: tuple[str, ...] = DEFAULT_MENU, timeout: float = CALL_TIMEOUT,
                 clock: Callable[[], float] = time.monotonic) -> None:
        keys.robot(robot)    # a ValueError with a sentence for a bad id
        self.bus, self.robot, self.longest, self.token = bus, robot, longest, token
        self.menu, self.timeout, self.clock = menu, timeout, clock
        self._lock = threading.Lock()
        self._sessions: set[Session] = set()
        self._motions: dict[str, _Motion] = {}
        self._arm_saved: dict[str, list[float]] = {}
        self.counters = {"commands": 0, "ok": 0, "refused": 0, "not_understood": 0, "stops_on_disconnect": 0,
                         "stops_on_longest": 0}
        self.board = StatusBoard(bus, self._on_notice)
        self._words = self._handlers()
        vocab.check_handlers(self._words)

    def _handlers(self) -> dict[str, Handler]:
        """Every word of the vocabulary and its handler."""
        return {
            **{word: self._drive(word) for word in vocab.PRIMITIVES},
            **{word: self._step(word) for word in vocab.ARM_STEPS},
            "stop": self._do_stop, "faster": self._do_faster, "slower": self._do_slower,
            "wider": self._do_wider, "narrower": self._do_narrower, "goto": self._do_goto,
            "save position": self._do_save_position, "recall position": self._do_recall_position,
            "places": self._do_places,
            "grab": self._do_grab, "release": self._do_release, "arm save": self._do_arm_save,
            "arm recall": self._do_arm_recall, "arm home": self._do_arm_home, "arm stop": self._do_arm_stop,
            "run": self._do_run, "tasks": self._do_tasks,
            "robot": self._do_robot, "token": self._do_token, "next": self._do_next, "previous": self._do_previous,
            "select": self._do_select, "status": self._do_status, "help": self._do_help,
        }

    # ------------------------------------------------------------------ sessions
    def open_session(self, peer: str) -> Session:
        session = Session(self.robot, peer, authorized=self.token is None)
        with self._lock:
            self._sessions.add(session)
        return session

    def close_session(self, session: Session) -> None:
        """The client went away: stop a base motion it started that still runs."""
        with self._lock:
            self._sessions.discard(session)
        self._stop_own_motion(session, session.robot, "stops_on_disconnect")

    def sessions(self) -> int:
        with self._lock:
            return len(self._sessions)

    def _on_notice(self, notice: Notice) -> None:
        with self._lock:
            targets = [s for s in self._sessions if s.robot == notice.robot]
        for s in targets:
            try:
                s.notify(notice)
            except Exception:   # a client's sink must not stop the others
                log.exception("telling %r failed", s)

    # ------------------------------------------------------------------ commands
    def execute(self, session: Session, text: object) -> Reply:
        """Parse and run one command; never raises."""
        self.counters["commands"] += 1
        try:
            cmd = vocab.parse(text)
        except vocab.NotUnderstood as exc:
            self.counters["not_understood"] += 1
            return Reply(False, str(exc), "not_understood")
        return self.run(session, cmd)

    def run(self, session: Session, cmd: vocab.Command) -> Reply:
        # a stop needs no token: stopping is always safe, and whoever needs it must not be held up
        if not session.authorized and cmd.word not in ("token", "stop"):
            self.counters["refused"] += 1
            return Reply(False, "This bridge serves the network and needs its access token first: "
                                "send 'token <secret>' (asterics_bridge printed it at start).", "forbidden")
        try:
            text = self._words[cmd.word](session, cmd.arg)
        except RpcError as exc:
            self.counters["refused"] += 1
            return Reply(False, exc.message, exc.code)
        except Exception as exc:     # a bug: say so, keep serving
            log.exception("%s failed", cmd)
            self.counters["refused"] += 1
            return Reply(False, f"'{cmd}' failed inside the bridge ({type(exc).__name__}); see its log.", "internal")
        self.counters["ok"] += 1
        return Reply(True, text)

    # ------------------------------------------------------------------ services
    @contextmanager
    def _nav(self, robot: str) -> Iterator[NavClient]:
        with _answering("nav", robot):
            yield NavClient.on(self.bus, robot, timeout=self.timeout)

    @contextmanager
    def _arm(self, robot: str, timeout: float | None = None) -> Iterator[CartesianClient]:
        with _answering("kinematics", robot):
            yield CartesianClient.on(self.bus, robot, timeout=timeout or self.timeout)

    @contextmanager
    def _tasks(self, robot: str) -> Iterator[TasksClient]:
        # One Task Creator serves every robot: its absence is not the robot's.
        with _answering("web (Task Creator)", None):
            yield TasksClient.on(self.bus, robot, timeout=self.timeout)

    def _stop_base(self, robot: str) -> None:
        with self._nav(robot) as nav:
            nav.stop()

    def _stop_arm(self, robot: str) -> None:
        with self._arm(robot) as arm:
            arm.stop()

    def _stop_task(self, robot: str) -> None:
        with self._tasks(robot) as tasks:
            tasks.stop()

    # ------------------------------------------------------------------ base
    def _drive(self, word: str) -> Handler:
        """The handler of a base word that is one of nav's driving primitives."""
        name, continuous = vocab.PRIMITIVES[word]

        def drive(s: Session, arg: str) -> str:
            with self._nav(s.robot) as nav:
                text = nav.primitive(name, continuous)
            self._started(s, word, continuous)
            return text
        return drive

    def _started(self, s: Session, word: str, continuous: bool) -> None:
        s.target = vocab.BASE
        with self._lock:
            self._motions[s.robot] = _Motion(s, word, self.clock(), time.time_ns(), continuous)

    def _do_stop(self, s: Session, arg: str) -> str:
        """Stop everything of the robot that answers: base, arm, a task launched from here."""
        done, errors = [], []
        with self._lock:
            self._motions.pop(s.robot, None)
        task = self.board.robot(s.robot).task
        calls = [("base", lambda: self._stop_base(s.robot)), ("arm", lambda: self._stop_arm(s.robot))]
        if task:
            calls.append((f"task {task}", lambda: self._stop_task(s.robot)))
        for what, call in calls:
            try:
                call()
                done.append(what)
            except Unavailable:
                continue
            except RpcError as exc:
                errors.append(exc)
        if task and f"task {task}" in done:
            self.board.robot(s.robot).task = ""
        if errors and not done:
            raise errors[0]
        if not done:
            raise Unavailable(f"Nothing answers for robot '{s.robot}' (no nav, kinematics or task service); "
                              "is it running? Choose another robot with 'robot <id>'.")
        return "stopped " + " and ".join(done)

    def _settings(self, s: Session, change: str) -> str:
        with self._nav(s.robot) as nav:
            return nav.settings(change)["text"]

    def _do_faster(self, s: Session, arg: str) -> str:
        s.target = vocab.BASE
        return self._settings(s, "faster")

    def _do_slower(self, s: Session, arg: str) -> str:
        s.target = vocab.BASE
        return self._settings(s, "slower")

    def _do_wider(self, s: Session, arg: str) -> str:
        return self._width(s, +1)

    def _do_narrower(self, s: Session, arg: str) -> str:
        return self._width(s, -1)

    def _width(self, s: Session, delta: int) -> str:
        if s.target == vocab.ARM:
            old = s.arm_level
            s.arm_level = min(len(ARM_STEPS_MM), max(1, old + delta))
            edge = "" if s.arm_level != old else (" (already the longest)" if delta > 0 else " (already the shortest)")
            return f"arm step {ARM_STEPS_MM[s.arm_level - 1]} mm{edge}"
        return self._settings(s, "wider" if delta > 0 else "narrower")

    def _place_names(self, robot: str) -> list[str]:
        with self._nav(robot) as nav:
            return list(nav.places())

    def _do_goto(self, s: Session, place: str) -> str:
        names = self._place_names(s.robot)
        found = vocab.find(place, names)
        if found is None:
            known = ", ".join(names) if names else "none yet"
            raise RpcError("bad_request", f"unknown place '{place[:40]}'{vocab.suggest(place, names)} "
                                          f"(places: {known})")
        with self._nav(s.robot) as nav:
            reply = nav.goto_reply(found)
        self._started(s, f"goto {found}", False)
        return reply.get("text") or f"going to {found}"

    def _do_save_position(self, s: Session, arg: str) -> str:
        with self._nav(s.robot) as nav:
            nav.save_position()
        s.target = vocab.BASE
        return "position saved"

    def _do_recall_position(self, s: Session, arg: str) -> str:
        with self._nav(s.robot) as nav:
            reply = nav.recall_position()
        self._started(s, "recall position", False)
        return reply.get("text") or "going back to the saved position"

    def _do_places(self, s: Session, arg: str) -> str:
        names = self._place_names(s.robot)
        return "places: " + (", ".join(names) if names else "none yet")

    # ------------------------------------------------------------------ arm
    def _point(self, s: Session) -> list[float]:
        with self._arm(s.robot) as arm:
            return [float(v) for v in arm.stat()]

    def _movl(self, s: Session, point: list[float]) -> None:
        with self._arm(s.robot) as arm:
            arm.movl(point)

    def _step(self, word: str) -> Handler:
        """The handler of an arm step word: a straight line of the session's step."""
        direction = vocab.ARM_STEPS[word]

        def step(s: Session, arg: str) -> str:
            s.target = vocab.ARM
            mm = ARM_STEPS_MM[s.arm_level - 1]
            point = self._point(s)
            for i, d in enumerate(direction):
                point[i] += d * mm / 1000.0
            self._movl(s, point)
            return f"{word} {mm} mm"
        return step

    def _grip(self, s: Session, action: str) -> dict:
        s.target = vocab.ARM
        with self._arm(s.robot, GRIP_TIMEOUT) as arm:
            return arm.act(action)

    def _do_grab(self, s: Session, arg: str) -> str:
        reply = self._grip(s, "close")
        return "holding something" if reply["holding"] else "gripper closed, holding nothing"

    def _do_release(self, s: Session, arg: str) -> str:
        self._grip(s, "open")
        return "gripper open"

    def _do_arm_save(self, s: Session, arg: str) -> str:
        s.target = vocab.ARM
        point = self._point(s)
        with self._lock:
            self._arm_saved[s.robot] = point
        return "arm position saved: [" + ", ".join(f"{v:.3f}" for v in point) + "]"

    def _do_arm_recall(self, s: Session, arg: str) -> str:
        s.target = vocab.ARM
        with self._lock:
            point = self._arm_saved.get(s.robot)
        if point is None:
            raise RpcError("bad_request", f"No arm position is saved for {s.robot} yet; say 'arm save' first.")
        self._movl(s, point)
        return "arm going back to the saved position"

    def _do_arm_home(self, s: Session, arg: str) -> str:
        s.target = vocab.ARM
        with self._arm(s.robot) as arm:
            arm.home()
        return "arm going home"

    def _do_arm_stop(self, s: Session, arg: str) -> str:
        self._stop_arm(s.robot)
        return "arm stopped"

    # ------------------------------------------------------------------ tasks
    def _task_names(self, robot: str) -> list[str]:
        with self._tasks(robot) as tasks:
            return [t["name"] for t in tasks.tasks()]

    def _do_run(self, s: Session, task: str) -> str:
        try:
            with self._tasks(s.robot) as tasks:
                name = tasks.launch(task)["task"]
        except RpcError as exc:
            if exc.code == "bad_request":
                try:
                    names = self._task_names(s.robot)
                except RpcError:
                    names = []
                if names and vocab.find(task, names) is None:
                    raise RpcError("bad_request", f"unknown task '{task[:40]}'{vocab.suggest(task, names)} "
                                                  f"(tasks: {', '.join(names)})") from None
            raise
        self.board.robot(s.robot).task = name
        return f"running {name}"

    def _do_tasks(self, s: Session, arg: str) -> str:
        names = self._task_names(s.robot)
        return "tasks: " + (", ".join(names) if names else "none yet")

    # ------------------------------------------------------------------ the bridge
    def _do_robot(self, s: Session, robot: str) -> str:
        try:
            keys.robot(robot)
        except ValueError as exc:
            raise RpcError("bad_request", str(exc)) from None
        if not (self.bus.wait_for(keys.nav_rpc(robot, "status"), 0.3)
                or self.bus.wait_for(keys.cart_rpc(robot, "stat"), 0.3)):
            robots = sorted({r for r in map(keys.robot_of, self.bus.alive(keys.ALL_DRIVERS, 0.3)) if r})
            raise Unavailable(f"No robot '{robot[:40]}' answers (no nav or kinematics service)"
                              + (vocab.suggest(robot, robots) or "") + f"; robots on the bus: "
                              f"{', '.join(robots) if robots else 'none'}.")
        if robot != s.robot:
            self._stop_own_motion(s, s.robot, "stops_on_disconnect")
            s.robot = robot
        return f"now driving {robot}"

    def _do_token(self, s: Session, secret: str) -> str:
        if self.token is None:
            return "this bridge needs no token"
        if not hmac.compare_digest(secret.encode(), self.token.encode()):
            raise RpcError("bad_request", "That token is not this bridge's; check it and send 'token <secret>' again.")
        s.authorized = True
        return "token accepted"

    def _do_next(self, s: Session, arg: str) -> str:
        s.menu_index = (s.menu_index + 1) % len(self.menu)
        return self.menu[s.menu_index]

    def _do_previous(self, s: Session, arg: str) -> str:
        s.menu_index = (s.menu_index - 1) % len(self.menu)
        return self.menu[s.menu_index]

    def _do_select(self, s: Session, arg: str) -> str:
        if s.menu_index < 0:
            raise RpcError("bad_request", "Nothing is announced yet; say 'next' to hear the first command.")
        reply = self.run(s, vocab.parse(self.menu[s.menu_index]))
        if not reply.ok:
            raise RpcError(reply.code if reply.code in CODES else "bad_request", reply.text)
        return reply.text

    def _do_status(self, s: Session, arg: str) -> str:
        st = self.board.json(s.robot)
        parts = [f"{s.robot}: {st['text'] or st['state']}"]
        if st["pose"]:
            p = st["pose"]
            parts.append(f"at x {p['x']:.2f} m, y {p['y']:.2f} m, heading {p['theta']:.0f} deg")
        if st["battery"] is not None:
            parts.append(f"battery {st['battery']:.1f} V")
        if st["estop"]:
            parts.append("emergency stop engaged")
        return "; ".join(parts)

    def _do_help(self, s: Session, arg: str) -> str:
        return vocab.help_text()

    # ------------------------------------------------------------------ safety
    def _running(self, robot: str, motion: _Motion) -> bool:
        """Whether nav may still be driving `motion`: no status since it started says otherwise."""
        nav = self.board.robot(robot).nav
        return nav is None or nav.stamp <= motion.stamp or nav.state == "active"

    def _stop_own_motion(self, s: Session, robot: str, counter: str) -> None:
        with self._lock:
            motion = self._motions.get(robot)
            if motion is None or motion.session is not s:
                return
            del self._motions[robot]
        if self._running(robot, motion):
            self._send_stop(robot, motion, counter)

    def _send_stop(self, robot: str, motion: _Motion, counter: str) -> bool:
        self.counters[counter] += 1
        try:
            self._stop_base(robot)
            log.info("stopped %s (%s of %r)", robot, counter.replace("_", " "), motion.session)
            return True
        except RpcError as exc:
            log.warning("could not stop %s after %s: %s", robot, motion.word, exc)
            return False

    def expire(self) -> None:
        """Stop continuous motions older than `longest` s (call it a few times a second)."""
        now = self.clock()
        with self._lock:
            due = {r: mo for r, mo in self._motions.items()
                   if mo.continuous and now - mo.started > self.longest}
            for robot in due:
                del self._motions[robot]
        for robot, motion in due.items():
            if self._running(robot, motion) and self._send_stop(robot, motion, "stops_on_longest"):
                motion.session.notify(Notice(robot, "stopped", f"Stopped: {self.longest:g} s is the longest "
                                                               f"a motion lasts ({motion.word}).", "info"))

    def close(self) -> None:
        """The bridge stops: stop the motions its clients started that still run."""
        with self._lock:
            motions, self._motions = self._motions, {}
        for robot, motion in motions.items():
            if self._running(robot, motion):
                self._send_stop(robot, motion, "stops_on_disconnect")

    def health(self) -> dict:
        return {**self.counters, "clients": self.sessions(), "moving": sorted(self._motions)}


@contextmanager
def _answering(service: str, robot: str | None) -> Iterator[None]:
    """Calls to `service` (of `robot`): when nobody answers, the user hears which service it is
    and what to do, not the bus's key."""
    try:
        yield
    except Unavailable:
        where = f" for robot '{robot}'" if robot else ""
        raise Unavailable(f"No {service} service answers{where}; start it (asibot up), "
                          "or choose another robot with 'robot <id>'.") from None


def parse_events(text: str) -> dict[int, str]:
    """`--events "1=next,2=select,3=stop"` -> {1: "next", ...}; a ValueError sentence otherwise."""
    out: dict[int, str] = {}
    for item in filter(None, (p.strip() for p in text.split(","))):
        port, sep, command = item.partition("=")
        if not sep or not port.strip().isdigit() or not 1 <= int(port) <= 10:
            raise ValueError(f"--events takes port=command pairs with ports 1-10, e.g. '1=next,3=stop'; "
                             f"not {item!r}")
        try:
            vocab.parse(command)
        except vocab.NotUnderstood as exc:
            raise ValueError(f"--events {item!r}: {exc}") from None
        out[int(port)] = command.strip()
    return out


def parse_menu(text: str) -> tuple[str, ...]:
    items = tuple(filter(None, (p.strip() for p in text.split(","))))
    if not items:
        raise ValueError("--menu needs at least one command, e.g. 'stop,forward,turn left'")
    for item in items:
        try:
            vocab.parse(item)
        except vocab.NotUnderstood as exc:
            raise ValueError(f"--menu {item!r}: {exc}") from None
        if item.lower() in ("next", "previous", "select"):
            raise ValueError(f"--menu cannot hold {item!r}: it is what walks the menu")
    return items

