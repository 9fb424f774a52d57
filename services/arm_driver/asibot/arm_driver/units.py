"""Joint units (rad) <-> drive units (encoder counts), as TechnosoftIposBase converts them.

counts = deg x gear ratio x encoder pulses / 360, so the ASIBOT's gear 160 and 4096 pulses give
655 360 counts per joint turn (1820.44 counts/deg). Velocity and acceleration go to the drive in
counts per sampling period (1 ms) as 16.16 fixed point. Source: docs/canopen.md, "Units".
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Units:
    """Conversions for one joint."""

    gear_ratio: float = 160.0
    encoder_pulses: int = 4096
    sampling_period: float = 0.001
    reverse: bool = False

    @property
    def counts_per_rad(self) -> float:
        sign = -1.0 if self.reverse else 1.0
        return sign * self.gear_ratio * self.encoder_pulses / (2.0 * math.pi)

    def to_counts(self, rad: float) -> int:
        return int(round(rad * self.counts_per_rad))

    def to_rad(self, counts: float) -> float:
        return counts / self.counts_per_rad

    def velocity_iu(self, rad_s: float) -> int:
        """Velocity as the drive wants it: counts per sample, 16.16 fixed point (0x6081, 0x60FF)."""
        return fixed_16_16(abs(rad_s * self.counts_per_rad) * self.sampling_period)

    def acceleration_iu(self, rad_s2: float) -> int:
        """Acceleration: counts per sample squared, 16.16 fixed point (0x6083)."""
        return fixed_16_16(abs(rad_s2 * self.counts_per_rad) * self.sampling_period ** 2)

    def from_velocity_iu(self, iu: int) -> float:
        """rad/s from a 16.16 counts-per-sample value."""
        return iu / 65536.0 / self.sampling_period / abs(self.counts_per_rad)

    def from_acceleration_iu(self, iu: int) -> float:
        return iu / 65536.0 / self.sampling_period ** 2 / abs(self.counts_per_rad)


def fixed_16_16(value: float) -> int:
    """Unsigned 16.16 fixed point (CanUtils::encodeFixedPoint), saturated to 32 bits."""
    return max(0, min(0xFFFFFFFF, int(round(value * 65536.0))))
