"""PDO layouts: which objects a PDO carries, and how its bytes pack and unpack.

The master and the emulator share this, so a mapping changed in the robot's YAML changes
both sides; the objects' sizes and signs come from `objects`.
"""

from __future__ import annotations

from dataclasses import dataclass

from asibot.arm_driver import objects

# CiA 301 pre-defined connection set: PDO n of node id uses these COB-ID bases.
TPDO_BASE = {1: 0x180, 2: 0x280, 3: 0x380, 4: 0x480}
RPDO_BASE = {1: 0x200, 2: 0x300, 3: 0x400, 4: 0x500}
PDO_INVALID = 0x80000000   # COB-ID bit 31: PDO does not exist / is being changed
SYNC_CYCLIC = 1            # transmission type: every SYNC
ON_CHANGE = 255            # transmission type: event driven (manufacturer/device profile)


@dataclass(frozen=True)
class Entry:
    index: int
    subindex: int
    bits: int

    @property
    def mapping(self) -> int:
        """The u32 written to 0x16xx/0x1Axx: index << 16 | subindex << 8 | bits."""
        return self.index << 16 | self.subindex << 8 | self.bits

    @classmethod
    def from_mapping(cls, value: int) -> "Entry":
        return cls(value >> 16, (value >> 8) & 0xFF, value & 0xFF)


@dataclass(frozen=True)
class Layout:
    """One PDO: direction ("tpdo"/"rpdo"), number 1..4, entries, and communication parameters."""

    kind: str
    number: int
    entries: tuple[Entry, ...]
    transmission: int = ON_CHANGE
    inhibit_ms: float | None = None
    event_timer_ms: int | None = None

    def __post_init__(self) -> None:
        if self.kind not in ("tpdo", "rpdo") or self.number not in (1, 2, 3, 4):
            raise ValueError(f"{self.kind}{self.number}: use tpdo1..tpdo4 or rpdo1..rpdo4")
        if not 0 <= self.transmission <= 255:
            raise ValueError(f"{self.name}: transmission type must be 0..255")
        for e in self.entries:
            t = objects.type_of(e.index, e.subindex)
            if t.bits != e.bits:
                raise ValueError(f"{self.name}: 0x{e.index:04X}:{e.subindex:02X} is {t.bits} bits, "
                                 f"the mapping says {e.bits}")
        if self.size > 8:
            raise ValueError(f"{self.name}: {self.size} bytes do not fit in one CAN frame (max 8)")

    @property
    def name(self) -> str:
        return f"{self.kind}{self.number}"

    @property
    def size(self) -> int:
        return sum(e.bits for e in self.entries) // 8

    def cob_id(self, node: int) -> int:
        return (TPDO_BASE if self.kind == "tpdo" else RPDO_BASE)[self.number] + node

    @property
    def comm_index(self) -> int:
        return (objects.TPDO_COMM if self.kind == "tpdo" else objects.RPDO_COMM) + self.number - 1

    @property
    def map_index(self) -> int:
        return (objects.TPDO_MAP if self.kind == "tpdo" else objects.RPDO_MAP) + self.number - 1

    def encode(self, values: dict[int, int]) -> bytes:
        """Pack values keyed by object index, in mapping order."""
        out = bytearray()
        for e in self.entries:
            out += objects.type_of(e.index, e.subindex).encode(int(values[e.index]))
        return bytes(out)

    def decode(self, data: bytes) -> dict[int, int]:
        """Unpack a received PDO; ValueError if it is shorter than the mapping."""
        if len(data) < self.size:
            raise ValueError(f"{self.name} carries {len(data)} bytes, its mapping needs {self.size}")
        out, offset = {}, 0
        for e in self.entries:
            t = objects.type_of(e.index, e.subindex)
            out[e.index] = t.decode(data[offset: offset + t.size])
            offset += t.size
        return out


def decode_entries(entries: list[Entry], data: bytes) -> dict[int, int]:
    """Unpack bytes for an arbitrary (emulator-side) mapping."""
    out, offset = {}, 0
    for e in entries:
        t = objects.type_of(e.index, e.subindex)
        out[e.index] = t.decode(data[offset: offset + t.size])
        offset += t.size
    return out
