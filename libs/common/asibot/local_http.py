"""Who may talk to an HTTP server of the stack: the Host it is called by and the page that calls.

A server on 127.0.0.1 is reachable from every web page the user visits: a page on another
origin can POST to it (a "simple" request needs no preflight), open a WebSocket to it (the
browser sends its Origin but enforces nothing), embed its images, and, through DNS rebinding
(a name of the attacker's that resolves to 127.0.0.1), even read its answers. The browser
tells the server who is calling, and these checks read it:

- `Host` must be one of the names the server is reached by (loopback names, the LAN names
  it serves, any the user adds): a rebinding page calls it by the attacker's name;
- `Origin`, sent with every cross-origin request, every POST and every WebSocket, must be
  the server's own or one the user allowed;
- `Sec-Fetch-Site` (Fetch Metadata, sent by current browsers with every request, GETs and
  images included) must say the request comes from the page itself or from the user (typed,
  bookmarked), or be a navigation to the page.

Programs that are not browsers send none of the browser's headers; they are held by the
servers' own tokens. Plain functions and one class, so the web (ASGI) and the AsTeRICS
bridge (a Starlette app) apply the same rules.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from urllib.parse import urlsplit

#: The names a loopback server is reached by.
LOOPBACK = ("127.0.0.1", "localhost", "::1")
#: Fetch Metadata values a browser sends for a request of the page itself or of the user.
OWN_SITES = ("same-origin", "none")


def host_name(host: str) -> str:
    """The name in a Host header or an origin's authority, without its port, lower case;
    IPv6 addresses without brackets ("[::1]:8080" -> "::1")."""
    host = host.strip().lower()
    if host.startswith("["):
        return host[1:].partition("]")[0]
    if host.count(":") > 1:          # a bare IPv6 address
        return host
    return host.partition(":")[0]


def names_from_env(variable: str) -> list[str]:
    """Extra names or origins from a comma-separated environment variable (empty: none)."""
    return [part.strip() for part in os.environ.get(variable, "").split(",") if part.strip()]


class Callers:
    """The Host names a server answers to and the foreign origins it trusts.

    `hosts` are names ("robot.local", "192.168.1.20"); loopback names are always included.
    `origins` are whole origins of other pages allowed to call ("https://grid.asterics.eu");
    the server's own origin (the scheme and Host of the request) is always allowed.
    """

    def __init__(self, hosts: Iterable[str] = (), origins: Iterable[str] = ()) -> None:
        self.hosts = frozenset({*LOOPBACK, *(host_name(h) for h in hosts if h)})
        self.origins = frozenset(o.strip().rstrip("/").lower() for o in origins if o.strip())
        for origin in self.origins:
            if not urlsplit(origin).scheme or not urlsplit(origin).netloc:
                raise ValueError(f"{origin!r} is not an origin: write it as scheme://name[:port], "
                                 "for example https://grid.asterics.eu")

    def host_refusal(self, host: str | None) -> str | None:
        """None when `host` (a Host header) names this server, else the sentence of the refusal."""
        if host and host_name(host) in self.hosts:
            return None
        shown = repr(host[:60]) if host else "no Host header"
        return (f"This server does not answer to {shown}: open it by one of its own names "
                f"({', '.join(sorted(self.hosts))}). A name of yours can be added to the server's allowed hosts.")

    def origin_allowed(self, origin: str, scheme: str, host: str) -> bool:
        """Whether a page of `origin` may call this server, reached at scheme://host."""
        origin = origin.strip().rstrip("/").lower()
        return origin == f"{scheme}://{host.strip().lower()}" or origin in self.origins

    def caller_refusal(self, headers: dict[str, str], scheme: str, *, navigation_ok: bool = False) -> str | None:
        """None when a request with these headers (lower-case names) comes from the server's
        own page, an allowed origin or a program that is not a browser; else the sentence.
        `navigation_ok`: a top-level GET navigation from another site is taken (a link to the page)."""
        host = headers.get("host", "")
        origin = headers.get("origin")
        if origin is not None and not self.origin_allowed(origin, scheme, host):
            return (f"A page of {origin[:80]!r} may not use this server: only its own page "
                    "and the origins its owner allowed may.")
        site = headers.get("sec-fetch-site")
        if site is None or site in OWN_SITES or origin is not None:
            return None
        if navigation_ok and headers.get("sec-fetch-mode") == "navigate" and headers.get("sec-fetch-dest") == "document":
            return None
        return "Another site's page may not use this server."
