"""A whole service: tells the user when the Pioneer's battery runs low.

Run it beside the stack: `python docs/example_service/battery_monitor.py --robot pioneer-sim`.
Its test, on the in-memory bus, is tests/docs/test_example_service.py.
"""

import argparse
import sys

from asibot import keys, runtime
from asibot.bus import Bus
from asibot.messages import Battery, Event

NAME = "battery_monitor"


class BatteryMonitor(runtime.Service):
    """Warns once when the voltage falls under `low`, and again only after a recharge."""

    def __init__(self, bus: Bus, robot: str, low: float) -> None:
        self.low, self.volts, self.warned = low, None, False
        self._events = bus.publisher(keys.events(robot), Event)
        bus.subscribe(keys.base_battery(robot), Battery, self.on_battery)

    def on_battery(self, msg: Battery) -> None:
        self.volts = msg.volts
        if msg.volts < self.low and not self.warned:
            self._events.put(Event(level="warning", code="battery_low",
                                   text=f"Battery low ({msg.volts:.1f} V): please charge the robot."))
        self.warned = msg.volts < self.low + 0.5  # half a volt of hysteresis: no chatter

    def health(self) -> dict:
        return {"volts": self.volts, "warned": self.warned}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--low-volts", type=float, default=11.5, help="warning threshold (V)")


def build(bus: Bus, args: argparse.Namespace) -> BatteryMonitor:
    if not args.robot:
        raise ValueError("say which robot to watch: --robot pioneer-sim")
    if not 0 < args.low_volts < 60:
        raise ValueError(f"--low-volts must be between 0 and 60 V, not {args.low_volts}")
    return BatteryMonitor(bus, args.robot, args.low_volts)


if __name__ == "__main__":
    raise SystemExit(runtime.run(sys.modules[__name__]))
