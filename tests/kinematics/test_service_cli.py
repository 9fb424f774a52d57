"""The service's command line: the robot catalog picks the solver, --solver overrides it."""

import argparse

import numpy as np
import pytest

from asibot import robots
from asibot import keys
from asibot.bus import Bus
from asibot.kinematics.service import add_arguments, build
from asibot.kinematics.model import AsibotModel, PinocchioModel


@pytest.fixture
def bus(request):
    with Bus("test", f"mem://{request.node.name}") as b:
        yield b


def parse(*argv):
    p = argparse.ArgumentParser()
    p.add_argument("--robot")
    add_arguments(p)
    return p.parse_args(list(argv))


@pytest.mark.parametrize("argv, model", [
    (["--robot", "asibot-sim"], AsibotModel),
    (["--robot", "asibot-sim", "--solver", "pinocchio"], PinocchioModel),
    (["--robot", "pioneer-sim"], PinocchioModel),
])
def test_the_solver_comes_from_the_catalog_or_the_flag(argv, model, bus):
    server = build(bus, parse(*argv))
    try:
        assert isinstance(server.model, model)
        assert bus.wait_for(keys.cart_rpc(argv[1], "movl"), 1)
    finally:
        server.close()


def test_both_asibot_solvers_agree_through_the_service_model(bus):
    closed = build(bus, parse("--robot", "asibot-sim"))
    generic = build(bus, parse("--robot", "asibot-sim", "--solver", "pinocchio"))
    try:
        spec = robots.get("asibot-sim")
        for q in np.random.default_rng(5).uniform(np.array(spec.lower) / 3, np.array(spec.upper) / 3, (20, 5)):
            assert np.allclose(closed.model.fwd(q), generic.model.fwd(q), atol=1e-9)
    finally:
        closed.close()
        generic.close()


def test_bad_arguments_are_refused_with_a_sentence(bus):
    with pytest.raises(ValueError, match="ASIBOT's closed form"):
        build(bus, parse("--robot", "pioneer-sim", "--solver", "asibot"))
    with pytest.raises(ValueError, match="unknown robot 'moon'"):
        build(bus, parse("--robot", "moon"))
    with pytest.raises(ValueError, match="--robot is required"):
        build(bus, parse())
