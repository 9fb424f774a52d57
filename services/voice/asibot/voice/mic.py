"""The robot's own microphone, through sounddevice (PortAudio), for `--local-mic`.

sounddevice comes with pocketsphinx, but it needs the PortAudio library of the system
(Debian: `sudo apt-get install libportaudio2`); it is imported only when a local microphone
is asked for, so the stack runs without it. Blocks of `block` s of mono float32 at the
device's own rate (48 kHz at most: the converter takes 8 to 48 kHz) go to `put`, which must
return at once (it runs on PortAudio's thread): `Streams.put` checks a block and queues it.
A block of NaN is refused there with a sentence; a device that stops sending is forgotten
after the streams' silence limit, so either way nothing moves.
"""

from __future__ import annotations

import logging
import time
from typing import Any, Callable

log = logging.getLogger("asibot.voice")

SOURCE = "local"
BLOCK = 0.1
MAX_RATE = 48000

Put = Callable[[str, bytes, int, str, int], bool]


def sounddevice_module() -> Any:
    """sounddevice, or ValueError with the sentence that says what to install."""
    try:
        import sounddevice
    except (ImportError, OSError) as exc:     # OSError: "PortAudio library not found"
        raise ValueError(f"--local-mic needs sounddevice and the PortAudio library ({exc}); install them with "
                         "`sudo apt-get install libportaudio2` and `pip install sounddevice`") from None
    return sounddevice


class LocalMic:
    """Streams the input device `device` (None: the system's default) to `put` as source 'local'."""

    def __init__(self, put: Put, device: str | int | None = None, block: float = BLOCK) -> None:
        sd = sounddevice_module()
        self._put = put
        self.device = device
        self.blocks = self.problems = 0
        self._last_problem_log = 0.0
        try:
            info = sd.query_devices(device, "input")
            self.rate = min(int(info["default_samplerate"]), MAX_RATE)
            self._stream = sd.InputStream(device=device, samplerate=self.rate, channels=1, dtype="float32",
                                          blocksize=int(self.rate * block), callback=self._on_block)
            self._stream.start()
        except Exception as exc:          # sd.PortAudioError, ValueError: no such device, no input
            raise ValueError(f"the microphone {device if device is not None else '(default)'} cannot be opened "
                             f"({exc}); list the devices with `python -m sounddevice` and choose one with "
                             "--mic-device") from None
        self.name = str(info.get("name", device))
        log.info("voice: listening to the microphone %s at %d Hz", self.name, self.rate)

    def _on_block(self, indata: Any, frames: int, time_info: Any, status: Any) -> None:
        self.blocks += 1
        if status:                        # an overflow of the device's buffer: audio was lost
            self.problems += 1
            now = time.monotonic()
            if now - self._last_problem_log > 10.0:
                self._last_problem_log = now
                log.warning("voice: the microphone reports %s (%d times so far)", status, self.problems)
        self._put(SOURCE, indata.tobytes(), self.rate, "float32", 1)

    def health(self) -> dict:
        return {"mic": self.name, "mic_rate": self.rate, "mic_blocks": self.blocks, "mic_problems": self.problems}

    def close(self) -> None:
        try:
            self._stream.stop()
            self._stream.close()
        except Exception:
            log.debug("voice: closing the microphone failed", exc_info=True)
