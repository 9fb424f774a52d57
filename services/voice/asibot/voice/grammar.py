"""The words the robot listens for, as a JSGF grammar for pocketsphinx.

A carer assigns words or phrases to tasks ("give me the red can", "drink"); the user's
words.ini keeps them as typed. The recogniser listens for exactly those, plus the fixed
words `stop`, `yes` and `no`, and nothing else: a closed grammar is what makes a small
offline recogniser reliable for a handful of commands.

Phrases are compared as spoken: case, punctuation and runs of spaces do not matter
("Give me the red can!" and "give me the red can" are one phrase; the first spelling is
the one reported). Every word must be in the pronunciation dictionary shipped with
pocketsphinx (CMUdict, 126 000 English words): pocketsphinx 5 has no letter-to-sound
fallback, and a word without a pronunciation cannot be recognised, so it is refused with a
sentence naming it, not silently dropped, unless the user taught the recogniser how they
say it (`learned`: phone strings from their own recordings, asibot.voice.learning), which
also adds their way of saying a word the dictionary does know. Digits are not words ("room
2" is refused: write "room two").

Building is cheap (string work plus one set lookup per word, the dictionary is read once
per process), so the web service can rebuild on every change of words.ini.
"""

from __future__ import annotations

import hashlib
import re
import unicodedata
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Iterable, Mapping, Sequence

from asibot.errors import quote
from asibot.voice.errors import GrammarError

#: Said to the robot whatever the tasks: stop what you do, answer a question.
FIXED_WORDS = ("stop", "yes", "no")
#: Said again and again in a hurry ("stop, stop, stop!"): still one command.
REPEATABLE = ("stop",)
MAX_PHRASES = 500
"""A grammar of hundreds of phrases still decodes in real time; thousands would not, and
no carer assigns that many."""
MAX_WORDS_PER_PHRASE = 12
_APOSTROPHES = str.maketrans({"\u2019": "'", "\u2018": "'", "`": "'", "\u00b4": "'"})
_SEPARATORS = re.compile(r"[^\w'\-]+")     # anything but letters, digits, _, ' and - splits words


def default_dictionary() -> Path:
    """The pronunciation dictionary inside the pocketsphinx wheel (CMUdict, US English)."""
    from pocketsphinx import get_model_path
    return Path(get_model_path("en-us/cmudict-en-us.dict"))


@lru_cache(maxsize=4)
def _read_words(path: str) -> frozenset[str]:
    words = set()
    with open(path, encoding="utf-8") as f:
        for line in f:
            head = line.split(" ", 1)[0].split("\t", 1)[0]
            if head:
                words.add(head.split("(", 1)[0])        # "can(2)": a second pronunciation of "can"
    return frozenset(words)


class Lexicon:
    """The words the recogniser can pronounce: those of a pocketsphinx dictionary file."""

    def __init__(self, path: str | Path | None = None) -> None:
        self.path = Path(path) if path is not None else default_dictionary()
        try:
            self.words = _read_words(str(self.path))
        except OSError as e:
            raise GrammarError(f"The pronunciation dictionary {self.path} cannot be read ({e.strerror or e}); "
                               "reinstall pocketsphinx (`pip install pocketsphinx`).") from None

    def __contains__(self, word: str) -> bool:
        return word in self.words


def tokens(text: str) -> list[str]:
    """The words of `text` as the dictionary spells them: lower case, no punctuation.

    Apostrophes stay inside words (don't, o'clock), hyphens too when the dictionary has the
    hyphenated word (t-shirt); `tokens` alone does not look at the dictionary, so a hyphen
    is kept here and `normalise` decides.
    """
    text = unicodedata.normalize("NFC", text).translate(_APOSTROPHES).casefold()
    out = []
    for raw in _SEPARATORS.split(text.replace("_", " ")):
        word = raw.strip("'-")
        if word:
            out.append(word)
    return out


def spoken(text: object) -> str:
    """The phrase as said, without asking the dictionary ("Zorblat!" -> "zorblat"): the name
    of a pronunciation learned from a recording. GrammarError: not text, empty, too long."""
    if not isinstance(text, str):
        raise GrammarError(f"A word or phrase must be text; got {quote(text)}.")
    return _phrase(tokens(text), text)


def phrase_key(text: object, lexicon: Lexicon | None = None) -> str:
    """The name the grammar knows `text` by: `normalise` when the dictionary has every word, else
    `spoken` (a learned pronunciation is kept under the name the grammar will look it up by)."""
    try:
        return normalise(text, lexicon)
    except GrammarError:
        return spoken(text)


def normalise(text: object, lexicon: Lexicon | None = None) -> str:
    """The phrase as the grammar holds it ("Give me the red can!" -> "give me the red can").

    Raises GrammarError with a sentence naming the problem: not text, empty, too long, or a
    word the dictionary does not have.
    """
    if not isinstance(text, str):
        raise GrammarError(f"A word or phrase must be text; got {quote(text)}.")
    lexicon = lexicon or Lexicon()
    words: list[str] = []
    for word in tokens(text):
        if word in lexicon:
            words.append(word)
        elif "-" in word and all(part in lexicon for part in word.split("-") if part):
            words.extend(part for part in word.split("-") if part)     # "red-can": two known words
        else:
            raise GrammarError(_unknown_sentence(word, text))
    return _phrase(words, text)


def _phrase(words: list[str], text: str) -> str:
    """`words` as one phrase, or GrammarError when there are none or too many."""
    if not words:
        raise GrammarError(f"The phrase {quote(text, 40)} has no words; type a word or a phrase to say.")
    if len(words) > MAX_WORDS_PER_PHRASE:
        raise GrammarError(f"The phrase {quote(text, 40)} has {len(words)} words; a voice command may have at "
                           f"most {MAX_WORDS_PER_PHRASE}.")
    return " ".join(words)


def _unknown_sentence(word: str, text: str) -> str:
    where = "" if word == text.strip().casefold() else f" in {quote(text, 40)}"
    if any(c.isdigit() for c in word):
        return (f"The word {word!r}{where} cannot be recognised: write numbers as words "
                f"(for example 'two', not '2').")
    return (f"The word {word!r}{where} is not in the recogniser's English dictionary, so it cannot be "
            "recognised; use another word (check the spelling, or choose a common English word).")


def check_phrase(text: object, lexicon: Lexicon | None = None) -> str:
    """What the web service calls when a carer types a word: the spoken form, or GrammarError."""
    phrase = normalise(text, lexicon)
    if phrase in FIXED_WORDS:
        raise GrammarError(f"{phrase!r} is a fixed voice word (the robot always understands "
                           f"{', '.join(FIXED_WORDS)}); choose another word for a task.")
    return phrase


@dataclass(frozen=True)
class Grammar:
    """A compiled-ready grammar: JSGF text and what each spoken phrase stands for."""

    jsgf: str
    phrases: dict[str, str]
    """spoken form -> the word as the user wrote it (the fixed words map to themselves)."""
    refused: dict[str, str] = field(default_factory=dict)
    """word as written -> the sentence saying why it was left out (with skip_unknown)."""
    learned: dict[str, tuple[str, tuple[str, ...]]] = field(default_factory=dict)
    """dictionary entry -> (the spoken phrase, its phones): the user's own pronunciations, each
    a made-up word the recogniser must be given (`Recognizer.set_grammar` adds them)."""

    def phrase_of(self, word: str) -> str:
        """What a word of a search result says: a learned pronunciation is its whole phrase."""
        entry = self.learned.get(word)
        return entry[0] if entry else word

    def lookup(self, hypothesis: str) -> str | None:
        """The phrase a search result is ("stop stop" is "stop"), or None (a partial phrase)."""
        if hypothesis in self.phrases:
            return hypothesis
        words = hypothesis.split()
        if words and words[0] in REPEATABLE and all(w == words[0] for w in words):
            return words[0]
        return None

    @property
    def key(self) -> str:
        """Same key, same grammar: lets a recogniser skip a rebuild that changes nothing."""
        return hashlib.sha1(self.jsgf.encode()).hexdigest()[:16]


def build_grammar(words: Iterable[str], lexicon: Lexicon | None = None, skip_unknown: bool = False,
                  learned: Mapping[str, Sequence[Sequence[str]]] | None = None) -> Grammar:
    """The grammar of `words` (the user's phrases) and FIXED_WORDS.

    `learned` (spoken phrase -> phone strings, as `Pronunciations.all()` gives) adds the user's
    own pronunciations as alternatives, and lets in a phrase whose words the dictionary lacks.
    A phrase that cannot be used raises GrammarError naming it, or with `skip_unknown` is
    left out and listed in `Grammar.refused` (the rest still works: one misspelt word in
    words.ini should not silence every command). An empty list gives the fixed words alone.
    """
    if isinstance(words, str):
        raise GrammarError("build_grammar needs a list of words or phrases, not one string; "
                           f"pass [{words!r}].")
    lexicon = lexicon or Lexicon()
    learned = learned or {}
    phrases = {w: w for w in FIXED_WORDS}
    refused: dict[str, str] = {}
    for text in words:
        try:
            spoken_form = _usable(text, lexicon, learned)
        except GrammarError as e:
            if not skip_unknown:
                raise
            refused[str(text)] = str(e)
            continue
        phrases.setdefault(spoken_form, text)       # "Drink" and "drink!" are one phrase: the first spelling wins
        if len(phrases) > MAX_PHRASES + len(FIXED_WORDS):
            raise GrammarError(f"There are more than {MAX_PHRASES} voice phrases; the recogniser takes at most "
                               f"{MAX_PHRASES} (remove some words).")
    entries: dict[str, tuple[str, tuple[str, ...]]] = {}
    alternatives = []
    for p in phrases:
        # normalised phrases and learned entries hold only JSGF-safe characters
        said = [p] if all(w in lexicon for w in p.split()) else []
        for phones in learned.get(p, ()):
            entry = learned_entry(p, phones)
            entries[entry] = (p, tuple(phones))
            said.append(entry)
        body = said[0] if len(said) == 1 else f"({' | '.join(said)})"
        alternatives.append(f"{body}+" if p in REPEATABLE else body)
    jsgf = f"#JSGF V1.0;\ngrammar asibot;\npublic <command> = {' | '.join(alternatives)};\n"
    return Grammar(jsgf, phrases, refused, entries)


def _usable(text: object, lexicon: Lexicon, learned: Mapping[str, Sequence[object]]) -> str:
    """The spoken form of a phrase the grammar can hold: every word in the dictionary, or learned."""
    try:
        return check_phrase(text, lexicon)
    except GrammarError:
        key = spoken(text)
        if learned.get(key) and key not in FIXED_WORDS:
            return key
        raise


def learned_entry(phrase: str, phones: Sequence[str]) -> str:
    """The dictionary entry of one learned pronunciation: named by its content, so the same
    pronunciation is the same entry after any rebuild, and a new one never clashes with an old one."""
    digest = hashlib.sha1(f"{phrase}|{' '.join(phones)}".encode()).hexdigest()[:12]
    return f"learned-{digest}"
