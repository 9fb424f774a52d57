"""The service's command line: the robot catalog picks the solver, --solver overrides it."""

import argparse

import numpy as np
import pytest

from asibot import robots
from asibot.kinematics.__main__ import add_arguments, build
from asibot.kinematics.model import AsibotModel, PinocchioModel


class RecordingBus:
    """Enough of a Bus to construct the server without a router: records what it declares."""

    def __init__(self):
        self.served = []

    def publisher(self, *a, **k):
        return self

    def put(self, msg):
        pass

    def subscribe(self, *a, **k):
        pass

    def watch(self, *a, **k):
        pass

    def serve(self, key, handler):
        self.served.append(key)

    def announce(self, *a, **k):
        pass


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
def test_the_solver_comes_from_the_catalog_or_the_flag(argv, model):
    bus = RecordingBus()
    server = build(bus, parse(*argv))
    try:
        assert isinstance(server.model, model)
        assert "rb/%s/cart/rpc/movl" % argv[1] in bus.served
    finally:
        server.close()


def test_both_asibot_solvers_agree_through_the_service_model():
    closed = build(RecordingBus(), parse("--robot", "asibot-sim"))
    generic = build(RecordingBus(), parse("--robot", "asibot-sim", "--solver", "pinocchio"))
    try:
        spec = robots.get("asibot-sim")
        for q in np.random.default_rng(5).uniform(np.array(spec.lower) / 3, np.array(spec.upper) / 3, (20, 5)):
            assert np.allclose(closed.model.fwd(q), generic.model.fwd(q), atol=1e-9)
    finally:
        closed.close()
        generic.close()


def test_the_closed_form_refuses_another_arm():
    with pytest.raises(SystemExit, match="ASIBOT's closed form"):
        build(RecordingBus(), parse("--robot", "pioneer-sim", "--solver", "asibot"))
