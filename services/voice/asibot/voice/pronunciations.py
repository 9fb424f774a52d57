"""The user's own pronunciations, learned from recordings, kept in their data folder.

`<data>/voice/pronunciations.json` maps each learned phrase, as spoken ("give me the red
can"), to up to MAX_SAYINGS phone strings, newest last:

    {"zorblat": ["Z L AO R OW N D L ER", "P AO R D L ER"]}

A few sayings rather than one: the same person says a word a little differently each time,
and each saying becomes a variant the recogniser may match (CMUdict's `word(2)` idea). The
file is written whole or not at all (`asibot.files.write_atomic`); a file that cannot be read
is left as it is, with a warning, and learning starts afresh rather than stopping the service.
"""

from __future__ import annotations

import json
import logging
import threading
from pathlib import Path

from asibot.files import private_dir, write_atomic
from asibot.voice.phones import check_phones

log = logging.getLogger("asibot.voice")

MAX_SAYINGS = 3
"""Variants kept per phrase: more sayings would let more other speech through."""
MAX_PHRASES = 500            # as many as the grammar takes

Learned = dict[str, list[tuple[str, ...]]]


class Pronunciations:
    """Learned phrase -> its phone strings, in a JSON file. Thread-safe."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._lock = threading.Lock()
        self._learned: Learned = _read(path)

    def all(self) -> Learned:
        with self._lock:
            return {phrase: list(sayings) for phrase, sayings in self._learned.items()}

    def get(self, phrase: str) -> list[tuple[str, ...]]:
        with self._lock:
            return list(self._learned.get(phrase, []))

    def add(self, phrase: str, phones: tuple[str, ...]) -> tuple[list[tuple[str, ...]], bool]:
        """Keep `phones` as a saying of `phrase`: (its sayings now, whether the oldest was dropped).

        A saying already kept is not kept twice; beyond MAX_SAYINGS the oldest goes.
        """
        phones = check_phones(phones)
        with self._lock:
            sayings = [s for s in self._learned.get(phrase, []) if s != phones] + [phones]
            dropped = len(sayings) > MAX_SAYINGS
            if phrase not in self._learned and len(self._learned) >= MAX_PHRASES:
                raise ValueError(f"{MAX_PHRASES} phrases are learned already; forget some before learning more.")
            changed = {**self._learned, phrase: sayings[-MAX_SAYINGS:]}
            self._write(changed)
            self._learned = changed
            return list(changed[phrase]), dropped

    def forget(self, phrase: str) -> int:
        """Forget every saying of `phrase`; how many there were (0: nothing was learned)."""
        with self._lock:
            if phrase not in self._learned:
                return 0
            changed = {p: s for p, s in self._learned.items() if p != phrase}
            self._write(changed)
            count = len(self._learned[phrase])
            self._learned = changed
            return count

    def _write(self, learned: Learned) -> None:
        private_dir(self.path.parent)
        text = {phrase: [" ".join(s) for s in sayings] for phrase, sayings in learned.items()}
        write_atomic(self.path, json.dumps(text, indent=1, ensure_ascii=False).encode())


def _read(path: Path) -> Learned:
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as exc:
        log.warning("voice: %s cannot be read (%s); no learned pronunciations until a word is learned again",
                    path, exc)
        return {}
    if not isinstance(raw, dict):
        log.warning("voice: %s is not a map of phrases to pronunciations; it is ignored", path)
        return {}
    learned: Learned = {}
    for phrase, sayings in raw.items():
        try:
            if not isinstance(sayings, list) or not sayings:
                raise ValueError("it needs a list of pronunciations")
            learned[phrase] = [check_phones(s) for s in sayings][-MAX_SAYINGS:]
        except ValueError as exc:
            log.warning("voice: %s: the pronunciations of %r are left out: %s", path, phrase, exc)
    return learned
