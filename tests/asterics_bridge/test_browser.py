"""A real browser against the bridge: Debian's chromium driven by Playwright (never a
downloaded browser), the bridge on the in-memory bus with the doubles.

An attacker's page, served on another loopback port (another origin, the same site), tries
every route of the bridge the way a page can: fetch with and without CORS, with and without
headers that need a preflight, a beacon, a WebSocket and a no-cors POST to the TCP port. The
robot is never commanded and the page reads nothing. A page of an origin the user allowed,
with the token (AsTeRICS-Grid's case: its HTTP action sends authUser/authPw as Basic auth),
drives and reads the status."""

from __future__ import annotations

import http.server
import threading
from collections.abc import Iterator

import pytest

from asibot.testing import free_port, wait_until

from .harness import HTTP_TOKEN, Bridge

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
PAGE = b"<!doctype html><html><head><title>a page</title></head><body>hello</body></html>"

ATTACK = """async ({http, tcp}) => {
  const base = `http://127.0.0.1:${http}`;
  const results = {};
  const tryFetch = async (name, url, init) => {
    try {
      const r = await fetch(url, init);
      let text = null;
      try { text = await r.text(); } catch (e) { text = null; }
      results[name] = {type: r.type, status: r.status, text};
    } catch (e) {
      results[name] = {error: String(e)};
    }
  };
  const post = (body, extra) => Object.assign({method: 'POST', body}, extra || {});
  await tryFetch('simple text/plain', base + '/command', post('turn left', {headers: {'Content-Type': 'text/plain'}}));
  await tryFetch('simple, no content type', base + '/command', post('forward'));
  await tryFetch('no-cors text/plain', base + '/command', post('forward', {mode: 'no-cors'}));
  await tryFetch('no-cors stop', base + '/command', post('stop', {mode: 'no-cors'}));
  await tryFetch('form-urlencoded', base + '/command', post(new URLSearchParams({command: 'forward'})));
  await tryFetch('json (preflight)', base + '/command',
                 post(JSON.stringify({command: 'grab'}), {headers: {'Content-Type': 'application/json'}}));
  await tryFetch('guessed bearer (preflight)', base + '/command',
                 post('forward', {headers: {'Authorization': 'Bearer guess'}}));
  await tryFetch('guessed basic (preflight)', base + '/command?robot=asibot-sim',
                 post('arm up', {headers: {'Authorization': 'Basic ' + btoa('asibot:guess')}}));
  await tryFetch('status', base + '/status');
  await tryFetch('status no-cors', base + '/status', {mode: 'no-cors'});
  await tryFetch('status ?token=', base + '/status?token=guess');
  results['beacon'] = navigator.sendBeacon(base + '/command', 'forward');
  const tcpBase = `http://127.0.0.1:${tcp}/`;
  await tryFetch('tcp no-cors', tcpBase, post('goto fridge\\n', {mode: 'no-cors'}));
  await tryFetch('tcp cors', tcpBase, post('forward\\n'));
  await tryFetch('tcp long url', tcpBase + 'x'.repeat(2000), post('goto fridge\\n', {mode: 'no-cors'}));
  results['tcp websocket'] = await new Promise(resolve => {
    const ws = new WebSocket(`ws://127.0.0.1:${tcp}/`);
    ws.onopen = () => { ws.send('forward'); resolve('open'); };
    ws.onerror = () => resolve('error');
    ws.onclose = () => resolve('closed');
  });
  return results;
}"""

GRID_LIKE = """async ({http, token}) => {
  const base = `http://127.0.0.1:${http}`;
  const auth = {'Authorization': 'Basic ' + btoa('asibot:' + token)};
  const send = async (body, headers) => {
    const r = await fetch(base + '/command',
                          {method: 'POST', body, headers: Object.assign({'Content-Type': 'text/plain'}, headers)});
    return [r.status, await r.text()];
  };
  const out = {};
  out.forward = await send('forward', auth);
  const r = await fetch(base + '/status', {headers: Object.assign({'Accept': 'application/json'}, auth)});
  out.status = [r.status, await r.json()];
  out.noToken = await send('turn left', {});
  out.stopNoToken = await send('stop', {});
  return out;
}"""


class Pages:
    """A tiny web server of one page on a loopback port: an origin of its own."""

    def __init__(self) -> None:
        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self) -> None:
                self.send_response(200)
                self.send_header("Content-Type", "text/html; charset=utf-8")
                self.send_header("Content-Length", str(len(PAGE)))
                self.end_headers()
                self.wfile.write(PAGE)

            def log_message(self, *args: object) -> None:
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", free_port()), Handler)
        self.origin = f"http://127.0.0.1:{self.server.server_address[1]}"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    from playwright.sync_api import sync_playwright
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.fixture
def sites() -> Iterator[tuple[Pages, Pages]]:
    """(the grid's page, an attacker's page): two origins on this machine."""
    grid, attacker = Pages(), Pages()
    yield grid, attacker
    grid.close()
    attacker.close()


@pytest.fixture
def bridge(memory_bus, sites):
    b = Bridge(memory_bus, origins=(sites[0].origin,))
    yield b
    b.close()


@pytest.fixture
def page(browser):
    context = browser.new_context()
    yield context.new_page()
    context.close()


def test_a_page_of_another_origin_commands_nothing_and_reads_nothing(bridge, sites, page):
    page.goto(sites[1].origin + "/")
    results = page.evaluate(ATTACK, {"http": bridge.servers.http_port, "tcp": bridge.servers.tcp_port})
    # what reached the bridge: 11 HTTP requests or preflights, 4 connections to the TCP port
    counters = bridge.servers.counters
    wait_until(lambda: bridge.dispatcher.counters["commands"] or (
        counters["refused_origin"] >= 11 and counters["refused_http_like"] >= 3
        and counters["refused_bad_first_line"] >= 1), 15,
        message=lambda: f"not every attempt reached the bridge: {counters}; {results}")
    assert bridge.dispatcher.counters["commands"] == 0, results
    assert bridge.nav.calls == [] and bridge.arm.calls == [] and bridge.other_arm.calls == []
    assert bridge.tasks.calls == [] and bridge.cmd_vel.all() == []
    for name, result in results.items():
        if isinstance(result, dict) and "error" not in result:
            # an opaque answer (no-cors): no status, no body
            assert (result["type"], result["status"], result["text"]) == ("opaque", 0, ""), (name, result)
    assert results["simple text/plain"]["error"].startswith("TypeError")
    assert results["status"]["error"].startswith("TypeError")
    assert results["tcp websocket"] in ("error", "closed")


def test_the_allowed_grid_with_the_token_drives_and_reads(bridge, sites, page):
    page.goto(sites[0].origin + "/")
    out = page.evaluate(GRID_LIKE, {"http": bridge.servers.http_port, "token": HTTP_TOKEN})
    assert out["forward"] == [200, "ok: forward, until you say stop\n"]
    status, st = out["status"]
    assert status == 200 and st["robot"] == "pioneer-sim"
    assert out["noToken"][0] == 401 and "access token" in out["noToken"][1]
    assert out["stopNoToken"] == [200, "ok: stopped base and arm\n"]
    assert [r["name"] for r in bridge.nav.requests("primitive")] == ["forward", "stop"]
