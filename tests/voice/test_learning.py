"""Learning the user's own pronunciation from recordings: a made-up word spoken by espeak-ng
(not in the dictionary, so it cannot be in the grammar) becomes recognisable when said again
by another voice or at another speed, other speech is still refused, a second saying is
checked against the first, bad recordings keep nothing, the file outlives a restart."""

from __future__ import annotations

import json

import numpy as np
import pytest

from asibot.voice.audio import AudioFormat, read_wav, to_16k
from asibot.voice.errors import BadAudio, GrammarError
from asibot.voice.grammar import build_grammar
from asibot.voice.learning import Learner, speech_in
from asibot.voice.phones import PhoneReader, check_phones
from asibot.voice.pronunciations import MAX_SAYINGS, Pronunciations
from asibot.voice.recognizer import Recognizer
from asibot.voice.vad import Vad

from .sounds import as_int16, noise

WORD = "zorblat"                  # espeak-ng says it; CMUdict does not have it
WORDS = [WORD, "drink", "open the fridge"]
TEACHER = ("en-us", 140)          # the saying it learns from
#: New sayings: another voice, another speed; each is recognised with the learned pronunciation.
AGAIN = [("en-us+m1", 130), ("en-us", 120), ("en-us", 170)]
#: More voices, for a fourth and fifth different saying.
OTHER_VOICES = [("en-us+f3", 140), ("en-us+m3", 150)]
OTHERS = ["what a lovely morning", "give me the red can", "corporate"]
LONG = "give me the red can and open the fridge and then go to the desk and bring me a towel please"


@pytest.fixture(scope="module")
def reader():
    r = PhoneReader()
    yield r
    r.close()


def with_quiet(x: np.ndarray, seconds: float = 0.6) -> np.ndarray:
    """A recording as a microphone makes it: quiet (a little hiss), the word, quiet."""
    hiss = as_int16(noise(seconds, -60, seed=3))
    return np.concatenate([hiss, x, hiss])


@pytest.fixture
def learner(tmp_path, reader):
    recognizer = Recognizer()
    store = Pronunciations(tmp_path / "voice" / "pronunciations.json")
    return Learner(recognizer, store, lambda: list(WORDS), reader)


def test_a_made_up_word_is_recognised_once_learned_and_other_speech_still_is_not(learner, speech):
    with pytest.raises(GrammarError, match="'zorblat' is not in the recogniser's English dictionary"):
        build_grammar(WORDS)
    before = learner.recognizer.set_words(WORDS, skip_unknown=True)
    assert WORD in before.refused and WORD not in before.phrases
    new_saying = read_wav(speech.wav(WORD, *AGAIN[0]))
    assert learner.recognizer.decode(new_saying).heard is None          # cannot be heard: not in the grammar

    learned = learner.learn_recording(WORD, with_quiet(read_wav(speech.wav(WORD, *TEACHER))))
    assert learned.phrase == WORD and learned.matched is None and learned.heard == ""
    assert len(learned.phones) >= 4 and learned.sayings == [learned.phones]

    grammar = learner.recognizer.set_words(WORDS, skip_unknown=True, learned=learner.store.all())
    assert grammar.refused == {} and grammar.phrases[WORD] == WORD
    for voice, speed in AGAIN:
        d = learner.recognizer.decode(read_wav(speech.wav(WORD, voice, speed)))
        assert d.heard is not None and d.heard.word == WORD, (voice, speed, d.reason)
    for other in OTHERS:
        d = learner.recognizer.decode(read_wav(speech.wav(other)))
        assert d.heard is None, (other, d.hypothesis)
    assert learner.recognizer.recognize(read_wav(speech.wav("drink"))).word == "drink"    # the dictionary's words too


@pytest.mark.parametrize("offset", [50, 70, 90, 140])
def test_the_whole_word_is_learned_wherever_its_frames_fall(learner, speech, offset):
    """The web page's microphone starts anywhere in a saying's 10 ms frames: read once from these
    starting points, "zorblat" lost its end ("S AO R OW G", "G AO R OW G", "S L AO R OW N") and a
    pronunciation learned so was never heard again. Its end is "D L ER" as this model hears it."""
    samples, rate = speech.samples(WORD, *TEACHER)
    quiet = np.zeros(2 * rate, np.int16)
    loop = to_16k(np.concatenate([quiet, samples, quiet]).tobytes(), AudioFormat(rate, "int16", 1))
    (utterance, *_) = Vad().feed(np.concatenate([np.zeros(offset, np.int16), loop, loop]))
    learned = learner.learn(WORD, utterance.samples)
    assert learned.phones[-3:] == ("D", "L", "ER"), learned.phones


def test_a_second_saying_is_checked_against_the_first_and_at_most_three_are_kept(learner, speech):
    first = learner.learn_recording(WORD, with_quiet(read_wav(speech.wav(WORD, *TEACHER))))
    second = learner.learn(WORD, read_wav(speech.wav(WORD, "en-us+m1", 175)))
    assert second.matched is True and second.heard == WORD
    assert second.sayings == [first.phones, second.phones] and not second.dropped
    kept = json.loads(learner.store.path.read_text())
    assert kept == {WORD: [" ".join(first.phones), " ".join(second.phones)]}
    # a saying that reads as one kept already is kept once, as the newest
    later = [learner.learn(WORD, read_wav(speech.wav(WORD, voice, speed))) for voice, speed in AGAIN + OTHER_VOICES]
    assert any(learned.dropped for learned in later)
    assert len(later[-1].sayings) == MAX_SAYINGS and later[-1].sayings[-1] == later[-1].phones
    assert first.phones not in learner.store.get(WORD)               # the oldest went first


def test_a_word_of_the_dictionary_said_differently_is_checked_with_the_dictionary(learner, speech):
    # "drink" is in CMUdict, so the first saying is compared with the dictionary's pronunciation
    learned = learner.learn_recording("Drink!", with_quiet(read_wav(speech.wav("drink"))))
    assert learned.phrase == "drink" and learned.matched is True and learned.heard == "drink"
    # said as something else entirely: learned all the same, and told that it did not match
    other = learner.learn("open the fridge", read_wav(speech.wav("drink")))
    assert other.matched is False and other.heard == "drink"


def test_bad_recordings_and_bad_words_are_refused_and_nothing_is_kept(learner, speech):
    word = with_quiet(read_wav(speech.wav(WORD)))
    cases = [
        (lambda: learner.learn_recording(WORD, as_int16(noise(2.0, -60))), BadAudio, "No speech was found"),
        (lambda: learner.learn_recording(WORD, np.zeros(16000, np.int16)), BadAudio, "No speech was found"),
        (lambda: learner.learn_recording(WORD, np.zeros(0, np.int16)), BadAudio, "No speech was found"),
        (lambda: learner.learn_recording(WORD, with_quiet(read_wav(speech.wav(LONG)))), BadAudio, "without a pause"),
        (lambda: learner.learn_recording(WORD, word.astype(np.float32)), BadAudio, "16 kHz mono int16"),
        (lambda: learner.learn_recording("", word), GrammarError, "has no words"),
        (lambda: learner.learn_recording(3, word), GrammarError, "must be text"),
        (lambda: learner.learn_recording(" ".join(["zorblat"] * 13), word), GrammarError, "at most 12"),
        (lambda: learner.learn(WORD, as_int16(noise(0.05, -20))), BadAudio, "Too little speech"),
    ]
    for call, error, sentence in cases:
        with pytest.raises(error, match=sentence):
            call()
    assert learner.store.all() == {} and not learner.store.path.exists()


def test_speech_is_cut_out_of_the_recording(speech):
    x = read_wav(speech.wav(WORD))
    cut = speech_in(with_quiet(x, 1.0))
    assert len(x) <= len(cut) < len(x) + 16000                     # the word, a little quiet, not the second of it


def test_forget_and_a_restart(learner, speech, tmp_path):
    learner.learn_recording(WORD, with_quiet(read_wav(speech.wav(WORD, *TEACHER))))
    again = Pronunciations(learner.store.path)                     # a restart reads what was learned
    assert again.all() == learner.store.all() and len(again.get(WORD)) == 1
    assert learner.forget("Zorblat!") == (WORD, 1)
    assert learner.forget(WORD) == (WORD, 0)
    assert Pronunciations(learner.store.path).all() == {}


def test_a_damaged_file_is_read_as_far_as_it_is_good(tmp_path, caplog):
    path = tmp_path / "pronunciations.json"
    path.write_text(json.dumps({"zorblat": ["Z AO R B L AE T"], "blip": ["Q X"], "blop": [], "blup": "B L AH P"}))
    assert Pronunciations(path).all() == {"zorblat": [("Z", "AO", "R", "B", "L", "AE", "T")]}
    assert "'blip' are left out" in caplog.text and "Q, X are not phones" in caplog.text
    path.write_text("{not json")
    assert Pronunciations(path).all() == {}
    assert path.read_text() == "{not json"                         # left for a person to look at


def test_phones_are_checked():
    assert check_phones("G IH V") == ("G", "IH", "V")
    for bad, sentence in [(["G", "q"], "q is not a phone"), ("G", "2 to 60 phones"), (3, "list of phones"),
                          (["G"] * 61, "this one has 61")]:
        with pytest.raises(ValueError, match=sentence):
            check_phones(bad)


def test_a_capture_takes_the_next_utterance_that_starts_after_it_is_armed(speech):
    """The phrase under way when the word is asked for is the end of something else: it is
    recognised as usual, and the next one is the word."""
    from asibot.voice.audio import AudioFormat
    from asibot.voice.recognizer import Listener
    recognizer = Recognizer()
    recognizer.set_words(["drink"])
    listener = Listener(recognizer, AudioFormat(16000))
    drink = with_quiet(read_wav(speech.wav("drink")))
    half = len(drink) // 2
    captured = []
    assert listener.feed(drink[:half]) == [] and listener.in_speech
    listener.arm(captured.append)
    results = listener.feed(drink[half:])
    assert [r.heard.word for r in results] == ["drink"] and captured == []
    assert listener.feed(drink) == [] and len(captured) == 1        # the next saying goes to the capture
    assert abs(captured[0].seconds - len(drink) / 16000) < 1.0
    assert listener.capture is None and [r.heard.word for r in listener.feed(drink)] == ["drink"]
