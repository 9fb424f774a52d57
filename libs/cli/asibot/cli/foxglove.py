"""`asibot foxglove`: the running stack, live in Foxglove, from a shell.

    asibot foxglove                    # ws://127.0.0.1:8765 until Ctrl-C
    asibot foxglove --port 9000
    asibot foxglove --host 0.0.0.0     # other machines too: they see the cameras and the map

Every key on the bus is served as `asibot export --foxglove` writes a recording
(`asibot.recorder.live_view`), on a Foxglove WebSocket server bound to this machine only
unless --host says otherwise. In Foxglove: Open connection > Foxglove WebSocket, and the URL
it prints. It only reads (a `reader` login where the router checks them), and its viewers
cannot publish: nothing in Foxglove moves a robot. Ctrl-C stops it and exits 130, as every
command does.
"""

from __future__ import annotations

import argparse
import ipaddress
import sys


#: The same as asibot.recorder.live_view's, spelled here so that `asibot --help` does not
#: load foxglove-sdk (every command would pay for it).
DEFAULT_HOST, DEFAULT_PORT = "127.0.0.1", 8765


def _port(text: str) -> int:
    if not text.isdigit() or not 0 <= int(text) < 65536:
        raise argparse.ArgumentTypeError(f"give a port from 1 to 65535 (0: any free one), not {text!r}")
    return int(text)


def _loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def cmd_foxglove(args: argparse.Namespace) -> int:
    # main imports this module to declare the subcommand: its helpers are imported when it runs.
    from asibot.cli.main import _connect, _stop_on_signals
    from asibot.recorder.live_view import LiveView

    bus = _connect("foxglove", args.wait)
    if bus is None:
        return 1
    with bus:
        try:
            view = LiveView(bus, host=args.host, port=args.port)
        except RuntimeError as exc:
            hint = ("is another `asibot foxglove` running? Choose another port with --port (0: any free one)"
                    if "in use" in str(exc) else f"give --host an address of this machine (default {DEFAULT_HOST})")
            print(f"could not serve on {args.host}:{args.port} ({exc}): {hint}", file=sys.stderr)
            return 1
        with view:
            stop = _stop_on_signals()      # from here Ctrl-C stops the server; before, it interrupts
            if not _loopback(args.host):
                print(f"warning: {args.host} lets other machines watch the robots' cameras and the map "
                      "of the home; the default, 127.0.0.1, keeps them on this machine", file=sys.stderr)
            print(f"serving the stack on {bus.endpoint} at {view.url}: in Foxglove, Open connection > "
                  "Foxglove WebSocket; Ctrl-C stops", flush=True)
            stop.wait()
            print(f"stopped: {view.messages} messages on {len(view.channels.schemas)} topics")
    return stop.exit_code()


def add_parser(sub: argparse._SubParsersAction) -> None:
    fx = sub.add_parser("foxglove", help="serve the running stack live to Foxglove (WebSocket) until Ctrl-C")
    fx.add_argument("--port", type=_port, default=DEFAULT_PORT,
                    help=f"port of the WebSocket server (default {DEFAULT_PORT}, Foxglove's own)")
    fx.add_argument("--host", default=DEFAULT_HOST,
                    help=f"address to listen on (default {DEFAULT_HOST}: this machine only; "
                         "0.0.0.0 lets other machines in)")
    fx.add_argument("--wait", type=float, default=2.0, help="seconds to wait for the router")
    fx.set_defaults(func=cmd_foxglove)
