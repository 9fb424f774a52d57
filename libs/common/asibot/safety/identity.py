"""Who sent a command or an estop: a key made at start, whose public half is the id.

On the open router any process could read a holder's id from its liveliness token and
command the robot as it, and an estop said it was released "by" whatever its sender wrote
(issue 25). Now an id is `<name>-<Ed25519 public key, base32>`, and every motion command and
estop carries a sequence number and a signature, by the id's private key, over what it is
for (robot and part), its type and every field. The private key never leaves the process
that made it, so reading ids or commands on the bus gives nobody the right to send them:

- a driver obeys a command only when its holder's key signed it, with a sequence number
  newer than the last it obeyed from that holder (`asibot.safety.ownership.Holder.refusal`): a
  recorded command played again is refused;
- an estop release counts only when signed, and the drivers' events name the key that
  signed it with the name its holder gave (`asibot.safety.estop`).

The keys are per process and per start, like the ids before them; nothing is stored.
libsodium (PyNaCl) signs and checks: it checks in half the time OpenSSL takes here, and a
driver checks every command of its holder (bench/bench_identity.py).
"""

from __future__ import annotations

import base64
import binascii
import dataclasses
import functools
import itertools
import threading
from typing import TYPE_CHECKING, Any, TypeVar

from nacl.exceptions import BadSignatureError, CryptoError
from nacl.signing import SigningKey, VerifyKey

from asibot import messages

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

# Not bound to messages.Message: mypy would then check replace()'s fields against Message's
# (`stamp` only), while every signed message has `seq` and `signature` of its own.
T = TypeVar("T", bound="DataclassInstance")

#: Length of the public key in an id: base32 of 32 bytes, lower case, without padding.
KEY_CHARS = 52


def _text(raw: bytes) -> str:
    return base64.b32encode(raw).decode("ascii").rstrip("=").lower()


@functools.lru_cache(maxsize=256)
def public_key(signer: str) -> VerifyKey | None:
    """The public key an id carries, or None when it carries none (an id from before keys,
    or not an id at all)."""
    _, sep, text = signer.rpartition("-")
    if not sep or len(text) != KEY_CHARS:
        return None
    try:
        return VerifyKey(base64.b32decode(text.upper() + "===="))
    except (binascii.Error, ValueError, CryptoError):
        return None


def short(signer: str) -> str:
    """An id as a person reads it in an event: its name and the first 8 characters of its key."""
    name, sep, text = signer.rpartition("-")
    return f"{name}-{text[:8]}" if sep and len(text) == KEY_CHARS else signer


def signer_field(msg: Any) -> str:
    """The field of a signed message that names its signer: `controller` in motion commands,
    `signer` in an EStop."""
    return "controller" if "controller" in msg._fields else "signer"


def signed_bytes(context: str, msg: Any) -> bytes:
    """What a signature covers: the context ("<robot>/<part>"), then the message as encoded
    with an empty signature (type and every field, the stamp and the sequence number too)."""
    return context.encode() + b"\n" + messages.encode(dataclasses.replace(msg, signature=b""))


def refusal(context: str, msg: Any) -> str | None:
    """None when `msg` is signed, for `context`, by the key its signer id carries; otherwise
    why not, as the end of a sentence."""
    signer = getattr(msg, signer_field(msg))
    key = public_key(signer) if signer else None
    if key is None:
        return "its sender's id carries no key to check it by" if signer else "it is not signed"
    if not msg.signature:
        return "it is not signed"
    try:
        key.verify(signed_bytes(context, msg), msg.signature)
    except (BadSignatureError, ValueError):
        return f"its signature is not {short(signer)}'s (for {context})"
    return None


class Identity:
    """A sender's id and its private key, made at start: `sign` and `put` what it sends.

    Sequence numbers count up across everything it signs; `put` signs and publishes under
    one lock, so they reach a subscriber in order whichever thread sends."""

    def __init__(self, name: str) -> None:
        self._key = SigningKey.generate()
        self.id = f"{name}-{_text(bytes(self._key.verify_key))}"
        self._seq = itertools.count(1)
        self._lock = threading.Lock()

    def sign(self, msg: T, context: str) -> T:
        """A copy of `msg` that names this id, with the next sequence number and a signature."""
        msg = dataclasses.replace(msg, **{signer_field(msg): self.id}, seq=next(self._seq), signature=b"")
        # Sign the form a receiver decodes (ints it reads as floats, tuples as lists).
        msg = messages.decode(type(msg), messages.encode(msg))
        return dataclasses.replace(msg, signature=self._key.sign(signed_bytes(context, msg)).signature)

    def put(self, publisher: Any, msg: Any, context: str) -> None:
        """Sign `msg` and publish it, in sequence order."""
        with self._lock:
            publisher.put(self.sign(msg, context))

    def __repr__(self) -> str:
        return f"Identity({short(self.id)!r})"
