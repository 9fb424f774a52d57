"""Spoken feedback: WAVs the recogniser understands, say() that returns at once, clear refusals."""

from __future__ import annotations

import io
import sys
import time
import wave

import numpy as np
import pytest

from asibot.voice.audio import AudioFormat, to_16k
from asibot.voice.errors import BadText, SpeakerMissing
from asibot.voice.speaker import Speaker


def recorder(path) -> list[str]:
    """A 'player' that writes what it is given to `path`: the test's loudspeaker."""
    return [sys.executable, "-c", f"import sys; open({str(path)!r}, 'wb').write(sys.stdin.buffer.read())"]


def test_synthesize_gives_a_wav_the_recogniser_understands(shared_recognizer):
    data = Speaker(voice="en-us", speed=140).synthesize("open the fridge")
    with wave.open(io.BytesIO(data)) as w:
        assert (w.getnchannels(), w.getsampwidth(), w.getframerate()) == (1, 2, 22050)
        samples = np.frombuffer(w.readframes(w.getnframes()), "<i2")
        assert w.getnframes() == len(samples) and 0.8 < len(samples) / 22050 < 3.0
    heard = shared_recognizer.recognize(to_16k(samples.tobytes(), AudioFormat(22050)))
    assert heard is not None and heard.text == "open the fridge"


def test_say_returns_at_once_and_plays_the_whole_message(tmp_path):
    speaker = Speaker(player=recorder(tmp_path / "played.wav"))
    start = time.perf_counter()
    speaker.say("I will give you the red can. " * 8)
    assert time.perf_counter() - start < 0.5
    assert speaker.wait(20)
    played = (tmp_path / "played.wav").read_bytes()
    assert played[:4] == b"RIFF" and len(played) > 22050 * 2 * 5          # more than five seconds of speech


def test_a_new_message_interrupts_the_old_one(tmp_path):
    speaker = Speaker(player=[sys.executable, "-c", "import sys, time; sys.stdin.buffer.read(); time.sleep(30)"])
    speaker.say("going to the desk")
    first = list(speaker._procs)
    speaker.say("stopping")
    assert all(p.wait(5) is not None for p in first)            # ended, not left to finish in 30 s
    assert speaker.speaking
    speaker.stop()
    assert speaker.wait(5) and not speaker.speaking


def test_text_that_looks_like_an_option_is_spoken(tmp_path):
    speaker = Speaker(player=recorder(tmp_path / "dash.wav"))
    speaker.say("--help -v xx")
    assert speaker.wait(10)
    assert len((tmp_path / "dash.wav").read_bytes()) > 22050          # speech, not espeak-ng's help text


def test_missing_espeak_is_a_sentence_saying_to_install_it():
    speaker = Speaker(program="espeak-ng-not-installed")
    assert not speaker.available
    for call in (speaker.say, speaker.synthesize):
        with pytest.raises(SpeakerMissing, match=r"espeak-ng-not-installed is not installed, so the robot cannot "
                                                 r"speak; install it with `sudo apt-get install espeak-ng`"):
            call("hello")


def test_a_missing_player_is_a_sentence():
    with pytest.raises(SpeakerMissing, match="The player 'no-such-player' cannot be started"):
        Speaker(player=["no-such-player"]).say("hello")


@pytest.mark.parametrize("text, words", [
    ("", "empty"), ("   \n ", "empty"), (None, "must be text"), (b"hi", "must be text"),
    ("x" * 501, "at most 500"), ("bell\x07", "control character"),
])
def test_bad_text_is_refused(text, words):
    with pytest.raises(BadText, match=words):
        Speaker().synthesize(text)
    with pytest.raises(ValueError):
        Speaker().say(text)


@pytest.mark.parametrize("kw, words", [
    (dict(voice="en us"), "not an espeak-ng voice name"), (dict(voice="-w/tmp/x"), "not an espeak-ng voice name"),
    (dict(speed=20), "80 to 450"), (dict(speed=150.0), "80 to 450"),
])
def test_bad_voice_settings_are_refused(kw, words):
    with pytest.raises(BadText, match=words):
        Speaker(**kw)
