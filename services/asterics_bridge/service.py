"""The AsTeRICS bridge on the bus: `python -m asibot.asterics_bridge --robot pioneer-sim`.

In: commands from AsTeRICS NetConnection clients and text clients (TCP, `--port`, 21112) and
HTTP clients such as AsTeRICS-Grid (`--http-port`, 8090); events, nav status, odometry,
battery and estop of every robot (`asibot.asterics_bridge.status`).
Out: nav, kinematics and Task Creator RPC calls (`asibot.asterics_bridge.dispatcher`); what
happens, back to the clients that drive that robot. docs/asterics.md is the user's page.
"""

from __future__ import annotations

import argparse
import os

from asibot import runtime
from asibot.bus import Bus

from asibot.asterics_bridge.dispatcher import (DEFAULT_EVENTS, DEFAULT_LONGEST, DEFAULT_MENU, Dispatcher,
                                               parse_events, parse_menu)
from asibot.asterics_bridge.servers import DEFAULT_HTTP_PORT, DEFAULT_TCP_PORT, Limits, Servers

NAME = "asterics_bridge"
DEFAULT_ROBOT = "pioneer-sim"
LOOPBACK = ("127.0.0.1", "localhost", "::1")


class BridgeService(runtime.Service):
    def __init__(self, dispatcher: Dispatcher, servers: Servers) -> None:
        self.dispatcher, self.servers = dispatcher, servers

    def health(self) -> dict:
        return {**self.dispatcher.health(), **self.servers.counters, "tcp_port": self.servers.tcp_port,
                "http_port": self.servers.http_port}

    def close(self) -> None:
        self.servers.close()
        self.dispatcher.close()


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--port", type=int, default=int(os.environ.get("ASIBOT_ASTERICS_PORT", DEFAULT_TCP_PORT)),
                   help="TCP port of NetConnection and text clients (default 21112, the plugin's; "
                        "or ASIBOT_ASTERICS_PORT)")
    p.add_argument("--http-port", type=int,
                   default=int(os.environ.get("ASIBOT_ASTERICS_HTTP_PORT", DEFAULT_HTTP_PORT)),
                   help="HTTP port for AsTeRICS-Grid and scripts (default 8090, or ASIBOT_ASTERICS_HTTP_PORT; "
                        "-1: no HTTP)")
    p.add_argument("--host", default=None,
                   help="address to listen on (default ASIBOT_WEB_HOST, else 127.0.0.1: this machine only; "
                        "another address needs --token)")
    p.add_argument("--token", default=os.environ.get("ASIBOT_ASTERICS_TOKEN") or None,
                   help="access token clients must give first (text: 'token <secret>'; HTTP: Bearer or Basic "
                        "auth); default ASIBOT_ASTERICS_TOKEN")
    p.add_argument("--longest", type=float, default=DEFAULT_LONGEST,
                   help=f"s a continuous motion (forward, turn left, curves) lasts at most (default {DEFAULT_LONGEST:g})")
    p.add_argument("--events", default=",".join(f"{k}={v}" for k, v in DEFAULT_EVENTS.items()),
                   help="NetConnection event ports to commands (default '1=next,2=select,3=stop')")
    p.add_argument("--menu", default=",".join(DEFAULT_MENU),
                   help="the commands 'next'/'previous' announce and 'select' runs, comma-separated")
    p.add_argument("--max-clients", type=int, default=Limits.max_clients, help="TCP clients at once (default 100)")


def build(bus: Bus, args: argparse.Namespace) -> BridgeService:
    robot = runtime.robot_id(args, DEFAULT_ROBOT)
    for name, port in (("--port", args.port), ("--http-port", args.http_port)):
        if not (0 <= port < 65536 or (name == "--http-port" and port == -1)):
            raise ValueError(f"{name} must be 0 to 65535 (0: any free port), not {port}")
    if not 0.5 <= args.longest <= 3600:
        raise ValueError(f"--longest must be between 0.5 and 3600 s, not {args.longest:g}")
    if not 1 <= args.max_clients <= 1000:
        raise ValueError(f"--max-clients must be 1 to 1000, not {args.max_clients}")
    host = args.host or os.environ.get("ASIBOT_WEB_HOST", "127.0.0.1")
    if args.host and args.host not in LOOPBACK and not args.token:
        raise ValueError(f"--host {args.host} lets the network drive the robot: add --token SECRET (clients "
                         "then send 'token SECRET' first, or HTTP Bearer/Basic auth)")
    events, menu = parse_events(args.events), parse_menu(args.menu)
    dispatcher = Dispatcher(bus, robot, longest=args.longest, token=args.token, menu=menu)
    servers = Servers(dispatcher, host=host, tcp_port=args.port,
                      http_port=None if args.http_port == -1 else args.http_port, events=events,
                      limits=Limits(max_clients=args.max_clients))
    try:
        servers.start()
    except OSError as exc:
        raise ValueError(f"cannot listen on {host} ports {args.port}/{args.http_port} ({exc.strerror or exc}); "
                         "is another bridge running? Choose others with --port and --http-port") from None
    return BridgeService(dispatcher, servers)
