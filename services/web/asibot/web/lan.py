"""Serving phones and tablets on the LAN: HTTPS with a self-signed certificate and a token.

By default the page is served on 127.0.0.1 only. `--lan` serves it to the local network, which
needs two things the loopback page does not: HTTPS (browsers give the gamepad, the motion
sensors and the microphone only to secure pages) and a secret, because anyone on the network
could otherwise move the robot. The certificate is made on first use and kept in the data
folder; so is the token, which is printed once, when it is made (a new one: --new-token).
A browser presents the token once (`/?token=...`, the address printed or shown as a QR code)
and keeps it in a cookie.
"""

from __future__ import annotations

import datetime
import hmac
import os
import secrets
import socket
from pathlib import Path
from typing import Any

from asibot.certificates import alt_names
from asibot.files import private_dir, write_atomic

COOKIE = "asibot_token"
#: Paths a browser may load before it has the token (the page tells it how to get one).
OPEN_PATHS = ("/static/", "/favicon")


def lan_addresses() -> list[str]:
    """This machine's IPv4 addresses other than loopback (for the address to print)."""
    found: set[str] = set()
    try:
        for *_, sockaddr in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET):
            host = sockaddr[0]
            if isinstance(host, str):     # always, for AF_INET: (host, port)
                found.add(host)
    except OSError:
        pass
    return sorted(a for a in found if not a.startswith("127."))


def ensure_certificate(folder: Path, names: list[str]) -> tuple[Path, Path]:
    """The self-signed certificate and key in `folder`, made on first use (valid 825 days,
    the longest browsers accept) for this host's names and addresses."""
    cert, key = folder / "cert.pem", folder / "key.pem"
    if cert.exists() and key.exists():
        return cert, key
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    private_dir(folder)
    private = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "ASIBOT Task Creator")])
    now = datetime.datetime.now(datetime.timezone.utc)
    certificate = (x509.CertificateBuilder().subject_name(subject).issuer_name(subject)
                   .public_key(private.public_key()).serial_number(x509.random_serial_number())
                   .not_valid_before(now - datetime.timedelta(minutes=5))
                   .not_valid_after(now + datetime.timedelta(days=825))
                   .add_extension(alt_names(names), critical=False)
                   .sign(private, hashes.SHA256()))
    write_atomic(key, private.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                            serialization.NoEncryption()))
    os.chmod(key, 0o600)
    write_atomic(cert, certificate.public_bytes(serialization.Encoding.PEM))
    return cert, key


def ensure_token(folder: Path, renew: bool = False) -> tuple[str, bool]:
    """The LAN token and whether it was just made (then, and only then, it is printed)."""
    path = folder / "token"
    if path.exists() and not renew:
        return path.read_text().strip(), False
    private_dir(folder)
    token = secrets.token_urlsafe(18)
    write_atomic(path, token.encode())
    os.chmod(path, 0o600)
    return token, True


class TokenGate:
    """ASGI middleware: every request and WebSocket needs the token (cookie, or
    `Authorization: Bearer`); `/?token=...` stores it in a cookie and goes to the page."""

    def __init__(self, app: Any, token: str) -> None:
        self.app = app
        self.token = token.encode()

    def _ok(self, headers: dict[bytes, bytes]) -> bool:
        auth = headers.get(b"authorization", b"")
        if auth.startswith(b"Bearer ") and hmac.compare_digest(auth[7:].strip(), self.token):
            return True
        for part in headers.get(b"cookie", b"").split(b";"):
            name, _, value = part.strip().partition(b"=")
            if name == COOKIE.encode() and hmac.compare_digest(value, self.token):
                return True
        return False

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        if scope["type"] not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        headers = dict(scope.get("headers") or [])
        path = scope.get("path", "")
        if self._ok(headers) or path.startswith(OPEN_PATHS):
            return await self.app(scope, receive, send)
        query = scope.get("query_string", b"").decode("latin-1")
        given = dict(p.partition("=")[::2] for p in query.split("&") if p).get("token", "")
        if scope["type"] == "http" and path == "/" and hmac.compare_digest(given.encode(), self.token):
            await send({"type": "http.response.start", "status": 303, "headers": [
                (b"location", b"/"),
                (b"set-cookie", f"{COOKIE}={given}; Path=/; Max-Age=31536000; Secure; HttpOnly; SameSite=Strict".encode())]})
            return await send({"type": "http.response.body", "body": b""})
        if scope["type"] == "websocket":
            return await send({"type": "websocket.close", "code": 1008})
        body = (b"This robot's page needs its access token. Open the address that `asibot up` printed "
                b"(it ends with ?token=...), or the QR code on the Home page of a computer that has it.")
        await send({"type": "http.response.start", "status": 401,
                    "headers": [(b"content-type", b"text/plain; charset=utf-8")]})
        await send({"type": "http.response.body", "body": body})


def qr_png(text: str) -> bytes:
    """A QR code of `text` as a PNG (black on white, a quiet zone of 4 modules, 8 px a module):
    a phone's camera app opens it."""
    import io

    import segno
    out = io.BytesIO()
    segno.make(text, error="m").save(out, kind="png", scale=8, border=4)
    return out.getvalue()


class PhoneAccess:
    """How a phone or tablet reaches this page, for the Home page: in LAN mode the address with
    the token (as text and as a QR code; only a browser that already has the token sees it),
    else a sentence that says how to serve the LAN."""

    def __init__(self, urls: list[str] | None = None) -> None:
        self.urls = urls or []

    @classmethod
    def lan(cls, addresses: list[str], port: int, token: str) -> "PhoneAccess":
        return cls([f"https://{a}:{port}/?token={token}" for a in addresses])

    def json(self) -> dict[str, Any]:
        if not self.urls:
            return {"lan": False, "urls": [], "text": "This page is served to this computer only. For a phone or a "
                    "tablet on your network (the Pointer tab, the Launcher), start the web service with --lan "
                    "(python -m asibot.web --lan): it serves HTTPS with an access token and shows its QR code here."}
        return {"lan": True, "urls": self.urls, "text": "Point the phone's camera at the code, or type the address: "
                "the phone keeps the access, so this is needed once. The browser warns about the self-signed "
                "certificate the first time; accept it for this robot."}
