"""Learning words by saying them, through the voice service on the in-memory bus: from a
recording sent with `learn`, and from the next thing a live source (a page's microphone)
says, which then launches nothing; a task word outside the dictionary launches its task once
learned; forget; bad requests answer a sentence and keep nothing."""

from __future__ import annotations

import json
import threading

import numpy as np
import pytest

from asibot import keys
from asibot.errors import RpcError
from asibot.testing import wait_until

from .sounds import as_int16, noise
from .test_service import SOURCE, Rig

WORD = "zorblat"
TASKS = {"Zorblat": [WORD], "Drink water": ["drink"]}
OTHER_VOICE = ("en-us+m1", 130)


@pytest.fixture
def rig(memory_bus, speech, tmp_path, monkeypatch):
    monkeypatch.setenv("ASIBOT_DATA", str(tmp_path))          # each test learns into its own folder
    r = Rig(speech, tasks=TASKS)
    yield r
    r.close()


def call(r: Rig, verb: str, request: dict, timeout: float = 90) -> dict:
    """A verb of the voice service; learning runs the phone recogniser (seconds of a core, more
    beside a browser), so the deadline is generous."""
    return r.test_bus.call(keys.voice_rpc(verb), request, timeout=timeout)


def recording(speech, text: str, voice=("en-us", 140)) -> dict:
    """The learn request's audio: espeak-ng's WAV (22050 Hz int16) with quiet around it."""
    x, rate = speech.samples(text, *voice)
    hiss = as_int16(noise(0.5, -60, rate, seed=4))
    return {"data": np.concatenate([hiss, x, hiss]).tobytes(), "rate": rate, "sample": "int16", "channels": 1}


def test_a_task_word_outside_the_dictionary_launches_its_task_once_learned_from_a_recording(rig, speech, tmp_path):
    status = call(rig, "status", {})
    assert WORD in status["refused"] and status["learned"] == []
    rig.say(WORD, voice=OTHER_VOICE)
    assert rig.next_heard(1).action == "nothing"                 # not in the grammar: cannot be heard

    reply = call(rig, "learn", {"word": "Zorblat", **recording(speech, WORD)})
    assert reply["phrase"] == WORD and reply["matched"] is None and len(reply["phones"].split()) >= 4
    assert reply["sayings"] == [reply["phones"]]
    status = call(rig, "status", {})
    assert status["refused"] == {} and WORD in status["words"] and status["learned"] == [WORD]
    assert json.loads((tmp_path / "voice" / "pronunciations.json").read_text()) == {WORD: [reply["phones"]]}
    assert call(rig, "learned", {"words": ["Zorblat!", "drink"]}) == {
        "ok": True, "words": {WORD: [reply["phones"]]}, "phrases": {"Zorblat!": WORD, "drink": "drink"}}

    rig.say(WORD, voice=OTHER_VOICE)                             # said again, by another voice
    h = rig.next_heard(2)
    assert (h.text, h.word, h.action, h.task) == (WORD, WORD, "launch", "Zorblat")
    rig.desk.finish()
    rig.say("what a lovely morning")
    assert rig.next_heard(3).action == "nothing"


def test_a_word_is_learned_from_the_live_microphone_and_that_saying_launches_nothing(rig, speech):
    replies: list = []

    def learn(voice_seconds: float) -> threading.Thread:
        t = threading.Thread(target=lambda: replies.append(
            call(rig, "learn", {"word": WORD, "source": SOURCE, "seconds": voice_seconds}, timeout=30)))
        t.start()
        wait_until(lambda: SOURCE in call(rig, "status", {})["learning_from"], 5,
                   message="the service never started listening for the word")
        return t

    t = learn(15)
    rig.say(WORD)
    t.join(20)
    assert replies and replies[0]["phrase"] == WORD and replies[0]["matched"] is None
    t = learn(15)
    rig.say(WORD, voice=OTHER_VOICE)
    t.join(20)
    assert len(replies) == 2 and replies[1]["matched"] is True and replies[1]["heard"] == WORD
    assert len(replies[1]["sayings"]) == 2
    rig.say("drink")                       # the first utterance acted on: the two sayings launched nothing
    h = rig.next_heard(1)
    assert (h.text, h.action) == ("drink", "launch")
    assert rig.desk.verbs("launch") == [{"task": "Drink water", "robot": "asibot-sim"}]
    assert call(rig, "status", {})["learning_from"] == []


def test_forget_makes_the_word_unknown_again(rig, speech):
    call(rig, "learn", {"word": WORD, **recording(speech, WORD)})
    assert call(rig, "forget", {"word": "Zorblat!"}) == {"ok": True, "phrase": WORD, "forgotten": 1}
    assert call(rig, "learned", {"words": ["Zorblat!", "!!"]}) == {"ok": True, "words": {}, "phrases": {"Zorblat!": WORD}}
    assert WORD in call(rig, "status", {})["refused"]
    assert call(rig, "forget", {"word": WORD})["forgotten"] == 0
    with pytest.raises(RpcError, match="has no words"):
        call(rig, "forget", {"word": "!!"})
    with pytest.raises(RpcError, match="'words' must be a list"):
        call(rig, "learned", {"words": "zorblat"})


def test_bad_requests_are_refused_with_a_sentence_and_nothing_is_learned(rig, speech, tmp_path):
    good = recording(speech, WORD)
    silence = {"data": np.zeros(32000, np.int16).tobytes(), "rate": 16000, "sample": "int16", "channels": 1}
    cases = [
        ({"word": WORD}, "either a recording"),
        ({"word": WORD, **good, "source": SOURCE}, "not both"),
        ({"word": WORD, **good, "data": b""}, "empty"),
        ({"word": WORD, **silence}, "No speech was found"),
        ({"word": WORD, **good, "rate": 4000}, "'rate' must be a whole number from 8000 to 48000"),
        ({"word": WORD, **good, "rate": "fast"}, "'rate' must be a whole number"),
        ({"word": WORD, **{**good, "rate": None}}, "whole number of Hz"),
        ({"word": WORD, **good, "sample": "int8"}, "'sample' must be int16 or float32; got 'int8'"),
        ({"word": WORD, **good, "sample": ["int16"]}, "int16 or float32"),
        ({"word": WORD, **good, "data": b"\0\0\0"}, "whole number"),
        ({"word": WORD, **silence, "data": np.zeros(16000 * 11, np.int16).tobytes()}, "at most 10 s"),
        ({"word": "!!", **good}, "has no words"),
        ({"word": "", **good}, "'word' must be a word or phrase"),
        ({"word": 3, **good}, "'word' must be a word or phrase"),
        ({"word": WORD, "source": "no/such"}, "audio source"),
        ({"word": WORD, "source": SOURCE, "seconds": 0}, "'seconds' must be a number in [1, 20] s"),
        ({"word": WORD, **good, "loud": True}, "takes only"),
    ]
    for request, sentence in cases:
        with pytest.raises(RpcError) as exc:
            call(rig, "learn", request)
        assert exc.value.code == "bad_request" and sentence in exc.value.message, (request.get("rate"), exc.value)
        assert exc.value.message.endswith(".")
    with pytest.raises(RpcError) as exc:                         # nobody says anything
        call(rig, "learn", {"word": WORD, "source": SOURCE, "seconds": 1})
    assert exc.value.code == "timeout" and "Nothing was said" in exc.value.message
    assert call(rig, "learned", {})["words"] == {} and not (tmp_path / "voice" / "pronunciations.json").exists()
    assert call(rig, "status", {})["learning_from"] == []
