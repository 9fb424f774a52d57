"""The one error of perception's plain classes: input refused whole, with a sentence.

A depth image with a NaN, an image whose shape is not its CameraInfo's, a CameraInfo with a
zero focal length: each is refused as a `BadInput` whose sentence says what is wrong and what
to do, and nothing is computed or published from it. The service counts and logs them
(`Bus.reject`); the classes never half-use bad data, since a wrong scan is worse than none
for the obstacle warnings and for navigation.
"""

from __future__ import annotations


class BadInput(ValueError):
    """A message perception refuses; `str(exc)` is the sentence for the log and the user."""
