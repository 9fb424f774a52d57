"""The grammar of the user's words: spoken forms, refusals naming the word, fixed words, cheap rebuilds."""

from __future__ import annotations

import time

import pytest

from asibot.voice.errors import GrammarError
from asibot.voice.grammar import FIXED_WORDS, Lexicon, build_grammar, check_phrase, normalise


@pytest.mark.parametrize("text, spoken", [
    ("Give me the RED can!", "give me the red can"),
    ("  open   the fridge. ", "open the fridge"),
    ("Don\u2019t stop", "don't stop"),
    ("'drink'", "drink"),
    ("bring me a t-shirt", "bring me a t-shirt"),        # the dictionary has "t-shirt"
    ("red-can", "red can"),                               # it has no "red-can": two words
    ("go_to the desk", "go to the desk"),
    ("Coca-Cola, please?", "coca-cola please"),
])
def test_phrases_are_compared_as_spoken(text, spoken):
    assert normalise(text) == spoken


@pytest.mark.parametrize("text, words", [
    ("give me the zorblax", r"The word 'zorblax' in 'give me the zorblax' is not in the recogniser's English dictionary"),
    ("zorblax", r"The word 'zorblax' is not in"),
    ("go to room 2", r"'2' in 'go to room 2' cannot be recognised: write numbers as words"),
    ("K\u00fchlschrank", r"'k\u00fchlschrank' is not in"),
    ("!!! ...", r"has no words"),
    ("", r"has no words"),
    ("a b c d e f g h i j k l m", r"has 13 words; a voice command may have at most 12"),
    (42, r"must be text; got 42"),
    (None, r"must be text; got None"),
])
def test_unusable_phrases_are_refused_with_a_sentence(text, words):
    with pytest.raises(GrammarError, match=words) as err:
        check_phrase(text)
    assert str(err.value).endswith(".")


@pytest.mark.parametrize("word", ["stop", "Stop!", " YES", "no."])
def test_fixed_words_cannot_be_assigned(word):
    with pytest.raises(GrammarError, match="is a fixed voice word"):
        check_phrase(word)


def test_empty_words_still_give_the_fixed_words():
    g = build_grammar([])
    assert list(g.phrases) == list(FIXED_WORDS) == ["stop", "yes", "no"]
    assert "public <command> = stop+ | yes | no;" in g.jsgf        # "stop stop stop" is a stop
    assert g.lookup("stop stop") == "stop" and g.lookup("yes yes") is None and g.lookup("no") == "no"


def test_grammar_maps_spoken_forms_to_the_words_as_written():
    g = build_grammar(["Give me the red can!", "drink", "Drink!", "open the fridge"])
    assert g.phrases == {"stop": "stop", "yes": "yes", "no": "no", "give me the red can": "Give me the red can!",
                         "drink": "drink", "open the fridge": "open the fridge"}
    assert "give me the red can | drink | open the fridge;" in g.jsgf
    assert g.key == build_grammar(["give me the RED can", "drink", "open the fridge"]).key
    assert g.key != build_grammar(["drink"]).key


def test_one_bad_word_refuses_all_or_is_left_out_when_asked():
    with pytest.raises(GrammarError, match="'zorblax'"):
        build_grammar(["drink", "fetch the zorblax"])
    g = build_grammar(["drink", "fetch the zorblax", "stop", "open the fridge"], skip_unknown=True)
    assert list(g.phrases) == ["stop", "yes", "no", "drink", "open the fridge"]
    assert set(g.refused) == {"fetch the zorblax", "stop"}
    assert "'zorblax'" in g.refused["fetch the zorblax"] and "fixed voice word" in g.refused["stop"]


def test_words_must_be_a_list_of_texts():
    with pytest.raises(GrammarError, match=r"not one string; pass \['drink'\]"):
        build_grammar("drink")
    with pytest.raises(GrammarError, match="must be text; got 3"):
        build_grammar(["drink", 3])


def test_too_many_phrases_are_refused():
    lex = Lexicon()
    many = [f"{a} {b} {c}" for a in ("give", "bring", "open", "close", "find", "take")
            for b in ("me", "the", "a", "my", "your", "this", "that", "his", "her")
            for c in ("can", "cup", "box", "door", "bottle", "book", "phone", "pen", "glass", "plate")]
    assert len(many) == 540
    with pytest.raises(GrammarError, match="more than 500 voice phrases"):
        build_grammar(many, lex)


def test_rebuilding_is_cheap():
    lex = Lexicon()
    words = [f"{a} the {b} {c}" for a in ("give me", "bring me", "open", "close")
             for b in ("red", "blue", "green", "small", "big") for c in ("can", "cup", "box", "door", "bottle")]
    build_grammar(words, lex)                            # the dictionary is read once per process
    start = time.perf_counter()
    for _ in range(20):
        g = build_grammar(words, lex)
    per_build = (time.perf_counter() - start) / 20
    assert len(g.phrases) == 103
    assert per_build < 0.01, f"{per_build * 1e3:.1f} ms per build of 100 phrases"
