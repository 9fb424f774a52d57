"""The driving primitives' names: what nav, the web and the AsTeRICS bridge agree on.

The thesis drives a mobile base one command at a time, for a person with one switch or a head
tracker: step forward, turn, curve, stop. These are those commands' names as people say them.
Nav's `primitive` verb takes any of them, in any case and spacing ("Turn  Left 90" is "turn
left 90", `normalise`); the web's Base page draws a button for each; the bridge's words name
them. They are spelled here only, and nav refuses to start if its primitives differ
(`asibot.nav.primitives`), so a renamed primitive cannot leave a button or a word that nav
refuses.

The two settings of the primitives change one level at a time with `CHANGES`: speed (faster,
slower) and width (wider, narrower: how far a step goes and how wide a curve is).
"""

from __future__ import annotations

#: The primitives, the stop last. A step goes one width; nav's `continuous` keeps the moving
#: ones going until "stop"; the exact turns ("turn left 90", "turn around") always end.
PRIMITIVES: tuple[str, ...] = (
    "forward", "backward", "turn left", "turn right", "turn left 90", "turn right 90", "turn around",
    "curve forward left", "curve forward right", "curve backward left", "curve backward right", "stop",
)

#: One level up or down of the primitives' speed or width.
CHANGES: tuple[str, ...] = ("faster", "slower", "wider", "narrower")


def normalise(name: str) -> str:
    """`name` as PRIMITIVES spell it: lower case, one space between words. Whether it is one
    of them is for the caller to say (nav answers with the list)."""
    return " ".join(name.lower().split())
