"""What a recording sounds like, as phones: the first half of learning a user's own pronunciation.

pocketsphinx decodes speech into the 39 phones of its US English model (ARPAbet, as CMUdict
writes them) when its search is a phone loop weighted by a phone language model (`allphone`,
with `en-us-phone.lm.bin` from the wheel). The phones are not a transcription a linguist would
write, they are how *this acoustic model* hears *this speaker*, which is exactly what the
grammar recogniser needs to find the same sound again: a word the dictionary does not have
("zorblat", a name) or a word a person says differently becomes a word with a pronunciation.

Measured on espeak-ng speech (docs/voice.md, "Learning a word by saying it"): context-dependent
phones (`allphone_ci` off) and a language weight of 4 gave the longest, most repeatable phone
strings; the default context-independent search dropped half the phones of a made-up word.
Context-dependent phones are slow with pocketsphinx's default beams (20 s for a 1 s word on a
busy 2-core machine); beams of 1e-20 (1e-15 for words) gave the same phones on every test
recording in 1 to 3 s, and narrower ones (1e-10) lost the end of the word.

One reading is not enough: where the saying's 10 ms frames happen to fall decides how much of
the word the phone loop keeps. "zorblat" read from 16 starting points within one frame gave
"Z L AO R OW N D L ER" (or S for Z, or without the L) 31 times in 64, and the rest lost the word's
end ("S L AO R OW N", "S AO R OW G"); a pronunciation learned cut matched later sayings only in
part ("accounts for only 62% of the speech") and the word was never heard. So `readings` reads
each saying from three starting points a third of a frame apart, and the learner keeps the one
that explains the saying best (asibot.voice.learning).

pocketsphinx keeps Python's GIL while it decodes: 2 s of phone search in the service's own
process would stall every thread of it (the microphone's worker, "stop", the bus). So the
phone loop runs in child processes of its own (one a reading, the three at once), started on
the first word learned and kept for the next.
"""

from __future__ import annotations

import multiprocessing
import threading
import time
from concurrent.futures import ProcessPoolExecutor, TimeoutError as FutureTimeout
from typing import Iterable, Protocol

import numpy as np

from asibot.voice.errors import BadAudio
from asibot.voice.vad import FRAME, RATE

#: The phones of the US English model, as CMUdict spells them; anything else is not a pronunciation.
PHONES = frozenset("AA AE AH AO AW AY B CH D DH EH ER EY F G HH IH IY JH K L M N NG OW OY P R S SH T TH "
                   "UH UW V W Y Z ZH".split())
MIN_PHONES = 2
"""Fewer phones than this is a cough or a click, not a word anyone could be recognised by."""
MAX_PHONES = 60
"""12 words of 5 phones: the longest phrase the grammar takes."""
_PAD = 0.2      # s of quiet around the clip: the phone loop, like the grammar, starts and ends in silence
READ_TIMEOUT = 60.0
"""s a reading may take at most (a 5 s phrase on a busy machine takes about 10)."""
SHIFTS = (0, FRAME // 3, 2 * FRAME // 3)
"""Samples each saying is also read from (see the top): a third of a frame apart."""


class PhoneReader:
    """pocketsphinx's phone loop: `readings(pcm16k)` -> the phones heard, in order, from each
    starting point. Thread-safe.

    The child processes and their model start on the first reading (about 1 s), so a service
    that never learns a word never pays for them; `close` ends them.
    """

    def __init__(self, lw: float = 4.0, context_dependent: bool = True) -> None:
        self.lw, self.context_dependent = lw, context_dependent
        self._lock = threading.Lock()
        self._pool: ProcessPoolExecutor | None = None

    def readings(self, pcm16k: np.ndarray) -> list[tuple[str, ...]]:
        """The phones of one utterance (16 kHz mono int16), silences and noises left out, read from
        each of SHIFTS (see the top), in that order."""
        if not isinstance(pcm16k, np.ndarray) or pcm16k.dtype != np.int16 or pcm16k.ndim != 1:
            raise BadAudio("The phone reader takes 16 kHz mono int16 samples as a 1-D numpy array; convert the "
                           "audio with asibot.voice.audio first.")
        if len(pcm16k) < FRAME:
            raise BadAudio(f"The audio is {len(pcm16k)} samples long; a word needs at least 10 ms.")
        with self._lock:                 # one saying at a time: each child has one decoder
            if self._pool is None:
                # spawn, not fork: the service has threads, and a forked copy of their locks could hang
                self._pool = ProcessPoolExecutor(len(SHIFTS), mp_context=multiprocessing.get_context("spawn"))
            futures = [self._pool.submit(_read, pcm16k[shift:].tobytes(), self.lw, self.context_dependent)
                       for shift in SHIFTS]
            deadline = time.monotonic() + READ_TIMEOUT
            try:
                return [f.result(max(0.0, deadline - time.monotonic())) for f in futures]
            except FutureTimeout:
                for f in futures:
                    f.cancel()
                raise RuntimeError(f"Reading the phones took more than {READ_TIMEOUT:g} s; the machine is too "
                                   "busy, try again.") from None

    def close(self) -> None:
        with self._lock:
            if self._pool is not None:
                self._pool.shutdown(cancel_futures=True)
                self._pool = None


class _Segment(Protocol):
    word: str


class _Decoder(Protocol):
    """What is used of pocketsphinx's Decoder, which has no type information."""

    def reinit_feat(self) -> None: ...
    def start_utt(self) -> None: ...
    def process_raw(self, data: bytes, no_search: bool = False, full_utt: bool = False) -> int: ...
    def end_utt(self) -> None: ...
    def seg(self) -> Iterable[_Segment] | None: ...


_decoders: dict[tuple[float, bool], _Decoder] = {}      # in the child: one decoder per setting, kept


def _read(pcm: bytes, lw: float, context_dependent: bool) -> tuple[str, ...]:
    """In the child process: decode `pcm` with the phone loop."""
    d = _decoders.get((lw, context_dependent))
    if d is None:
        from pocketsphinx import Decoder, get_model_path
        d = _decoders[(lw, context_dependent)] = Decoder(
            allphone=get_model_path("en-us/en-us-phone.lm.bin"), lm=None, lw=lw, allphone_ci=not context_dependent,
            beam=1e-20, pbeam=1e-20, wbeam=1e-15, loglevel="FATAL")
    pad = (np.random.default_rng(1).standard_normal(round(_PAD * RATE)) * 3).astype(np.int16).tobytes()
    d.reinit_feat()                      # as in the recogniser: the same audio, the same phones
    d.start_utt()
    d.process_raw(pad + pcm + pad, full_utt=True)
    d.end_utt()
    return tuple(s.word for s in (d.seg() or []) if s.word in PHONES)


def check_phones(phones: object) -> tuple[str, ...]:
    """A stored or sent pronunciation: MIN_PHONES to MAX_PHONES phones of PHONES, or ValueError."""
    if isinstance(phones, str):
        phones = phones.split()
    if not isinstance(phones, (list, tuple)) or not all(isinstance(p, str) for p in phones):
        raise ValueError(f"A pronunciation is a list of phones like ['G', 'IH', 'V']; got {str(phones)[:60]}.")
    unknown = sorted({p for p in phones if p not in PHONES})
    if unknown:
        raise ValueError(f"{', '.join(unknown[:5])} {'is not a phone' if len(unknown) == 1 else 'are not phones'} "
                         "of the English model (ARPAbet as CMUdict writes it: AA AE AH ... ZH).")
    if not MIN_PHONES <= len(phones) <= MAX_PHONES:
        raise ValueError(f"A pronunciation has {MIN_PHONES} to {MAX_PHONES} phones; this one has {len(phones)}.")
    return tuple(phones)
