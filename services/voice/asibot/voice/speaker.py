"""Spoken feedback: "I will give you the red can", "Sorry, I did not understand".

A person who cannot see the screen, or not easily, needs to hear that the robot understood.
espeak-ng (Debian package `espeak-ng`) speaks offline, in under 0.1 s for a sentence, on
the robot's own loudspeaker. `say` starts speaking and returns at once (the caller is a
recogniser or a web request: it must not wait for a sentence to finish); a new message
interrupts one still being spoken, since stale feedback ("going to the desk" after "stop")
is worse than none. `synthesize` returns the WAV instead, for the web page to play in the
browser.

The text goes to espeak-ng on its standard input, never on its command line, so text that
begins with "-" is spoken, not taken as an option.
"""

from __future__ import annotations

import logging
import re
import shutil
import struct
import subprocess
import threading
from typing import Sequence

import numpy as np

from asibot.errors import quote
from asibot.voice.audio import wav_bytes
from asibot.voice.errors import BadText, SpeakerMissing

log = logging.getLogger("asibot.voice")

MAX_TEXT = 500
_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f]")
_VOICE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_+\-]{0,40}")


def check_text(text: object) -> str:
    """The text to say, one line, or BadText with a sentence."""
    if not isinstance(text, str):
        raise BadText(f"The text to say must be text; got {quote(text)}.")
    tidy = " ".join(text.split())
    if not tidy:
        raise BadText("The text to say is empty; give a word or a sentence.")
    if len(tidy) > MAX_TEXT:
        raise BadText(f"The text to say is {len(tidy)} characters long; say at most {MAX_TEXT} at a time.")
    if _CONTROL.search(tidy):
        raise BadText(f"The text to say holds a control character; remove it: {quote(tidy, 40)}.")
    return tidy


class Speaker:
    """espeak-ng with one voice and speed; `say(text)` in the background, `synthesize(text)` -> WAV."""

    def __init__(self, voice: str = "en-us", speed: int = 150, program: str = "espeak-ng",
                 player: Sequence[str] | None = None, timeout: float = 30.0) -> None:
        if not isinstance(voice, str) or not _VOICE.fullmatch(voice):
            raise BadText(f"The voice {quote(voice)} is not an espeak-ng voice name (like 'en-us' or 'en+f3').")
        if isinstance(speed, bool) or not isinstance(speed, int) or not 80 <= speed <= 450:
            raise BadText(f"The speed must be 80 to 450 words per minute; got {quote(speed)}.")
        self.voice, self.speed, self.program = voice, speed, program
        self.player = list(player) if player else None
        """A command reading a WAV on stdin (["aplay", "-q"]): for robots where espeak-ng has no
        sound output of its own. None: espeak-ng plays it."""
        self.timeout = timeout
        self._lock = threading.Lock()
        self._procs: list[subprocess.Popen] = []

    @property
    def available(self) -> bool:
        """espeak-ng is installed (say and synthesize will work)."""
        return shutil.which(self.program) is not None

    def _command(self, *extra: str) -> list[str]:
        path = shutil.which(self.program)
        if path is None:
            raise SpeakerMissing(f"{self.program} is not installed, so the robot cannot speak; install it with "
                                 "`sudo apt-get install espeak-ng`.")
        return [path, "-v", self.voice, "-s", str(self.speed), "--stdin", *extra]

    def synthesize(self, text: str) -> bytes:
        """`text` spoken, as the bytes of a WAV file (mono, 16-bit, espeak-ng's 22050 Hz)."""
        text = check_text(text)
        try:
            done = subprocess.run(self._command("--stdout"), input=text.encode(), capture_output=True,
                                  timeout=self.timeout, check=False)
        except subprocess.TimeoutExpired:
            raise SpeakerMissing(f"{self.program} took more than {self.timeout:g} s to speak "
                                 f"{quote(text, 40)}; check that it works: `espeak-ng hello`.") from None
        if done.returncode != 0:
            raise SpeakerMissing(f"{self.program} failed (exit code {done.returncode}): "
                                 f"{done.stderr.decode(errors='replace').strip()[:200]}")
        return _fix_wav(done.stdout)

    def say(self, text: str) -> None:
        """Start speaking `text` and return at once; what was still being said stops."""
        text = check_text(text)
        command = self._command()
        with self._lock:
            self._stop_locked()
            if self.player is None:
                first = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                         stderr=subprocess.PIPE)
                procs = [first]
            else:
                first = subprocess.Popen([*command, "--stdout"], stdin=subprocess.PIPE,
                                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
                try:
                    second = subprocess.Popen(self.player, stdin=first.stdout, stdout=subprocess.DEVNULL,
                                              stderr=subprocess.PIPE)
                except OSError as e:
                    first.kill()
                    first.wait()
                    raise SpeakerMissing(f"The player {self.player[0]!r} cannot be started ({e.strerror or e}); "
                                         "install it or leave `player` unset.") from None
                assert first.stdout is not None
                first.stdout.close()             # the player owns the pipe now: espeak-ng sees it close
                first.stdout = None
                procs = [first, second]
            assert first.stdin is not None
            first.stdin.write(text.encode())     # at most 500 characters: far below a pipe's buffer
            first.stdin.close()
            first.stdin = None                   # so that the reaper's communicate() only reads stderr
            self._procs = procs
        for p in procs:
            threading.Thread(target=self._reap, args=(p,), name="voice-say", daemon=True).start()

    def stop(self) -> None:
        """Stop speaking now."""
        with self._lock:
            self._stop_locked()

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until the current message is spoken; False if `timeout` s passed first."""
        with self._lock:
            procs = list(self._procs)
        try:
            for p in procs:
                p.wait(timeout)
        except subprocess.TimeoutExpired:
            return False
        return True

    @property
    def speaking(self) -> bool:
        with self._lock:
            return any(p.poll() is None for p in self._procs)

    def _stop_locked(self) -> None:
        for p in self._procs:
            if p.poll() is None:
                p.terminate()
        self._procs = []

    def _reap(self, p: subprocess.Popen) -> None:
        try:
            _, err = p.communicate(timeout=self.timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.communicate()
            log.warning("voice: %s did not finish speaking in %.0f s and was stopped", self.program, self.timeout)
            return
        if p.returncode not in (0, -15):       # -15: interrupted by a newer message
            text = (err or b"").decode(errors="replace").strip().splitlines()
            log.warning("voice: speaking failed (exit code %s): %s", p.returncode, text[-1] if text else "")


def _fix_wav(data: bytes) -> bytes:
    """espeak-ng's --stdout WAV has placeholder sizes (it streams); rewrite it with true ones."""
    if len(data) < 44 or data[:4] != b"RIFF" or data[8:12] != b"WAVE":
        raise SpeakerMissing("espeak-ng did not produce a WAV file; check that it works: `espeak-ng hello`.")
    pos, rate, body = 12, 22050, b""
    while pos + 8 <= len(data):
        tag, size = data[pos:pos + 4], struct.unpack("<I", data[pos + 4:pos + 8])[0]
        if tag == b"fmt ":
            rate = struct.unpack("<I", data[pos + 12:pos + 16])[0]
        if tag == b"data":
            body = data[pos + 8:]                # to the end: the size field is a placeholder
            break
        pos += 8 + size + (size & 1)
    return wav_bytes(np.frombuffer(body[: len(body) // 2 * 2], "<i2"), rate)
