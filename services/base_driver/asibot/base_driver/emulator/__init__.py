"""Wire-level emulation of the Pioneer P3-AT's ARCOS controller, for tests, benchmarks and
the `emulated` profile (`python -m asibot.base_driver.emulator --listen HOST:PORT ...`).

| module | one idea |
|---|---|
| `robot.py` | the emulated controller: ARCOS bytes in and out, motion, watchdog, SIPs (pure) |
| `gridmap.py` | the world its sonar and bumpers see: a ROS map_server map, or an empty room |
| `server.py` | one emulated robot in real time on a TCP port or a pty, with line faults |
| `control.py` | the fault-injection line protocol of the standalone emulator |
| `cli.py`, `__main__.py` | its command line |

The driver never imports this package; the emulator imports the driver's protocol code
(codec, SIP layout, parameters) so both ends agree by construction.
"""

from asibot.base_driver.emulator.cli import main
from asibot.base_driver.emulator.control import ControlServer
from asibot.base_driver.emulator.robot import EmulatedP3at, Pose
from asibot.base_driver.emulator.server import ArcosEmulator

__all__ = ["ArcosEmulator", "ControlServer", "EmulatedP3at", "Pose", "main"]
