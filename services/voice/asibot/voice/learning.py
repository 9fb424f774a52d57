"""Learning a word by hearing the user say it, as assistive speech systems do.

A person whose speech differs from the dictionary's, or a word the dictionary lacks (a name,
a made-up word, the user's own sound for a command), is recognised once the recogniser knows
how *this* person says it: each recording is read as phones (`phones.PhoneReader`) and kept
as a pronunciation of the phrase (`pronunciations.Pronunciations`, up to three sayings); the
grammar then offers those pronunciations beside the dictionary's (`grammar.build_grammar`,
`learned=`).

Before a saying is kept, the recogniser is asked whether it would have heard the phrase in it
with what it knew until then (the words listened for, this phrase, the sayings kept so far):
"heard it again: matches" tells the user that saying it once more was not needed, "heard
'drink' instead" that a second saying helps. Plain logic, no bus: the service calls it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from asibot.voice.errors import BadAudio
from asibot.voice.grammar import build_grammar, phrase_key
from asibot.voice.phones import MIN_PHONES, PhoneReader, check_phones
from asibot.voice.pronunciations import Pronunciations
from asibot.voice.recognizer import Recognizer
from asibot.voice.vad import RATE, Vad, VadConfig


@dataclass(frozen=True)
class Learned:
    """One saying of a phrase, learned."""

    phrase: str
    """The phrase as spoken ("zorblat"); its pronunciations are kept under this name."""
    phones: tuple[str, ...]
    """The phones heard in this saying, now a pronunciation of the phrase."""
    sayings: list[tuple[str, ...]]
    """Every pronunciation kept for the phrase, oldest first (this one last)."""
    matched: bool | None
    """Would the recogniser have heard the phrase in this saying before it was learned? None when
    it could not have (the first saying of a word the dictionary lacks)."""
    heard: str
    """What it heard in this saying before it was learned ('' for nothing of its words)."""
    dropped: bool
    """The oldest saying was forgotten to keep at most MAX_SAYINGS."""
    seconds: float


class Learner:
    """`learn(text, utterance)` / `learn_recording(text, pcm16k)` / `forget(text)` (thread-safe
    through the recogniser's and the store's locks)."""

    def __init__(self, recognizer: Recognizer, store: Pronunciations, words: Callable[[], list[str]],
                 reader: PhoneReader | None = None, vad: VadConfig | None = None) -> None:
        self.recognizer, self.store, self.words = recognizer, store, words
        self.reader = reader or PhoneReader()
        self.vad = vad

    def phrase(self, text: object) -> str:
        """The name `text` is learned under, or GrammarError (not text, empty, too many words)."""
        return phrase_key(text, self.recognizer.lexicon)

    def learn_recording(self, text: object, pcm16k: np.ndarray) -> Learned:
        """Learn from a recording with quiet around the word: the speech in it is found first."""
        self.phrase(text)                      # a bad phrase is refused before the audio is looked at
        return self.learn(text, speech_in(pcm16k, self.vad))

    def learn(self, text: object, utterance: np.ndarray) -> Learned:
        """Learn from one utterance (16 kHz mono int16, as the VAD cut it); BadAudio or
        GrammarError with a sentence, and nothing kept, when it cannot be learned."""
        phrase = self.phrase(text)
        readings = self.reader.readings(utterance)
        most = max(len(r) for r in readings)
        if most < MIN_PHONES:
            raise BadAudio(f"Too little speech was heard to learn {phrase!r} ({most} sound"
                           f"{'' if most == 1 else 's'}); say the whole word again, clearly.")
        phones = self.best_reading(phrase, [check_phones(r) for r in readings if len(r) >= MIN_PHONES], utterance)
        check = build_grammar([*self.words(), phrase], self.recognizer.lexicon, skip_unknown=True,
                              learned=self.store.all())
        heard = self.recognizer.decode(utterance, check).heard
        said = heard.text if heard is not None else ""
        matched = said == phrase if phrase in check.phrases else None
        sayings, dropped = self.store.add(phrase, phones)
        return Learned(phrase, phones, sayings, matched, said, dropped, len(utterance) / RATE)

    def best_reading(self, phrase: str, readings: list[tuple[str, ...]], utterance: np.ndarray) -> tuple[str, ...]:
        """The reading that, as the phrase's only pronunciation, explains the most of its own
        saying (then scores best): a reading that lost the word's end explains only part of it,
        as it would every later saying."""
        def fit(phones: tuple[str, ...]) -> tuple[bool, float, float]:
            alone = build_grammar([phrase], self.recognizer.lexicon, skip_unknown=True, learned={phrase: [phones]})
            d = self.recognizer.decode(utterance, alone)
            return d.heard is not None, d.explained, d.score
        distinct = list(dict.fromkeys(readings))
        return distinct[0] if len(distinct) == 1 else max(distinct, key=fit)

    def forget(self, text: object) -> tuple[str, int]:
        """Forget the user's pronunciations of `text`: (its phrase, how many there were)."""
        phrase = self.phrase(text)
        return phrase, self.store.forget(phrase)


def speech_in(pcm16k: np.ndarray, vad: VadConfig | None = None) -> np.ndarray:
    """The part of a recording that is speech, from the first phrase's start to the last one's
    end (a pause inside a phrase may split it); BadAudio for silence or endless speech."""
    detector = Vad(vad)
    utterances = detector.feed(pcm16k) + detector.flush()
    if not utterances:
        raise BadAudio("No speech was found in the recording (silence, or too quiet); say the word close to "
                       "the microphone, after a moment of quiet.")
    if any(u.cut for u in utterances):
        raise BadAudio(f"The speech went on for more than {detector.config.max_utterance:g} s without a pause; "
                       "record only the word or phrase.")
    start = round(utterances[0].start * RATE)
    end = round(utterances[-1].start * RATE) + len(utterances[-1].samples)
    if end - start > detector.config.max_utterance * RATE:
        raise BadAudio(f"The recording holds {(end - start) / RATE:.1f} s of speech; say only the word or "
                       f"phrase, once (at most {detector.config.max_utterance:g} s).")
    return pcm16k[start:end]
