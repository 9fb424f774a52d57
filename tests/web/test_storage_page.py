"""The Program tab's storage line and "Empty the trash" in Debian's chromium: under the list of
programs, how much the programs keep of their 32 MiB (versions and trash included, with the
number of deleted items); emptying the trash asks first, and only the confirmed press removes
the deleted programs for good (the trash on disk); a press taken back changes nothing. A page
of another origin cannot empty it. The line and the button are whole, on screen and clear of
the floating Emergency stop at a laptop's size and a phone's.

Only the web service runs (no robot): the Program tab's files need none, and a simulation
would take a core from the other tests."""

from __future__ import annotations

import functools
import json
import re
import threading
import urllib.error
import urllib.request
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer

import pytest

from asibot.testing import free_port

from .conftest import SHOTS, _stack, fresh_page, http

pytestmark = [pytest.mark.slow, pytest.mark.browser, pytest.mark.timeout(300)]

SIZES = {"desktop": (1280, 800), "tablet": (1000, 800), "phone": (390, 844)}
ASK = "Sure? Deleted programs go for good: touch again"
#: The line as program.js says it; groups: the trash's size and its number of items.
LINE = re.compile(r"^Your programs use [0-9.]+ (?:bytes|KiB|MiB) of 32 MiB \(versions [0-9.]+ (?:bytes|KiB|MiB), "
                  r"trash ([0-9.]+ (?:bytes|KiB|MiB)): (\d+) deleted items?\)\.$")


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """`asibot up --only web`: the page and its files, on a bus of its own."""
    stack = _stack(tmp_path_factory.mktemp("storage"), [], [])
    yield stack
    stack.stop()


@pytest.fixture
def fresh(store):
    """The store emptied of programs and trash, for a test of its own."""
    for name in http(store, "GET", "/api/programs")["programs"]:
        http(store, "DELETE", f"/api/programs/{name}")
    http(store, "DELETE", "/api/trash")
    return store


def trash(store) -> list[str]:
    """The names in the trash folder on disk."""
    folder = store.data / ".trash"
    return sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []


def make_programs(store, deleted: tuple[str, ...], kept: tuple[str, ...]) -> None:
    """Programs from the template, each saved once more (so each keeps a previous version),
    then `deleted` deleted."""
    for name in (*kept, *deleted):
        http(store, "POST", "/api/programs", {"name": name})
        http(store, "PUT", f"/api/programs/{name}", {"text": f"print('{name}')\n"})
    for name in deleted:
        http(store, "DELETE", f"/api/programs/{name}")


def open_program_tab(page):
    page.evaluate("() => { location.hash = 'program'; }")
    page.get_by_role("group", name="Programs").get_by_role("button").first.wait_for(timeout=10000)


def storage_line(page):
    return page.locator("p.storage")


def expect_trash(page, store) -> re.Match:
    """The line once it says what the server says of the trash; its match."""
    from playwright.sync_api import expect
    usage = http(store, "GET", "/api/storage")
    items = "1 deleted item" if usage["trash_items"] == 1 else f"{usage['trash_items']} deleted items"
    expect(storage_line(page)).to_contain_text(f": {items})", timeout=10000)
    found = LINE.match(storage_line(page).inner_text())
    assert found, storage_line(page).inner_text()
    return found


def test_emptying_the_trash_asks_first_and_a_press_taken_back_changes_nothing(browser, fresh):
    from playwright.sync_api import expect
    store = fresh
    make_programs(store, deleted=("old_one",), kept=("keep_me", "brush_teeth", "give_me_the_can"))
    with fresh_page(browser, store.web_url, robots=(), size=SIZES["desktop"]) as page:
        open_program_tab(page)
        # One program deleted (with its previous version): the line counts what the trash holds.
        assert [n.split("-", 3)[-1] for n in trash(store)] == ["old_one.py", "old_one.versions"]
        shown = expect_trash(page, store)
        assert int(shown.group(2)) > 0 and shown.group(1) != "0 bytes"

        # A second one deleted on the page: the line counts it at once.
        page.get_by_role("group", name="Programs").get_by_role("button", name="brush_teeth", exact=True).click()
        expect(page.get_by_role("heading", name="brush_teeth.py")).to_be_visible(timeout=10000)
        page.get_by_role("button", name="Delete", exact=True).click()
        page.get_by_role("button", name="Sure? Touch again").click()
        expect(page.get_by_role("heading", name="No program open")).to_be_visible(timeout=10000)
        assert int(expect_trash(page, store).group(2)) > int(shown.group(2))
        before, line = trash(store), storage_line(page).inner_text()
        assert any(n.endswith("-brush_teeth.py") for n in before), before
        items = http(store, "GET", "/api/storage")["trash_items"]

        # A press taken back (a touch elsewhere): nothing changes, and the next press asks again.
        emptying: list[str] = []
        page.on("request", lambda r: emptying.append(r.url) if r.method == "DELETE" and r.url.endswith("/api/trash") else None)
        empty = page.get_by_role("button", name="Empty the trash")
        expect(empty).to_be_enabled()
        empty.click()
        sure = page.get_by_role("button", name=ASK)
        expect(sure).to_be_visible()
        assert trash(store) == before
        page.get_by_role("heading", name="Programs", exact=True).click()
        expect(page.get_by_role("button", name="Empty the trash")).to_be_visible()
        expect(sure).to_have_count(0)
        page.get_by_role("button", name="Empty the trash").click()
        expect(sure).to_be_visible()
        page.get_by_role("heading", name="Programs", exact=True).click()
        expect(page.get_by_role("button", name="Empty the trash")).to_be_visible()
        assert trash(store) == before
        assert storage_line(page).inner_text() == line
        assert emptying == [], "a press taken back asked the server to empty the trash"
        assert http(store, "GET", "/api/storage")["trash_items"] == items

        # Confirmed: the trash is emptied, on disk too; the live programs and their versions stay.
        page.get_by_role("button", name="Empty the trash").click()
        page.get_by_role("button", name=ASK).click()
        expect(storage_line(page)).to_contain_text("trash 0 bytes: 0 deleted items)", timeout=10000)
        expect(page.locator(".notice.info")).to_contain_text("Trash emptied:", timeout=10000)
        expect(page.get_by_role("button", name="Empty the trash")).to_be_disabled()
        assert len(emptying) == 1
        assert trash(store) == []
        assert http(store, "GET", "/api/storage")["trash_items"] == 0
        assert sorted(http(store, "GET", "/api/programs")["programs"]) == ["give_me_the_can", "keep_me"]
        assert not (store.data / "old_one.py").exists() and not (store.data / "brush_teeth.py").exists()
        assert (store.data / "keep_me.py").is_file() and (store.data / ".versions" / "keep_me").is_dir()
        assert http(store, "GET", "/api/programs/keep_me")["versions"]


ATTACK = """<!doctype html><meta charset="utf-8"><title>cat pictures</title>
<script>
async function attack(target) {
  const log = [];
  for (const mode of ['no-cors', 'cors']) {
    const headers = mode === 'cors' ? {'X-Asibot-Session': 'guess'} : {};
    try {
      const r = await fetch(target + '/api/trash', {method: 'DELETE', mode, headers});
      log.push({mode, type: r.type, status: r.status, read: mode === 'cors' ? await r.text() : null});
    } catch (e) { log.push({mode, error: String(e)}); }
  }
  return log;
}
</script><p>Nothing to see here.</p>"""


@pytest.fixture
def attacker(tmp_path):
    """The attacker's page on another loopback port (another origin, the same site)."""
    (tmp_path / "index.html").write_text(ATTACK)
    handler = functools.partial(SimpleHTTPRequestHandler, directory=str(tmp_path))
    handler.log_message = lambda *a: None
    server = ThreadingHTTPServer(("127.0.0.1", free_port()), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{server.server_address[1]}/"
    server.shutdown()


def delete_trash_from(store, origin: str, token: str | None) -> tuple[int, dict]:
    headers = {"Origin": origin, **({"X-Asibot-Session": token} if token else {})}
    request = urllib.request.Request(store.web_url.rstrip("/") + "/api/trash", method="DELETE", headers=headers)
    try:
        with urllib.request.urlopen(request, timeout=10) as reply:
            return reply.status, json.loads(reply.read() or b"null")
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read() or b"null")


def test_a_page_of_another_origin_cannot_empty_the_trash(browser, fresh, attacker):
    store = fresh
    # The route is one of those test_other_origin.py tries from its page (the API's description).
    status, schema = store.web("GET", "/openapi.json")
    assert "delete" in schema["paths"]["/api/trash"]
    make_programs(store, deleted=("old_one",), kept=("keep_me",))
    before = trash(store)
    items = http(store, "GET", "/api/storage")["trash_items"]
    assert before and items
    # The browser's own attempt: the user's page open, another page tries.
    context = browser.new_context()
    try:
        page = context.new_page()
        page.goto(store.web_url)
        page.wait_for_selector("body[data-ready=true]", timeout=15000)
        other = context.new_page()
        other.goto(attacker)
        log = other.evaluate("(t) => attack(t)", store.web_url.rstrip("/"))
    finally:
        context.close()
    assert len(log) == 2 and all(entry.get("read") in (None, "") for entry in log), log
    assert trash(store) == before
    # The guard refuses the origin itself, even with the page's own token (PageGuard: not_allowed).
    for token in (None, store.web_session()):
        status, answer = delete_trash_from(store, attacker.rstrip("/"), token)
        assert status == 403 and answer["error"] == "not_allowed", answer
        assert attacker.rstrip("/") in answer["message"]
    assert trash(store) == before
    assert http(store, "GET", "/api/storage")["trash_items"] == items


def shoot(page, name: str) -> None:
    """What the screen shows, in tests/web/screenshots as storage-NAME.png."""
    SHOTS.mkdir(exist_ok=True)
    shot = SHOTS / f"storage-{name}.png"
    page.screenshot(path=str(shot))


def box(page, locator) -> dict:
    return locator.evaluate("(e) => { const r = e.getBoundingClientRect();"
                            " return {left: r.left, right: r.right, top: r.top, bottom: r.bottom}; }")


@pytest.mark.parametrize("size", list(SIZES))
def test_the_line_and_the_button_are_whole_and_clear_of_the_emergency_stop(browser, fresh, size):
    from playwright.sync_api import expect
    store = fresh
    make_programs(store, deleted=("old_one", "older_one"), kept=("keep_me", "give_me_the_can", "brush_my_teeth"))
    width, height = SIZES[size]
    with fresh_page(browser, store.web_url, robots=(), size=SIZES[size]) as page:
        open_program_tab(page)
        expect_trash(page, store)
        line, button = storage_line(page), page.get_by_role("button", name="Empty the trash")
        expect(button).to_be_enabled()
        # The line and its button in the middle of the screen, as a person scrolls to them.
        button.evaluate("(e) => e.scrollIntoView({block: 'center'})")
        shoot(page, size)
        text, press = box(page, line), box(page, button)
        for what, b in (("line", text), ("button", press)):
            assert 0 <= b["left"] and b["right"] <= width, (what, b)
        # Side by side or one under the other, never over each other.
        assert press["left"] >= text["right"] or press["top"] >= text["bottom"] or press["bottom"] <= text["top"], (text, press)
        # A line of the paragraph is a line of words, not one word a line.
        assert text["right"] - text["left"] >= 0.5 * min(width, 600), text
        # What a touch at the button's middle reaches is the button, not the floating stop.
        hit = page.evaluate("([x, y]) => document.elementFromPoint(x, y).closest('button')?.textContent", [
            (press["left"] + press["right"]) / 2, (press["top"] + press["bottom"]) / 2])
        assert hit == "Empty the trash", hit
        stop = box(page, page.locator(".estop-box .estop"))
        for what, b in (("line", text), ("button", press)):
            apart = (b["right"] <= stop["left"] or b["left"] >= stop["right"]
                     or b["bottom"] <= stop["top"] or b["top"] >= stop["bottom"])
            assert apart, (what, b, stop)
        # Asking first, its longer words stay whole inside the panel; then emptied.
        button.click()
        asking = page.get_by_role("button", name=ASK)
        expect(asking).to_be_visible()
        asked = box(page, asking)
        assert 0 <= asked["left"] and asked["right"] <= width, asked
        assert asking.evaluate("(e) => e.scrollWidth <= e.clientWidth"), "the question spills out of its button"
        shoot(page, f"{size}-asking")
        asking.click()
        expect(line).to_contain_text("0 deleted items)", timeout=10000)
        expect(page.get_by_role("button", name="Empty the trash")).to_be_disabled()
        shoot(page, f"{size}-emptied")
        # Whatever the scroll: at the end of the page the stop covers neither.
        page.evaluate("() => window.scrollTo(0, document.documentElement.scrollHeight)")
        page.wait_for_function("() => Math.abs(window.scrollY + innerHeight - document.documentElement.scrollHeight) < 2",
                               timeout=5000)
        text, press, stop = box(page, line), box(page, button), box(page, page.locator(".estop-box .estop"))
        for what, b in (("line", text), ("button", press)):
            if b["bottom"] > 0 and b["top"] < height:      # on screen at the page's end
                apart = (b["right"] <= stop["left"] or b["left"] >= stop["right"]
                         or b["bottom"] <= stop["top"] or b["top"] >= stop["bottom"])
                assert apart, (what, b, stop)
