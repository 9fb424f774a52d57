"""Certificates for the router's TLS, so logins cross a network encrypted.

Over plain `tcp/` anyone on the network reads what crosses (commands, robot state, the
login exchange) and can pose as the router, so a router reached from other machines listens
on `tls/` too. Its certificate is issued by a certificate
authority made for this robot alone: clients trust only `ca.pem` (copied with their
credentials), so no public CA, no internet and no browser exception are involved, and a
router that moved to another address only needs a new certificate from the same CA (delete
router.pem and run `python -m asibot.access` on the robot).

Files, in the credentials folder (asibot.access): `ca.pem` (public: every client gets it),
`ca.key` (0600: only to issue the router's certificate again), `router.pem` and `router.key`
(0600: the router's).
"""

from __future__ import annotations

import datetime
import ipaddress
import os
import socket
from pathlib import Path
from typing import Any

from asibot.files import open_private, private_dir

CA, CA_KEY, ROUTER, ROUTER_KEY = "ca.pem", "ca.key", "router.pem", "router.key"
#: Years a certificate holds: a robot at home is not re-keyed every few months.
YEARS = 10


def this_machine() -> list[str]:
    """Names a client on the network may use for this machine: its host names and
    addresses besides loopback (loopback itself is always in the certificate)."""
    names = {socket.gethostname(), socket.getfqdn()}
    try:
        for info in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET):
            address = info[4][0]
            if isinstance(address, str):  # always, for AF_INET: (host, port)
                names.add(address)
    except OSError:
        pass
    return sorted(n for n in names if n and not n.startswith("127.") and n != "localhost")


def alt_names(names: list[str]) -> Any:
    """The subjectAltName extension for `names` plus localhost and 127.0.0.1: what a TLS
    client checks the address it dialled against."""
    from cryptography import x509

    alt: list[Any] = [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]
    for name in dict.fromkeys(names):
        try:
            alt.append(x509.IPAddress(ipaddress.ip_address(name)))
        except ValueError:
            alt.append(x509.DNSName(name))
    return x509.SubjectAlternativeName(alt)


def _write_private(path: Path, data: bytes) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open_private(tmp, "wb") as f:
        f.write(data)
    os.replace(tmp, path)


def ensure_router_certificate(folder: Path, names: list[str] | None = None) -> tuple[Path, Path, Path]:
    """(ca.pem, router.pem, router.key) in `folder`, made on first use for `names` (default:
    `this_machine()`). Existing files are kept, since clients already trust that CA; with
    router.pem deleted (the robot got a new name or address), the router's certificate is
    issued again by the same CA, so no client needs a new ca.pem."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import dsa, ec, rsa
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    ca_path, cert_path, key_path = folder / CA, folder / ROUTER, folder / ROUTER_KEY
    if ca_path.exists() and cert_path.exists() and key_path.exists():
        return ca_path, cert_path, key_path
    now = datetime.datetime.now(datetime.timezone.utc)
    start, end = now - datetime.timedelta(minutes=5), now + datetime.timedelta(days=365 * YEARS)
    pem, pkcs8, nothing = serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    private_dir(folder)

    if ca_path.exists() and (folder / CA_KEY).exists():
        ca = x509.load_pem_x509_certificate(ca_path.read_bytes())
        loaded = serialization.load_pem_private_key((folder / CA_KEY).read_bytes(), password=None)
        # Ours is EC; one put there by hand may be any key that signs with SHA-256.
        if not isinstance(loaded, (ec.EllipticCurvePrivateKey, rsa.RSAPrivateKey, dsa.DSAPrivateKey)):
            raise ValueError(f"{folder / CA_KEY} cannot sign certificates with SHA-256 (it is a "
                             f"{type(loaded).__name__}); remove {CA} and {CA_KEY} there to make a new CA")
        ca_key = loaded
    else:
        ca_key = ec.generate_private_key(ec.SECP256R1())
        ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, f"asibot robot CA ({socket.gethostname()})")])
        ca = (x509.CertificateBuilder().subject_name(ca_name).issuer_name(ca_name)
              .public_key(ca_key.public_key()).serial_number(x509.random_serial_number())
              .not_valid_before(start).not_valid_after(end)
              .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
              .add_extension(x509.KeyUsage(digital_signature=False, content_commitment=False,
                                           key_encipherment=False, data_encipherment=False, key_agreement=False,
                                           key_cert_sign=True, crl_sign=True, encipher_only=False,
                                           decipher_only=False), critical=True)
              .sign(ca_key, hashes.SHA256()))
        _write_private(folder / CA_KEY, ca_key.private_bytes(pem, pkcs8, nothing))
    router_key = ec.generate_private_key(ec.SECP256R1())
    router = (x509.CertificateBuilder()
              .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "asibot router")]))
              .issuer_name(ca.subject).public_key(router_key.public_key())
              .serial_number(x509.random_serial_number()).not_valid_before(start).not_valid_after(end)
              .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
              .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH]), critical=False)
              .add_extension(alt_names(this_machine() if names is None else names), critical=False)
              .sign(ca_key, hashes.SHA256()))
    _write_private(key_path, router_key.private_bytes(pem, pkcs8, nothing))
    _write_private(cert_path, router.public_bytes(pem))
    if not ca_path.exists():
        _write_private(ca_path, ca.public_bytes(pem))   # last: its presence says the set is whole
        os.chmod(ca_path, 0o644)
    return ca_path, cert_path, key_path
