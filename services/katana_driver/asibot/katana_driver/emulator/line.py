"""The emulator on a serial line: a pty pair, the emulator on its master side, a real
`serial.Serial` on its slave side for the driver (what `--serial emulated` opens).

The serving thread reads bytes, cuts them into frames as the controller does (a request is
`01 <address> <n>` then n + 2 bytes; the error request is `00 00 00 C1`; any other byte is
noise and dropped) and writes each answer back. `trace(direction, bytes)` sees every frame
both ways ("rx" what the emulator read, "tx" what it sent).
"""

from __future__ import annotations

import os
import select
import threading
import tty
from typing import Callable

import serial

from asibot.katana_driver import protocol as p
from asibot.katana_driver.emulator.controller import KatanaEmulator

Trace = Callable[[str, bytes], None]


class EmulatedLine:
    """`emulator` served on a pty; `port` is the driver's end, `path` its device name."""

    def __init__(self, emulator: KatanaEmulator, trace: Trace | None = None) -> None:
        self.emulator = emulator
        self.trace = trace
        self._master, slave = os.openpty()
        tty.setraw(self._master)
        self.path = os.ttyname(slave)
        self.port = serial.serial_for_url(self.path, baudrate=p.BAUD, bytesize=p.BYTESIZE, parity=p.PARITY,
                                          stopbits=p.STOPBITS, timeout=0.01, write_timeout=1.0)
        os.close(slave)                     # pyserial holds its own descriptor of the slave
        self._stop = threading.Event()
        self._wake_r, self._wake_w = os.pipe()
        self._thread = threading.Thread(target=self._serve, name="katana-emulator", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        buf = b""
        while not self._stop.is_set():
            ready, _, _ = select.select([self._master, self._wake_r], [], [], 0.5)
            if self._wake_r in ready or self._stop.is_set():
                return
            if not ready:
                continue
            try:
                data = os.read(self._master, 4096)
            except OSError:
                return
            buf += data
            while buf:
                frame, buf = _cut(buf)
                if frame is None:
                    break
                if not frame:
                    continue
                if self.trace is not None:
                    self.trace("rx", frame)
                answer = self.emulator.answer(frame)
                if answer is not None:
                    if self.trace is not None:
                        self.trace("tx", answer)
                    try:
                        os.write(self._master, answer)
                    except OSError:
                        return

    def close(self) -> None:
        self._stop.set()
        os.write(self._wake_w, b"x")
        self._thread.join(2.0)
        try:
            self.port.close()
        finally:
            for fd in (self._master, self._wake_r, self._wake_w):
                os.close(fd)


def _cut(buf: bytes) -> tuple[bytes | None, bytes]:
    """(one frame, the rest); (b"", rest) for a dropped noise byte; (None, buf) until more comes."""
    if buf[0] == p.HEADER_START:
        n = p.request_length(buf)
        if n is None or len(buf) < n:
            return None, buf
        return buf[:n], buf[n:]
    if buf[0] == 0:
        if len(buf) < len(p.ERROR_REQUEST):
            return (None, buf) if p.ERROR_REQUEST.startswith(buf) else (b"", buf[1:])
        if buf.startswith(p.ERROR_REQUEST):
            return p.ERROR_REQUEST, buf[len(p.ERROR_REQUEST):]
    return b"", buf[1:]
