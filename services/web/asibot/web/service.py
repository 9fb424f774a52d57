"""The web service: the Task Creator page on http://127.0.0.1:8080/ (`python -m asibot.web`).

It reaches the robots only through the bus, like any other service, and keeps the user's
files in one data folder (`--data`, `ASIBOT_DATA`, or the XDG data folder).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import socket
import threading
from pathlib import Path
from typing import Iterator

import uvicorn

from asibot import local_http, runtime
from asibot.bus import Bus
from asibot.files import private_dir
from asibot.web import guard, lan as lan_access, look_bus
from asibot.web.app import Web, create_app, stop_quietly
from asibot.web.cameras import Cameras
from asibot.web.fleet import Fleet
from asibot.web.live import Live
from asibot.web.motion import Motion
from asibot.web.runner import ProgramRunner, RunResult
from asibot.web.tasks_bus import TaskDesk
from asibot.web.trips import TripCounter
from asibot.web.userdata import UserData, default_root
from asibot.web.voice_relay import VoiceRelay
from asibot.web.world import World

NAME = "web"
#: More names the page is opened by (comma-separated: a reverse proxy's, a robot's DNS name).
HOSTS_ENV = "ASIBOT_WEB_HOSTS"

log = logging.getLogger("asibot.web")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--host", default=None,
                        help="address to serve on (default ASIBOT_WEB_HOST, else 127.0.0.1: this machine "
                             "only; with --lan 0.0.0.0)")
    parser.add_argument("--port", type=int, default=int(os.environ.get("ASIBOT_WEB_PORT", "8080")),
                        help="port (default 8080, or ASIBOT_WEB_PORT)")
    parser.add_argument("--data", type=Path, default=None,
                        help="the user's files: points, programs, words, tasks, icons "
                             "(default ASIBOT_DATA, else ~/.local/share/asibot)")
    parser.add_argument("--lan", action="store_true",
                        help="serve phones and tablets on the local network: HTTPS with a self-signed "
                             "certificate and an access token (printed once, when it is made)")
    parser.add_argument("--new-token", action="store_true", help="with --lan: replace the access token")


class _Server(uvicorn.Server):
    """uvicorn without its signal handlers: the runtime owns SIGTERM and SIGINT, and its stop
    event ends the server (`WebService.run`)."""

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        yield


class WebService(runtime.Service):
    def __init__(self, bus: Bus, host: str, port: int, data: UserData, *, lan: bool = False,
                 new_token: bool = False) -> None:
        self.host, self.port = host, port
        self.scheme = "https" if lan else "http"
        live = Live(lambda robot: self.fleet.view(robot), lambda: self.fleet.views())
        trips = TripCounter(data.favourites.used)
        self.fleet = Fleet(bus, on_change=live.changed, on_nav_status=trips.on_status)
        motion = Motion(bus)
        runner = ProgramRunner(
            env={"ASIBOT_ROUTER": bus.endpoint},
            on_output=lambda stream, line: live.send({"type": "output", "stream": stream, "line": line}),
            on_exit=self._ended,
            # Every page hears that a run started (the Program tab, the Launcher, however it was
            # launched: a page, the voice service, the AsTeRICS bridge), as it hears that one ended.
            on_start=lambda status: live.send({"type": "run", "status": status}),
            stop_robot=lambda robot: stop_quietly(motion, robot, "its program ended"))
        tasks = TaskDesk(bus, data, runner, is_live=lambda robot: robot in self.fleet.ids())
        names = [host, *local_http.names_from_env(HOSTS_ENV)]
        if lan:
            names += [*lan_access.lan_addresses(), socket.gethostname(), f"{socket.gethostname()}.local"]
        cameras = Cameras(bus)
        world = World(bus, cameras, data.folder, motion.inverse, self.fleet.point)
        look_bus.serve(bus, world)
        self.web = Web(fleet=self.fleet, motion=motion, data=data, runner=runner, live=live,
                       cameras=cameras, tasks=tasks, voice=VoiceRelay(bus, live.send), world=world,
                       callers=local_http.Callers(n for n in names if n not in ("0.0.0.0", "::")))
        self.app: guard.PageGuard | lan_access.TokenGate = create_app(self.web)
        tls: dict = {}
        if lan:
            folder = data.root / ".lan"
            cert, key = lan_access.ensure_certificate(folder, lan_access.lan_addresses() + [socket.gethostname()])
            token, made = lan_access.ensure_token(folder, renew=new_token)
            self.app = lan_access.TokenGate(self.app, token)
            tls = {"ssl_certfile": str(cert), "ssl_keyfile": str(key)}
            where = lan_access.lan_addresses() or [socket.gethostname()]
            self.web.phones = lan_access.PhoneAccess.lan(where, port, token)
            if made:
                for address in where:
                    print(f"web: open https://{address}:{port}/?token={token} on a phone or tablet of this network "
                          "(once; the browser keeps it). This token is shown only now.", flush=True)
            else:
                log.info("web on the LAN: https://%s:%d/ needs the token printed when it was made "
                         "(--new-token makes another)", where[0], port)
        self.server = _Server(uvicorn.Config(self.app, host=host, port=port, log_level="warning",
                                             ws_ping_interval=5.0, ws_ping_timeout=5.0, **tls))

    def _ended(self, result: RunResult) -> None:
        self.web.live.send({"type": "run", "status": self.web.runner.status()})
        self.web.tasks.finished(result)

    def health(self) -> dict:
        return {"pages": len(self.web.live.pages), "running": self.web.runner.running(),
                "url": f"{self.scheme}://{self.host}:{self.port}/"}

    def run(self, stop: threading.Event) -> None:
        def stop_server() -> None:
            stop.wait()
            self.server.should_exit = True

        threading.Thread(target=stop_server, daemon=True, name="web-stop").start()
        log.info("web: %s://%s:%d/ (user files in %s)", self.scheme, self.host, self.port, self.web.data.root)
        self.server.run()
        if not stop.is_set() and not self.server.should_exit:
            raise RuntimeError(f"the web server on {self.host}:{self.port} stopped by itself")

    def close(self) -> None:
        self.server.should_exit = True
        self.web.runner.close()
        self.web.world.close()
        self.web.cameras.close()


def build(bus: Bus, args: argparse.Namespace) -> WebService:
    if not 0 < args.port < 65536:
        raise ValueError(f"--port must be 1 to 65535, got {args.port}")
    root = args.data or default_root()
    try:
        data = UserData(private_dir(root))       # 0700, made or found (asibot.files)
    except OSError as exc:
        raise ValueError(f"cannot use {root} for the user's files ({exc.strerror}); "
                         "choose another folder with --data or ASIBOT_DATA") from None
    host = args.host or ("0.0.0.0" if args.lan else os.environ.get("ASIBOT_WEB_HOST", "127.0.0.1"))
    if args.new_token and not args.lan:
        raise ValueError("--new-token is for --lan (the page on 127.0.0.1 needs no token)")
    if host not in ("127.0.0.1", "localhost", "::1") and not args.lan and not os.environ.get("ASIBOT_WEB_HOST"):
        raise ValueError(f"--host {host} serves the page beyond this machine: add --lan, which adds HTTPS "
                         "and an access token, so nobody else on the network can move the robot")
    return WebService(bus, host, args.port, data, lan=args.lan, new_token=args.new_token)
