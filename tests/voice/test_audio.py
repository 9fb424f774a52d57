"""Audio in: formats, the resampler's accuracy and streaming, refusals that change nothing, WAV files."""

from __future__ import annotations

import math
import struct
import wave

import numpy as np
import pytest

from asibot.voice.audio import AudioFormat, Converter, Resampler, read_wav, to_16k, wav_bytes
from asibot.voice.errors import BadAudio

from .sounds import as_int16


def tone(freq: float, rate: int, seconds: float = 1.0, amp: float = 0.5) -> np.ndarray:
    t = np.arange(int(rate * seconds)) / rate
    return amp * np.sin(2 * math.pi * freq * t)


def rms_db(x: np.ndarray) -> float:
    x = np.asarray(x, np.float64)
    return 20 * math.log10(math.sqrt(np.mean(x * x)) + 1e-12)


def test_16k_int16_mono_passes_unchanged():
    x = as_int16(tone(440, 16000, 0.3))
    out = Converter(AudioFormat(16000)).convert(x.tobytes())
    assert out.dtype == np.int16 and np.array_equal(out, x)


def test_stereo_is_mixed_to_mono_and_float_is_scaled_and_clipped():
    stereo = np.array([[1000, 3000], [-2000, -4000]], np.int16)
    assert Converter(AudioFormat(16000, "int16", 2)).convert(stereo.tobytes()).tolist() == [2000, -3000]
    assert Converter(AudioFormat(16000, "int16", 2)).convert(stereo).tolist() == [2000, -3000]
    f = np.array([0.5, -0.25, 1.5, -3.0], np.float32)
    assert Converter(AudioFormat(16000, "float32")).convert(f).tolist() == [16384, -8192, 32767, -32768]
    assert Converter(AudioFormat(16000, "float32")).convert(f.tobytes()).tolist() == [16384, -8192, 32767, -32768]


@pytest.mark.parametrize("rate", [8000, 11025, 22050, 32000, 44100, 48000])
def test_speech_band_passes_at_unit_gain(rate):
    for freq in (200.0, 1000.0, 3000.0):
        out = to_16k(tone(freq, rate).astype(np.float32), AudioFormat(rate, "float32")) / 32768
        assert len(out) == math.ceil(rate * 16000 / rate)
        assert abs(rms_db(out[800:-800]) - rms_db(tone(freq, 16000))) < 0.1, (rate, freq)
        # and it is that tone, not something else of the same energy
        ref = tone(freq, 16000)[800:-800]
        corr = np.dot(out[800:-800], ref) / math.sqrt(np.dot(ref, ref) * np.dot(out[800:-800], out[800:-800]))
        assert corr > 0.999


@pytest.mark.parametrize("rate, freq", [(44100, 12000.0), (48000, 10000.0), (48000, 20000.0), (32000, 9000.0),
                                        (22050, 9500.0)])
def test_what_cannot_be_represented_does_not_fold_back(rate, freq):
    # Without the low-pass, 12 kHz at 44.1 kHz folds to 4 kHz: right in the band of speech.
    out = to_16k(tone(freq, rate).astype(np.float32), AudioFormat(rate, "float32")) / 32768
    assert rms_db(out[800:-800]) < rms_db(tone(freq, rate)) - 60, rms_db(out)


@pytest.mark.parametrize("rate", [44100, 48000, 8000, 22050])
def test_chunks_of_any_size_give_the_same_samples(rate):
    rng = np.random.default_rng(1)
    x = (rng.standard_normal(rate * 2) * 0.1).astype(np.float32)
    whole = to_16k(x, AudioFormat(rate, "float32"))
    conv = Converter(AudioFormat(rate, "float32"))
    parts, i = [], 0
    while i < len(x):
        n = int(rng.integers(1, 1500))
        parts.append(conv.convert(x[i:i + n]))
        i += n
    parts.append(conv.flush())
    assert np.array_equal(np.concatenate(parts), whole)
    assert len(whole) == math.ceil(len(x) * 16000 / rate)


def test_a_long_stream_keeps_little_state():
    r = Resampler(44100)
    x = np.zeros(4410, np.float32)
    for _ in range(600):                                  # a minute
        r.process(x)
    assert len(r._buf) < 2 * r.half + 64 and r._n < r.up


def _good_state_check(fmt: AudioFormat, chunk_before: bytes, chunk_after: bytes, bad) -> None:
    """A refused chunk between two good ones: the output is as if it had never been sent."""
    conv, ref = Converter(fmt), Converter(fmt)
    conv.convert(chunk_before)
    ref.convert(chunk_before)
    with pytest.raises(ValueError) as err:
        conv.convert(bad)
    text = str(err.value)
    assert text[0].isupper() and text.endswith(".") and len(text) < 300, text
    assert np.array_equal(conv.convert(chunk_after), ref.convert(chunk_after))


BAD_CHUNKS = [
    (AudioFormat(44100, "int16", 1), b"\x01\x02\x03", "not a whole number"),
    (AudioFormat(44100, "int16", 2), b"\x00" * 6, "not a whole number"),
    (AudioFormat(48000, "float32", 1), b"\x00" * 6, "not a whole number"),
    (AudioFormat(44100, "int16", 1), b"", "empty"),
    (AudioFormat(44100, "float32", 1), np.zeros(0, np.float32), "empty"),
    (AudioFormat(44100, "float32", 1), np.array([0.1, np.nan], np.float32), "NaN or infinity"),
    (AudioFormat(44100, "float32", 2), np.array([0.1, np.inf], np.float32).tobytes(), "NaN or infinity"),
    (AudioFormat(44100, "float32", 1), np.zeros(10, np.float64), "float64 samples"),
    (AudioFormat(44100, "int16", 1), np.zeros(10, np.int32), "int32 samples"),
    (AudioFormat(44100, "int16", 1), np.zeros(10, np.float32), "float32 samples"),
    (AudioFormat(44100, "int16", 2), np.zeros((10, 3), np.int16), "not whole frames"),
    (AudioFormat(44100, "int16", 2), np.zeros(11, np.int16), "not whole frames"),
    (AudioFormat(44100, "int16", 1), [1, 2, 3], "bytes or a numpy array"),
    (AudioFormat(8000, "int16", 1), b"\x00\x00" * 8000 * 11, "at most 10 s"),
]


@pytest.mark.parametrize("fmt, bad, words", BAD_CHUNKS)
def test_bad_chunks_are_sentences_and_change_nothing(fmt, bad, words):
    good = (np.random.default_rng(2).standard_normal(fmt.rate // 10 * fmt.channels) * 0.1)
    good = good.astype(np.float32) if fmt.sample == "float32" else as_int16(good)
    with pytest.raises(BadAudio, match=words):
        Converter(fmt).convert(bad)
    _good_state_check(fmt, good.tobytes(), good[::-1].tobytes(), bad)


@pytest.mark.parametrize("kw, words", [
    (dict(rate=7999), "7999 Hz is not supported"),
    (dict(rate=96000), "96000 Hz is not supported"),
    (dict(rate=16000.0), "whole number of Hz"),
    (dict(rate=True), "whole number of Hz"),
    (dict(rate=16000, sample="int24"), "'int24' is not supported"),
    (dict(rate=16000, sample="float64"), "'float64' is not supported"),
    (dict(rate=16000, channels=3), "3 channels is not supported"),
    (dict(rate=16000, channels=0), "0 channels is not supported"),
])
def test_bad_formats_are_sentences(kw, words):
    with pytest.raises(ValueError, match=words):
        AudioFormat(**kw)


def _write_wav(path, samples: np.ndarray, rate: int, channels: int = 1, width: int = 2) -> None:
    with wave.open(str(path), "wb") as w:
        w.setnchannels(channels)
        w.setsampwidth(width)
        w.setframerate(rate)
        w.writeframes(samples.tobytes())


def test_read_wav_converts_any_supported_wav(tmp_path):
    x = as_int16(tone(500, 44100, 0.5))
    _write_wav(tmp_path / "a.wav", np.stack([x, x], 1), 44100, channels=2)
    out = read_wav(tmp_path / "a.wav")
    assert len(out) == 8000 and abs(rms_db(out / 32768.0) - rms_db(x / 32768.0)) < 0.1
    assert np.array_equal(read_wav_bytes_roundtrip(out, tmp_path), out)


def read_wav_bytes_roundtrip(samples: np.ndarray, tmp_path) -> np.ndarray:
    (tmp_path / "b.wav").write_bytes(wav_bytes(samples))
    return read_wav(tmp_path / "b.wav")


def test_unreadable_wavs_are_sentences(tmp_path):
    _write_wav(tmp_path / "8bit.wav", np.full(800, 128, np.uint8), 8000, width=1)
    with pytest.raises(BadAudio, match="8-bit samples; only 16-bit PCM"):
        read_wav(tmp_path / "8bit.wav")
    _write_wav(tmp_path / "4k.wav", np.zeros(400, np.int16), 4000)
    with pytest.raises(BadAudio, match="4000 Hz is not supported"):
        read_wav(tmp_path / "4k.wav")
    # IEEE float WAV (format 3): the stdlib cannot read it, we say so
    data = np.zeros(100, "<f4").tobytes()
    fmt = struct.pack("<HHIIHH", 3, 1, 16000, 64000, 4, 32)
    (tmp_path / "float.wav").write_bytes(b"RIFF" + struct.pack("<I", 36 + len(data)) + b"WAVEfmt "
                                         + struct.pack("<I", 16) + fmt + b"data" + struct.pack("<I", len(data)) + data)
    with pytest.raises(BadAudio, match="is not a 16-bit PCM WAV file"):
        read_wav(tmp_path / "float.wav")
    (tmp_path / "text.wav").write_text("hello")
    with pytest.raises(BadAudio, match="is not a 16-bit PCM WAV file"):
        read_wav(tmp_path / "text.wav")
    with pytest.raises(BadAudio, match="cannot be read"):
        read_wav(tmp_path / "missing.wav")
