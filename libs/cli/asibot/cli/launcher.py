"""`asibot up`: the services of compose.yaml as local processes, supervised.

The same file drives `docker compose up`; here each service's command runs as a child
process with the compose environment, except that the router endpoint is rewritten to
loopback. Output lines are prefixed with the service name; crashed services restart per
their `restart:` policy with exponential backoff; Ctrl-C stops everything, router last.
While the router runs, the launcher is on the bus too (`BusReport`): `asibot status` lists it,
and its Health says how often each service was restarted (`asibot status --json`).
"""

from __future__ import annotations

import dataclasses
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import IO, Callable

from asibot import keys, messages
from asibot.access import ACCESS_ENV, PROGRAM_ROUTER_ENV, ROLE_ENV, program_endpoint
from asibot.bus import Bus
from asibot.cli.compose import ServiceSpec
from asibot.errors import AsibotError
from asibot.runtime import HEALTH_PERIOD

ROUTER_SERVICE = "router"
#: The launcher's service name and instance on the bus (one `asibot up` per router).
LAUNCHER, LAUNCHER_INSTANCE = "launcher", "main"
BACKOFF_START = 0.5
BACKOFF_MAX = 10.0
HEALTHY_AFTER = 10.0   # a run this long resets the backoff
STOP_GRACE = 3.0
COLORS = ("36", "33", "35", "32", "34", "31", "96", "93", "95", "92")


def local_command(command: list[str]) -> list[str]:
    """Map a container command to this machine: the venv's python and its `asibot`."""
    head, rest = command[0], command[1:]
    if head in ("python", "python3"):
        return [sys.executable, *rest]
    if head == "asibot":
        return [sys.executable, "-m", "asibot.cli.main", *rest]
    return list(command)


def local_environment(spec: ServiceSpec, endpoint: str, access: Path | None = None,
                      listen: str | None = None) -> dict[str, str]:
    """The child's environment. With `access` (a credentials folder, asibot.access) the
    router requires logins and each service logs in with the role of its own name; `listen`
    is where the router listens when that is more than `endpoint` (a tls/ one besides)."""
    env = dict(os.environ)
    env.update(spec.environment)
    # In containers the router is `tcp/router:7447`; here it is the loopback endpoint.
    env["ASIBOT_ROUTER"] = endpoint
    env["ASIBOT_ROUTER_LISTEN"] = listen or endpoint
    # In containers a volume the router and the web share; here this user's runtime folder.
    env.pop(PROGRAM_ROUTER_ENV, None)
    env[PROGRAM_ROUTER_ENV] = program_endpoint(endpoint)
    env["ASIBOT_WEB_HOST"] = "127.0.0.1"   # a container listens on all its interfaces; here loopback only
    env["PYTHONUNBUFFERED"] = "1"
    # A role set in the launcher's shell would give every service the same one.
    env.pop(ROLE_ENV, None)
    if access is None:
        env.pop(ACCESS_ENV, None)   # an open router refuses a session that logs in
    else:
        env[ACCESS_ENV] = str(access)
    return env


def _die_with_parent() -> None:
    """Children get SIGTERM if the launcher itself is killed, so no orphan keeps port 7447."""
    try:
        import ctypes
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def wait_for_port(endpoint: str, timeout: float) -> bool:
    host, _, port = endpoint.split("/", 1)[-1].rpartition(":")
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with socket.create_connection((host, int(port)), timeout=0.2):
                return True
        except OSError:
            time.sleep(0.05)
    return False


@dataclasses.dataclass
class Child:
    spec: ServiceSpec
    color: str
    proc: subprocess.Popen | None = None
    started: float = 0.0
    restarts: int = 0
    backoff: float = BACKOFF_START
    next_start: float = 0.0
    done: bool = False          # exited and not to be restarted
    exit_code: int | None = None


class Supervisor:
    """Starts, watches, restarts and stops the chosen services."""

    def __init__(self, services: list[ServiceSpec], endpoint: str, *, root: Path | None = None,
                 out: IO[str] | None = None, color: bool | None = None,
                 access: Path | None = None, listen: str | None = None) -> None:
        self.endpoint = endpoint
        self.access, self.listen = access, listen
        self.root = root or Path.cwd()
        self.out = out or sys.stdout
        self.color = self.out.isatty() if color is None else color
        self.children = [Child(s, COLORS[i % len(COLORS)]) for i, s in enumerate(services)]
        self.width = max((len(s.name) for s in services), default=6)
        self._out_lock = threading.Lock()
        self._stopping = threading.Event()
        self.on_event: Callable[[str, str], None] | None = None

    # ------------------------------------------------------------ output
    def say(self, name: str, line: str, color: str = "0") -> None:
        prefix = f"{name:<{self.width}} | "
        if self.color:
            prefix = f"\x1b[{color}m{prefix}\x1b[0m"
        with self._out_lock:
            self.out.write(prefix + line.rstrip("\n") + "\n")
            self.out.flush()

    def _pump(self, child: Child, stream: IO[bytes]) -> None:
        for raw in iter(stream.readline, b""):
            self.say(child.spec.name, raw.decode(errors="replace"), child.color)
        stream.close()

    def _event(self, name: str, what: str) -> None:
        if self.on_event:
            self.on_event(name, what)

    # ------------------------------------------------------------ lifecycle
    def start(self, child: Child) -> None:
        cmd = local_command(child.spec.command)
        child.proc = subprocess.Popen(
            cmd, cwd=self.root, env=local_environment(child.spec, self.endpoint, self.access, self.listen),
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            start_new_session=True,  # our Ctrl-C must not hit children before we decide
            preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None,
        )
        child.started = time.monotonic()
        threading.Thread(target=self._pump, args=(child, child.proc.stdout), daemon=True).start()
        self._event(child.spec.name, "started")

    def start_all(self) -> None:
        for child in self.children:
            self.start(child)
            if child.spec.name == ROUTER_SERVICE:
                if not wait_for_port(self.endpoint, 10.0):
                    self.say("asibot", f"the router did not open {self.endpoint} within 10 s")
                else:
                    self._event(ROUTER_SERVICE, "ready")

    def should_restart(self, child: Child, code: int) -> bool:
        policy = child.spec.restart
        return policy in ("always", "unless-stopped") or (policy == "on-failure" and code != 0)

    def poll(self) -> None:
        """One supervision step: reap exits, schedule and perform restarts."""
        now = time.monotonic()
        for child in self.children:
            if child.done or self._stopping.is_set():
                continue
            if child.proc is None:
                if now >= child.next_start:
                    child.restarts += 1
                    self.say("asibot", f"restarting {child.spec.name} (restart {child.restarts})")
                    self.start(child)
                continue
            code = child.proc.poll()
            if code is None:
                continue
            child.exit_code = code
            ran = now - child.started
            child.proc = None
            if ran >= HEALTHY_AFTER:
                child.backoff = BACKOFF_START
            if self.should_restart(child, code):
                self.say("asibot", f"{child.spec.name} exited with code {code}; "
                         f"restarting in {child.backoff:.1f} s")
                child.next_start = now + child.backoff
                child.backoff = min(child.backoff * 2, BACKOFF_MAX)
                self._event(child.spec.name, "exited")
            else:
                self.say("asibot", f"{child.spec.name} exited with code {code} (restart: {child.spec.restart})")
                child.done = True
                self._event(child.spec.name, "done")

    def run(self, stop: threading.Event) -> None:
        self.start_all()
        while not stop.wait(0.1):
            self.poll()
        self.stop_all()

    def stop_all(self) -> None:
        """SIGTERM everyone (services, then the router), SIGKILL whoever outlives the grace."""
        self._stopping.set()
        ordered = sorted(self.children, key=lambda c: c.spec.name == ROUTER_SERVICE)
        routers = [c for c in ordered if c.spec.name == ROUTER_SERVICE]
        for group in ([c for c in ordered if c.spec.name != ROUTER_SERVICE], routers):
            if group is routers and routers:
                self._event(ROUTER_SERVICE, "stopping")   # this process's own session lets go first
            for child in group:
                if child.proc and child.proc.poll() is None:
                    try:
                        os.killpg(child.proc.pid, signal.SIGTERM)
                    except ProcessLookupError:
                        pass
            deadline = time.monotonic() + STOP_GRACE
            for child in group:
                if not child.proc:
                    continue
                try:
                    child.proc.wait(max(0.0, deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    self.say("asibot", f"{child.spec.name} ignored SIGTERM; killing it")
                    try:
                        os.killpg(child.proc.pid, signal.SIGKILL)
                    except ProcessLookupError:
                        pass
                    child.proc.wait()

    def pids(self) -> dict[str, int]:
        return {c.spec.name: c.proc.pid for c in self.children if c.proc and c.proc.poll() is None}

    def report(self) -> list[dict]:
        """Each service: its compose name, pid while it runs, restarts so far, whether it runs.
        Called from another thread than `poll`: it reads, and reaps nothing."""
        out = []
        for c in self.children:
            proc = c.proc   # once: poll() may set it to None meanwhile
            running = proc is not None and proc.returncode is None
            out.append({"name": c.spec.name, "pid": proc.pid if proc is not None and running else None,
                        "restarts": c.restarts, "running": running})
        return out


class BusReport:
    """The launcher on the bus while the router runs: a liveliness token, so `asibot status`
    lists it, and a Health every HEALTH_PERIOD whose details carry `Supervisor.report()`, so
    `asibot status --json` gives each service's restart count (the same keys and message as
    every service's health: nothing new in the contract). Close it before the router stops."""

    def __init__(self, sup: Supervisor, endpoint: str) -> None:
        self._sup, self._endpoint = sup, endpoint
        self._started = time.monotonic()
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="launcher-report", daemon=True)
        self._thread.start()

    def _health(self) -> messages.Health:
        return messages.Health(service=LAUNCHER, instance=LAUNCHER_INSTANCE, pid=os.getpid(),
                               uptime=time.monotonic() - self._started,
                               details={"services": self._sup.report()})

    def _run(self) -> None:
        try:
            bus = Bus(LAUNCHER, self._endpoint, wait=10.0, stop=self._done)
        except (AsibotError, ValueError) as exc:   # the restart counts are a convenience: say, go on
            if not self._done.is_set():
                self._sup.say("asibot", f"`asibot status` will not show restart counts: {exc}")
            return
        with bus:
            bus.announce(keys.service(LAUNCHER, LAUNCHER_INSTANCE))
            health = bus.publisher(keys.health(LAUNCHER, LAUNCHER_INSTANCE), messages.Health)
            while True:
                health.put(self._health())
                if self._done.wait(HEALTH_PERIOD):
                    break

    def close(self) -> None:
        self._done.set()
        self._thread.join(5.0)
