"""Only the page's own requests reach a route (asibot.web.guard): every route that changes
something, tried without the page's session token, from another origin, by another Host name
and from another site's page, is refused before it runs, and nothing changes."""

from __future__ import annotations

import io
import re
import zipfile

import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from asibot.web import guard

from .conftest import API_ROBOT, page_client

OWN = "http://127.0.0.1:8080"
STRANGER = "http://127.0.0.1:9999"      # another server on this machine: another origin, same site


def routes(svc) -> list[tuple[str, str]]:
    """(method, path) of every API route that changes something (from the API's own description),
    with the robot and the names filled in."""
    app = svc.app
    while not hasattr(app, "openapi"):    # PageGuard -> BodyLimit -> Compressed -> FastAPI
        app = app.app
    found = []
    for path, methods in app.openapi()["paths"].items():
        path = re.sub(r"\{[a-z_]+\}", "x", path.replace("{robot}", API_ROBOT))
        found += [(method.upper(), path) for method in methods if method not in ("get", "head")]
    return found


def fresh(svc) -> TestClient:
    """A client with no token, calling the server by its own name."""
    return TestClient(svc.app, base_url=OWN)


def estopped(svc) -> bool:
    view = svc.fleet.view(API_ROBOT)
    return bool(view.get("estop", {}).get("engaged"))


def test_every_route_that_changes_something_is_listed(web):
    client, svc, driver, server = web
    listed = routes(svc)
    for expected in [("POST", "/api/estop"), ("POST", f"/api/robots/{API_ROBOT}/release"), ("POST", "/api/import"),
                     ("POST", "/api/icons"), ("POST", "/api/run/stop"), ("POST", f"/api/base/{API_ROBOT}/cancel"),
                     ("POST", "/api/programs/x/versions/x/restore"), ("PUT", "/api/voice"), ("DELETE", "/api/trash")]:
        assert expected in listed
    assert len(listed) >= 35


def test_without_the_pages_token_no_route_runs(web):
    client, svc, driver, server = web
    anonymous = fresh(svc)
    commands = len(driver.commands)
    for method, path in routes(svc):
        reply = anonymous.request(method, path, json={})
        assert reply.status_code == 403, (method, path, reply.status_code, reply.text)
        assert reply.json()["error"] == "session" and "reload the page" in reply.json()["message"]
    token = svc.web.session
    # Change the last character to one it is not: a fixed "A" was the token itself one time in 64.
    wrong = anonymous.post("/api/estop", headers={guard.HEADER: token[:-1] + ("B" if token.endswith("A") else "A")})
    assert wrong.status_code == 403
    assert len(driver.commands) == commands and not estopped(svc)


def test_a_multipart_import_without_the_token_writes_nothing(web):
    client, svc, driver, server = web
    archive = io.BytesIO()
    with zipfile.ZipFile(archive, "w") as z:
        z.writestr("programs/evil.py", "open('/tmp/pwned', 'w')\n")
        z.writestr("evil.task", "program=evil\n")
    reply = fresh(svc).post("/api/import", files={"file": ("seed.zip", archive.getvalue(), "application/zip")})
    assert reply.status_code == 403
    assert "evil" not in str(client.get("/api/programs").json()["programs"])


def test_another_origin_is_refused_even_with_the_token(web):
    client, svc, driver, server = web
    reply = client.post("/api/estop", headers={"Origin": STRANGER})
    assert reply.status_code == 403 and reply.json()["error"] == "not_allowed"
    assert "http://127.0.0.1:9999" in reply.json()["message"]
    assert client.post("/api/estop", headers={"Origin": "null"}).status_code == 403
    assert not estopped(svc)


def test_a_host_that_is_not_the_servers_is_refused_everywhere(web):
    """DNS rebinding: the attacker's name resolves to 127.0.0.1, the browser then calls it so."""
    client, svc, driver, server = web
    for path in ("/", "/api/robots", "/api/export.zip", "/static/css/app.css"):
        reply = client.get(path, headers={"Host": "evil.example:8080"})
        assert reply.status_code == 400 and reply.json()["error"] == "bad_host", path
        assert "evil.example" in reply.json()["message"]
    assert client.post("/api/estop", headers={"Host": "evil.example"}).status_code == 400
    for own in ("127.0.0.1:8080", "localhost:8080", "[::1]:8080"):
        assert client.get("/api/robots", headers={"Host": own}).status_code == 200


def test_another_sites_page_cannot_read_or_embed_but_may_link_to_the_page(web):
    client, svc, driver, server = web
    cross = {"Sec-Fetch-Site": "same-site", "Sec-Fetch-Mode": "no-cors", "Sec-Fetch-Dest": "image"}
    assert client.get(f"/api/robots/{API_ROBOT}/cameras", headers=cross).status_code == 403
    assert client.get("/api/export.zip", headers={**cross, "Sec-Fetch-Dest": "empty"}).status_code == 403
    link = {"Sec-Fetch-Site": "cross-site", "Sec-Fetch-Mode": "navigate", "Sec-Fetch-Dest": "document"}
    assert client.get("/", headers=link).status_code == 200
    assert client.get("/api/export.zip", headers=link).status_code == 403      # not a page to link to
    own = {"Sec-Fetch-Site": "same-origin", "Sec-Fetch-Mode": "cors", "Sec-Fetch-Dest": "empty"}
    assert client.get("/api/robots", headers=own).status_code == 200


def test_the_served_page_carries_the_token_and_no_cache_keeps_it(web):
    client, svc, driver, server = web
    page = fresh(svc).get("/")
    assert page.headers["cache-control"] == "no-store"
    assert f'<meta name="{guard.META}" content="{svc.web.session}">' in page.text


def test_the_websocket_needs_the_token_and_the_pages_origin(web):
    client, svc, driver, server = web
    url = f"ws://127.0.0.1:8080/ws?session={svc.web.session}"
    with client.websocket_connect(url, headers={"Origin": OWN}) as ws:
        assert ws.receive_json()["type"] == "hello"
    with pytest.raises(WebSocketDisconnect) as refused:
        with client.websocket_connect(url, headers={"Origin": STRANGER}) as ws:
            ws.receive_json()
    assert refused.value.code == guard.WS_REFUSED
    with pytest.raises(WebSocketDisconnect) as stale:
        with client.websocket_connect("ws://127.0.0.1:8080/ws?session=old", headers={"Origin": OWN}) as ws:
            ws.receive_json()
    assert stale.value.code == guard.WS_REFUSED and "reload" in stale.value.reason
    with pytest.raises(WebSocketDisconnect):
        with client.websocket_connect(url.replace("127.0.0.1", "evil.example")) as ws:
            ws.receive_json()


def test_names_added_by_the_user_are_served(tmp_path, monkeypatch):
    import argparse

    from asibot.bus import Bus
    from asibot.testing import memory_bus
    from asibot.web import service
    monkeypatch.setenv(service.HOSTS_ENV, "robot.example, kitchen-pc")
    with memory_bus("guard-hosts") as ep, Bus("web", ep) as bus:
        svc = service.build(bus, argparse.Namespace(host="127.0.0.1", port=8080, lan=False, new_token=False,
                                                    data=tmp_path))
        try:
            client = page_client(svc)
            assert client.get("/api/robots", headers={"Host": "robot.example:8080"}).status_code == 200
            assert client.get("/api/robots", headers={"Host": "kitchen-pc"}).status_code == 200
            assert client.get("/api/robots", headers={"Host": "other.example"}).status_code == 400
        finally:
            svc.close()
