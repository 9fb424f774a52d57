"""Labels fit (issue 27, point 6): at 1280x800, 1024x768 and on a 390x844 phone, every tab of the
Task Creator (and what shows more controls: the wizard, a message with its Dismiss button, the
Connection Manager with two robots, both stopped, the Esc hint), measured in the page: no text
of a button, tab, label, link or message is clipped or spills out of its box, no control is
under 44 px, and the page never scrolls sideways. Screenshots of every tab at every size are
left in tests/web/screenshots/labels-<size>-<tab>.png for a person to look at. And the words
match: a control that the page's help names in quotes is on the page with those words.
"""

from __future__ import annotations

import pytest

from asibot.testing import wait_until

from .conftest import _stack, http, screenshot

pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]

ASIBOT, PIONEER = "asibot-sim", "pioneer-sim"
ROBOTS = (ASIBOT, PIONEER)
SIZES = {
    "1280x800": {"viewport": {"width": 1280, "height": 800}},
    "1024x768": {"viewport": {"width": 1024, "height": 768}},
    "390x844": {"viewport": {"width": 390, "height": 844}, "is_mobile": True, "has_touch": True},
}
#: Every tab in the page's order, and what it shows once it has loaded what it lists. Pioneer arm
#: and Base first offer to command pioneer-sim (the page commands asibot-sim).
TABS = {
    "home": "text=Teach the robot a task", "joint": ".jog-grid button", "cartesian": ".jog-grid button",
    "pointer": "text=Motion control", "program": ".cm-content", "speech": ".points li .pname",
    "assigner": ".icons button", "launcher": ".task-button", "video": ".video img, .video p",
    "pioneer": ".about-robot button", "base": ".about-robot button", "access": "#access-intervalMs",
}
TASK, PROGRAM = "Give me the red can", "give_me_the_red_can"
WORDS = ("give me the red can", "good morning")
LONG_ERROR = ("asibot-sim: the program give_me_the_red_can stopped at line 12: the point above_can_on_the_kitchen_table "
              "is out of the arm's reach (x 0.512, y -0.301, z 0.090). Capture it again where the arm can go, then run it again.")
MESSAGES_STAY = """() => { if (!localStorage.getItem('asibot.access'))
    localStorage.setItem('asibot.access', JSON.stringify({format: 'asibot-access-settings', version: 1, messages: 'stay'})); }"""

# What the page shows, measured in the page. `where` names the view in each finding.
#  1. Each visible button, tab, link, label, heading, paragraph, list item and message: its content
#     wider or taller than its box (scrollWidth > clientWidth, scrollHeight > clientHeight); its
#     own text's line boxes (a Range's client rects) outside its border box, outside an ancestor
#     that clips (overflow hidden or clip), or outside the viewport sideways (unless an ancestor
#     scrolls sideways, as the tab row does on a phone: then the tab itself must be whole).
#     A select: its chosen option's text wider than the room the select gives it.
#  2. The boxes that hold them (panels, rows, cards, the notice, the wizard): content spilling out.
#  3. Every control (button, tab, button link, select, file input) at least 44 x 44 px.
#  4. The page itself wider than the viewport (a sideways scroll).
#  5. A control, message or status under the emergency stop's space (issues 52, 54): the stop has
#     room of its own. One the page's scroll has put under it counts only if scrolling it into
#     view (as a focus or the scanning ring does) leaves it there.
MEASURE = r"""(where) => {
  const vw = document.documentElement.clientWidth;
  const found = [];
  const IGNORED = '.cm-editor, .output, .skip, .scan-ring, [hidden]';
  const TEXTS = ['button', '[role=tab]', 'a[href]', 'label', 'select', 'h1', 'h2', 'h3', 'p', 'li', 'figcaption',
    'strong', '.lamp', '.name', '.kind', '.label', '.pname', '.pvals', '.notice > span', '[role=status]', '[role=alert]',
    '.estop-word', '.estop-key', 'progress'].join(',');
  const BOXES = ['.panel', '.row', '.notice', '.wizard', '.wizard ol', '.robot-card', '.lamps', '.connection', '.top', '.brand',
    '.estop-box', '.columns', '#view', '.modes', '.chips', '.icons', '.points', '.launcher', '.jog-grid', '.form-grid',
    '.drives', '.about-robot', '.video', 'figure', '.tabs'].join(',');
  const CONTROLS = 'button, [role=tab], a.button-link, select, input[type=file]';
  const shown = (n) => !n.closest(IGNORED) && n.checkVisibility({ visibilityProperty: true, opacityProperty: true })
    && n.getBoundingClientRect().width > 0;
  const words = (n) => {
    const t = n.tagName === 'SELECT' ? (n.selectedOptions[0] || {}).text || '' : n.innerText || n.getAttribute('aria-label') || '';
    return t.replace(/\s+/g, ' ').trim().slice(0, 70);
  };
  const what = (n) => n.tagName.toLowerCase() + (n.id ? `#${n.id}` : '') + (n.classList.length ? `.${[...n.classList].join('.')}` : '');
  const size = (r) => `${Math.round(r.width)}x${Math.round(r.height)}`;
  const say = (n, problem) => found.push({ where, what: what(n), text: words(n), size: size(n.getBoundingClientRect()), problem });
  const scrolls = (s) => s.overflowX === 'auto' || s.overflowX === 'scroll';
  const clips = (s) => s.overflowX === 'hidden' || s.overflowX === 'clip' || s.overflowY === 'hidden' || s.overflowY === 'clip';
  const spills = (n) => {
    const s = getComputedStyle(n);
    if (s.display === 'inline' || s.display === 'contents' || n.tagName === 'SELECT' || n.tagName === 'PROGRESS') return null;
    if (n.scrollWidth > n.clientWidth + 1 && !scrolls(s)) return `content ${n.scrollWidth} px wide in ${n.clientWidth}`;
    if (n.scrollHeight > n.clientHeight + 1 && s.overflowY !== 'auto' && s.overflowY !== 'scroll') return `content ${n.scrollHeight} px high in ${n.clientHeight}`;
    return null;
  };
  const out = (r, b, t = 1) => r.left < b.left - t || r.right > b.right + t || r.top < b.top - t || r.bottom > b.bottom + t;
  // The text nodes an element owns: not those of a descendant that is measured itself.
  const ownText = (n) => {
    const nodes = [];
    const walk = document.createTreeWalker(n, NodeFilter.SHOW_TEXT);
    for (let t = walk.nextNode(); t; t = walk.nextNode()) {
      if (!t.textContent.trim()) continue;
      const owner = t.parentElement.closest(TEXTS);
      if (owner === n) nodes.push(t);
    }
    return nodes;
  };
  for (const n of document.querySelectorAll(TEXTS)) {
    if (!shown(n)) continue;
    const problem = spills(n);
    if (problem) { say(n, problem); continue; }
    if (n.tagName === 'SELECT') {
      const s = getComputedStyle(n);
      const ctx = document.createElement('canvas').getContext('2d');
      ctx.font = `${s.fontWeight} ${s.fontSize} ${s.fontFamily}`;
      const room = n.clientWidth - parseFloat(s.paddingLeft) - parseFloat(s.paddingRight) - 16;   // 16: the arrow
      const need = ctx.measureText(words(n)).width;
      if (need > room + 1) say(n, `its choice needs ${Math.round(need)} px, has ${Math.round(room)}`);
      continue;
    }
    const box = n.getBoundingClientRect();
    const ancestors = [];
    let sideways = false;
    for (let a = n.parentElement; a && a !== document.body; a = a.parentElement) {
      const s = getComputedStyle(a);
      if (scrolls(s) && a.scrollWidth > a.clientWidth + 1) sideways = true;
      if (clips(s)) ancestors.push(a);
    }
    let said = false;
    for (const t of ownText(n)) {
      const range = document.createRange();
      range.selectNodeContents(t);
      for (const r of range.getClientRects()) {
        if (said || r.width === 0) continue;
        if (out(r, box)) { say(n, `text ${Math.round(r.left)}..${Math.round(r.right)} x ${Math.round(r.top)}..${Math.round(r.bottom)} outside its box`); said = true; continue; }
        if (!sideways && (r.left < -1 || r.right > vw + 1)) { say(n, `text ${Math.round(r.left)}..${Math.round(r.right)} outside the ${vw} px viewport`); said = true; continue; }
        const clipper = ancestors.find((a) => {
          const b = a.getBoundingClientRect();
          return out(r, { left: b.left + a.clientLeft, top: b.top + a.clientTop, right: b.left + a.clientLeft + a.clientWidth, bottom: b.top + a.clientTop + a.clientHeight });
        });
        if (clipper) { say(n, `text clipped by ${what(clipper)}`); said = true; }
      }
    }
  }
  for (const n of document.querySelectorAll(BOXES)) {
    if (!shown(n)) continue;
    const problem = spills(n);
    if (problem) say(n, problem);
  }
  for (const n of document.querySelectorAll(CONTROLS)) {
    if (!shown(n)) continue;
    const r = n.getBoundingClientRect();
    if (r.width < 44 || r.height < 44) say(n, `a target of ${size(r)}, under 44 px`);
  }
  const stop = document.querySelector('.estop-box');    // its whole space: the column or the bar
  const over = (n) => {
    const r = n.getBoundingClientRect(), b = stop.getBoundingClientRect();
    return r.left < b.right - 1 && r.right > b.left + 1 && r.top < b.bottom - 1 && r.bottom > b.top + 1;
  };
  const news = `${CONTROLS}, input, textarea, [role=status], [role=alert], .notice, .result, .now`;
  const scrolled = [window.scrollX, window.scrollY];
  for (const n of document.querySelectorAll(news)) {
    if (!shown(n) || n.closest('.estop-box') || !over(n)) continue;
    n.scrollIntoView({ block: 'nearest', inline: 'nearest', behavior: 'instant' });
    if (over(n)) say(n, 'under the emergency stop (scrolled into view)');
    window.scrollTo({ left: scrolled[0], top: scrolled[1], behavior: 'instant' });
  }
  const page = document.documentElement.scrollWidth;
  if (page > vw) {
    const wide = [...document.querySelectorAll('body *')].filter((n) => !n.closest('.skip, .scan-ring, .tabs') && n.checkVisibility()
      && n.getBoundingClientRect().right > vw + 1 && ![...n.children].some((c) => c.getBoundingClientRect().right > vw + 1));
    found.push({ where, what: 'page', text: wide.slice(0, 4).map((n) => `${what(n)} "${words(n).slice(0, 30)}"`).join(', '),
      size: `${page}x${document.documentElement.scrollHeight}`, problem: `the page scrolls sideways: ${page} px in ${vw}` });
  }
  return found;
}"""


# Words that match: a control the page's help or the wizard names in quotes (“Add word”) is on the
# page with those words on it (a button or a tab), or is a heading the person can find.
NAMED = r"""(where) => {
  const shown = (n) => n.checkVisibility() && n.getBoundingClientRect().width > 0;
  const text = (sel) => [...document.querySelectorAll(sel)].filter(shown).map((n) => n.innerText.replace(/\s+/g, ' ').trim());
  const controls = new Set(text('button, [role=tab]'));
  const headings = text('h2, h3');
  const found = [];
  for (const p of document.querySelectorAll('#view p, #wizard p')) {
    if (!shown(p)) continue;
    for (const [, name] of p.innerText.matchAll(/“([^”]+)”/g)) {
      if (!controls.has(name) && !headings.some((h) => h === name || h.startsWith(`${name} (`))) found.push({ where, what: 'p', text: p.innerText.slice(0, 70), size: '', problem: `names “${name}”, which no button, tab or heading shows` });
    }
  }
  return found;
}"""


def measure(page, where: str) -> list[dict]:
    return page.evaluate(MEASURE, where) + page.evaluate(NAMED, where)


def describe(found: list[dict]) -> str:
    return "\n".join(f"  [{f['where']}] {f['what']} \"{f['text']}\" ({f['size']}): {f['problem']}" for f in found)


def go(page, view: str, ready: str) -> None:
    page.evaluate("(v) => { location.hash = v; }", view)
    page.wait_for_selector(f"#tab-{view}[aria-selected=true]", timeout=15000)
    page.wait_for_selector(ready, timeout=30000)


def command(page, robot: str) -> None:
    """Command `robot` with the Connection Manager's button, as a person does."""
    page.get_by_role("button", name=f"Command {robot}", exact=True).click()
    page.get_by_role("button", name=f"Commanding {robot}", exact=True).wait_for(timeout=10000)


def walk(page, size: str, found: list[dict], shots: bool = True) -> None:
    """Every tab and every state with more controls, measured (and photographed) at `size`; what
    does not fit is added to `found` as it is seen."""

    def look(where: str, shot: str | None = None) -> None:
        found.extend(measure(page, where))
        if shots and shot:
            screenshot(page, f"labels-{size}-{shot}")

    for view, ready in TABS.items():
        go(page, view, ready)
        if view == "program":
            page.get_by_role("button", name=PROGRAM).click()
            page.wait_for_selector("text=All changes saved.", timeout=10000)
            page.wait_for_selector("#view button:has-text('Restore')", timeout=10000)
        look(view, view)
    # Pioneer arm and Base with their controls: pioneer-sim commanded.
    command(page, PIONEER)
    go(page, "pioneer", "#view .jog-grid button")
    page.wait_for_function("document.querySelectorAll('#view .jog-grid').length >= 2", timeout=30000)
    look("pioneer, commanded", "pioneer-commanded")
    go(page, "base", ".points li[data-place=fridge]")
    look("base, commanded", "base-commanded")
    command(page, ASIBOT)
    # The wizard over each of its steps.
    go(page, "home", TABS["home"])
    page.get_by_role("button", name="Start the Task Creator wizard").click()
    for step, (view, ready) in enumerate([("joint", TABS["joint"]), ("cartesian", TABS["cartesian"]), ("program", TABS["program"]),
                                          ("speech", TABS["speech"]), ("assigner", TABS["assigner"]), ("launcher", TABS["launcher"])]):
        if step:
            page.get_by_role("button", name="Next step").click()
        page.wait_for_selector(f"#wizard >> text=step {step + 1} of 6", timeout=10000)
        go(page, view, ready)
        look(f"wizard step {step + 1}, {view}", "wizard" if step == 0 else None)
    page.get_by_role("button", name="Close the wizard").click()
    page.wait_for_selector("#wizard", state="hidden", timeout=5000)
    # The Esc hint: an Esc in a text field arms the stop, and the button says so.
    go(page, "speech", TABS["speech"])
    page.get_by_label("Word or phrase").focus()
    page.keyboard.press("Escape")
    page.wait_for_selector("#estop.armed", timeout=5000)
    look("speech, Esc hint shown", "esc-hint")
    page.locator("#view h2").first.click()
    page.wait_for_selector("#estop:not(.armed)", timeout=5000)
    # The emergency stop: its message with Dismiss, both cards stopped with Release buttons.
    go(page, "home", TABS["home"])
    page.locator("#estop").click()
    page.wait_for_function("document.querySelectorAll('.robot-card .lamp.alarm:not(.away)').length === 2", timeout=15000)
    page.locator("#notice").get_by_role("button", name="Dismiss").wait_for(timeout=10000)
    look("home, both robots stopped, a message", "notice")
    go(page, "joint", TABS["joint"])
    look("joint, both robots stopped, a message")
    for robot in ROBOTS:
        page.get_by_role("button", name=f"Release emergency stop of {robot}").click()
    page.wait_for_function("document.querySelectorAll('.robot-card .lamp.alarm:not(.away)').length === 0", timeout=15000)
    page.locator("#notice").get_by_role("button", name="Dismiss").click()
    page.wait_for_selector("#notice", state="hidden", timeout=5000)
    # A long error (the page's own notify(), as a refusal shows it): it wraps, Dismiss stays whole.
    page.evaluate("(text) => import('/static/js/ui.js').then((ui) => ui.notify(text))", LONG_ERROR)
    page.locator("#notice").get_by_role("button", name="Dismiss").wait_for(timeout=5000)
    look("joint, a long error", "notice-long")
    page.locator("#notice").get_by_role("button", name="Dismiss").click()
    page.wait_for_selector("#notice", state="hidden", timeout=5000)


def dedupe(found: list[dict]) -> list[dict]:
    """One finding per element and problem in a view (an element can be both a message and a box)."""
    seen: set[tuple] = set()
    return [f for f in found if (key := tuple(f.values())) not in seen and not seen.add(key)]


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    """Both simulations, each arm's kinematics, the Pioneer's navigation and the page, with a
    program (two versions), two words, a task and a taught point to list."""
    stack = _stack(tmp_path_factory.mktemp("both"), ["kinematics-asibot-sim", "kinematics-pioneer-sim", "nav-pioneer-sim"],
                   ["sim/asibot-sim", "kinematics/asibot-sim", "sim/pioneer-sim", "kinematics/pioneer-sim", "nav/pioneer-sim"])
    try:
        fill(stack)
    except BaseException:
        stack.stop()
        raise
    yield stack
    for robot in ROBOTS:
        http(stack, "POST", f"/api/robots/{robot}/release")
    stack.stop()


def fill(stack) -> None:
    """What the lists show: a program saved twice, two words, a task, a point."""
    http(stack, "POST", "/api/programs", {"name": PROGRAM})
    for text in ("print('hello')\n", "print('here is your red can')\n"):
        http(stack, "PUT", f"/api/programs/{PROGRAM}", {"text": text})
    for word in WORDS:
        http(stack, "POST", "/api/words", {"text": word})
    http(stack, "PUT", "/api/tasks/" + TASK.replace(" ", "%20"), {"program": PROGRAM, "words": list(WORDS[:1]), "icon": "can.svg"})
    # A capture takes the web's newest tool position: there is one once the kinematics has spoken.
    def placed() -> bool:
        status, robot = stack.web("GET", f"/api/robots/{ASIBOT}")
        return status == 200 and bool(robot.get("point"))
    wait_until(placed, timeout=60, interval=0.3, message=f"the web never had a tool position of {ASIBOT}")
    http(stack, "POST", f"/api/robots/{ASIBOT}/capture", {"name": "above_can"})


@pytest.mark.parametrize("size", list(SIZES))
def test_every_label_fits_its_box_at_every_size(browser, both, size):
    context = browser.new_context(**SIZES[size])
    context.add_init_script(f"({MESSAGES_STAY})()")
    page = context.new_page()
    page.set_default_timeout(15000)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        page.goto(both.web_url)
        page.wait_for_selector("body[data-ready=true]", timeout=15000)
        for robot in ROBOTS:
            page.wait_for_selector(f".robot-card[data-robot={robot}]", timeout=30000)
        if not page.get_by_role("button", name=f"Commanding {ASIBOT}", exact=True).is_visible():
            command(page, ASIBOT)       # the page took the robot that came first
        found: list[dict] = []
        try:
            walk(page, size, found)
        except Exception as e:    # a control that cannot be used: say what did not fit up to there
            raise AssertionError(f"{e}\nWhat did not fit until then:\n{describe(dedupe(found))}") from e
    finally:
        context.close()
    found = dedupe(found)
    assert not found, f"{len(found)} labels that do not fit at {size}:\n{describe(found)}"
    assert not errors, f"the page raised: {errors}"
