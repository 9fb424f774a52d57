"""The serial line, named by a URL as pyserial's `serial_for_url` understands it.

`/dev/ttyUSB0` (a real port, 8N1 raw), `socket://127.0.0.1:8101` (MobileSim, ser2net, the
emulator), `loop://` and the other pyserial handlers all work unchanged (docs/arcos.md "Serial line").
"""

from __future__ import annotations

from typing import Protocol

import socket

import serial

#: ARCOS's power-on rate (docs/arcos.md "Serial line": ARIA and p2os both start at 9600).
DEFAULT_BAUD = 9600

LinkError = (serial.SerialException, OSError)


class Link(Protocol):
    """What the ARCOS client needs from a line: pyserial's Serial satisfies it."""

    def read(self, size: int = 1) -> bytes: ...
    def write(self, data: bytes) -> int | None: ...
    def reset_input_buffer(self) -> None: ...
    def close(self) -> None: ...

    @property
    def in_waiting(self) -> int: ...


def open_link(url: str, baud: int = DEFAULT_BAUD, read_timeout: float = 0.02) -> serial.SerialBase:
    """Open the line; raises serial.SerialException with pyserial's reason when it cannot."""
    link = serial.serial_for_url(url, baudrate=baud, bytesize=8, parity="N", stopbits=1,
                                 timeout=read_timeout, write_timeout=1.0)
    _no_delay(link)
    return link


def _no_delay(link: serial.SerialBase) -> None:
    """Disable Nagle on socket:// lines: a 9-byte VEL must not wait ~40 ms for a delayed ACK.

    pyserial keeps the socket in the private `_socket` attribute and does not set TCP_NODELAY.
    """
    sock = getattr(link, "_socket", None)
    if isinstance(sock, socket.socket) and sock.family in (socket.AF_INET, socket.AF_INET6):
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
