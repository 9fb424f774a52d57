"""The errors of the voice library: input refused whole, with a sentence.

Audio in a format the library cannot read, a phrase whose word the recogniser does not know,
a missing espeak-ng: each is a `ValueError` (or, for the missing program, a `RuntimeError`)
whose sentence says what was wrong and what to do, and nothing is kept from the refused call.
The web service shows the sentence to the carer unchanged, so it is written for people.
"""

from __future__ import annotations


class BadAudio(ValueError):
    """Audio refused (format, rate, length, NaN): nothing of it was used or buffered."""


class GrammarError(ValueError):
    """A word or phrase that cannot go into the grammar; the sentence names it."""


class BadText(ValueError):
    """Text the speaker refuses to say (not text, empty, too long, control characters)."""


class SpeakerMissing(RuntimeError):
    """espeak-ng is not installed, so no spoken feedback can be made."""
