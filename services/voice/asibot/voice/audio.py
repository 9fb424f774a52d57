"""Audio in: what a browser or sounddevice sends, made into what the recogniser hears.

The recogniser's model was trained on 16 kHz mono 16-bit speech; a browser's AudioWorklet
sends float32 at the sound card's rate (44100 or 48000 Hz), sounddevice sends int16 or
float32, mono or interleaved stereo. `AudioFormat` says which; `Converter` turns a stream
of chunks of that format into 16 kHz mono int16, chunk by chunk, with a resampler that
keeps its history across chunks (cutting a stream into chunks changes no sample).

The resampler is a polyphase FIR: a Kaiser-windowed sinc low-pass at 0.45 of the lower of
the two rates, evaluated only at the output instants (for 48 kHz -> 16 kHz: one phase, 108
taps; for 44.1 kHz: 160 phases). The low-pass matters: without it, everything between 8
and 24 kHz of a 48 kHz stream (fans, keyboard clicks, sibilants) folds into the band the
model listens to. No scipy: it is not a dependency of the stack, and numpy suffices.

Input is checked whole before anything is kept: a wrong dtype, a byte count that is not a
whole number of frames, a rate outside 8000..48000 Hz, a NaN or an empty chunk is a
`BadAudio` (a ValueError) with a sentence, and the converter's state is as before the call.
"""

from __future__ import annotations

import math
import wave
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Union

import numpy as np

from asibot.voice.errors import BadAudio

RATE = 16000
MIN_RATE, MAX_RATE = 8000, 48000
SAMPLE_TYPES: dict[str, np.dtype] = {"int16": np.dtype("<i2"), "float32": np.dtype("<f4")}
MAX_CHUNK_SECONDS = 10.0
"""A streamed chunk is a few tens of ms; ten seconds at once is a client bug, refused
before it costs memory."""
MAX_CLIP_SECONDS = 60.0
"""A whole recording (a WAV file, `to_16k`): a minute is far more than any phrase."""

Chunk = Union[bytes, bytearray, memoryview, np.ndarray]


SampleType = Literal["int16", "float32"]


def _check_rate(value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise BadAudio(f"The sample rate must be a whole number of Hz; got {value!r}.")
    if not MIN_RATE <= value <= MAX_RATE:
        raise BadAudio(f"The sample rate {value} Hz is not supported; send audio at "
                       f"{MIN_RATE} to {MAX_RATE} Hz (16000 is best).")
    return int(value)


def _check_sample(value: object) -> SampleType:
    if value == "int16":
        return "int16"
    if value == "float32":
        return "float32"
    raise BadAudio(f"The sample type {value!r} is not supported; send 'int16' or 'float32' "
                   "(little-endian).")


def _check_channels(value: object) -> int:
    if value not in (1, 2):
        raise BadAudio(f"Audio with {value!r} channels is not supported; send mono or "
                       "interleaved stereo.")
    return 1 if value == 1 else 2


@dataclass(frozen=True)
class AudioFormat:
    """What a client sends: sample rate (Hz), sample type (little-endian), channels."""

    rate: int
    sample: SampleType = "int16"
    channels: int = 1

    def __post_init__(self) -> None:
        # The annotations say what a checked format holds; a caller may still pass anything.
        _check_rate(self.rate)
        _check_sample(self.sample)
        _check_channels(self.channels)

    @classmethod
    def parse(cls, rate: object, sample: object = "int16", channels: object = 1) -> AudioFormat:
        """The format from values not checked yet (a request, a message); BadAudio as the
        constructor's for a wrong one."""
        return cls(_check_rate(rate), _check_sample(sample), _check_channels(channels))

    @property
    def frame_bytes(self) -> int:
        """Bytes of one frame (one sample of every channel)."""
        return SAMPLE_TYPES[self.sample].itemsize * self.channels


def decode(chunk: Chunk, fmt: AudioFormat, max_seconds: float = MAX_CHUNK_SECONDS) -> np.ndarray:
    """`chunk` as float32 mono in [-1, 1], or BadAudio with a sentence; nothing else happens."""
    dtype = SAMPLE_TYPES[fmt.sample]
    if isinstance(chunk, np.ndarray):
        if chunk.dtype.kind != dtype.kind or chunk.dtype.itemsize != dtype.itemsize:
            raise BadAudio(f"The audio array holds {chunk.dtype} samples but the format says {fmt.sample}; "
                           f"send {fmt.sample} samples or declare the format that is sent.")
        if chunk.ndim == 2 and chunk.shape[1] == fmt.channels:
            frames = chunk.astype(dtype, copy=False)
        elif chunk.ndim == 1 and chunk.size % fmt.channels == 0:
            frames = chunk.astype(dtype, copy=False).reshape(-1, fmt.channels)
        else:
            raise BadAudio(f"The audio array has shape {chunk.shape}, which is not whole frames of "
                           f"{fmt.channels} channel(s); send (frames,) or (frames, {fmt.channels}).")
    elif isinstance(chunk, (bytes, bytearray, memoryview)):
        raw = memoryview(chunk).cast("B")
        if len(raw) % fmt.frame_bytes:
            raise BadAudio(f"The audio chunk has {len(raw)} bytes, not a whole number of {fmt.frame_bytes}-byte "
                           f"frames ({fmt.sample}, {fmt.channels} channel(s)); send whole frames.")
        frames = np.frombuffer(raw, dtype=dtype).reshape(-1, fmt.channels)
    else:
        raise BadAudio(f"Audio must be bytes or a numpy array; got {type(chunk).__name__}.")
    if len(frames) == 0:
        raise BadAudio("The audio chunk is empty; send at least one frame.")
    if len(frames) > max_seconds * fmt.rate:
        raise BadAudio(f"The audio chunk is {len(frames) / fmt.rate:.1f} s long; send at most "
                       f"{max_seconds:g} s at a time.")
    if fmt.sample == "float32":
        mono = frames.mean(axis=1, dtype=np.float64) if fmt.channels > 1 else frames[:, 0].astype(np.float64)
        if not np.isfinite(mono).all():
            raise BadAudio("The float32 audio contains NaN or infinity; send finite samples in [-1, 1].")
        return np.clip(mono, -1.0, 1.0).astype(np.float32)
    mono = frames.mean(axis=1, dtype=np.float64) if fmt.channels > 1 else frames[:, 0]
    return (np.asarray(mono, np.float32) / np.float32(32768.0))


def to_int16(x: np.ndarray) -> np.ndarray:
    """Float samples in [-1, 1] as int16, rounded and clipped (a resampler may overshoot)."""
    return np.clip(np.rint(x * 32768.0), -32768, 32767).astype(np.int16)


class Resampler:
    """Polyphase FIR resampler for a stream: `process(x)` now, `flush()` at the end.

    Output sample n is the input, low-passed, at time n * rate_in / rate_out (in input
    samples). The filter's taps for each of the `up` fractional offsets are made once; the
    state between calls is the input the next outputs still need (2 * half samples) and the
    position, so memory does not grow with the length of the stream.
    """

    def __init__(self, rate_in: int, rate_out: int = RATE, zeros: int = 16, beta: float = 8.0,
                 cutoff: float = 0.45) -> None:
        g = math.gcd(rate_in, rate_out)
        self.rate_in, self.rate_out = rate_in, rate_out
        self.up, self.down = rate_out // g, rate_in // g
        fc = cutoff * min(rate_in, rate_out)                     # Hz
        self.half = math.ceil(zeros * rate_in / (2.0 * fc))      # filter half-width, input samples
        k = 2 * self.half
        # d: offset of each tap from the output instant, in input samples, per phase
        d = (np.arange(self.up)[:, None] / self.up) + (self.half - 1 - np.arange(k))[None, :]
        taps = (2 * fc / rate_in) * np.sinc(2 * fc * d / rate_in)
        taps *= np.i0(beta * np.sqrt(np.clip(1.0 - (d / self.half) ** 2, 0.0, None))) / np.i0(beta)
        taps /= taps.sum(axis=1, keepdims=True)                  # exact unity gain at DC, every phase
        self._taps = taps.astype(np.float32)
        self.reset()

    def reset(self) -> None:
        """Forget the stream: the next sample is the first of a new one."""
        self._buf = np.zeros(self.half, np.float32)    # silence before the first sample
        self._x0 = -self.half                          # index of _buf[0] in the stream
        self._n = 0                                    # next output, relative to the same origin
        self._in_total = 0
        self._out_total = 0

    @property
    def identity(self) -> bool:
        return self.up == self.down

    def process(self, x: np.ndarray) -> np.ndarray:
        """The output samples that `x` (float32) completes; fewer than `up/down * len(x)` at first."""
        if self.identity:
            return x
        self._buf = np.concatenate([self._buf, x.astype(np.float32, copy=False)])
        self._in_total += len(x)
        return self._produce(limit=None)

    def flush(self) -> np.ndarray:
        """The rest of the stream (its last input sample followed by silence), then reset."""
        if self.identity:
            return np.zeros(0, np.float32)
        want = -(-self._in_total * self.up // self.down) - self._out_total
        self._buf = np.concatenate([self._buf, np.zeros(self.half + 1, np.float32)])
        out = self._produce(limit=want)
        self.reset()
        return out

    def _produce(self, limit: int | None) -> np.ndarray:
        last = self._x0 + len(self._buf) - 1 - self.half         # the latest base index computable
        end = -(-(last + 1) * self.up // self.down)               # ceil: first output not computable
        count = max(0, end - self._n)
        if limit is not None:
            count = min(count, limit)
        n = self._n + np.arange(count, dtype=np.int64)
        base = (n * self.down) // self.up
        phase = (n * self.down - base * self.up).astype(np.intp)
        first = (base - self.half + 1 - self._x0).astype(np.intp)
        out = np.empty(count, np.float32)
        k = 2 * self.half
        for s in range(0, count, 4096):                          # blocks: (4096, k) floats at most
            idx = first[s:s + 4096, None] + np.arange(k)
            out[s:s + 4096] = np.einsum("ij,ij->i", self._buf[idx], self._taps[phase[s:s + 4096]])
        self._n += count
        self._out_total += count
        keep_from = (self._n * self.down) // self.up - self.half + 1 - self._x0
        if keep_from > 0:
            self._buf = self._buf[keep_from:]
            self._x0 += keep_from
        # shift the origin by whole periods so the indices stay small however long the stream
        periods = self._n // self.up
        self._n -= periods * self.up
        self._x0 -= periods * self.down
        return out


class Converter:
    """A stream of chunks in `fmt` to 16 kHz mono int16, chunk by chunk.

    One converter per stream (one browser tab, one microphone): the resampler carries the
    end of one chunk into the next. A refused chunk leaves the converter as it was.
    """

    def __init__(self, fmt: AudioFormat) -> None:
        self.format = fmt
        self._resampler = Resampler(fmt.rate)

    def convert(self, chunk: Chunk) -> np.ndarray:
        """The 16 kHz int16 samples this chunk completes (may be empty for a tiny chunk)."""
        return to_int16(self._resampler.process(decode(chunk, self.format)))

    def flush(self) -> np.ndarray:
        """The last samples the resampler still holds; the converter is then fresh."""
        return to_int16(self._resampler.flush())

    def reset(self) -> None:
        self._resampler.reset()


def to_16k(chunk: Chunk, fmt: AudioFormat) -> np.ndarray:
    """A whole recording in `fmt` as 16 kHz mono int16 (up to a minute)."""
    x = decode(chunk, fmt, max_seconds=MAX_CLIP_SECONDS)
    r = Resampler(fmt.rate)
    return to_int16(np.concatenate([r.process(x), r.flush()]))


def read_wav(path: str | Path) -> np.ndarray:
    """A 16-bit PCM WAV file (mono or stereo, 8..48 kHz) as 16 kHz mono int16."""
    try:
        with wave.open(str(path), "rb") as w:
            width, channels, rate, n = w.getsampwidth(), w.getnchannels(), w.getframerate(), w.getnframes()
            if width != 2:
                raise BadAudio(f"{path} has {8 * width}-bit samples; only 16-bit PCM WAV files can be read "
                               "(convert it, e.g. `sox in.wav -b 16 out.wav`).")
            if n > MAX_CLIP_SECONDS * rate:
                raise BadAudio(f"{path} is {n / rate:.0f} s long; a voice command file may be at most "
                               f"{MAX_CLIP_SECONDS:g} s.")
            raw = w.readframes(n)
    except (wave.Error, EOFError) as e:
        raise BadAudio(f"{path} is not a 16-bit PCM WAV file ({e}); convert it to one.") from None
    except OSError as e:
        raise BadAudio(f"{path} cannot be read: {e.strerror or e}.") from None
    return to_16k(raw, AudioFormat(rate, "int16", channels))


def wav_bytes(samples: np.ndarray, rate: int = RATE) -> bytes:
    """Mono int16 samples as the bytes of a WAV file (for tests, recordings, the web page)."""
    import io
    buf = io.BytesIO()
    with wave.open(buf, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(np.asarray(samples, "<i2").tobytes())
    return buf.getvalue()
