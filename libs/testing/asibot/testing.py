"""Test helpers: a real router on a free loopback port, polling with a deadline, an ideal
arm driver to test controllers against (also used by bench/bench_control.py), and a stream
of commands on a thread, as a held jog button sends them."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from asibot.safety import estop, identity
from asibot import keys, messages
from asibot.bus import MEMORY_SCHEME, ROUTER_ENV, Bus, open_router
from asibot.safety.driver_contract import DriverContract, command
from asibot.safety.ownership import Holder
from asibot.errors import MessageError
from asibot.safety.identity import Identity
from asibot.messages import ArmCommand, ArmState, EStop, GripperCommand, GripperState
from asibot.timing import Ticker


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def _every_bus_on(endpoint: str) -> Iterator[str]:
    """Point ASIBOT_ROUTER, the default of every Bus(), at `endpoint` (restored after)."""
    previous = os.environ.get(ROUTER_ENV)
    os.environ[ROUTER_ENV] = endpoint
    try:
        yield endpoint
    finally:
        if previous is None:
            os.environ.pop(ROUTER_ENV, None)
        else:
            os.environ[ROUTER_ENV] = previous


@contextlib.contextmanager
def router(port: int | None = None) -> Iterator[str]:
    """Run a Zenoh router in this process and point ASIBOT_ROUTER at it (restored after)."""
    endpoint = f"tcp/127.0.0.1:{port or free_port()}"
    session = open_router(endpoint)
    try:
        with _every_bus_on(endpoint):
            yield endpoint
    finally:
        session.close()


@contextlib.contextmanager
def memory_bus(name: str) -> Iterator[str]:
    """Point every Bus() opened in this process at the in-memory bus `mem://NAME` (no router)."""
    with _every_bus_on(MEMORY_SCHEME + name) as endpoint:
        yield endpoint


def scheduling_delay(samples: int = 20, period: float = 0.005) -> float:
    """How late this machine wakes a sleeping thread right now (the worst of `samples` short
    sleeps), s. Timing checks allow for it instead of assuming an idle machine."""
    worst = 0.0
    for _ in range(samples):
        t = time.monotonic()
        time.sleep(period)
        worst = max(worst, time.monotonic() - t - period)
    return worst


#: A browser script (Playwright's `add_init_script`) that makes a page believe a graphics card
#: draws its WebGL: the renderer's name is all the 3D view asks (viewer3d.js). On these machines
#: Chromium has none and draws in software.
PRETEND_GPU = """(() => {
  for (const proto of [WebGLRenderingContext.prototype, WebGL2RenderingContext.prototype]) {
    const real = proto.getParameter;
    proto.getParameter = function (what) { return what === 0x9246 ? 'Pretended GPU' : real.call(this, what); };
  }
})();"""


#: The start of a program that tries what a confined program must not do, each wall once:
#: `attempt(name, fn)` prints "NAME allowed", or "NAME refused" when fn raises OSError.
ATTEMPTS = """
def attempt(name, fn):
    try:
        fn()
        print(name, "allowed")
    except OSError:
        print(name, "refused")
"""

#: A program that escapes its process group two ways, a child that calls setsid() and a daemon
#: (double fork, setsid, orphaned), both marked with `{marker}` in their command lines; it says
#: "both up" once both run, then runs `{then}`. What the sandbox's Stop must end.
ESCAPING_PROGRAM = """
import os, subprocess, sys, time
M = "{marker}"
subprocess.Popen([sys.executable, "-c", "import os, time; os.setsid(); time.sleep(60)", M])
pid = os.fork()
if pid == 0:
    os.setsid()
    if os.fork() == 0:
        os.execv(sys.executable, [sys.executable, "-c", "import time; time.sleep(60)", M])
    os._exit(0)
os.waitpid(pid, 0)

def running():
    n = 0
    for p in os.listdir("/proc"):
        try:
            with open(f"/proc/{{p}}/cmdline", "rb") as f:
                n += M.encode() in f.read()
        except OSError:
            pass
    return n
while running() < 2:
    time.sleep(0.01)
print("both up", flush=True)
{then}
"""


def alive(pid: int) -> bool:
    """Running, not a zombie (an orphan's zombie may wait for a busy init in a container)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ("Z", "X")


def processes_with(marker: str) -> list[int]:
    """The pids (this side's) of live processes with `marker` in their command line."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if marker.encode() in (entry / "cmdline").read_bytes() and alive(int(entry.name)):
                    found.append(int(entry.name))
            except OSError:
                pass
    return found


def release_counts_only_signed(bus: Any, robot: str, events: Callable[[str], list], by: str) -> None:
    """The driver contract's estop release, as a driver test checks it: a release that only
    writes a name (`by`) is refused with a `release_refused` Event; a signed one releases,
    and its `estop_released` Event names `by` and the key that signed it. `events(code)` is
    the driver's Events of that code so far."""
    bus.latch(keys.estop(robot), EStop(engaged=False, by=by))
    wait_until(lambda: events("release_refused"), 5, message="no release_refused event")
    assert f"{by}, unsigned) was ignored: it is not signed" in events("release_refused")[0].text
    assert not events("estop_released")
    sender = Identity("asibot-release")
    estop.latch(bus, robot, sender, False, "asibot release", by)
    wait_until(lambda: events("estop_released"), 5, message="no estop_released event")
    text = events("estop_released")[0].text
    assert f"released by {by}, key {identity.short(sender.id)}" in text, text


def signed_raw(controller: Any, cls: type, payload: dict) -> bytes:
    """`payload` as a `cls` command of `controller` would travel: signed when it makes a valid
    message (values a driver must refuse itself), else as it is, in its name (values the
    message check refuses before any signature counts)."""
    try:
        msg = cls(**payload)
    except MessageError:
        return messages.pack({**payload, "controller": controller.id})
    return messages.encode(controller.sign(msg))


def file_mode(path: Any) -> int:
    """The permission bits of `path` (0o600 ...), for tests of what is private."""
    import stat
    return stat.S_IMODE(os.stat(path).st_mode)


def release(bus: Any, robot: str, reason: str = "released by a test", by: str = "a test") -> EStop:
    """Release the estop of `robot` as people and programs do: signed (asibot.safety.estop)."""
    return estop.latch(bus, robot, Identity("test"), False, reason, by)


@contextlib.contextmanager
def busy_cores(n: int = os.cpu_count() or 2) -> Iterator[None]:
    """`n` processes spinning while the block runs (both cores of this machine busy): what a
    real-time part must survive. For a test marked `alone` or a benchmark."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        time.sleep(0.2 if n else 0)         # running before the block starts
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


def wait_until(predicate: Callable[[], object], timeout: float = 5.0, interval: float = 0.01,
               message: str | Callable[[], str] = "") -> object:
    """Poll until predicate() is truthy; return its value or raise AssertionError on timeout.

    `message` may be a function, called at the timeout, to say the state then rather than
    the state when the wait began."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            said = message() if callable(message) else message
            raise AssertionError(said or f"condition not met within {timeout} s")
        time.sleep(interval)


class IdealDriver:
    """An ideal arm driver behind the driver contract (asibot.safety.driver_contract), as the
    CANopen driver and the sim are: an integrator that publishes arm/state and gripper/state at
    100 Hz and obeys arm/command in position mode within the joint limits and max velocities,
    from the controller that holds the robot only, holding still while the estop is engaged,
    for the robot `robot` of catalog entry `spec` (asibot.robots.RobotSpec). Starts at
    spec.home; `set_joints(q)` teleports it (rad). The fingers move at 0.1 m/s and stop on an
    object of width `object_width` (m) if set; with `gripper_start_delay` (s) they start only
    that long after each gripper command, as a slow gripper or a loaded machine does (and
    never, while it is `math.inf`)."""

    def __init__(self, robot: str, spec: Any) -> None:
        self.spec = spec
        self.q = np.asarray(spec.home, float).copy()
        self.target = self.q.copy()
        self.vmax = np.asarray(spec.max_velocity, float)
        self.commands: list[ArmCommand] = []
        self.gripper = 0.0
        self.gripper_target = 0.0
        #: Width of an object between the fingers (m), or None: closing stops on it.
        self.object_width: float | None = None
        #: How long after a gripper command the fingers start to move, s.
        self.gripper_start_delay = 0.0
        self._grip_pending: tuple[float, float] | None = None  # (opening, when commanded)
        self._estop = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self.bus = Bus("ideal-driver")
        self.pub = self.bus.publisher(keys.arm_state(robot), ArmState)
        self.grip_pub = self.bus.publisher(keys.gripper_state(robot), GripperState)
        self.contract = DriverContract(self.bus, robot)
        self.contract.serve([command("arm", self._obey_arm), command("gripper", self._obey_grip)],
                            on_holder=lambda part, holder: None, on_estop=self._on_estop,
                            status=lambda: {"estop": self._estop}, reset_fault=dict)
        self.thread = threading.Thread(target=self._run, name="ideal-driver", daemon=True)
        self.thread.start()

    @property
    def holder(self) -> Holder:
        """Who holds the arm, as the driver sees it."""
        return self.contract.holders["arm"]

    def _obey_arm(self, cmd: ArmCommand) -> None:
        """`commands`: every position command of the holder, obeyed or refused by the estop."""
        if cmd.mode != "position" or len(cmd.values) != len(self.q):
            return
        with self._lock:
            self.commands.append(cmd)
            if self._estop:
                raise ValueError("the estop is engaged")   # refused by the stop: counted, no Event
            self.target = np.clip(cmd.values, self.spec.lower, self.spec.upper)

    def _obey_grip(self, cmd: GripperCommand) -> None:
        if self._estop:
            raise ValueError("the estop is engaged")   # refused by the stop: counted, no Event
        with self._lock:
            self._grip_pending = (cmd.opening, time.monotonic())

    def _on_estop(self, engaged: bool, reason: str, by: str) -> None:
        with self._lock:
            self._estop = engaged
            if engaged:                      # hold where it is, as the drivers do
                self.target = self.q.copy()
                self._grip_pending = None
                self.gripper_target = self.gripper

    def set_joints(self, q) -> None:
        """Put the arm at q (rad) at once, holding there."""
        with self._lock:
            self.q = np.asarray(q, float).copy()
            self.target = self.q.copy()

    def move_to(self, q) -> None:
        """Start moving towards q (rad) at the joints' max speeds, as on a command the
        controller under test did not send (a stale one, another program's)."""
        with self._lock:
            self.target = np.clip(np.asarray(q, float), self.spec.lower, self.spec.upper)

    def _run(self) -> None:
        ticker = Ticker(100.0, stop=self._stop)
        dt = ticker.period
        for _ in ticker:
            with self._lock:
                step = np.clip(self.target - self.q, -self.vmax * dt, self.vmax * dt)
                self.q = self.q + step
                q, v = self.q.tolist(), (step / dt).tolist()
                if self._grip_pending is not None and \
                        time.monotonic() >= self._grip_pending[1] + self.gripper_start_delay:
                    self.gripper_target, self._grip_pending = self._grip_pending[0], None
                floor = self.object_width if self.object_width is not None else 0.0
                target = max(self.gripper_target, floor)
                self.gripper += float(np.clip(target - self.gripper, -0.1 * dt, 0.1 * dt))
                holding = self.object_width is not None and abs(self.gripper - floor) < 1e-6 \
                    and self.gripper_target < floor
            self.pub.put(ArmState(names=list(self.spec.joint_names), positions=q, velocities=v, mode="position"))
            self.grip_pub.put(GripperState(opening=self.gripper, holding=holding))

    def close(self) -> None:
        self._stop.set()
        self.thread.join(timeout=1.0)
        self.bus.close()


class Inbox:
    """A thread-safe list of what a subscription delivered: `bus.subscribe(key, T, inbox)`."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._items: list = []

    def __call__(self, msg: object) -> None:
        with self._lock:
            self._items.append(msg)

    def __len__(self) -> int:
        with self._lock:
            return len(self._items)

    def all(self) -> list:
        with self._lock:
            return list(self._items)

    def last(self) -> object:
        with self._lock:
            return self._items[-1]


class Stack:
    """`asibot up` as a user runs it, for end-to-end tests: a subprocess reading a copy of
    `compose` in `folder`, its own router and web ports, recordings and user files in `folder`,
    stopped with Ctrl-C (SIGINT)."""

    def __init__(self, folder: Path, profile: str, only: list[str], compose: Path) -> None:
        self.folder = folder
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.web_port = free_port()
        self.web_url = f"http://127.0.0.1:{self.web_port}/"
        self.data = folder / "data"
        #: the emulated Pioneer's ARCOS and control ports, and the AsTeRICS bridge's TCP and HTTP
        #: ports (compose.yaml): this stack's own, unless the environment names them
        ports = {name: int(os.environ.get(name) or free_port()) for name in (
            "ASIBOT_PIONEER_EMULATOR_PORT", "ASIBOT_PIONEER_CONTROL_PORT", "ASIBOT_ASTERICS_PORT",
            "ASIBOT_ASTERICS_HTTP_PORT")}
        self.pioneer_port, self.pioneer_control = ports["ASIBOT_PIONEER_EMULATOR_PORT"], ports["ASIBOT_PIONEER_CONTROL_PORT"]
        self.asterics_port, self.asterics_http_port = ports["ASIBOT_ASTERICS_PORT"], ports["ASIBOT_ASTERICS_HTTP_PORT"]
        self.env = dict(os.environ, ASIBOT_ROUTER=self.endpoint, ASIBOT_WEB_PORT=str(self.web_port),
                        ASIBOT_DATA=str(self.data), ASIBOT_RECORDINGS=str(folder / "recordings"),
                        **{name: str(port) for name, port in ports.items()})
        shutil.copy(compose, folder / "compose.yaml")
        self.log_path = folder / "up.log"
        self._log = open(self.log_path, "w")
        cmd = [sys.executable, "-m", "asibot.cli.main", "up", "--profile", profile, "--file", str(folder / "compose.yaml")]
        if only:
            cmd += ["--only", *only]
        self.proc = subprocess.Popen(cmd, cwd=folder, env=self.env, stdout=self._log, stderr=subprocess.STDOUT)
        self.bus = Bus("e2e-test", self.endpoint, wait=20.0)

    def log(self) -> str:
        return self.log_path.read_text()

    def web_session(self) -> str:
        """The session token the page's server writes into the page (asibot.web.guard)."""
        import re
        import urllib.request
        with urllib.request.urlopen(self.web_url, timeout=10) as reply:
            found = re.search(r'<meta name="asibot-session" content="([^"]+)">', reply.read().decode())
        assert found, "the page carries no session token"
        return found.group(1)

    def web(self, method: str, path: str, body: object = None) -> tuple[int, Any]:
        """One call of the page's API as the page makes it: (HTTP status, the JSON answer).
        `body`: a JSON value, or bytes sent as they are."""
        import json
        import urllib.error
        import urllib.request
        data = body if isinstance(body, bytes) or body is None else json.dumps(body).encode()
        request = urllib.request.Request(self.web_url.rstrip("/") + path, data=data, method=method, headers={
            "Content-Type": "application/json", "X-Asibot-Session": self.web_session()})
        try:
            with urllib.request.urlopen(request, timeout=10) as reply:
                return reply.status, json.loads(reply.read() or b"null")
        except urllib.error.HTTPError as exc:
            return exc.code, json.loads(exc.read() or b"null")

    def wait_alive(self, *services: str, timeout: float = 60.0) -> list[str]:
        """Wait until each `<service>/<instance>` announces itself; the live service keys."""
        want = {keys.service(*s.split("/", 1)) for s in services}
        try:
            wait_until(lambda: want <= set(self.bus.alive(keys.ALL_SERVICES)), timeout, interval=0.5)
        except AssertionError:
            missing = sorted(want - set(self.bus.alive(keys.ALL_SERVICES)))
            raise AssertionError(f"not alive after {timeout} s: {missing}\n{self.log()}") from None
        return self.bus.alive(keys.ALL_SERVICES)

    def run(self, *args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
        """Run a Python program against the stack; on a hang, fail with what it printed."""
        try:
            return subprocess.run([sys.executable, *args], env=self.env, capture_output=True, text=True,
                                  timeout=timeout, cwd=self.folder)
        except subprocess.TimeoutExpired as exc:
            # Bytes (or None) despite text=True: run() does not decode what a timeout cut short.
            printed = "\n".join((out or b"").decode(errors="replace") for out in (exc.stdout, exc.stderr))
            raise AssertionError(f"{args} did not finish within {timeout} s; it printed:\n"
                                 f"{printed}\n--- asibot up:\n{self.log()}") from None

    def stop(self) -> int:
        self.bus.close()
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)  # Ctrl-C
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close()
        return self.proc.returncode


class Stream:
    """Calls `send()` every `period` s on a thread, as a held jog button or a program in a loop
    does, until `close()`. A call that raises is counted in `errors` and the stream goes on.
    `pause()` stops it (it returns once no call runs), `resume()` starts it again; `sent`
    holds the monotonic time of every call, for `longest_gap`."""

    def __init__(self, send: Callable[[], object], period: float = 0.02) -> None:
        self._send, self.period = send, period
        self.sent: list[float] = []
        self.errors: list[Exception] = []
        self._lock = threading.Lock()
        self._running = threading.Event()
        self._closed = threading.Event()
        self._idle = threading.Event()
        self._thread = threading.Thread(target=self._run, name="stream", daemon=True)
        self.resume()
        self._thread.start()

    def _run(self) -> None:
        while not self._closed.is_set():
            if not self._running.is_set():
                self._idle.set()
                self._running.wait(0.05)
                continue
            self._idle.clear()
            t = time.monotonic()
            try:
                self._send()
            except Exception as exc:
                with self._lock:
                    self.errors.append(exc)
            with self._lock:
                self.sent.append(t)
            time.sleep(max(0.0, t + self.period - time.monotonic()))
        self._idle.set()

    def pause(self) -> None:
        self._running.clear()
        self._idle.clear()
        self._idle.wait(5.0)

    def resume(self) -> None:
        self._running.set()

    def longest_gap(self, since: float = 0.0) -> float:
        """The longest time between two calls from `since` on, s (0 with fewer than two)."""
        with self._lock:
            times = [t for t in self.sent if t >= since]
        return max((b - a for a, b in zip(times, times[1:])), default=0.0)

    def close(self) -> None:
        self._closed.set()
        self._running.set()
        self._thread.join(timeout=2.0)

    def __enter__(self) -> "Stream":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
