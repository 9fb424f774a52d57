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
