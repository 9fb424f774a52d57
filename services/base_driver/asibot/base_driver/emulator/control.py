"""The standalone emulator's fault injection: a tiny line protocol on a TCP socket.

One text line in, one JSON line out: `status`, `silent SECONDS`, `garbage COUNT`,
`drop COUNT`, `unplug SECONDS` (0..3600), acted on an `ArcosEmulator`.
"""

from __future__ import annotations

import json
import socket
import threading

from asibot.base_driver.emulator.server import ArcosEmulator


class ControlServer:
    """Tiny line protocol for the standalone emulator's fault injection."""

    def __init__(self, emulator: ArcosEmulator, listen: tuple[str, int]) -> None:
        self.emulator = emulator
        self._server = socket.create_server(listen)
        self._server.settimeout(0.2)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="emulator-control", daemon=True)

    @property
    def address(self) -> tuple[str, int]:
        return self._server.getsockname()[:2]

    def start(self) -> "ControlServer":
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=1.0)
        self._server.close()

    def _loop(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._server.accept()
            except (TimeoutError, OSError):
                continue
            with conn, conn.makefile("rw", encoding="utf-8", newline="\n") as f:
                conn.settimeout(5.0)
                try:
                    for line in f:
                        f.write(json.dumps(self.handle(line)) + "\n")
                        f.flush()
                except OSError:
                    pass

    def handle(self, line: str) -> dict:
        words = line.split()
        if not words:
            return {"ok": False, "message": "empty command; try: status, silent S, garbage N, drop N, unplug S"}
        verb, rest = words[0].lower(), words[1:]
        e = self.emulator
        try:
            if verb == "status":
                return {"ok": True, **e.status()}
            if len(rest) != 1:
                raise ValueError
            value = float(rest[0])
            if not value >= 0 or value > 3600:
                raise ValueError
        except ValueError:
            return {"ok": False, "message": f"bad command {line.strip()!r}; use: status, silent SECONDS, "
                                            "garbage COUNT, drop COUNT, unplug SECONDS (0..3600)"}
        actions = {"silent": lambda: e.go_silent(value), "garbage": lambda: e.inject_garbage(int(value)),
                   "drop": lambda: e.drop_bytes(int(value)), "unplug": lambda: e.pull_cable(value)}
        if verb not in actions:
            return {"ok": False, "message": f"unknown command {verb!r}; use status, silent, garbage, drop or unplug"}
        actions[verb]()
        return {"ok": True}
