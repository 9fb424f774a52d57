"""Sounds for the voice tests: espeak-ng speech made at test time, noise, a reference resampler."""

from __future__ import annotations

import shutil
import subprocess
import wave
from pathlib import Path

import numpy as np

#: What a carer might have assigned, written as typed in the web page.
ASSIGNED = ["Give me the red can!", "open the fridge", "Go to the desk.", "drink"]
SPOKEN = ["give me the red can", "open the fridge", "go to the desk", "drink"]
#: (espeak-ng voice, words per minute): the default US voice, another male US voice, fast and slow.
VOICES = [("en-us", 140), ("en-us+m1", 175), ("en-us+m1", 130)]


class Speech:
    """espeak-ng WAVs (22050 Hz mono int16) made on demand, once per session."""

    def __init__(self, folder: Path) -> None:
        if shutil.which("espeak-ng") is None:
            raise RuntimeError("espeak-ng is not installed; the voice tests need it: sudo apt-get install espeak-ng")
        self.folder = folder
        self._made: dict[tuple[str, str, int], Path] = {}

    def wav(self, text: str, voice: str = "en-us", speed: int = 140) -> Path:
        key = (text, voice, speed)
        if key not in self._made:
            path = self.folder / f"{len(self._made):03d}.wav"
            subprocess.run(["espeak-ng", "-v", voice, "-s", str(speed), "-w", str(path), text], check=True,
                           capture_output=True)
            self._made[key] = path
        return self._made[key]

    def samples(self, text: str, voice: str = "en-us", speed: int = 140) -> tuple[np.ndarray, int]:
        """(int16 samples, rate) of the phrase."""
        with wave.open(str(self.wav(text, voice, speed))) as w:
            return np.frombuffer(w.readframes(w.getnframes()), "<i2").copy(), w.getframerate()


def fft_resample(x: np.ndarray, rate_in: int, rate_out: int) -> np.ndarray:
    """Band-limited resampling by zero-padding the spectrum: an independent reference
    (not asibot.voice.audio's resampler) to make 44.1 and 48 kHz test input."""
    x = np.asarray(x, np.float64)
    n_out = int(round(len(x) * rate_out / rate_in))
    spectrum = np.fft.rfft(x)
    out = np.zeros(n_out // 2 + 1, complex)
    m = min(len(spectrum), len(out))
    out[:m] = spectrum[:m]
    return np.fft.irfft(out, n_out) * (n_out / len(x))


def noise(seconds: float, dbfs: float, rate: int = 16000, seed: int = 0) -> np.ndarray:
    """White noise at `dbfs` (RMS), float in [-1, 1]."""
    rng = np.random.default_rng(seed)
    return rng.standard_normal(int(seconds * rate)) * 10 ** (dbfs / 20)


def as_int16(x: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(np.asarray(x) * 32768), -32768, 32767).astype(np.int16)
