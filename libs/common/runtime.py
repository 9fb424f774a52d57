"""The service runtime: what every service's `__main__` shares.

A service is `build(bus, args) -> object`. The runtime parses the common flags, connects
(waiting for the router), announces the service, publishes Health every 2 s, and on
SIGTERM/SIGINT closes the object and the bus within 2 s, so `asibot up`, Docker and a
user's Ctrl-C all stop it the same way.
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
from typing import Any, Callable, Sequence

from asibot import keys, messages
from asibot.bus import Bus
from asibot.errors import Unavailable

HEALTH_PERIOD = 2.0
SHUTDOWN_BUDGET = 2.0

log = logging.getLogger("asibot.runtime")


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


def parser(service: str, add_arguments: Callable[[argparse.ArgumentParser], None] | None = None
           ) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=f"python -m asibot.{service}", description=f"the {service} service")
    p.add_argument("--robot", default=os.environ.get("ASIBOT_ROBOT"), help="robot id, e.g. asibot-sim")
    p.add_argument("--instance", default=None, help="instance name (default: the robot id, or 'main')")
    p.add_argument("--router", default=None, help="Zenoh router endpoint (default: $ASIBOT_ROUTER or tcp/127.0.0.1:7447)")
    p.add_argument("--log-level", default=os.environ.get("ASIBOT_LOG_LEVEL", "info"),
                   choices=["debug", "info", "warning", "error"])
    p.add_argument("--log-format", default=os.environ.get("ASIBOT_LOG_FORMAT", "text"), choices=["text", "json"])
    if add_arguments:
        add_arguments(p)
    return p


class _Shutdown:
    """Turns SIGTERM/SIGINT into an Event, and enforces the shutdown budget."""

    def __init__(self) -> None:
        self.event = threading.Event()
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, self._on_signal)

    def _on_signal(self, signum: int, frame: Any) -> None:
        if self.event.is_set():
            os._exit(130)  # second Ctrl-C: the user means it
        log.info("received %s, stopping", signal.Signals(signum).name)
        self.event.set()
        # If closing hangs on a driver or a socket, do not outlive the budget.
        t = threading.Timer(SHUTDOWN_BUDGET, lambda: os._exit(0))
        t.daemon = True
        t.start()


def run(service: str, build: Callable[[Bus, argparse.Namespace], Any],
        add_arguments: Callable[[argparse.ArgumentParser], None] | None = None,
        argv: Sequence[str] | None = None) -> int:
    """Run a service until signalled. Returns the process exit code."""
    args = parser(service, add_arguments).parse_args(argv)
    args.instance = args.instance or args.robot or "main"
    setup_logging(service, args.instance, args.log_level, args.log_format)
    shutdown = _Shutdown()
    args.stop = shutdown.event
    started = time.monotonic()
    try:
        bus = Bus(service, args.router, stop=shutdown.event)
    except Unavailable:
        return 0 if shutdown.event.is_set() else 1
    try:
        obj = build(bus, args)
    except Exception as exc:
        log.error("could not start: %s", exc, exc_info=log.isEnabledFor(logging.DEBUG) or not str(exc))
        bus.close()
        return 1
    bus.announce(keys.service(service, args.instance))
    health = bus.publisher(keys.health(service, args.instance), messages.Health)

    def publish_health() -> None:
        while not shutdown.event.wait(HEALTH_PERIOD):
            try:
                details = obj.health() if hasattr(obj, "health") else {}
                health.put(messages.Health(service=service, instance=args.instance,
                                           uptime=time.monotonic() - started, pid=os.getpid(),
                                           rejected=bus.rejected, details=details or {}))
            except Exception:
                log.exception("health report failed")

    threading.Thread(target=publish_health, name="health", daemon=True).start()
    log.info("running (pid %d, router %s)", os.getpid(), bus.endpoint)
    code = 0
    try:
        if hasattr(obj, "run"):
            obj.run(shutdown.event)  # services that own the main thread (e.g. a viewer)
        else:
            shutdown.event.wait()
    except Exception:
        log.exception("crashed")
        code = 1
    finally:
        try:
            if hasattr(obj, "close"):
                obj.close()
        except Exception:
            log.exception("close failed")
        bus.close()
    log.info("stopped")
    return code
