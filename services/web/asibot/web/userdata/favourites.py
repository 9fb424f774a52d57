"""What this person uses most: how often each task was launched and each place gone to, and the
order the carer chose, in favourites.json of the data folder.

The page's Home offers the person's tasks and places one level deep, most used lately first, so
one switch reaches the usual ones in a few presses; a carer who knows better sets the order, and
what the order leaves out follows by use. Use is counted, and weighs half for every two weeks
since an item was last used: what the person does now comes before what they did last winter.
An item is named by a key:

    task:<task name>                 a Launcher task
    place:<robot>/<place name>       a named place of a mobile robot

    {"uses": {"task:Give me the red can": 4, "place:pioneer-sim/fridge": 2},
     "last": {"task:Give me the red can": 1795000000.0, "place:pioneer-sim/fridge": 1794000000.0},
     "order": ["place:pioneer-sim/fridge", "task:Give me the red can"]}

Plain Python, no web framework and no bus; writes are atomic and under the folder's one lock.
A file edited by hand keeps what makes sense and leaves the rest out.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from dataclasses import dataclass, field

from asibot.files import write_atomic
from asibot.web.userdata.errors import UserDataError
from asibot.web.userdata.folder import Folder, log

FILE = "favourites.json"
#: Keys kept: every task and place of a home, with room; a runaway page cannot grow the file.
MAX_KEYS = 500
MAX_KEY = 200
KINDS = ("task", "place")
#: s after which a use weighs half as much in the order: two weeks.
HALF_LIFE = 14 * 24 * 3600.0


def task_key(name: str) -> str:
    return f"task:{name}"


def place_key(robot: str, name: str) -> str:
    return f"place:{robot}/{name}"


def check_key(key: object) -> str:
    """A key as the page sends it, or a sentence saying what a key looks like."""
    if not isinstance(key, str) or not 0 < len(key) <= MAX_KEY:
        raise UserDataError(f"An item is named by a key of 1 to {MAX_KEY} characters, like \"task:Give me the "
                            "red can\" or \"place:pioneer-sim/fridge\".")
    kind, _, rest = key.partition(":")
    if kind not in KINDS or not rest or (kind == "place" and "/" not in rest):
        raise UserDataError(f"{key!r} is not an item: say \"task:<task>\" or \"place:<robot>/<place>\".")
    return key


@dataclass
class Usage:
    uses: dict[str, int]
    order: list[str]
    last: dict[str, float] = field(default_factory=dict)    # when each was last used, epoch s

    def weight(self, key: str, now: float) -> float:
        """Its uses, halved for every HALF_LIFE since its last (a file from before `last` was
        kept: its count as it is)."""
        age = max(0.0, now - self.last.get(key, now))
        return self.uses.get(key, 0) * 0.5 ** (age / HALF_LIFE)

    def rank(self, keys: list[str], now: float | None = None) -> list[str]:
        """`keys` in the person's order: the carer's first, as the carer put them; then by use,
        most used lately first; then tasks before places (a task is what the Launcher is for),
        then by name."""
        now = time.time() if now is None else now
        chosen = [k for k in self.order if k in keys]
        rest = sorted((k for k in keys if k not in chosen),
                      key=lambda k: (-self.weight(k, now), KINDS.index(k.partition(":")[0]), k.casefold()))
        return chosen + rest


class Favourites:
    """favourites.json of one folder."""

    def __init__(self, folder: Folder) -> None:
        self.folder = folder

    def read(self) -> Usage:
        with self.folder.lock:
            path = self.folder.root / FILE
            raw: object = {}
            if path.is_file():
                try:
                    raw = json.loads(path.read_text(encoding="utf-8"))
                except (OSError, ValueError) as exc:
                    # Kept aside, not overwritten by the next count: a carer's hand edit is not lost.
                    aside = path.with_name(FILE + ".unreadable")
                    log.warning("%s is not JSON (%s): kept as %s, counting starts again", FILE, exc, aside.name)
                    with contextlib.suppress(OSError):
                        os.replace(path, aside)
            raw = raw if isinstance(raw, dict) else {}
            uses, order, last = raw.get("uses"), raw.get("order"), raw.get("last")
            kept_uses = dict(list({k: v for k, v in (uses.items() if isinstance(uses, dict) else ())
                                   if _is_key(k) and isinstance(v, int) and not isinstance(v, bool) and v > 0
                                   }.items())[:MAX_KEYS])
            kept_last = {k: float(v) for k, v in (last.items() if isinstance(last, dict) else ())
                         if k in kept_uses and isinstance(v, (int, float)) and not isinstance(v, bool)}
            kept_order = list(dict.fromkeys(k for k in (order if isinstance(order, list) else []) if _is_key(k)))
            return Usage(kept_uses, kept_order[:MAX_KEYS], kept_last)

    def _write(self, usage: Usage) -> None:
        body = {"uses": usage.uses, "last": usage.last, "order": usage.order}
        write_atomic(self.folder.root / FILE, (json.dumps(body, indent=1) + "\n").encode())

    def used(self, key: str, now: float | None = None) -> None:
        """Count one use of `key` (a launch, a trip). It never raises: the launch or the trip it
        counts has happened, and a full disk must not make it look refused."""
        now = time.time() if now is None else now
        try:
            check_key(key)
            with self.folder.lock:
                usage = self.read()
                if key not in usage.uses and len(usage.uses) >= MAX_KEYS:
                    # Forget the least used lately: what is used now matters more.
                    gone = min(usage.uses, key=lambda k: usage.weight(k, now))
                    del usage.uses[gone]
                    usage.last.pop(gone, None)
                usage.uses[key] = usage.uses.get(key, 0) + 1
                usage.last[key] = now
                self._write(usage)
        except (OSError, UserDataError) as exc:
            log.warning("a use of %r was not counted: %s", key, exc)

    def set_order(self, order: list[str]) -> Usage:
        """The carer's order (an empty list: by use alone); a bad key changes nothing."""
        if len(order) > MAX_KEYS:
            raise UserDataError(f"An order may name up to {MAX_KEYS} items.")
        checked = [check_key(k) for k in order]
        if len(set(checked)) != len(checked):
            raise UserDataError("An item may appear once in the order.")
        with self.folder.lock:
            usage = self.read()
            usage.order = checked
            self._write(usage)
            return usage


def _is_key(key: object) -> bool:
    try:
        check_key(key)
    except UserDataError:
        return False
    return True
