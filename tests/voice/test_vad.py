"""The VAD: phrases cut from a stream with their edges, pauses, endless speech, endless silence, noise."""

from __future__ import annotations

import numpy as np
import pytest

from asibot.voice.errors import BadAudio
from asibot.voice.vad import Vad, VadConfig

from .sounds import as_int16, noise

RATE = 16000


def voice_like(seconds: float, dbfs: float = -20.0, seed: int = 0) -> np.ndarray:
    """A buzzing vowel chain: 140 Hz and harmonics, four 'syllables' a second dipping 15 dB between."""
    t = np.arange(int(seconds * RATE)) / RATE
    x = sum(np.sin(2 * np.pi * 140 * k * t) / k for k in range(1, 8))
    envelope = 10 ** (-15 / 20 * (0.5 - 0.5 * np.cos(2 * np.pi * 4 * t)))
    x = x * envelope
    return x / np.sqrt(np.mean(x * x)) * 10 ** (dbfs / 20)


def feed_in_chunks(vad: Vad, x: np.ndarray, seed: int = 0, flush: bool = True):
    rng = np.random.default_rng(seed)
    pcm, out, i = as_int16(x), [], 0
    while i < len(pcm):
        n = int(rng.integers(50, 2000))
        out += vad.feed(pcm[i:i + n])
        i += n
    return out + (vad.flush() if flush else [])


def test_a_phrase_in_a_long_stream_is_cut_with_its_edges():
    x = np.concatenate([noise(3.0, -60), voice_like(1.2), noise(3.0, -60, seed=1)])
    (u,) = feed_in_chunks(Vad(), x)
    assert not u.cut
    # starts with the pre-roll (0.3 s) before the voice at 3.0 s, ends after the hangover
    assert 2.65 <= u.start <= 2.75
    assert 3.0 + 1.2 + 0.4 <= u.start + u.seconds <= 3.0 + 1.2 + 0.5
    pcm = as_int16(x)
    s = round(u.start * RATE)
    assert np.array_equal(u.samples, pcm[s:s + len(u.samples)])


def test_short_pauses_stay_inside_a_phrase_and_long_ones_split_it():
    gap = lambda s: noise(s, -60, seed=int(s * 100))                                   # noqa: E731
    x = np.concatenate([gap(1.0), voice_like(0.5), gap(0.25), voice_like(0.5), gap(1.0), voice_like(0.6), gap(1.0)])
    utterances = feed_in_chunks(Vad(), x)
    assert [u.start for u in utterances] == [pytest.approx(0.7, abs=0.05), pytest.approx(2.95, abs=0.05)]
    assert 1.25 + 0.4 < utterances[0].seconds < 1.25 + 0.3 + 0.5


def test_endless_speech_is_cut_at_the_maximum_and_says_so():
    x = np.concatenate([noise(1.0, -60), voice_like(12.0), noise(1.0, -60, seed=3)])
    utterances = feed_in_chunks(Vad(VadConfig(max_utterance=5.0)), x)
    assert [u.cut for u in utterances] == [True, True, False]
    assert [round(u.seconds, 2) for u in utterances[:2]] == [5.0, 5.0]
    total = sum(u.seconds for u in utterances)
    assert 12.0 < total < 12.0 + 0.3 + 0.5 + 0.3                # speech, pre-rolls and the last hangover


def test_endless_silence_finds_nothing_and_keeps_nothing():
    vad = Vad()
    quiet = as_int16(noise(1.0, -62))
    chunk = quiet[:1600]
    for i in range(600):                                           # ten minutes in 100 ms chunks
        assert vad.feed(quiet[(i % 10) * 1600:(i % 10 + 1) * 1600] if i % 7 else chunk) == []
    assert not vad.in_speech
    assert len(vad._pre) <= vad._pre.maxlen and len(vad._rest) < 160 and vad._speech is None
    assert vad.flush() == []


def test_digital_silence_and_clicks_are_not_speech():
    vad = Vad()
    assert vad.feed(np.zeros(RATE * 5, np.int16)) == []
    click = np.concatenate([np.zeros(RATE, np.int16), as_int16(voice_like(0.05, -10)), np.zeros(RATE, np.int16)])
    assert vad.feed(click) == []
    assert feed_in_chunks(vad, np.concatenate([noise(1, -70), voice_like(0.4), noise(1, -70)]))[0].seconds > 0.4


def test_a_noise_that_starts_and_stays_is_learnt_after_one_cut():
    vad = Vad()
    x = np.concatenate([noise(2.0, -60), noise(20.0, -30, seed=4), voice_like(1.0, -10), noise(2.0, -30, seed=5)])
    utterances = feed_in_chunks(vad, x)
    assert [u.cut for u in utterances[:1]] == [True]           # the vacuum cleaner starts: one cut
    assert len(utterances) == 2                                 # then only the loud phrase over it
    assert 21.5 < utterances[1].start < 22.0 and not utterances[1].cut


def test_the_noise_floor_follows_a_quieter_room_at_once():
    vad = Vad()
    feed_in_chunks(vad, noise(3.0, -40), flush=False)
    assert vad.floor == pytest.approx(-40, abs=2)
    feed_in_chunks(vad, noise(0.5, -60, seed=6), flush=False)
    assert vad.floor < -55
    utterances = feed_in_chunks(vad, np.concatenate([voice_like(0.8, -35), noise(1.0, -60)]))
    assert len(utterances) == 1                                 # a soft voice, heard in the quiet room


@pytest.mark.parametrize("bad", [np.zeros(10, np.float32), np.zeros((10, 2), np.int16), b"\x00\x00", [0, 0]])
def test_the_vad_takes_only_16k_int16_arrays(bad):
    vad = Vad()
    with pytest.raises(BadAudio, match="16 kHz mono int16"):
        vad.feed(bad)


@pytest.mark.parametrize("kw, words", [
    (dict(start_db=5.0, stop_db=8.0), "stop_db <= start_db"),
    (dict(start_frames=12), "start_frames <= start_window"),
    (dict(max_utterance=60.0), "0.5 to 30 s"),
    (dict(hangover=-1.0), "must not be negative"),
])
def test_bad_settings_are_sentences(kw, words):
    with pytest.raises(ValueError, match=words):
        VadConfig(**kw)
