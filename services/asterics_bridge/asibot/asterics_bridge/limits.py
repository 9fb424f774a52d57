"""The bounds of the bridge's entries (TCP: `servers`; HTTP: `http_bounds`, `http_server`)."""

from __future__ import annotations

from dataclasses import dataclass

#: After this long without sending, a NetConnection client gets a keepalive (the plugin's own
#: server side waits about 7.75 s; it ignores them, and a dead peer shows as a failed write).
KEEPALIVE_S = 7.75


@dataclass(frozen=True)
class Limits:
    """What one client may take, so that no client (nor a web page) can take the bridge from
    the others; tests make them small."""
    max_clients: int = 100              # TCP clients at once; when all are taken, the longest silent makes room
    per_address: int = 50               # TCP clients from one address other than loopback (`slots.group_of`)
    first_item_s: float = 15.0          # to send the first whole frame or line (the plugin: a keepalive after 9 s)
    idle_s: float = 300.0               # silent that long once it spoke (no line, no frame, no keepalive): closed
    partial_s: float = 5.0              # to finish a frame or line once started
    refused_waiting: int = 200          # clients over the limits given a moment to send a stop
    refused_wait_s: float = 2.0         # how long such a client may take to send it
    send_buffer: int = 256 * 1024       # bytes waiting for a client that does not read
    queued_commands: int = 16
    bad_frames: int = 50
    keepalive_s: float = KEEPALIVE_S
    http_header_bytes: int = 8 * 1024
    http_body_bytes: int = 4 * 1024
    http_idle_s: float = 30.0           # for a body, and for a head once the connection is free (whole s, rounded up)
    sndbuf: int | None = None           # SO_SNDBUF of client sockets (tests make it small)
    workers: int = 8
