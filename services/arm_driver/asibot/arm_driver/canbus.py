"""Open a CAN bus by name, the way python-can names interfaces: `socketcan:can0`,
`pcan:PCAN_USBBUS1`, `kvaser:0`, `virtual:asibot`, `slcan:/dev/ttyACM0@115200`...

`emulated` is this driver's own: it starts the five-drive emulator (the `emulator` package) in
this process on a private virtual channel, so `asibot up --profile emulated` needs no
hardware, no kernel module and no multicast.
"""

from __future__ import annotations

import uuid
from dataclasses import dataclass, field

import can

EMULATED = "emulated"


@dataclass(frozen=True)
class BusSpec:
    interface: str
    channel: str
    options: dict = field(default_factory=dict)

    @property
    def emulated(self) -> bool:
        return self.interface == EMULATED


def parse(spec: str) -> BusSpec:
    """'interface:channel[,key=value...]' -> BusSpec; ValueError says what a valid name looks like."""
    if not isinstance(spec, str) or not spec.strip():
        raise ValueError("name the CAN bus like python-can: --can socketcan:can0, --can pcan:PCAN_USBBUS1, "
                         "--can virtual:asibot or --can emulated")
    text = spec.strip()
    if text == EMULATED or text.startswith(EMULATED + ":"):
        return BusSpec(EMULATED, text.partition(":")[2] or "")
    interface, sep, rest = text.partition(":")
    if not sep or not rest:
        raise ValueError(f"CAN bus {spec!r} needs a channel: write interface:channel, e.g. socketcan:can0")
    if interface not in can.interfaces.VALID_INTERFACES:
        raise ValueError(f"unknown python-can interface {interface!r}; use one of "
                         f"{', '.join(sorted(can.interfaces.VALID_INTERFACES))} or 'emulated'")
    channel, *opts = rest.split(",")
    options = {}
    for opt in opts:
        key, eq, value = opt.partition("=")
        if not eq or not key:
            raise ValueError(f"CAN bus option {opt!r} must be key=value, e.g. socketcan:can0,fd=false")
        options[key] = _value(value)
    if interface == "slcan" and "@" in channel:
        channel, _, baud = channel.partition("@")
        options.setdefault("tty_baudrate", int(baud))
    return BusSpec(interface, channel, options)


def _value(text: str) -> object:
    low = text.lower()
    if low in ("true", "false"):
        return low == "true"
    try:
        return int(text, 0)
    except ValueError:
        return text


def open_bus(spec: BusSpec, bitrate: int) -> can.BusABC:
    """A python-can bus for a real or virtual interface (not `emulated`: see emulator.start_private)."""
    if spec.emulated:
        raise ValueError("the emulated bus is opened by asibot.arm_driver.emulator.start_private()")
    kwargs = dict(spec.options)
    if spec.interface != "virtual":
        kwargs.setdefault("bitrate", bitrate)
    try:
        return can.Bus(interface=spec.interface, channel=spec.channel, **kwargs)
    except (can.CanError, OSError, ImportError, ValueError) as exc:
        raise ConnectionError(f"cannot open CAN bus {spec.interface}:{spec.channel}: {exc}. Check the adapter is "
                              "plugged in and up (e.g. `ip link set can0 up type can bitrate 1000000`).") from exc


def private_channel() -> str:
    """A virtual channel name nobody else uses (python-can virtual buses meet by channel name)."""
    return f"asibot-emulated-{uuid.uuid4().hex[:8]}"
