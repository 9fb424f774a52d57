"""The page's live feed: one WebSocket per open page, robot state pushed at a steady rate.

Bus callbacks arrive on bus threads at up to 100 Hz per robot; a page needs about 30 Hz and
must never make the bus wait. So bus threads only mark a robot as changed (thread-safe, O(1)),
and one asyncio task sends the changed robots' views to every page PUSH_HZ times a second.
A page that cannot keep up loses intermediate states, never the newest one.
"""

from __future__ import annotations

import asyncio
import json
import logging
import secrets
import threading
from typing import Any, Callable

from fastapi import WebSocket

#: Robot state pushes per second to each page (the 3D view follows at this rate).
PUSH_HZ = 30.0
#: Messages queued for a slow page before it is dropped (it reconnects and gets a fresh view).
QUEUE_LIMIT = 200

log = logging.getLogger("asibot.web.live")


class Page:
    """One connected page: a bounded outbox drained by its own sender task."""

    def __init__(self, socket: WebSocket) -> None:
        self.socket = socket
        self.outbox: asyncio.Queue[str] = asyncio.Queue(QUEUE_LIMIT)
        self.holding: str | None = None   # the robot this page streams hold-to-move to
        self.id = secrets.token_hex(4)      # names its microphone's stream for the voice service
        self.mic_rate: int | None = None    # Hz, while the page listens
        self.mic: Any = None                # the subscription to what voice says of its audio

    def offer(self, text: str) -> bool:
        try:
            self.outbox.put_nowait(text)
            return True
        except asyncio.QueueFull:
            return False


class Live:
    """Pages and what changed since the last push."""

    def __init__(self, view_of: Callable[[str], dict[str, Any]], views: Callable[[], list[dict[str, Any]]]) -> None:
        self.view_of = view_of
        self.views = views
        self.pages: set[Page] = set()
        self._changed: set[str] = set()
        self._sent: dict[str, str] = {}     # robot -> the last view pushed
        self._lock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None

    # --- from any thread ---------------------------------------------------------------------
    def changed(self, robot_id: str) -> None:
        """A robot's state changed (called from bus threads)."""
        with self._lock:
            self._changed.add(robot_id)

    def send(self, message: dict[str, Any]) -> None:
        """Send one message to every page, from any thread (program output, run status)."""
        loop = self._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self._broadcast, json.dumps(message))

    # --- on the event loop ---------------------------------------------------------------------
    def _broadcast(self, text: str) -> None:
        for page in list(self.pages):
            if not page.offer(text):
                log.warning("a page is too slow for its feed; closing it so it reconnects")
                self.pages.discard(page)
                asyncio.ensure_future(page.socket.close(code=1013))

    async def pusher(self) -> None:
        """Push the changed robots' views PUSH_HZ times a second (runs for the app's lifetime)."""
        self._loop = asyncio.get_running_loop()
        while True:
            await asyncio.sleep(1.0 / PUSH_HZ)
            with self._lock:
                changed, self._changed = self._changed, set()
            for robot_id in sorted(changed):
                try:
                    view = self.view_of(robot_id)
                except KeyError:
                    continue
                text = json.dumps({"type": "robot", "robot": view})
                # A still robot sends the same state 100 times a second: the page has it already
                # (a new page gets every robot when it attaches), and redrawing it costs a
                # tablet's page a sixth of a core for nothing.
                if text != self._sent.get(robot_id):
                    self._sent[robot_id] = text
                    self._broadcast(text)

    async def attach(self, socket: WebSocket) -> Page:
        """A new page: it first gets every robot, then the changes."""
        page = Page(socket)
        self.pages.add(page)
        # Its snapshot may be newer than what was pushed last: push every robot's next view, or
        # a robot back where it was at the last push would leave this page on the snapshot.
        self._sent.clear()
        page.offer(json.dumps({"type": "hello", "page": page.id}))
        page.offer(json.dumps({"type": "robots", "robots": self.views()}))
        return page

    def detach(self, page: Page) -> None:
        self.pages.discard(page)

    @staticmethod
    async def drain(page: Page) -> None:
        """Send a page's outbox until its socket closes."""
        while True:
            text = await page.outbox.get()
            await page.socket.send_text(text)
