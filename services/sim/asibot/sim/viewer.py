"""Optional on-screen viewer: only with --viewer and a DISPLAY; the sim is headless otherwise."""

from __future__ import annotations

import logging
import os
import threading

from asibot.sim.simulation import Simulation

log = logging.getLogger("asibot.sim.viewer")


def available() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def run(sim: Simulation, stop: threading.Event, rate_hz: float = 30.0) -> None:
    """Show the world in MuJoCo's passive viewer until the window closes or stop is set."""
    import mujoco.viewer  # imported here: it needs a display and GLFW

    with mujoco.viewer.launch_passive(sim.model, sim.data) as v:
        while v.is_running() and not stop.wait(1.0 / rate_hz):
            with sim.lock:
                v.sync()
