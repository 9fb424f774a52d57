"""The example service of docs/ works, tested on the in-memory bus as a service's unit test is."""

import argparse
import importlib.util
from pathlib import Path

import pytest

from asibot import keys
from asibot.bus import Bus
from asibot.messages import Battery, Event
from asibot.testing import wait_until

PATH = Path(__file__).parents[2] / "docs" / "example_service" / "battery_monitor.py"


@pytest.fixture(scope="module")
def example():
    spec = importlib.util.spec_from_file_location("battery_monitor", PATH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def args(example, *argv):
    p = argparse.ArgumentParser()
    p.add_argument("--robot")
    example.add_arguments(p)
    return p.parse_args(list(argv))


def test_it_warns_once_when_the_battery_runs_low(example, request):
    endpoint = f"mem://{request.node.name}"
    with Bus("monitor", endpoint) as bus, Bus("robot", endpoint) as robot:
        monitor = example.build(bus, args(example, "--robot", "p1", "--low-volts", "11.5"))
        events = []
        robot.subscribe(keys.events("p1"), Event, events.append)
        battery = robot.publisher(keys.base_battery("p1"), Battery)
        for volts in (12.4, 11.4, 11.3, 11.6, 11.2, 12.5, 11.0):
            battery.put(Battery(volts=volts))
        wait_until(lambda: monitor.health()["volts"] == 11.0, 2)
        wait_until(lambda: len(events) == 2, 2)
        assert [e.code for e in events] == ["battery_low", "battery_low"]
        assert "11.4 V" in events[0].text and "11.0 V" in events[1].text


def test_bad_arguments_are_a_sentence(example, request):
    with Bus("monitor", f"mem://{request.node.name}") as bus:
        with pytest.raises(ValueError, match="--robot pioneer-sim"):
            example.build(bus, args(example))
        with pytest.raises(ValueError, match="between 0 and 60"):
            example.build(bus, args(example, "--robot", "p1", "--low-volts", "-3"))
