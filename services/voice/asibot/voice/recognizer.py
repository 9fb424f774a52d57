"""Recognition: a phrase of the grammar, or nothing.

`Recognizer` runs pocketsphinx (the US English model inside its wheel) restricted to the
grammar of the user's words. A closed grammar always answers with *some* phrase of the
grammar, or with a part of one, so what matters most is saying "nothing" when the person
said something else ("what is the weather like today" must not start "go to the desk").
Three checks, measured on espeak-ng speech (docs/voice.md has the figures):

1. the search must end on a whole phrase: when the audio does not fit, pocketsphinx
   returns the best *partial* path ("give me the"), which is refused ("stop" may be
   repeated: "stop stop stop" is a stop);
2. the phrase must account for the speech: pocketsphinx puts silence and filler models
   around the words it found, and out-of-grammar speech ends up there ("drink some
   water" -> "drink" + 0.9 s of "silence"). The frames that are loud (12 dB over the
   clip's quiet and within 25 dB of its peak) but not inside a word of the phrase must be
   at most `max_unexplained` of the loud ones;
3. the phrase must sound like itself: the acoustic log-likelihood per frame of its words,
   relative to the best-scoring senone of each frame (pocketsphinx normalises that way),
   must be at least `min_score`. This catches the out-of-grammar phrase that the search
   stretched over the whole utterance ("I am hungry" -> "open the fridge").

Two classic garbage models were tried first and dropped: a loop of the 39 phones as an
alternative inside the grammar made a 2 s clip take 15 s to decode, and pocketsphinx's
keyword spotter (threshold 1e-80) reported only the one-word phrases on espeak-ng speech,
never the longer ones. Its per-hypothesis posterior (`prob`) did not separate the two
kinds of speech either.

`Listener` is the pipeline for a stream: audio chunks -> 16 kHz -> VAD -> Recognizer,
one per stream; several listeners may share one recogniser. The grammar can be swapped
from any thread at any time; a phrase being decoded finishes with the old grammar.
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
from dataclasses import dataclass
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from asibot.voice.audio import AudioFormat, Chunk, Converter
from asibot.voice.errors import BadAudio, GrammarError
from asibot.voice.grammar import Grammar, Lexicon, build_grammar
from asibot.voice.vad import FRAME, RATE, Utterance, Vad, VadConfig, frame_dbfs

log = logging.getLogger("asibot.voice")

_FILLERS = ("<s>", "</s>", "<sil>")
PAD_SECONDS = 0.2
"""Quiet added around a clip: the model begins and ends every phrase in silence, and a
tightly cut clip (a WAV from a synthesiser, a VAD with no hangover) otherwise loses its
first and last phones."""
MAX_SECONDS = 30.0


@dataclass(frozen=True)
class Heard:
    """A phrase of the grammar, recognised."""

    text: str
    """The phrase as spoken and as the grammar holds it: "give me the red can"."""
    word: str
    """The entry of the user's words it stands for, as written ("Give me the red can!");
    a fixed word (stop, yes, no) stands for itself."""
    confidence: float
    """0 at the rejection thresholds, 1 for a perfect match: for ranking and logs, not a
    probability."""
    score: float
    """Acoustic log-likelihood per 10 ms frame of the phrase's words, nats, relative to the
    best senone of each frame (0 is the best possible)."""
    explained: float
    """Fraction of the loud frames inside the phrase's words."""
    seconds: float
    """Length of the audio that was decoded (without the padding)."""


@dataclass(frozen=True)
class Decoding:
    """Everything one decode found, accepted or not: for logs, tests and tuning."""

    hypothesis: str
    """What the search ended on, fillers removed ('' for nothing)."""
    score: float
    explained: float
    seconds: float
    decode_seconds: float
    heard: Heard | None
    reason: str
    """'' when heard; otherwise why not, as a sentence."""


@dataclass(frozen=True)
class RecognizerConfig:
    """The decoder's settings and the rejection thresholds (see the module's docstring)."""

    lw: float = 2.0
    """Language weight of the grammar. pocketsphinx's default (6.5) is tuned for n-gram
    models; with a flat grammar it made silence and fillers so cheap that the last word
    of a phrase was often dropped (74 of 105 espeak-ng phrases recognised, 91 at 2.0)."""
    max_unexplained: float = 0.33
    min_score: float = -4.8
    hmm: str | None = None
    """Acoustic model folder; None: the en-us model in the pocketsphinx wheel."""
    dictionary: str | None = None
    """Pronunciation dictionary; None: the wheel's CMUdict."""


class Recognizer:
    """pocketsphinx restricted to a grammar; `recognize(pcm16k)` -> Heard or None. Thread-safe."""

    def __init__(self, grammar: Grammar | None = None, config: RecognizerConfig | None = None) -> None:
        try:
            from pocketsphinx import Decoder
        except ImportError:
            raise RuntimeError("pocketsphinx is not installed; install it with `pip install 'pocketsphinx>=5'` "
                               "(voice recognition needs it).") from None
        self.config = config or RecognizerConfig()
        kw: dict[str, object] = dict(lm=None, lw=self.config.lw, loglevel="FATAL")
        if self.config.hmm:
            kw["hmm"] = self.config.hmm
        if self.config.dictionary:
            kw["dict"] = self.config.dictionary
        self.lexicon = Lexicon(self.config.dictionary)
        self._lock = threading.Lock()
        self._decoder = Decoder(**kw)
        self._logmath = self._decoder.get_logmath()
        self._names = itertools.count()
        self._grammar: Grammar | None = None
        self._search: str | None = None
        self._entries: set[str] = set()      # learned pronunciations already in the decoder's dictionary
        self._pad = (np.random.default_rng(0).standard_normal(round(PAD_SECONDS * RATE)) * 3).astype(np.int16)
        self.set_grammar(grammar if grammar is not None else build_grammar([], self.lexicon))

    @property
    def grammar(self) -> Grammar:
        assert self._grammar is not None
        return self._grammar

    def set_grammar(self, grammar: Grammar) -> None:
        """Listen for `grammar` from the next phrase on; a bad grammar changes nothing.

        Costs about 0.5 ms for 50 phrases, 2 ms for 200 (docs/voice.md), so call it on
        every change of the words.
        """
        if not isinstance(grammar, Grammar):
            raise GrammarError(f"set_grammar needs a Grammar (from build_grammar); got {type(grammar).__name__}.")
        with self._lock:
            if self._grammar is not None and grammar.key == self._grammar.key:
                self._grammar = grammar          # same phrases; the spellings may differ
                return
            name = self._compile(grammar)
            self._decoder.activate_search(name)
            if self._search is not None:
                self._decoder.remove_search(self._search)
            self._search, self._grammar = name, grammar

    def _compile(self, grammar: Grammar) -> str:
        """Add `grammar` as a search of the decoder (its learned pronunciations first); its name."""
        for entry, (_, phones) in grammar.learned.items():
            if entry not in self._entries:
                try:
                    self._decoder.add_word(entry, " ".join(phones), False)
                except RuntimeError:
                    raise GrammarError(f"The learned pronunciation {' '.join(phones)!r} has phones the model does "
                                       "not have; learn the word again.") from None
                self._entries.add(entry)
        name = f"g{next(self._names)}"
        try:
            self._decoder.add_jsgf_string(name, grammar.jsgf)
        except (ValueError, RuntimeError):
            raise GrammarError("The grammar could not be compiled by pocketsphinx; check that its words "
                               "are in the recogniser's dictionary (build it with build_grammar).") from None
        return name

    def set_words(self, words: Iterable[str], skip_unknown: bool = False,
                  learned: Mapping[str, Sequence[Sequence[str]]] | None = None) -> Grammar:
        """Build the grammar of `words` (plus stop, yes, no, and the `learned` pronunciations)
        and listen for it; returns it."""
        grammar = build_grammar(words, self.lexicon, skip_unknown=skip_unknown, learned=learned)
        self.set_grammar(grammar)
        return grammar

    def recognize(self, pcm16k: np.ndarray) -> Heard | None:
        """The phrase said in `pcm16k` (16 kHz mono int16, one utterance), or None."""
        return self.decode(pcm16k).heard

    def decode(self, pcm16k: np.ndarray, grammar: Grammar | None = None) -> Decoding:
        """`recognize` with the numbers and the reason for a refusal; with `grammar`, against
        that grammar once instead of the one listened for (a check, such as "would this new
        saying of a word be heard?"), which stays as it is."""
        if not isinstance(pcm16k, np.ndarray) or pcm16k.dtype != np.int16 or pcm16k.ndim != 1:
            raise BadAudio("The recogniser takes 16 kHz mono int16 samples as a 1-D numpy array; convert the "
                           "audio with asibot.voice.audio (to_16k, Converter or read_wav) first.")
        if len(pcm16k) < FRAME:
            raise BadAudio(f"The audio is {len(pcm16k)} samples long; an utterance needs at least 10 ms "
                           f"({FRAME} samples at 16 kHz).")
        if len(pcm16k) > MAX_SECONDS * RATE:
            raise BadAudio(f"The audio is {len(pcm16k) / RATE:.0f} s long; recognise at most {MAX_SECONDS:g} s "
                           "at a time (cut the stream with the VAD).")
        seconds = len(pcm16k) / RATE
        x = np.concatenate([self._pad, pcm16k, self._pad])
        start = time.perf_counter()
        with self._lock:
            d = self._decoder
            checked = self._compile(grammar) if grammar is not None and grammar.key != self.grammar.key else None
            grammar = grammar or self.grammar
            if checked:
                d.activate_search(checked)
            try:
                # The model's feat.params switch on noise removal, whose noise estimate carries
                # over from one utterance to the next: the same audio decoded differently
                # depending on what came before. Reset (0.06 ms), a phrase is recognised or not
                # on its own, and tests are reproducible.
                d.reinit_feat()
                d.start_utt()
                d.process_raw(x.tobytes(), full_utt=True)
                d.end_utt()
                segments = [(s.word, s.start_frame, s.end_frame, s.ascore) for s in (d.seg() or [])]
                n_frames = d.n_frames()
            finally:
                if checked:
                    d.activate_search(self._search)
                    d.remove_search(checked)
        words, ascore, word_frames = [], 0.0, 0
        covered = np.zeros(n_frames, bool)
        for word, sf, ef, asc in segments:
            if word in _FILLERS or word.startswith("["):
                continue
            words.append(grammar.phrase_of(word.split("(", 1)[0]))    # "can(2)": the second pronunciation
            covered[sf:ef + 1] = True
            word_frames += ef - sf + 1
            ascore += self._logmath.log_to_ln(self._logmath.log(asc)) if asc > 0 else -1e9
        phrase = grammar.lookup(" ".join(words))
        hypothesis = phrase or " ".join(words)
        score = ascore / word_frames if word_frames else float("-inf")
        explained = _explained(x, covered)
        elapsed = time.perf_counter() - start
        cfg = self.config
        if not hypothesis:
            reason = "Nothing of the grammar was heard."
        elif phrase is None:
            reason = f"Only part of a phrase was heard ({hypothesis!r})."
        elif 1.0 - explained > cfg.max_unexplained:
            reason = (f"The phrase {hypothesis!r} accounts for only {explained:.0%} of the speech; something "
                      "else was said.")
        elif score < cfg.min_score:
            reason = (f"The phrase {hypothesis!r} matched the speech too poorly (score {score:.2f}, "
                      f"at least {cfg.min_score:.2f} needed).")
        else:
            reason = ""
        heard = None
        if not reason:
            fit = min(1.0, max(0.0, 1.0 - score / cfg.min_score))
            cover = min(1.0, max(0.0, (explained - (1.0 - cfg.max_unexplained)) / cfg.max_unexplained))
            heard = Heard(hypothesis, grammar.phrases[hypothesis], round(fit * cover, 3), score, explained, seconds)
        return Decoding(hypothesis, score, explained, seconds, elapsed, heard, reason)


def _explained(x: np.ndarray, covered: np.ndarray) -> float:
    """Fraction of the loud frames of `x` that `covered` (one flag per 10 ms frame) marks."""
    n = len(covered)
    if n == 0:
        return 0.0
    win = 400                                                # pocketsphinx's 25 ms analysis window
    padded = np.concatenate([x, np.zeros(max(0, n * FRAME + win - len(x)), np.int16)])
    frames = np.lib.stride_tricks.as_strided(padded, (n, win), (FRAME * padded.strides[0], padded.strides[0]))
    e = frame_dbfs(frames)
    loud = e > max(float(np.percentile(e, 10)) + 12.0, float(e.max()) - 25.0)
    total = int(loud.sum())
    return 1.0 if total == 0 else float((loud & covered).sum()) / total


@dataclass(frozen=True)
class Result:
    """One utterance of a stream and what came of it."""

    heard: Heard | None
    start: float
    """s from the start of the stream."""
    seconds: float
    cut: bool
    """The speaker did not pause within the VAD's max_utterance: the audio was cut there."""
    reason: str
    """'' when heard; otherwise a sentence (for logs, or "Sorry, I did not understand")."""


class Listener:
    """A stream of audio chunks in, recognised phrases out: convert, cut, recognise.

    One listener per audio stream (a browser tab, a microphone), fed from one thread at
    a time (`feed` is locked, so a second thread waits). `feed` decodes the utterances a
    chunk completes before it returns, about 20 ms each on a slow machine: call it from a
    worker thread, not an event loop. `on_result`, if given, is called with every Result too.
    """

    def __init__(self, recognizer: Recognizer, fmt: AudioFormat, vad: VadConfig | None = None,
                 on_result: Callable[[Result], None] | None = None) -> None:
        if not isinstance(fmt, AudioFormat):
            raise BadAudio(f"Listener needs an AudioFormat (rate, sample type, channels); got {type(fmt).__name__}.")
        self.recognizer = recognizer
        self.format = fmt
        self._converter = Converter(fmt)
        self._vad = Vad(vad)
        self._on_result = on_result
        self._lock = threading.Lock()
        self.capture: Callable[[Utterance], None] | None = None
        """Set (with `arm`): the next utterance goes to it instead of the recogniser (a word being learned)."""
        self._started_before = False

    def arm(self, capture: Callable[[Utterance], None]) -> None:
        """Hand the next utterance that *starts* from now on to `capture`: one under way began
        before the person was asked to speak, and would be the end of some other phrase."""
        self.capture, self._started_before = capture, self._vad.in_speech

    def feed(self, chunk: Chunk) -> list[Result]:
        """The results of the utterances that ended in `chunk` (usually none). A refused chunk
        (BadAudio) changes nothing."""
        with self._lock:
            pcm = self._converter.convert(chunk)
            return self._recognise(self._vad.feed(pcm) if len(pcm) else [])

    def flush(self) -> list[Result]:
        """End of stream: recognise the phrase under way, if any; the listener starts afresh."""
        with self._lock:
            tail = self._converter.flush()
            utterances = (self._vad.feed(tail) if len(tail) else []) + self._vad.flush()
            return self._recognise(utterances)

    def set_words(self, words: Iterable[str], skip_unknown: bool = False) -> Grammar:
        """Listen for new words from the next phrase on (the recogniser's, for all its listeners)."""
        return self.recognizer.set_words(words, skip_unknown=skip_unknown)

    @property
    def in_speech(self) -> bool:
        """Someone is speaking now (for a "listening..." indicator)."""
        return self._vad.in_speech

    def _recognise(self, utterances: list[Utterance]) -> list[Result]:
        results = []
        for u in utterances:
            if self.capture is not None and not self._started_before:
                capture, self.capture = self.capture, None
                capture(u)               # a word being learned is not a command
                continue
            self._started_before = False
            d = self.recognizer.decode(u.samples)
            reason = d.reason
            if u.cut:
                reason = ((reason + " " if reason else "") +
                          f"The speech went on for more than {u.seconds:.0f} s without a pause and was cut there.")
            r = Result(d.heard, u.start, u.seconds, u.cut, reason)
            results.append(r)
            if self._on_result is not None:
                try:
                    self._on_result(r)
                except Exception:
                    log.exception("voice: the on_result callback failed")
        return results
