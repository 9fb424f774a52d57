"""Text lines (sniffing, framing, bad input) and the command vocabulary."""

import pytest

from asibot.asterics_bridge import lines
from asibot.asterics_bridge import vocabulary as vocab
from asibot.asterics_bridge.lines import BadLine, LineDecoder
from asibot.nav.primitives import PRIMITIVES as NAV_PRIMITIVES

#: The words issue 15 asks for, at least.
ISSUE_WORDS = ["forward", "backward", "turn left", "turn right", "stop", "turn around", "turn left 90",
               "turn right 90", "curve left", "curve right", "curve back left", "curve back right", "faster",
               "slower", "goto fridge", "save position", "recall position", "arm forward", "arm backward",
               "arm left", "arm right", "arm up", "arm down", "grab", "release", "arm save", "arm recall",
               "arm home", "wider", "narrower", "run give me the red can", "robot asibot-sim"]


def test_sniff_tells_netconnection_from_text():
    assert lines.sniff(b"@NS\x01") == lines.NETCONNECTION
    assert lines.sniff(b"@N") == lines.NETCONNECTION
    assert lines.sniff(b"@") is None and lines.sniff(b"") is None
    assert lines.sniff(b"forward\n") == lines.TEXT
    assert lines.sniff(b"@x") == lines.TEXT


def test_lines_are_split_on_lf_and_crlf_in_any_chunks():
    d = LineDecoder()
    assert d.feed(b"forw") == []
    assert d.feed(b"ard\r\nstop\nturn ") == ["forward", "stop"]
    assert d.feed(b"left\n") == ["turn left"]
    assert d.feed("arm up \u00e9\n".encode()) == ["arm up \u00e9"]


def test_bad_lines_are_answered_and_the_next_line_is_read():
    d = LineDecoder(max_bytes=16)
    out = d.feed(b"x" * 40)
    assert len(out) == 1 and isinstance(out[0], BadLine) and "longer than 16" in out[0].text
    assert d.pending() == 0
    assert d.feed(b"y" * 40 + b"\nstop\n") == ["stop"]        # the rest of the long line is dropped
    out = d.feed(b"\xff\xfe\n" + b"forward\n")
    assert isinstance(out[0], BadLine) and "UTF-8" in out[0].text and out[1] == "forward"
    assert lines.encode_line("a\nb") == b"a b\n"


@pytest.mark.parametrize("text", ISSUE_WORDS)
def test_every_word_of_the_issue_parses(text):
    cmd = vocab.parse(text)
    assert str(cmd) == text
    assert vocab.parse(text.upper()).word == cmd.word            # case-insensitive
    assert vocab.parse("  " + text.replace(" ", "   ") + " ").word == cmd.word


def test_base_words_map_onto_nav_primitives():
    for word, (name, continuous) in vocab.PRIMITIVES.items():
        assert name in NAV_PRIMITIVES, word
        assert continuous == (NAV_PRIMITIVES[name][3] is None), word
    assert vocab.PRIMITIVES["curve left"] == ("curve forward left", True)
    assert vocab.PRIMITIVES["curve back left"] == ("curve backward left", True)


def test_arguments_keep_their_case_and_aliases_work():
    assert vocab.parse("GOTO Fridge") == vocab.Command("goto", "Fridge")
    assert vocab.parse("go to the desk") == vocab.Command("goto", "the desk")
    assert vocab.parse("Run Drink") == vocab.Command("run", "Drink")
    assert vocab.parse("backwards").word == "backward"


@pytest.mark.parametrize("text, sentence", [
    ("forwrd", "unknown command 'forwrd'; did you mean 'forward'?"),
    ("trun left", "unknown command 'trun left'; did you mean 'turn left'?"),
    ("got fridge", "unknown command 'got fridge'; did you mean 'goto fridge'?"),
    ("fly", "unknown command 'fly'; say 'help' for the list of words."),
    ("goto", "'goto' needs a place: 'goto <place>'."),
    ("", "The command is empty; send a word such as 'forward' or 'help'."),
    ("stop\x00", "The command contains control characters; send plain words such as 'forward'."),
])
def test_what_is_not_understood_gets_a_sentence(text, sentence):
    with pytest.raises(vocab.NotUnderstood) as err:
        vocab.parse(text)
    assert str(err.value) == sentence


def test_limits():
    with pytest.raises(vocab.NotUnderstood, match="at most 200"):
        vocab.parse("goto " + "x" * 300)
    with pytest.raises(vocab.NotUnderstood):
        vocab.parse(b"forward")
    assert vocab.suggest("frige", ["fridge", "desk"]) == "; did you mean 'fridge'?"
    assert vocab.find("FRIDGE", ["fridge"]) == "fridge"
