"""The handheld pointer: a phone's tilt or a gamepad moves the arm tip, as the seed's Wii Remote.

The page sends what the device reports, as it is (`DeviceReading`: a phone's pitch and roll in
degrees, or a gamepad's stick in -1..1, and its buttons), about every `beat_ms`; this module
turns it into one request of the kinematics `pointer` verb (asibot.kinematics.pointer), so the
mapping lives here once and the page holds no unit or gain. The seed's Wii space:

- the tool's pitch follows the device's pitch: a phone held flat points the tool ahead
  (rot(y') 90 deg), its top edge raised points it up; a gamepad's stick pushed up or down
  leads the tool's pitch by up to `stick_lead` degrees, so it turns while the stick is held;
- the arm turns about its base with the device's roll (a phone tipped left turns it to the
  left), at a rate that grows past a dead band, up to `max_yaw`;
- forward moves the tip along the tool, backward away; with neither (or both) the tip stays
  where it is and only the tool turns with the device. Nothing moves without the dead-man (held
  or, as the seed's users preferred, toggled on the page).

A reading with a value that is not a finite number in its range is refused with a sentence,
and nothing moves. The page stops the arm itself when the device stops reporting, the page
loses focus or motion control is switched off; the controller's 200 ms watchdog stops it if
even that message is lost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from asibot.errors import RpcError, quote

SOURCES = ("phone", "gamepad")


@dataclass(frozen=True)
class PointerSettings:
    """The mapping's gains; `page()` is what the page needs (timing only)."""

    deadband: float = 8.0          # deg of roll (phone) before the arm turns
    yaw_gain: float = 1.5          # deg/s of base turn per deg of roll past the dead band
    max_yaw: float = 45.0          # deg/s
    pitch_limit: float = 90.0      # deg of device pitch that counts: a phone on edge points the tool straight up or down
    stick_deadband: float = 0.15   # of a gamepad stick's travel
    stick_lead: float = 12.0       # deg the tool's pitch target leads it at full stick
    speed: float = 0.05            # m/s along the tool (the seed's trajectoryRefSpeed)
    beat_ms: int = 60              # the page sends a reading this often while the dead-man is on
    silence_ms: int = 400          # no device report for this long: the page stops the arm

    def page(self) -> dict[str, Any]:
        return {"beat_ms": self.beat_ms, "silence_ms": self.silence_ms, "sources": list(SOURCES)}


@dataclass(frozen=True)
class DeviceReading:
    """One report of the device, as the page saw it."""

    source: str                    # "phone" | "gamepad"
    pitch: float                   # phone: DeviceOrientation beta, deg; gamepad: stick up (+1) .. down (-1)
    roll: float                    # phone: gamma, deg (right positive); gamepad: stick right (+1) .. left (-1)
    deadman: bool
    forward: bool = False
    backward: bool = False

    @classmethod
    def from_message(cls, msg: dict[str, Any]) -> "DeviceReading":
        """From the page's message; RpcError bad_request naming the field that is wrong."""
        source = msg.get("source")
        if source not in SOURCES:
            raise RpcError("bad_request", f"The pointer's source must be one of {', '.join(SOURCES)}; got {source!r}.")
        limit = (180.0, 90.0) if source == "phone" else (1.0, 1.0)
        values = {}
        for name, top in zip(("pitch", "roll"), limit):
            v = msg.get(name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or abs(v) > top:
                raise RpcError("bad_request", f"The {source}'s {name} must be a number from {-top:g} to {top:g}; "
                                              f"got {quote(v, 40)}. Nothing moved.")
            values[name] = float(v)
        flags = {}
        for name in ("deadman", "forward", "backward"):
            v = msg.get(name, False)
            if not isinstance(v, bool):
                raise RpcError("bad_request", f"The pointer's {name} must be true or false; got {quote(v, 40)}.")
            flags[name] = v
        return cls(source, values["pitch"], values["roll"], **flags)


def _past(value: float, band: float) -> float:
    """`value` with the dead band taken off (0 inside it), keeping its sign."""
    return math.copysign(max(0.0, abs(value) - band), value)


class PointerMapping:
    """A device reading to a `pointer` request (None: nothing may move)."""

    def __init__(self, settings: PointerSettings = PointerSettings()) -> None:
        self.settings = settings

    def request(self, reading: DeviceReading, tool_pitch: float | None) -> dict[str, Any] | None:
        """`tool_pitch`: the tool's rot(y') now (deg), which a gamepad's stick leads."""
        s = self.settings
        if not reading.deadman:
            return None
        direction = "hold" if reading.forward == reading.backward else "forward" if reading.forward else "backward"
        if reading.source == "phone":
            yaw = -s.yaw_gain * _past(reading.roll, s.deadband)      # tipped left (negative roll): counter-clockwise
            pitch: float | None = 90.0 - max(-s.pitch_limit, min(s.pitch_limit, reading.pitch))
        else:
            stick_x = _past(reading.roll, s.stick_deadband) / (1.0 - s.stick_deadband)
            stick_y = _past(reading.pitch, s.stick_deadband) / (1.0 - s.stick_deadband)
            yaw = -s.max_yaw * stick_x
            pitch = None if stick_y == 0.0 or tool_pitch is None else tool_pitch - s.stick_lead * stick_y
        yaw = max(-s.max_yaw, min(s.max_yaw, yaw))
        req: dict[str, Any] = {"deadman": True, "direction": direction, "yaw": yaw, "speed": s.speed}
        if pitch is not None:
            req["pitch"] = max(-180.0, min(180.0, pitch))
        return req
