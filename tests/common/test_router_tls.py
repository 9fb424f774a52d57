"""Logins across a network: the guarded router also listens on `tls/`, with a certificate from
the robot's own CA (asibot.certificates). What travels is read by nobody in between, a client
trusts only that CA, and the robot's own services keep plain loopback.

"Read by nobody in between" is shown with a relay that records every byte between client and
router: a message's text is in the recording over `tcp/` and absent over `tls/`.
"""

from __future__ import annotations

import shutil
import socket
import stat
import threading

import pytest

from asibot import access, certificates, keys, messages
from asibot.bus import Bus, open_router
from asibot.errors import Unavailable
from asibot.messages import Event
from asibot.testing import free_port, wait_until

ROBOT = "tls-bot"
SECRET = "the-carer-said-the-door-code-is-4711"


class Relay:
    """A TCP relay on a free loopback port to `target`, keeping the bytes that pass."""

    def __init__(self, target: int) -> None:
        self.target = target
        self.seen = bytearray()
        self._lock = threading.Lock()
        self._server = socket.create_server(("127.0.0.1", 0))
        self.port = self._server.getsockname()[1]
        self._sockets: list[socket.socket] = [self._server]
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self._server.accept()
            except OSError:
                return
            upstream = socket.create_connection(("127.0.0.1", self.target))
            self._sockets += [client, upstream]
            for a, b in ((client, upstream), (upstream, client)):
                threading.Thread(target=self._pump, args=(a, b), daemon=True).start()

    def _pump(self, src: socket.socket, dst: socket.socket) -> None:
        while True:
            try:
                data = src.recv(65536)
                if not data:
                    break
                with self._lock:
                    self.seen += data
                dst.sendall(data)
            except OSError:
                break
        for s in (src, dst):
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def saw(self, text: str) -> bool:
        with self._lock:
            return text.encode() in self.seen

    def close(self) -> None:
        for s in self._sockets:
            s.close()


@pytest.fixture
def guarded(tmp_path, monkeypatch):
    """A guarded router on loopback tcp/ and tls/; (tcp endpoint, tls port, folder)."""
    folder = access.ensure_credentials(tmp_path / "access")
    monkeypatch.setenv(access.ACCESS_ENV, str(folder))
    monkeypatch.delenv(access.ROLE_ENV, raising=False)
    tcp, tls = free_port(), free_port()
    session = open_router(f"tcp/127.0.0.1:{tcp},tls/127.0.0.1:{tls}", folder)
    try:
        yield f"tcp/127.0.0.1:{tcp}", tls, folder
    finally:
        session.close()


def test_the_credentials_folder_holds_the_robots_ca_and_router_certificate(tmp_path):
    folder = access.ensure_credentials(tmp_path / "access")
    for name in (certificates.CA_KEY, certificates.ROUTER, certificates.ROUTER_KEY):
        assert stat.S_IMODE((folder / name).stat().st_mode) == 0o600, name
    assert stat.S_IMODE((folder / certificates.CA).stat().st_mode) == 0o644   # public: clients get it
    from cryptography import x509
    router = x509.load_pem_x509_certificate((folder / certificates.ROUTER).read_bytes())
    ca = x509.load_pem_x509_certificate((folder / certificates.CA).read_bytes())
    assert router.issuer == ca.subject
    names = router.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "localhost" in names.get_values_for_type(x509.DNSName)
    assert socket.gethostname() in names.get_values_for_type(x509.DNSName)
    before = (folder / certificates.ROUTER).read_bytes()
    access.ensure_credentials(folder)   # kept: clients already trust that CA
    assert (folder / certificates.ROUTER).read_bytes() == before
    # A new name for the robot: router.pem deleted is issued again by the same CA
    ca_before = (folder / certificates.CA).read_bytes()
    (folder / certificates.ROUTER).unlink()
    certificates.ensure_router_certificate(folder, ["robot.example"])
    again = x509.load_pem_x509_certificate((folder / certificates.ROUTER).read_bytes())
    assert (folder / certificates.CA).read_bytes() == ca_before and again.issuer == ca.subject
    assert again.extensions.get_extension_for_class(x509.SubjectAlternativeName).value \
        .get_values_for_type(x509.DNSName) == ["localhost", "robot.example"]
    again.verify_directly_issued_by(ca)


def _exchange(sender: Bus, receiver: Bus) -> None:
    got: list[Event] = []
    receiver.subscribe(keys.events(ROBOT), Event, got.append)
    wait_until(lambda: sender.put_raw(keys.events(ROBOT), messages.encode(
        Event(level="info", code="note", text=SECRET))) or got, timeout=10.0, interval=0.1,
        message="the event never crossed the router")


def test_over_tls_nobody_in_between_reads_what_crosses(guarded):
    tcp, tls_port, _ = guarded
    with Bus("web", tcp, wait=10.0) as local:
        plain = Relay(int(tcp.rsplit(":", 1)[1]))
        try:
            with Bus("arm_driver", f"tcp/127.0.0.1:{plain.port}", wait=10.0) as remote:
                _exchange(remote, local)
            assert plain.saw(SECRET)      # the relay's recording works: tcp/ shows the text
        finally:
            plain.close()
        sealed = Relay(tls_port)
        try:
            with Bus("arm_driver", f"tls/127.0.0.1:{sealed.port}", wait=10.0) as remote:
                _exchange(remote, local)
            assert len(sealed.seen) > 1000 and not sealed.saw(SECRET)
        finally:
            sealed.close()


def test_a_client_trusts_only_the_robots_ca(guarded, tmp_path, monkeypatch):
    _, tls_port, folder = guarded
    # Another robot's folder with this robot's password: the login is right, the CA is not.
    other = access.ensure_credentials(tmp_path / "other")
    shutil.copy(folder / "operator.credentials", other / "operator.credentials")
    monkeypatch.setenv(access.ACCESS_ENV, str(other))
    with pytest.raises(Unavailable, match=r"or its certificate is not issued by .*other/ca.pem"):
        Bus("web", f"tls/127.0.0.1:{tls_port}", wait=2.0)
    # No CA at all: says which file to copy.
    empty = tmp_path / "empty"
    empty.mkdir()
    shutil.copy(folder / "operator.credentials", empty / "operator.credentials")
    monkeypatch.setenv(access.ACCESS_ENV, str(empty))
    with pytest.raises(Unavailable, match=r"copy ca.pem from the robot's credentials folder"):
        Bus("web", f"tls/127.0.0.1:{tls_port}", wait=2.0)
    # The right folder gets in.
    monkeypatch.setenv(access.ACCESS_ENV, str(folder))
    with Bus("web", f"tls/127.0.0.1:{tls_port}", wait=10.0) as bus:
        assert bus.alive(keys.ALL_SERVICES) is not None


def test_a_tls_router_needs_its_certificate_and_logins(tmp_path):
    with pytest.raises(ValueError, match="a tls/ endpoint is for a router with access control"):
        open_router(f"tls/127.0.0.1:{free_port()}")
    folder = access.ensure_credentials(tmp_path / "access")
    (folder / certificates.ROUTER).unlink()
    with pytest.raises(ValueError, match="python -m asibot.access"):
        open_router(f"tls/127.0.0.1:{free_port()}", folder)
