"""The AsTeRICS bridge on the bus: `python -m asibot.asterics_bridge --robot pioneer-sim`.

In: commands from AsTeRICS NetConnection clients and text clients (TCP, `--port`, 21112) and
HTTP clients such as AsTeRICS-Grid (`--http-port`, 8090); events, nav status, odometry,
battery and estop of every robot (`asibot.asterics_bridge.status`).
Out: nav, kinematics and Task Creator RPC calls (`asibot.asterics_bridge.dispatcher`); what
happens, back to the clients that drive that robot. docs/asterics.md is the user's page.

Who may drive: programs of this machine; web pages only from the origins the user allows
(`--allow-origin`, default AsTeRICS-Grid's own, https://grid.asterics.eu) and only with the HTTP
token (`http_token`: made once, kept in the data folder, carried by the user's grids); the
network only with `--token`.
"""

from __future__ import annotations

import argparse
import logging
import os
import socket

from asibot import runtime
from asibot.bus import Bus
from asibot.local_http import LOOPBACK, Callers, names_from_env

from asibot.asterics_bridge.dispatcher import (DEFAULT_EVENTS, DEFAULT_LONGEST, DEFAULT_MENU, Dispatcher,
                                               parse_events, parse_menu)
from asibot.asterics_bridge import http_token
from asibot.asterics_bridge.servers import DEFAULT_HTTP_PORT, DEFAULT_TCP_PORT, Limits, Servers

NAME = "asterics_bridge"
DEFAULT_ROBOT = "pioneer-sim"
ORIGINS_ENV, HOSTS_ENV = "ASIBOT_ASTERICS_ORIGINS", "ASIBOT_ASTERICS_HOSTS"
#: The web pages that may call the HTTP port by default: AsTeRICS-Grid where its makers serve
#: it (and docs/asterics-setups.md opens it). A copy served elsewhere is added by its origin.
DEFAULT_ORIGINS = ("https://grid.asterics.eu",)
WILDCARDS = ("0.0.0.0", "::", "")

log = logging.getLogger("asibot.asterics_bridge")


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
                   help="access token every client must give (text: 'token <secret>'; HTTP: Bearer or Basic "
                        "auth); default ASIBOT_ASTERICS_TOKEN. Without it the HTTP port still needs the token "
                        "kept in <data>/asterics/token, and TCP clients need none")
    p.add_argument("--no-token", action="store_true",
                   help="HTTP without a token (this machine only: its programs, and pages of the allowed origins, "
                        "may drive without one)")
    p.add_argument("--allow-origin", action="append", metavar="ORIGIN",
                   help="a web page origin that may call the HTTP port, repeated or comma-separated; 'none': no "
                        f"page (default {ORIGINS_ENV}, else {','.join(DEFAULT_ORIGINS)})")
    p.add_argument("--allow-host", action="append", metavar="NAME",
                   help="another name the HTTP port answers to besides loopback ones and --host, repeated or "
                        f"comma-separated (or {HOSTS_ENV})")
    p.add_argument("--longest", type=float, default=DEFAULT_LONGEST,
                   help=f"s a continuous motion (forward, turn left, curves) lasts at most (default {DEFAULT_LONGEST:g})")
    p.add_argument("--events", default=",".join(f"{k}={v}" for k, v in DEFAULT_EVENTS.items()),
                   help="NetConnection event ports to commands (default '1=next,2=select,3=stop')")
    p.add_argument("--menu", default=",".join(DEFAULT_MENU),
                   help="the commands 'next'/'previous' announce and 'select' runs, comma-separated")
    p.add_argument("--max-clients", type=int, default=Limits.max_clients,
                   help=f"TCP clients at once (default {Limits.max_clients}); when all are taken, the one silent the "
                        "longest makes room for a new one")
    p.add_argument("--max-clients-per-address", type=int, default=Limits.per_address,
                   help=f"TCP clients from one other machine (default {Limits.per_address}); this machine's own "
                        "programs (loopback) have no share of their own")


def build(bus: Bus, args: argparse.Namespace) -> BridgeService:
    robot = runtime.robot_id(args, DEFAULT_ROBOT)
    for name, port in (("--port", args.port), ("--http-port", args.http_port)):
        if not (0 <= port < 65536 or (name == "--http-port" and port == -1)):
            raise ValueError(f"{name} must be 0 to 65535 (0: any free port), not {port}")
    if not 0.5 <= args.longest <= 3600:
        raise ValueError(f"--longest must be between 0.5 and 3600 s, not {args.longest:g}")
    if not 1 <= args.max_clients <= 1000:
        raise ValueError(f"--max-clients must be 1 to 1000, not {args.max_clients}")
    if not 1 <= args.max_clients_per_address <= args.max_clients:
        raise ValueError(f"--max-clients-per-address must be 1 to --max-clients ({args.max_clients}), "
                         f"not {args.max_clients_per_address}")
    host = args.host or os.environ.get("ASIBOT_WEB_HOST", "127.0.0.1")
    if args.host and args.host not in LOOPBACK and not args.token:
        raise ValueError(f"--host {args.host} lets the network drive the robot: add --token SECRET (clients "
                         "then send 'token SECRET' first, or HTTP Bearer/Basic auth)")
    if args.token and args.no_token:
        raise ValueError("--token and --no-token contradict each other: choose one "
                         "(ASIBOT_ASTERICS_TOKEN sets --token)")
    callers = Callers(allowed_hosts(args, host), allowed_origins(args))   # a ValueError sentence for a bad origin
    events, menu = parse_events(args.events), parse_menu(args.menu)
    secret = None if args.no_token else args.token or _stored_token()
    dispatcher = Dispatcher(bus, robot, longest=args.longest, token=args.token, menu=menu)
    servers = Servers(dispatcher, host=host, tcp_port=args.port,
                      http_port=None if args.http_port == -1 else args.http_port, events=events,
                      limits=Limits(max_clients=args.max_clients, per_address=args.max_clients_per_address),
                      http_token=secret, callers=callers)
    try:
        servers.start()
    except OSError as exc:
        raise ValueError(f"cannot listen on {host} ports {args.port}/{args.http_port} ({exc.strerror or exc}); "
                         "is another bridge running? Choose others with --port and --http-port") from None
    if servers.http_port is not None:
        _tell_grids(servers, host, secret, callers)
    return BridgeService(dispatcher, servers)


def _split(values: list[str]) -> list[str]:
    """Repeated, comma-separated option values as one list."""
    return [part.strip() for value in values for part in value.split(",") if part.strip()]


def allowed_origins(args: argparse.Namespace) -> list[str]:
    """--allow-origin, else ASIBOT_ASTERICS_ORIGINS, else AsTeRICS-Grid's own; 'none': no page."""
    given = _split(args.allow_origin) if args.allow_origin else names_from_env(ORIGINS_ENV)
    if not given:
        return list(DEFAULT_ORIGINS)
    return [] if [g.lower() for g in given] == ["none"] else given


def allowed_hosts(args: argparse.Namespace, host: str) -> list[str]:
    """The names the HTTP port answers to besides loopback ones: --host itself (all of this
    machine's names and addresses when it listens on every interface), --allow-host and
    ASIBOT_ASTERICS_HOSTS. A page of another name (DNS rebinding) is refused."""
    names = [*_split(args.allow_host or []), *names_from_env(HOSTS_ENV)]
    if host not in WILDCARDS:
        return [host, *names]
    if host in WILDCARDS and not args.host:
        return names          # a container's 0.0.0.0, published on the host's loopback only
    machine = socket.gethostname()
    addresses: set[str] = set()
    try:
        for *_, sockaddr in socket.getaddrinfo(machine, None):
            address = sockaddr[0]
            if isinstance(address, str):     # always, for IPv4 and IPv6
                addresses.add(address)
    except OSError:
        pass
    return [machine, f"{machine}.local", *sorted(addresses), *names]


def _stored_token() -> str:
    """The HTTP token of <data>/asterics/token, made (and printed, once) on first use."""
    token, made = http_token.ensure_token()
    if made:
        print(f"asterics_bridge: the HTTP port's token is {token} (kept in {http_token.default_folder()}/token; "
              "shown only now). AsTeRICS-Grid's buttons carry it: see docs/asterics-setups.md.", flush=True)
    return token


def _tell_grids(servers: Servers, host: str, secret: str | None, callers: Callers) -> None:
    """Write the user's AsTeRICS-Grid keyboards for this bridge (its address, its token) and
    say where they are: the file to import."""
    name = host if host not in WILDCARDS else "127.0.0.1"
    url = f"http://{'[' + name + ']' if ':' in name else name}:{servers.http_port}"
    try:
        path = http_token.write_user_grids(secret, url)
    except OSError as exc:
        log.warning("could not write the AsTeRICS-Grid keyboards to %s: %s", http_token.default_folder(), exc)
        return
    origins = ", ".join(sorted(callers.origins)) or "none"
    log.info("AsTeRICS-Grid: import %s (for %s; pages of %s may call it)", path, url, origins)
