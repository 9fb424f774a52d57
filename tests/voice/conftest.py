"""Fixtures for the voice tests: real speech from espeak-ng, made at test time, and audio helpers.

espeak-ng is a Debian package the stack needs anyway (spoken feedback), so the tests speak
the phrases themselves instead of storing recordings. The voices and speeds used are the
ones every phrase below is recognised in (docs/voice.md lists those that are not).
"""

from __future__ import annotations

import pytest

from asibot.voice.recognizer import Recognizer

from .sounds import ASSIGNED, Speech


@pytest.fixture(scope="session")
def speech(tmp_path_factory) -> Speech:
    return Speech(tmp_path_factory.mktemp("speech"))


@pytest.fixture(scope="session")
def shared_recognizer() -> Recognizer:
    """A recogniser of ASSIGNED, for the tests that do not change its words."""
    r = Recognizer()
    r.set_words(ASSIGNED)
    return r


@pytest.fixture
def recognizer() -> Recognizer:
    """A recogniser of ASSIGNED of the test's own, for tests that change its words."""
    r = Recognizer()
    r.set_words(ASSIGNED)
    return r
