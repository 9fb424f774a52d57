"""Unit conversions, the YAML configuration and bus names."""

from __future__ import annotations

import copy
import math

import pytest
import yaml

from asibot import robots
from asibot.arm_driver import canbus, config
from asibot.arm_driver.units import Units


def test_asibot_counts_match_the_reference_arithmetic():
    u = Units(160, 4096, 0.001)
    assert u.counts_per_rad * math.pi / 180 == pytest.approx(1820.44, abs=0.01)   # docs/canopen.md "Units"
    assert u.to_counts(2 * math.pi) == 655360
    assert u.velocity_iu(math.radians(25)) / 65536 == pytest.approx(45.51, abs=0.01)
    assert u.to_rad(u.to_counts(0.123456)) == pytest.approx(0.123456, abs=1e-5)
    assert u.from_velocity_iu(u.velocity_iu(0.3)) == pytest.approx(0.3, rel=1e-4)


def test_reversed_joint_counts_the_other_way():
    assert Units(160, 4096, 0.001, reverse=True).to_counts(1.0) == -Units().to_counts(1.0)


def test_config_joins_yaml_and_catalog(cfg):
    spec = robots.get("asibot")
    assert cfg.names == spec.joint_names and cfg.nodes == [1, 2, 3, 4, 5]
    assert [j.upper for j in cfg.joints] == spec.upper
    assert cfg.joints[0].max_velocity == pytest.approx(math.radians(25))
    assert cfg.bitrate == 1_000_000 and cfg.control_rate_hz == 100
    assert cfg.heartbeat_timeout == pytest.approx(0.15)
    assert cfg.pdos["tpdo3"].transmission == 1


def _raw():
    with open(config.path_for("asibot"), encoding="utf-8") as fh:
        return yaml.safe_load(fh)


@pytest.mark.parametrize("change, words", [
    (lambda r: r.update(robot="pioneer"), "'robot'"),
    (lambda r: r["joints"].pop(), "'joints' must list"),
    (lambda r: r["joints"][1].update(node=1), "unique id"),
    (lambda r: r["joints"][1].update(node=200), "unique id"),
    (lambda r: r.update(control_rate_hz=-5), "control_rate_hz"),
    (lambda r: r.update(control_rate_hz=5000), "above 1000"),
    (lambda r: r["pdo"].pop("rpdo3"), "pdo.rpdo3 is required"),
    (lambda r: r["pdo"]["tpdo3"]["map"].append([0x6064, 0, 32]), "do not fit"),
    (lambda r: r["pdo"]["tpdo3"]["map"].__setitem__(0, [0x6063, 0, 16]), "is 32 bits"),
    (lambda r: r.pop("gear_ratio"), "missing 'gear_ratio'"),
])
def test_bad_config_is_refused_with_the_field_named(change, words):
    raw = copy.deepcopy(_raw())
    change(raw)
    with pytest.raises(config.ConfigError, match=words):
        config.parse(raw, robots.get("asibot"))


def test_unknown_robot_config():
    with pytest.raises(config.ConfigError, match="no CAN configuration"):
        config.load("pioneer")


@pytest.mark.parametrize("name, interface, channel, options", [
    ("socketcan:can0", "socketcan", "can0", {}),
    ("pcan:PCAN_USBBUS1", "pcan", "PCAN_USBBUS1", {}),
    ("virtual:asibot", "virtual", "asibot", {}),
    ("slcan:/dev/ttyACM0@115200", "slcan", "/dev/ttyACM0", {"tty_baudrate": 115200}),
    ("socketcan:can0,fd=false,ignore_rx_error_frames=false", "socketcan", "can0",
     {"fd": False, "ignore_rx_error_frames": False}),
    ("emulated", "emulated", "", {}),
])
def test_bus_names_like_python_can(name, interface, channel, options):
    spec = canbus.parse(name)
    assert (spec.interface, spec.channel, spec.options) == (interface, channel, options)


@pytest.mark.parametrize("name, words", [
    ("", "name the CAN bus"), ("can0", "needs a channel"), ("nosuchcan:0", "unknown python-can interface"),
    ("socketcan:can0,fd", "key=value"),
])
def test_bad_bus_names(name, words):
    with pytest.raises(ValueError, match=words):
        canbus.parse(name)


def test_opening_a_missing_adapter_says_what_to_check():
    with pytest.raises(ConnectionError, match="cannot open CAN bus"):
        canbus.open_bus(canbus.parse("socketcan:asibot-no-such-can"), 1_000_000)
