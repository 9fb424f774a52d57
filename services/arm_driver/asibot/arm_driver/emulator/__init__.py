"""Wire-level emulation of the ASIBOT's CAN side, for tests, benchmarks and `--can emulated`.

| module | one idea |
|---|---|
| `drive.py` | one CiA 402 drive as the iPOS behaves: frames in, frames out (pure) |
| `encoder.py` | one absolute encoder board answering polls (pure) |
| `network.py` | drives and encoder boards on a python-can bus, with fault injection |

The real driver never imports this package, except `asibot.arm_driver.service` for
`--can emulated`; the emulator imports the driver's protocol tables (objects, PDOs, CiA 402,
EMCY, CUI bytes) so both ends agree by construction.
"""

from asibot.arm_driver.emulator.drive import EmulatedDrive
from asibot.arm_driver.emulator.network import (CAN_ERR_BUSOFF, CAN_ERR_RESTARTED, DriveEmulator,
                                                encoders_of, start_private)

__all__ = ["CAN_ERR_BUSOFF", "CAN_ERR_RESTARTED", "DriveEmulator", "EmulatedDrive", "encoders_of", "start_private"]
