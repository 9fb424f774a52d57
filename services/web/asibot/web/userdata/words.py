"""Recorded words and phrases: words.ini, one a line, in the order they were added."""

from __future__ import annotations

from asibot.files import write_atomic
from asibot.web.userdata.errors import AlreadyExists, NotFound, UserDataError
from asibot.web.userdata.folder import Folder, log
from asibot.web.userdata.names import CONTROL_RE, quote

MAX_WORD = 80


def check_word(text: object) -> str:
    """A word or phrase is one line of words.ini; ';' joins several in a .task file."""
    if not isinstance(text, str):
        raise UserDataError(f"The word must be text; got {quote(text)}.")
    text = text.strip()  # spaces around a spoken phrase mean nothing
    if not text:
        raise UserDataError("The word is empty; please type a word or a phrase.")
    if len(text) > MAX_WORD:
        raise UserDataError(f"The word {quote(text)} is longer than {MAX_WORD} characters.")
    if CONTROL_RE.search(text) or ";" in text:
        raise UserDataError(f"The word {quote(text)} must be one line without ';'.")
    return text


class Words:
    """words.ini of one folder; the same word in other capitals is the same word."""

    def __init__(self, folder: Folder) -> None:
        self.folder = folder

    def all(self) -> list[str]:
        out: list[str] = []
        seen: set[str] = set()
        for line in self.folder.read_lines("words.ini"):
            try:
                w = check_word(line)
            except UserDataError as e:
                log.warning("words.ini line left out: %s", e)
                continue
            if w.casefold() not in seen:
                seen.add(w.casefold())
                out.append(w)
        return out

    def add(self, text: str) -> str:
        text = check_word(text)
        if text.casefold() in {w.casefold() for w in self.all()}:
            raise AlreadyExists(f"The word {quote(text)} is already in the list of words.")
        self.write(self.all() + [text])
        return text

    def delete(self, text: str) -> None:
        text = check_word(text)
        words = self.all()
        kept = [w for w in words if w.casefold() != text.casefold()]
        if len(kept) == len(words):
            raise NotFound(f"The word {quote(text)} is not in the list of words.")
        self.write(kept)

    def add_new(self, words: list[str]) -> None:
        """Record those of `words` (checked already) that are not recorded yet."""
        known = self.all()
        folded = {w.casefold() for w in known}
        new = [w for w in words if w.casefold() not in folded]
        if new:
            self.write(known + new)

    def write(self, words: list[str]) -> None:
        write_atomic(self.folder.root / "words.ini", "".join(w + "\n" for w in words).encode())
