"""Plain text on the NetConnection port: newline-terminated UTF-8 lines (netcat, scripts, the
thesis's own plugins), told apart from NetConnection by the first bytes, answered with lines.

`sniff(first_bytes)` says which protocol a connection speaks: NetConnection frames start with
`@N`; anything else is text. `LineDecoder.feed(bytes)` returns the complete lines (CR LF or
LF; CR is dropped), and a `BadLine` for a line that is too long or not UTF-8, without holding
more than `max_bytes` of a line.
"""

from __future__ import annotations

from dataclasses import dataclass

from asibot.asterics_bridge.netconnection import MAGIC

NETCONNECTION, TEXT = "netconnection", "text"
MAX_LINE_BYTES = 1024


def sniff(first: bytes) -> str | None:
    """The protocol of a connection from its first bytes; None while they cannot tell yet
    (a lone '@')."""
    if not first:
        return None
    if first[:len(MAGIC)] == MAGIC:
        return NETCONNECTION
    if first == MAGIC[:1]:
        return None
    return TEXT


@dataclass(frozen=True)
class BadLine:
    text: str


class LineDecoder:
    def __init__(self, max_bytes: int = MAX_LINE_BYTES) -> None:
        self.max_bytes = max_bytes
        self._buf = bytearray()
        self._skipping = False     # inside a line that was too long: drop up to its newline

    def pending(self) -> int:
        return len(self._buf)

    def partial(self) -> bool:
        """Whether a line has begun and not ended (also one too long, being skipped)."""
        return bool(self._buf) or self._skipping

    def feed(self, data: bytes) -> list[str | BadLine]:
        out: list[str | BadLine] = []
        self._buf += data
        while True:
            end = self._buf.find(b"\n")
            if end < 0:
                if len(self._buf) > self.max_bytes:
                    if not self._skipping:
                        out.append(self._too_long())
                    self._skipping = True
                    self._buf.clear()
                return out
            raw = bytes(self._buf[:end]).rstrip(b"\r")
            del self._buf[:end + 1]
            if self._skipping:
                self._skipping = False
                continue
            if len(raw) > self.max_bytes:
                out.append(self._too_long())
                continue
            try:
                out.append(raw.decode("utf-8"))
            except UnicodeDecodeError:
                out.append(BadLine("That line is not UTF-8 text; send commands as UTF-8 lines such as 'forward'."))

    def _too_long(self) -> BadLine:
        return BadLine(f"That line is longer than {self.max_bytes} bytes; it was ignored. "
                       "Send one command a line, such as 'forward'.")


def encode_line(text: str) -> bytes:
    """One answer line: no newline inside it, UTF-8, LF-terminated."""
    return (" ".join(text.splitlines()) + "\n").encode("utf-8", "replace")
