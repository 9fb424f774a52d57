"""Voice activity detection: a continuous 16 kHz stream cut into utterances.

The microphone is open all day; the recogniser should see only the seconds when someone
speaks, each phrase whole. Energy against an adaptive noise floor is enough for that here:
the grammar and the recogniser's own checks reject what is not a command (a cough, a door),
so the VAD only has to be generous about where speech starts and ends, and bounded.
(webrtcvad has no cp311 wheel on PyPI, so it would need a compiler; an energy detector
needs nothing.)

Per 10 ms frame, the energy in dBFS is compared with the noise floor:

- the floor follows quiet frames: down at once (a noise that stopped), up slowly
  (0.5 s time constant) so a room getting louder is learnt, never pulled up by speech.
  It starts at the first frame's energy: a stream that starts with speech finds its floor
  in the first pause between syllables;
- speech starts when `start_frames` of the last `start_window` frames are `start_db` above
  the floor; it goes on while frames are `stop_db` above it (hysteresis) and within
  `below_peak_db` of the phrase's loudest frame, and ends after `hangover` seconds
  otherwise, so the short pauses between words stay inside the phrase;
- `pre_roll` seconds before the start are kept (a soft "f" or "h" begins below the
  threshold);
- a phrase longer than `max_utterance` is cut there and marked `cut` (someone talking
  on and on, a radio, a vacuum cleaner): the recogniser still gets it, the caller can say
  "please speak in short commands". If the floor is the reason (a new constant noise),
  the floor jumps to that noise, so it does not cut again every five seconds;
- bursts shorter than `min_speech` (a click, a knock) are dropped.

Memory is bounded: the pre-roll ring and at most `max_utterance` of speech.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass

import numpy as np

from asibot.voice.errors import BadAudio

RATE = 16000
FRAME = 160                     # 10 ms, the recogniser's frame rate too


@dataclass(frozen=True)
class VadConfig:
    """Thresholds of the detector; the defaults suit a desk or wheelchair microphone."""

    start_db: float = 12.0
    stop_db: float = 7.0
    below_peak_db: float = 30.0
    """A frame this far below the phrase's loudest is not speech, however far above the floor:
    the floor can be far too low (a microphone's noise gate sends digital silence, then hiss)."""
    start_window: int = 10
    start_frames: int = 6
    hangover: float = 0.45
    """s of quiet that end a phrase: longer than a pause between words (~0.2 s)."""
    pre_roll: float = 0.3
    min_speech: float = 0.12
    max_utterance: float = 5.0
    min_floor_dbfs: float = -65.0
    """The floor never goes below this: digital silence would make any hiss 'speech'."""
    rise: float = 0.02
    """Per quiet frame, the floor moves this fraction of the way up (~0.5 s)."""

    def __post_init__(self) -> None:
        if not 0 < self.stop_db <= self.start_db:
            raise BadAudio(f"The VAD needs 0 < stop_db <= start_db; got stop_db={self.stop_db}, "
                           f"start_db={self.start_db}.")
        if not 1 <= self.start_frames <= self.start_window:
            raise BadAudio(f"The VAD needs 1 <= start_frames <= start_window; got {self.start_frames} and "
                           f"{self.start_window}.")
        if not 0.5 <= self.max_utterance <= 30:
            raise BadAudio(f"max_utterance must be 0.5 to 30 s; got {self.max_utterance}.")
        if min(self.hangover, self.pre_roll, self.min_speech) < 0:
            raise BadAudio("hangover, pre_roll and min_speech must not be negative.")


@dataclass(frozen=True)
class Utterance:
    """One phrase cut from the stream: samples (16 kHz int16, pre-roll and hangover included)."""

    samples: np.ndarray
    start: float
    """s from the start of the stream to the first sample."""
    cut: bool = False
    """True when the speaker had not paused after max_utterance: the phrase may go on."""

    @property
    def seconds(self) -> float:
        return len(self.samples) / RATE


def frame_dbfs(frames: np.ndarray) -> np.ndarray:
    """Energy of each row of int16 samples in dBFS (full-scale sine ~ -3 dBFS, digital silence -100)."""
    x = frames.astype(np.float32) / 32768.0
    return 10.0 * np.log10(np.mean(x * x, axis=-1) + 1e-10)


class Vad:
    """Feed 16 kHz mono int16 samples in any chunk sizes; get the finished utterances."""

    def __init__(self, config: VadConfig | None = None) -> None:
        self.config = config or VadConfig()
        c = self.config
        self._hang_frames = max(1, round(c.hangover * RATE / FRAME))
        self._max_frames = round(c.max_utterance * RATE / FRAME)
        self._min_frames = round(c.min_speech * RATE / FRAME)
        # pre-roll before the first frame of the window that started the phrase
        self._pre: collections.deque[np.ndarray] = collections.deque(
            maxlen=round(c.pre_roll * RATE / FRAME) + c.start_window)
        self._recent: collections.deque[bool] = collections.deque(maxlen=c.start_window)  # loud or not, last frames
        self.reset()

    def reset(self) -> None:
        """Forget the stream (a new microphone session)."""
        self.floor = float("inf")               # the first frame sets it (the floor only falls at once)
        self._rest = np.zeros(0, np.int16)       # < one frame left over from the last chunk
        self._pre.clear()
        self._recent.clear()
        self._speech: list[np.ndarray] | None = None   # frames of the phrase under way
        self._energies: list[float] = []
        self._loud = 0
        self._quiet = 0
        self._peak = -100.0
        self._frames_seen = 0
        self._start_frame = 0

    @property
    def in_speech(self) -> bool:
        return self._speech is not None

    def feed(self, samples: np.ndarray) -> list[Utterance]:
        """The utterances that ended within `samples` (usually none)."""
        if not isinstance(samples, np.ndarray) or samples.dtype != np.int16 or samples.ndim != 1:
            raise BadAudio("The VAD takes 16 kHz mono int16 samples as a 1-D numpy array; convert the audio "
                           "with asibot.voice.audio.Converter first.")
        x = np.concatenate([self._rest, samples]) if len(self._rest) else samples
        n = len(x) // FRAME
        self._rest = x[n * FRAME:].copy()
        if n == 0:
            return []
        frames = x[: n * FRAME].reshape(n, FRAME)
        energies = frame_dbfs(frames)
        out: list[Utterance] = []
        for frame, e in zip(frames, energies.tolist()):
            u = self._step(frame, e)
            if u is not None:
                out.append(u)
        return out

    def flush(self) -> list[Utterance]:
        """End of stream: the phrase under way, if long enough, then a fresh detector."""
        out = []
        if self._speech is not None and self._loud >= self._min_frames:
            out.append(self._finish(cut=False))
        self.reset()
        return out

    def _step(self, frame: np.ndarray, e: float) -> Utterance | None:
        c = self.config
        self._frames_seen += 1
        if self._speech is None:
            loud = e > self.floor + c.start_db
            self._recent.append(loud)
            if not loud:
                self._adapt(e)
            self._pre.append(frame)
            if loud and sum(self._recent) >= c.start_frames:
                # the phrase began with the pre-roll: the window's first loud frame is inside it
                self._speech = list(self._pre)
                self._start_frame = self._frames_seen - len(self._pre)
                self._energies = []
                self._peak = e
                self._loud, self._quiet = sum(self._recent), 0
                self._pre.clear()
                self._recent.clear()
            return None
        self._speech.append(frame)
        self._energies.append(e)
        self._peak = max(self._peak, e)
        if e > self.floor + c.stop_db and e > self._peak - c.below_peak_db:
            self._loud += 1
            self._quiet = 0
        else:
            self._quiet += 1
            if e < self.floor:
                self._adapt(e)
        if len(self._speech) >= self._max_frames:
            return self._finish(cut=True)
        if self._quiet >= self._hang_frames:
            if self._loud < self._min_frames:
                self._drop()
                return None
            return self._finish(cut=False)
        return None

    def _adapt(self, e: float) -> None:
        if e < self.floor:
            self.floor = max(e, self.config.min_floor_dbfs)
        else:
            self.floor += self.config.rise * (e - self.floor)

    def _finish(self, cut: bool) -> Utterance:
        samples = np.concatenate(self._speech) if self._speech else np.zeros(0, np.int16)
        u = Utterance(samples, self._start_frame * FRAME / RATE, cut)
        if cut and self._energies:
            # Five seconds without a pause: if even its quietest tenth is loud, that is a
            # noise that started (speech has gaps between syllables): learn it as the floor.
            self.floor = max(self.floor, float(np.percentile(self._energies, 10)) - 3.0)
        self._drop()
        return u

    def _drop(self) -> None:
        self._speech = None
        self._energies = []
        self._loud = self._quiet = 0
        self._recent.clear()
