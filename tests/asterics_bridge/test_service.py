"""The service's shape: arguments, build on the in-memory bus, health, refusals as sentences."""

import pytest

from asibot import runtime
from asibot.bus import Bus

from asibot.asterics_bridge import service

from .harness import Client, command


def args(*argv):
    return runtime.parser(service.NAME, service.add_arguments).parse_args(list(argv))


def test_build_serves_and_reports_health(memory_bus):
    bus = Bus("asterics_bridge", memory_bus)
    svc = service.build(bus, args("--robot", "pioneer-sim", "--port", "0", "--http-port", "0", "--longest", "5"))
    try:
        c = Client(svc.servers.tcp_port)
        assert command(c, "forward").startswith("No nav service answers for robot 'pioneer-sim'")
        c.close()
        h = svc.health()
        assert h["commands"] == 1 and h["connections"] == 1 and h["tcp_port"] == svc.servers.tcp_port
    finally:
        svc.close()
        bus.close()


@pytest.mark.parametrize("argv, words", [
    (("--port", "70000"), "--port must be 0 to 65535"),
    (("--longest", "0"), "--longest must be between 0.5 and 3600 s"),
    (("--host", "0.0.0.0"), "add --token"),
    (("--events", "1=fly"), "unknown command 'fly'"),
    (("--menu", "next"), "it is what walks the menu"),
    (("--token", "x", "--no-token"), "contradict each other"),
    (("--allow-origin", "grid.asterics.eu"), "is not an origin: write it as scheme://name"),
    (("--max-clients", "10", "--max-clients-per-address", "11"), "--max-clients-per-address must be 1 to"),
    (("--robot", "a/b"), "--robot:"),
])
def test_bad_arguments_are_sentences(memory_bus, argv, words):
    bus = Bus("asterics_bridge", memory_bus)
    try:
        with pytest.raises(ValueError, match=words):
            service.build(bus, args("--port", "0", "--http-port", "-1", *argv))
    finally:
        bus.close()


def test_a_port_in_use_is_a_sentence(memory_bus):
    bus = Bus("asterics_bridge", memory_bus)
    first = service.build(bus, args("--port", "0", "--http-port", "-1"))
    try:
        with pytest.raises(ValueError, match="is another bridge running"):
            service.build(bus, args("--port", str(first.servers.tcp_port), "--http-port", "-1"))
    finally:
        first.close()
        bus.close()


def test_the_http_token_is_made_once_kept_private_and_carried_by_the_user_s_grids(memory_bus, tmp_path, monkeypatch,
                                                                                  capsys):
    import json
    import stat

    from asibot.asterics_bridge import http_token
    from .test_http import request

    monkeypatch.setenv("ASIBOT_DATA", str(tmp_path))
    bus = Bus("asterics_bridge", memory_bus)
    svc = service.build(bus, args("--port", "0", "--http-port", "0"))
    try:
        folder = tmp_path / "asterics"
        token = (folder / "token").read_text()
        assert token in capsys.readouterr().out          # printed once, when made
        assert stat.S_IMODE(folder.stat().st_mode) == 0o700
        assert stat.S_IMODE((folder / "token").stat().st_mode) == 0o600
        grids = folder / http_token.GRIDS_NAME
        assert stat.S_IMODE(grids.stat().st_mode) == 0o600
        actions = [a for g in json.loads(grids.read_text())["grids"] for e in g["gridElements"]
                   for a in e["actions"] + ([e["liveAction"]] if "liveAction" in e else [])
                   if a["modelName"] == "GridActionHTTP"]
        assert actions and all(a["authPw"] == token for a in actions)
        assert all(a["restUrl"].startswith(f"http://127.0.0.1:{svc.servers.http_port}/") for a in actions)
        assert request(svc, "POST", "/command", "status", auth=False)[0] == 401
        assert request(svc, "POST", "/command", "status", {"Authorization": f"Bearer {token}"})[0] == 200
    finally:
        svc.close()
    again = service.build(bus, args("--port", "0", "--http-port", "0"))
    try:
        assert again.servers.http_token == token and token not in capsys.readouterr().out
    finally:
        again.close()
        bus.close()


def test_no_token_and_the_allowed_origins(memory_bus, monkeypatch):
    monkeypatch.delenv(service.ORIGINS_ENV, raising=False)
    bus = Bus("asterics_bridge", memory_bus)
    try:
        built = service.build(bus, args("--port", "0", "--http-port", "0", "--no-token"))
        assert built.servers.http_token is None
        assert built.servers.callers.origins == {"https://grid.asterics.eu"}      # the default
        built.close()
        built = service.build(bus, args("--port", "0", "--http-port", "-1", "--allow-origin",
                                        "http://127.0.0.1:8000,https://Grid.Example.org/", "--allow-origin",
                                        "http://localhost:9000", "--allow-host", "robot.local"))
        assert built.servers.callers.origins == {"http://127.0.0.1:8000", "https://grid.example.org",
                                                 "http://localhost:9000"}
        assert "robot.local" in built.servers.callers.hosts
        built.close()
        monkeypatch.setenv(service.ORIGINS_ENV, "none")
        built = service.build(bus, args("--port", "0", "--http-port", "-1"))
        assert built.servers.callers.origins == set()
        built.close()
    finally:
        bus.close()
