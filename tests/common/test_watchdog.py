"""asibot.safety.watchdog: a stream that stops arriving stops the robot, once per silence."""

import pytest

from asibot.messages import COMMAND_WATCHDOG_S
from asibot.safety.watchdog import Watchdog


def test_it_fires_once_per_silence_while_something_moves():
    dog = Watchdog()
    assert dog.period == COMMAND_WATCHDOG_S
    dog.feed(10.0)
    assert not dog.silent(10.2) and not dog.fires(10.2)
    assert dog.silent(10.21)
    assert not dog.fires(10.21, moving=False)        # nothing moves: nothing to stop
    assert dog.fires(10.21) and not dog.fires(10.5)  # once
    dog.feed(11.0)                                    # a new stream: ready again
    assert not dog.fires(11.1) and dog.fires(11.3)


def test_it_says_its_period_and_refuses_a_bad_one():
    assert Watchdog(0.5).says("cmd_vel", "the base stopped") == "No cmd_vel for 500 ms: the base stopped."
    for bad in (0, -1, float("nan")):
        with pytest.raises(ValueError, match="positive number of seconds"):
            Watchdog(bad)
