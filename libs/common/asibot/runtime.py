"""The service runtime: what every service's `__main__` shares.

Every service folder has a `service.py` with three names (a `ServiceModule`): `NAME`,
`add_arguments(parser)` and `build(bus, args) -> Service`, and a `__main__.py` of three lines:

    from asibot import runtime
    from asibot.<name> import service
    raise SystemExit(runtime.run(service))

The runtime parses the common flags, owns the instance name, connects (waiting for the
router), builds the service, announces it, publishes Health every 2 s, and on SIGTERM/SIGINT
closes the service and the bus within 2 s (a second Ctrl-C exits at once), so `asibot up`,
Docker and a user's Ctrl-C all stop it the same way. `build` refuses bad arguments with a
ValueError whose sentence the runtime prints.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import threading
import time
from typing import Callable, Protocol, Sequence

from asibot import keys, messages
from asibot.bus import Bus
from asibot.errors import Unavailable

HEALTH_PERIOD = 2.0
SHUTDOWN_BUDGET = 2.0

log = logging.getLogger("asibot.runtime")


class Service(Protocol):
    """What `build` returns. Subclass it to inherit the defaults: no health details, and
    `run` that waits for the stop signal (a service that owns the main thread overrides it)."""

    def health(self) -> dict:
        """A few numbers for `asibot status` and the Health message."""
        return {}

    def run(self, stop: threading.Event) -> None:
        """Block until `stop` is set; the service's threads do the work meanwhile."""
        stop.wait()

    def close(self) -> None:
        """Release hardware, threads and sockets; the bus is closed by the runtime after."""


class ServiceModule(Protocol):
    """A service's `service.py`."""

    NAME: str

    def add_arguments(self, parser: argparse.ArgumentParser) -> None: ...

    def build(self, bus: Bus, args: argparse.Namespace) -> Service: ...


class JsonFormatter(logging.Formatter):
    """One JSON object per line, for log shippers; the text format is for people."""

    def __init__(self, service: str, instance: str) -> None:
        super().__init__()
        self.service, self.instance = service, instance

    def format(self, record: logging.LogRecord) -> str:
        entry = {
            "t": round(record.created, 3), "level": record.levelname.lower(),
            "service": self.service, "instance": self.instance,
            "logger": record.name, "msg": record.getMessage(),
        }
        if record.exc_info:
            entry["exc"] = self.formatException(record.exc_info)
        return json.dumps(entry)


def setup_logging(service: str, instance: str, level: str = "info", fmt: str = "text") -> None:
    handler = logging.StreamHandler(sys.stderr)
    if fmt == "json":
        handler.setFormatter(JsonFormatter(service, instance))
    else:
        handler.setFormatter(logging.Formatter(
            f"%(asctime)s %(levelname)-7s {service}/{instance} %(name)s: %(message)s", "%H:%M:%S"))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level.upper())


def parser(service: str, add_arguments: Callable[[argparse.ArgumentParser], None] | None = None,
           package: str | None = None) -> argparse.ArgumentParser:
    """The common flags, then the service's own; `package` is what `python -m` runs."""
    p = argparse.ArgumentParser(prog=f"python -m {package or 'asibot.' + service}",
                                description=f"the {service} service")
    p.add_argument("--robot", default=os.environ.get("ASIBOT_ROBOT"), help="robot id, e.g. asibot-sim")
    p.add_argument("--instance", default=None, help="instance name (default: the robot id, or 'main')")
    p.add_argument("--router", default=None, help="Zenoh router endpoint (default: $ASIBOT_ROUTER or tcp/127.0.0.1:7447)")
    p.add_argument("--log-level", default=os.environ.get("ASIBOT_LOG_LEVEL", "info"),
                   choices=["debug", "info", "warning", "error"])
    p.add_argument("--log-format", default=os.environ.get("ASIBOT_LOG_FORMAT", "text"), choices=["text", "json"])
    if add_arguments:
        add_arguments(p)
    return p


def robot_id(args: argparse.Namespace, default: str | None = None, *, example: str = "asibot-sim") -> str:
    """The service's --robot (or `default`), checked once here: a ValueError that names --robot
    and says what a robot id may be, so `build` refuses before anything starts. Without a
    `default`, --robot is required, and the sentence says what to give (`example`)."""
    robot = args.robot or default
    if not robot:
        raise ValueError(f"--robot is required: the robot this service works for, e.g. {example}")
    try:
        keys.robot(robot)
    except ValueError as exc:
        raise ValueError(f"--robot: {exc}") from None
    return robot


class _Shutdown:
    """Turns SIGTERM/SIGINT into an Event, and enforces the shutdown budget."""

    def __init__(self) -> None:
        self.event = threading.Event()
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, self._on_signal)

    def _on_signal(self, signum: int, frame: object) -> None:
        if self.event.is_set():
            os._exit(130)  # second Ctrl-C: the user means it
        log.info("received %s, stopping", signal.Signals(signum).name)
        self.event.set()
        # If closing hangs on a driver or a socket, do not outlive the budget.
        t = threading.Timer(SHUTDOWN_BUDGET, lambda: os._exit(0))
        t.daemon = True
        t.start()


def run(service: ServiceModule, argv: Sequence[str] | None = None) -> int:
    """Run a service until signalled. Returns the process exit code."""
    name = service.NAME
    args = parser(name, service.add_arguments, getattr(service, "__package__", None)).parse_args(argv)
    args.instance = args.instance or args.robot or "main"
    setup_logging(name, args.instance, args.log_level, args.log_format)
    shutdown = _Shutdown()
    args.stop = shutdown.event
    started = time.monotonic()
    try:
        bus = Bus(name, args.router, stop=shutdown.event)
    except Unavailable:
        return 0 if shutdown.event.is_set() else 1
    except ValueError as exc:   # a bad login (ASIBOT_ROLE, a credentials file): its sentence
        log.error("could not join the bus: %s", exc)
        return 1
    try:
        obj = service.build(bus, args)
    except Exception as exc:
        log.error("could not start: %s", exc, exc_info=log.isEnabledFor(logging.DEBUG) or not str(exc))
        bus.close()
        return 1
    bus.announce(keys.service(name, args.instance))
    health = bus.publisher(keys.health(name, args.instance), messages.Health)

    def publish_health() -> None:
        while not shutdown.event.wait(HEALTH_PERIOD):
            try:
                health.put(messages.Health(service=name, instance=args.instance,
                                           uptime=time.monotonic() - started, pid=os.getpid(),
                                           rejected=bus.rejected, details=obj.health() or {}))
            except Exception:
                log.exception("health report failed")

    threading.Thread(target=publish_health, name="health", daemon=True).start()
    log.info("running (pid %d, router %s)", os.getpid(), bus.endpoint)
    code = 0
    try:
        obj.run(shutdown.event)
    except Exception:
        log.exception("crashed")
        code = 1
    finally:
        try:
            obj.close()
        except Exception:
            log.exception("close failed")
        bus.close()
    log.info("stopped")
    return code
