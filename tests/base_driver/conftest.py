"""Helpers: an in-memory line to an emulated robot with a fake clock, and a TCP emulator."""

from __future__ import annotations

import pytest

from asibot.base_driver.emulator import ArcosEmulator
from asibot.base_driver.emulator.robot import EmulatedP3at


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class RobotLink:
    """A Link straight into an EmulatedP3at: every read advances the fake clock by `tick`."""

    def __init__(self, robot: EmulatedP3at | None = None, clock: FakeClock | None = None, tick: float = 0.02):
        self.robot = robot or EmulatedP3at()
        self.clock = clock or FakeClock()
        self.tick = tick
        self.pending = bytearray()
        self.written: list[bytes] = []
        self.closed = False

    def write(self, data: bytes) -> int:
        self.written.append(bytes(data))
        self.pending += self.robot.receive(bytes(data), self.clock())
        return len(data)

    def read(self, size: int = 1) -> bytes:
        self.clock.t += self.tick
        self.pending += self.robot.step(self.clock())
        out = bytes(self.pending[:size])
        del self.pending[:size]
        return out

    @property
    def in_waiting(self) -> int:
        return len(self.pending)

    def reset_input_buffer(self) -> None:
        self.pending.clear()

    def close(self) -> None:
        self.closed = True


@pytest.fixture
def emulator():
    with ArcosEmulator() as emu:
        yield emu
