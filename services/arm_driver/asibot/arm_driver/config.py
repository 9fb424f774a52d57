"""Per-robot CAN configuration (robots/<robot>.yaml) joined with the robot catalog.

The catalog (asibot.robots) owns joint names, limits and max speeds, so a limit changes in one
place; the YAML owns what only the CAN side needs (node ids, gearing, PDO mappings, timing).
"""

from __future__ import annotations
from importlib import resources

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from asibot import robots
from asibot.arm_driver import objects
from asibot.arm_driver.pdo import Entry, Layout
from asibot.arm_driver.units import Units

ROBOTS_DIR = Path(str(resources.files("asibot.arm_driver") / "robots"))
REQUIRED_PDOS = ("tpdo1", "tpdo3", "rpdo1", "rpdo3")


@dataclass(frozen=True)
class AbsoluteEncoder:
    """The joint's absolute encoder board (asibot.arm_driver.cui) and its sign."""
    can_id: int
    reverse: bool = False


@dataclass(frozen=True)
class Joint:
    name: str
    node: int
    lower: float          # rad
    upper: float          # rad
    max_velocity: float   # rad/s
    units: Units
    absolute: AbsoluteEncoder | None = None


@dataclass(frozen=True)
class ArmConfig:
    robot: str
    bitrate: int
    control_rate_hz: float
    heartbeat_ms: int
    heartbeat_timeout_periods: float
    sdo_timeout_s: float
    state_timeout_s: float
    profile_velocity: float       # rad/s
    profile_acceleration: float   # rad/s^2
    joints: list[Joint]
    pdos: dict[str, Layout] = field(default_factory=dict)
    # The master's own node on the bus (ours): it produces a heartbeat on 0x700 + master_node,
    # which every drive consumes (0x1016) and acts on by 0x6007 when it stops.
    master_node: int = 127
    master_heartbeat_ms: int = 100
    drive_consumer_ms: int = 300
    connection_loss: str = "quick_stop"

    @property
    def names(self) -> list[str]:
        return [j.name for j in self.joints]

    @property
    def nodes(self) -> list[int]:
        return [j.node for j in self.joints]

    @property
    def period(self) -> float:
        return 1.0 / self.control_rate_hz

    @property
    def heartbeat_timeout(self) -> float:
        return self.heartbeat_ms / 1000.0 * self.heartbeat_timeout_periods


class ConfigError(ValueError):
    """The YAML is wrong; the message says which field and what to write instead."""


def path_for(robot_id: str) -> Path:
    return ROBOTS_DIR / f"{robot_id}.yaml"


def load(robot_id: str, path: str | Path | None = None) -> ArmConfig:
    """Read robots/<robot_id>.yaml (or `path`) and join it with the catalog entry of robot_id."""
    p = Path(path) if path else path_for(robot_id)
    if not p.is_file():
        known = ", ".join(sorted(f.stem for f in ROBOTS_DIR.glob("*.yaml")))
        raise ConfigError(f"no CAN configuration {p}; write one like robots/asibot.yaml (known: {known})")
    with open(p, encoding="utf-8") as fh:
        raw = yaml.safe_load(fh)
    try:
        spec = robots.get(robot_id)
    except KeyError as exc:
        raise ConfigError(str(exc.args[0])) from None
    return parse(raw, spec, source=str(p))


def _number(raw: dict, key: str, source: str, *, positive: bool = True) -> float:
    if key not in raw:
        raise ConfigError(f"{source}: missing '{key}'")
    v = raw[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (positive and v <= 0):
        raise ConfigError(f"{source}: '{key}' must be a {'positive ' if positive else ''}number, got {v!r}")
    return float(v)


def _layout(name: str, raw: Any, source: str) -> Layout:
    if not isinstance(raw, dict) or not isinstance(raw.get("map"), list):
        raise ConfigError(f"{source}: pdo.{name} needs a 'map' list of [index, subindex, bits]")
    try:
        entries = tuple(Entry(int(i), int(s), int(b)) for i, s, b in raw["map"])
        return Layout(kind=name[:4], number=int(name[4:]), entries=entries,
                      transmission=int(raw.get("transmission", 255)),
                      inhibit_ms=raw.get("inhibit_ms"), event_timer_ms=raw.get("event_timer_ms"))
    except (ValueError, TypeError, KeyError) as exc:
        raise ConfigError(f"{source}: pdo.{name}: {exc}") from None


def _absolute(joint: dict, source: str) -> AbsoluteEncoder | None:
    raw = joint.get("absolute")
    if raw is None:
        return None
    can_id = raw.get("can_id") if isinstance(raw, dict) else None
    # The board answers on id + 0x180, which must stay a standard 11-bit identifier.
    if not isinstance(can_id, int) or isinstance(can_id, bool) or not 1 <= can_id <= 0x7FF - 0x180:
        raise ConfigError(f"{source}: joint {joint['name']}: absolute needs a can_id 1..{0x7FF - 0x180}, "
                          f"like {{can_id: 102, reverse: false}}; got {raw!r}")
    return AbsoluteEncoder(can_id, bool(raw.get("reverse", False)))


def parse(raw: Any, spec: robots.RobotSpec, source: str = "config") -> ArmConfig:
    """Validate a loaded YAML document against the catalog spec."""
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: expected a mapping at the top level")
    if raw.get("robot") != spec.robot_id:
        raise ConfigError(f"{source}: 'robot' is {raw.get('robot')!r}, expected {spec.robot_id!r}")
    gear = _number(raw, "gear_ratio", source)
    pulses = int(_number(raw, "encoder_pulses", source))
    sampling = _number(raw, "sampling_period_s", source)
    joints_raw = raw.get("joints")
    if not isinstance(joints_raw, list) or [j.get("name") for j in joints_raw if isinstance(j, dict)] != spec.joint_names:
        raise ConfigError(f"{source}: 'joints' must list {spec.joint_names} in this order, "
                          "each as {name, node, reverse}")
    joints, seen = [], set()
    for i, j in enumerate(joints_raw):
        node = j.get("node")
        if not isinstance(node, int) or not 1 <= node <= 127 or node in seen:
            raise ConfigError(f"{source}: joint {j['name']}: node must be a unique id 1..127, got {node!r}")
        seen.add(node)
        joints.append(Joint(
            name=j["name"], node=node, lower=spec.lower[i], upper=spec.upper[i],
            max_velocity=spec.max_velocity[i],
            units=Units(gear, pulses, sampling, bool(j.get("reverse", False))),
            absolute=_absolute(j, source)))
    ids = [j.absolute.can_id for j in joints if j.absolute] + [j.node for j in joints]
    if len(ids) != len(set(ids)):
        raise ConfigError(f"{source}: absolute encoder ids must differ from each other and from the drives' nodes")
    pdos_raw = raw.get("pdo") or {}
    if not isinstance(pdos_raw, dict):
        raise ConfigError(f"{source}: 'pdo' must be a mapping of tpdoN/rpdoN")
    pdos = {name: _layout(name, v, source) for name, v in pdos_raw.items()}
    for name in REQUIRED_PDOS:
        if name not in pdos:
            raise ConfigError(f"{source}: pdo.{name} is required")
    rate = _number(raw, "control_rate_hz", source)
    if rate > 1000:
        raise ConfigError(f"{source}: control_rate_hz {rate} is above 1000; a SYNC period under 1 ms "
                          "cannot carry 5 drives at 1 Mbit/s")
    hb = int(_number(raw, "heartbeat_ms", source))
    master = _master(raw, joints, source)
    return ArmConfig(
        robot=spec.robot_id,
        bitrate=int(_number(raw, "bitrate", source)),
        control_rate_hz=rate,
        heartbeat_ms=hb,
        heartbeat_timeout_periods=_number(raw, "heartbeat_timeout_periods", source),
        sdo_timeout_s=_number(raw, "sdo_timeout_s", source),
        state_timeout_s=_number(raw, "state_timeout_s", source),
        profile_velocity=math.radians(_number(raw, "profile_velocity_deg_s", source)),
        profile_acceleration=math.radians(_number(raw, "profile_acceleration_deg_s2", source)),
        joints=joints, pdos=pdos, **master)


def _master(raw: dict, joints: list[Joint], source: str) -> dict[str, Any]:
    """The master's heartbeat and what the drives do when it stops (optional keys; defaults ours)."""
    node = raw.get("master_node", 127)
    if isinstance(node, bool) or not isinstance(node, int) or not 1 <= node <= 127:
        raise ConfigError(f"{source}: master_node must be a CANopen node id 1..127, got {node!r}")
    if node in [j.node for j in joints]:
        raise ConfigError(f"{source}: master_node {node} is also a drive's node; pick a free id (127 is ours)")
    # The heartbeat COB-ID must not be a frame an absolute encoder board sends or listens on.
    board_ids = {j.absolute.can_id + off for j in joints if j.absolute for off in (0, 0x80, 0x100, 0x180)}
    if 0x700 + node in board_ids:
        raise ConfigError(f"{source}: master_node {node}: its heartbeat COB-ID 0x{0x700 + node:03X} is used by "
                          "an absolute encoder board")
    producer = int(_number(raw, "master_heartbeat_ms", source)) if "master_heartbeat_ms" in raw else 100
    consumer = int(_number(raw, "drive_consumer_ms", source)) if "drive_consumer_ms" in raw else 3 * producer
    if not producer < consumer <= 0xFFFF:
        raise ConfigError(f"{source}: drive_consumer_ms ({consumer}) must exceed master_heartbeat_ms ({producer}) "
                          "and fit 16 bits: a drive that waits less than one heartbeat period stops on time; "
                          "3 periods is ours")
    loss = raw.get("connection_loss", "quick_stop")
    if loss not in objects.CONNECTION_LOSS:
        raise ConfigError(f"{source}: connection_loss must be one of {', '.join(objects.CONNECTION_LOSS)} "
                          f"(0x6007), got {loss!r}")
    return {"master_node": node, "master_heartbeat_ms": producer, "drive_consumer_ms": consumer,
            "connection_loss": loss}
