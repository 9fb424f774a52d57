"""A web page the user happens to visit, on another origin, tries every route of the Task
Creator in Debian's chromium: no robot moves, nothing is written, nothing is read.

The attacker's page is served on another loopback port (another origin, the same site: the
hardest case, cookies would be sent) and by a DNS name that resolves to 127.0.0.1 (rebinding).
"""

from __future__ import annotations

import functools
import http.server
import json
import threading

import pytest

from asibot import keys
from asibot.messages import ArmState
from asibot.testing import free_port, wait_until

from .conftest import CHROMIUM, CHROMIUM_ARGS

pytestmark = pytest.mark.slow     # the kitchen simulation and two chromium pages

ROBOT = "asibot-sim"
#: A body every route that takes one could accept (a step, a move, a program, a goal ...).
BODY = {"space": "joint", "axis": 0, "direction": 1, "level": 5, "kind": "movj", "values": [60, 10, 10, 10, 0],
        "joints": True, "name": "evil", "text": "open('/tmp/evil', 'w')\n", "close": True, "place": "fridge",
        "u": 160, "v": 120, "steps": [], "template": "empty", "order": ["task:evil"]}
#: The routes of programs made of steps (api_steps.py), which openapi.json lists with the rest.
STEPS_ROUTES = [["PUT", "/api/programs/evil/steps"], ["POST", "/api/programs/evil/steps/preview"],
                ["POST", "/api/programs/evil/steps/template"], ["POST", "/api/step-programs"]]

ATTACK = """<!doctype html><meta charset="utf-8"><title>cat pictures</title>
<script>
async function attack(target, routes, body) {
  const log = [];
  const ws = target.replace('http', 'ws');
  for (const [method, path] of routes) {
    for (const mode of ['no-cors', 'cors']) {
      const headers = mode === 'cors' ? {'Content-Type': 'application/json', 'X-Asibot-Session': 'guess'}
                                      : {'Content-Type': 'text/plain'};
      try {
        const r = await fetch(target + path, {method, mode, headers, body: JSON.stringify(body)});
        log.push({path, method, mode, type: r.type, status: r.status, read: mode === 'cors' ? await r.text() : null});
      } catch (e) { log.push({path, method, mode, error: String(e)}); }
    }
  }
  const form = new FormData();
  form.append('file', new Blob(['PK'], {type: 'application/zip'}), 'seed.zip');
  try { await fetch(target + '/api/import', {method: 'POST', mode: 'no-cors', body: form}); } catch (e) {}
  const reads = {};
  for (const path of ['/', '/api/robots', '/api/programs', '/api/export.zip', '/api/client-reference',
                      '/api/robots/asibot-sim/depth-cameras', '/api/robots/asibot-sim/cameras/kitchen/cloud',
                      '/api/robots/asibot-sim/cameras/kitchen/calibration',
                      '/api/programs/evil/steps', '/api/favourites', '/docs', '/openapi.json']) {
    try { reads[path] = await (await fetch(target + path)).text(); } catch (e) { reads[path] = null; }
  }
  const socket = await new Promise((done) => {
    const s = new WebSocket(ws + '/ws?session=guess');
    let opened = false;
    s.onopen = () => {
      opened = true;
      for (let i = 0; i < 20; i++)
        s.send(JSON.stringify({type: 'hold', robot: 'asibot-sim', space: 'joint', axis: 0, direction: 1, level: 5}));
    };
    s.onmessage = (m) => { if (String(m.data).includes('hello')) opened = 'greeted'; };
    s.onclose = () => done(opened);
    setTimeout(() => done(opened), 5000);
  });
  return {log, reads, socket};
}
</script><p>Nothing to see here.</p>"""


@pytest.fixture
def attacker(tmp_path):
    """The attacker's page on another loopback port."""
    (tmp_path / "index.html").write_text(ATTACK)
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(tmp_path))
    handler.log_message = lambda *a: None
    server = http.server.ThreadingHTTPServer(("127.0.0.1", free_port()), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{server.server_address[1]}/"
    server.shutdown()


def changing_routes(kitchen) -> list[list[str]]:
    status, schema = kitchen.web("GET", "/openapi.json")
    found = []
    for raw, methods in schema["paths"].items():
        path = raw.replace("{robot}", ROBOT).replace("{name}", "evil").replace("{version}", "1").replace("{text}", "x")
        found += [[m.upper(), path] for m in methods if m not in ("get", "head")]
        if "/cameras/{name}/" in raw:     # and on the camera that is there, so only the guard can refuse
            found += [[m.upper(), path.replace("/cameras/evil/", "/cameras/kitchen/")] for m in methods if m not in ("get", "head")]
    return found


def joints(kitchen) -> list[float]:
    got = []
    sub = kitchen.bus.subscribe(keys.arm_state(ROBOT), ArmState, lambda m: got.append(list(m.positions)))
    try:
        wait_until(lambda: got, timeout=5)
    finally:
        sub.close()
    return got[-1]


def launch(playwright, *extra: str):
    return playwright.chromium.launch(executable_path=CHROMIUM, headless=True, args=[*CHROMIUM_ARGS, *extra])


def test_a_page_on_another_origin_can_do_nothing(kitchen, attacker):
    from playwright.sync_api import sync_playwright
    routes = changing_routes(kitchen)
    assert len(routes) >= 35
    # Touch to reach and the camera calibration are among them (api_world.py).
    for route in (["POST", f"/api/robots/{ROBOT}/cameras/evil/touch"], ["POST", f"/api/robots/{ROBOT}/cameras/evil/calibration/marks"],
                  ["POST", f"/api/robots/{ROBOT}/cameras/evil/calibration/spot"],
                  ["POST", f"/api/robots/{ROBOT}/cameras/evil/calibration/solve"], ["DELETE", f"/api/robots/{ROBOT}/cameras/evil/calibration"],
                  ["POST", "/api/points"], ["PUT", "/api/favourites/order"], ["POST", "/api/release"],
                  ["DELETE", "/api/trash"]):
        assert route in routes, route
    assert all(r in routes for r in STEPS_ROUTES), routes
    before = joints(kitchen)
    with sync_playwright() as p:
        browser = launch(p)
        try:
            page = browser.new_page()
            page.goto(kitchen.web_url)                      # the user has the Task Creator open ...
            page.wait_for_selector("body[data-ready=true]", timeout=15000)
            other = browser.new_page()
            other.goto(attacker)                            # ... and visits another page
            result = other.evaluate("([t, r, b]) => attack(t, r, b)", [kitchen.web_url.rstrip("/"), routes, BODY])
        finally:
            browser.close()
    # Nothing was read: every readable answer was refused, and no cross-origin read succeeded.
    assert all(v is None for v in result["reads"].values()), result["reads"]
    for entry in result["log"]:
        assert entry.get("read") in (None, ""), entry
    assert result["socket"] is False, "the page's WebSocket opened for another origin"
    # Nothing moved, nothing was engaged, nothing was written.
    assert joints(kitchen) == pytest.approx(before, abs=1e-3)
    status, robot = kitchen.web("GET", f"/api/robots/{ROBOT}")
    assert not robot["estop"]["engaged"]
    status, programs = kitchen.web("GET", "/api/programs")
    assert "evil" not in programs["programs"]
    assert not (kitchen.data / "evil.py").exists()
    assert not (kitchen.data / "cameras.json").exists()      # no calibration mark was paired
    status, points = kitchen.web("GET", "/api/points")
    assert "evil" not in [p["name"] for p in points["points"]]
    assert not (kitchen.data / "evil.steps.json").exists()
    assert not (kitchen.data / "favourites.json").exists()      # no order was set, no use counted


def test_a_rebound_dns_name_gets_nothing(kitchen):
    """evil.example resolves to 127.0.0.1 (as a rebinding attacker's DNS answers): a page of that
    name is same-origin with itself and could read everything, if the server answered it."""
    from playwright.sync_api import sync_playwright
    with sync_playwright() as p:
        browser = launch(p, "--host-resolver-rules=MAP evil.example 127.0.0.1")
        try:
            page = browser.new_page()
            reply = page.goto(kitchen.web_url.replace("127.0.0.1", "evil.example"))
            assert reply.status == 400
            answer = json.loads(page.inner_text("body"))
            assert answer["error"] == "bad_host" and "evil.example" in answer["message"]
            posted = page.evaluate("async () => (await fetch('/api/estop', {method: 'POST'})).status")
            assert posted == 400
        finally:
            browser.close()
    status, robot = kitchen.web("GET", f"/api/robots/{ROBOT}")
    assert not robot["estop"]["engaged"]
