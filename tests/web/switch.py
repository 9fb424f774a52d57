"""One switch (Space) from a test's or a bench's side: what the ring is on, a tap, a hold, two
quick taps, and paths to a control counted in presses, as a person with one switch makes them.

The page's scanning (services/web/asibot/web/static/js/scanning.js) marks what the ring stands
on with data-scanned, says what kind of entry it is (control, group, back) on the ring's
data-kind, and counts its moves in data-step."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

SETTINGS_FORMAT = {"format": "asibot-access-settings", "version": 1}

RINGED = """() => [...document.querySelectorAll('[data-scanned]')]
    .map((n) => (n.getAttribute('aria-label') || n.innerText).replace(/\\s+/g, ' ').trim())"""


def with_settings(page, where: str, ready: str, robot: str = "asibot-sim", **settings) -> None:
    """Load the page at `where` (a #view) with these access settings in the browser's storage (as
    an imported file does), once `robot` is listed and `ready` is shown. Two quick taps stop every
    robot only where a caller asks for it: a script taps faster than a person."""
    page.evaluate("(s) => localStorage.setItem('asibot.access', JSON.stringify(s))",
                  {**SETTINGS_FORMAT, "doubleTapStop": False, **settings})
    page.goto(page.url.split("#")[0] + where)
    page.reload()
    page.wait_for_selector("body[data-ready=true]")
    page.wait_for_selector(f".robot-card[data-robot={robot}]", timeout=15000)
    page.wait_for_selector(ready, timeout=15000)


def ringed(page) -> list[str]:
    return page.evaluate(RINGED)


def ring_kind(page) -> str:
    """What the ring stands on: a control, a group (or row) a select opens, or Back."""
    return page.evaluate("document.getElementById('scan-ring').dataset.kind || ''")


def ring_label(page) -> str:
    """The ring's words for what it stands on (a group's own name: "The whole page")."""
    return page.evaluate("document.getElementById('scan-ring').dataset.label || ''")


def moves(page) -> str:
    return page.evaluate("document.getElementById('scan-ring').dataset.step || '0'")


def tap(page) -> None:
    """A short press of Space: the ring moves on (or scanning starts)."""
    before = moves(page)
    page.keyboard.press("Space")
    page.wait_for_function("(s) => document.getElementById('scan-ring').dataset.step !== s", arg=before, timeout=5000)


def hold(page) -> None:
    """Space held until the page selects (400 ms by default), then let go."""
    before = moves(page)
    page.keyboard.down("Space")
    page.wait_for_function("""(s) => { const r = document.getElementById('scan-ring');
        return r.dataset.step !== s || r.classList.contains('latched'); }""", arg=before, timeout=5000)
    page.keyboard.up("Space")


def quick_taps(page) -> None:
    """Two taps of Space as quick as a person's deliberate double tap (about 100 ms apart)."""
    page.keyboard.press("Space")
    page.wait_for_timeout(100)
    page.keyboard.press("Space")


def tap_until(page, wanted, limit: int = 80) -> list[str]:
    for _ in range(limit):
        now = ringed(page)
        if wanted(now) and ring_kind(page) != "back":
            return now
        tap(page)
    raise AssertionError(f"the ring never got there; it is on {ringed(page)}")


def choose(page, name: str) -> None:
    """Step scanning with one switch: tap to the group or row holding `name`, hold to open it,
    and so on down (a group of many controls opens into rows), until the ring is on it; hold."""
    now = tap_until(page, lambda r: name in r)
    while len(now) > 1:
        hold(page)
        now = tap_until(page, lambda r: name in r)
    hold(page)


def wait_ringed(page, js_test: str, timeout: float = 30000) -> None:
    page.wait_for_function(f"() => ({js_test})(({RINGED})())", timeout=timeout)


@dataclass
class Presses:
    """Presses of the one switch, counted: what the bench reports and the tests bound."""

    page: Any
    count: int = 0
    #: what the ring stood on at each press ("tap: Wait"), for a count that came out too high
    trail: list[str] = field(default_factory=list)
    #: ms between a tap and the next one when two quick taps stop (a person's pace, not a double tap)
    gap_ms: int = 0
    _tapped: bool = False

    def __post_init__(self) -> None:
        stored = json.loads(self.page.evaluate("localStorage.getItem('asibot.access') || '{}'"))
        if stored.get("doubleTapStop", True):
            self.gap_ms = stored.get("doubleTapMs", 350) + 150

    def _pace(self) -> None:
        """After a tap, the next press waits as a person does: a press soon after a tap is the stop."""
        if self._tapped and self.gap_ms:
            self.page.wait_for_timeout(self.gap_ms)

    def _note(self, press: str, on: list[str] | None) -> None:
        """`on`: what the ring stands on, when the caller has just read it (one read a press)."""
        self.trail.append(f"{press}: {' | '.join(ringed(self.page) if on is None else on)[:60]}")

    def tap(self, on: list[str] | None = None) -> None:
        self._pace()
        self._note("tap", on)
        tap(self.page)
        self.count += 1
        self._tapped = True

    def hold(self, on: list[str] | None = None) -> None:
        self._pace()
        self._note("hold", on)
        hold(self.page)
        self.count += 1
        self._tapped = False

    def quick_taps(self) -> None:
        quick_taps(self.page)
        self.count += 2
        self._tapped = False

    def start(self) -> None:
        """The first press: scanning starts, the ring on the Emergency stop."""
        self.tap()

    def to(self, name: str, limit: int = 80) -> None:
        """The shortest way a person takes to the control named `name`: tap to the entry that
        holds it, hold to open it, and so on, then hold on it."""
        for _ in range(limit):
            now = ringed(self.page)
            if (name in now or ring_label(self.page) == name) and ring_kind(self.page) != "back":
                self.hold(now)
                if len(now) == 1:
                    return
            else:
                self.tap(now)
        raise AssertionError(f"{name!r} not reached in {limit} presses; the ring is on {ringed(self.page)}")

    def until(self, wanted, limit: int = 80) -> list[str]:
        """Tap (at a person's pace) until what the ring stands on satisfies `wanted`."""
        for _ in range(limit):
            now = ringed(self.page)
            if wanted(now) and ring_kind(self.page) != "back":
                return now
            self.tap(now)
        raise AssertionError(f"the ring never got there; it is on {ringed(self.page)}")


def make_pick_program(page, presses: Presses, point: str) -> None:
    """By one switch on the Program page: a "Pick it up" program from `point`, a Wait added at the
    end and moved up before the lift, saved (the test bounds its presses, the bench counts them)."""
    presses.to("New: Pick it up…")
    # A person sees the points offered before pressing on; a script would tap past them.
    page.get_by_role("button", name=f"Choose point {point}").wait_for(timeout=10000)
    presses.to(f"Choose point {point}")
    listed = page.get_by_role("list", name="Steps")
    listed.locator(".step-sentence").nth(4).wait_for(timeout=10000)
    presses.to("Wait")
    listed.locator(".step-sentence").nth(5).wait_for(timeout=10000)
    presses.to("Move step 6 up")
    page.get_by_text("Unsaved changes").wait_for(timeout=10000)
    presses.to("Save steps")
    page.get_by_text("Steps saved").wait_for(timeout=10000)
