"""An emulated Katana 300 controller (`controller`) served on a pty (`line`)."""

from asibot.katana_driver.emulator.controller import KatanaEmulator
from asibot.katana_driver.emulator.line import EmulatedLine

__all__ = ["KatanaEmulator", "EmulatedLine"]
