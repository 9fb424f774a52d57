"""The emulated drive on its own: SDO server, PDO mapping, NMT, motion, faults."""

from __future__ import annotations

import math
import struct

import pytest

from asibot.arm_driver import objects
from asibot.arm_driver.emulator.drive import (ABORT_DEVICE_STATE, ABORT_NO_OBJECT, ABORT_READ_ONLY,
                                              ABORT_VALUE_RANGE, EmulatedDrive)

CPR = 160 * 4096 / (2 * math.pi)


def sdo_write(d, index, sub, value, size, now=0.0):
    cs = {4: 0x23, 2: 0x2B, 1: 0x2F}[size]
    fmt = {4: "<i", 2: "<H", 1: "<b"}[size] if value < 0 else {4: "<I", 2: "<H", 1: "<B"}[size]
    data = bytes([cs]) + struct.pack("<HB", index, sub) + struct.pack(fmt, value).ljust(4, b"\0")
    (reply,) = [f for f in d.handle(0x600 + d.node, data, now) if f[0] == 0x580 + d.node]
    return reply[1]


def abort_code(reply):
    assert reply[0] == 0x80
    return struct.unpack_from("<I", reply, 4)[0]


def drive(**kw):
    d = EmulatedDrive(3, **kw)
    assert d.poll(0.0) == [(0x703, b"\x00")]          # boot-up
    return d


def map_pdo(d, comm, mapping, cob, transmission, entries):
    assert sdo_write(d, comm, 1, cob | 0x80000000, 4)[0] == 0x60
    assert sdo_write(d, comm, 2, transmission, 1)[0] == 0x60
    assert sdo_write(d, mapping, 0, 0, 1)[0] == 0x60
    for i, e in enumerate(entries, 1):
        assert sdo_write(d, mapping, i, e, 4)[0] == 0x60
    assert sdo_write(d, mapping, 0, len(entries), 1)[0] == 0x60
    assert sdo_write(d, comm, 1, cob, 4)[0] == 0x60


def operational_csp(d):
    map_pdo(d, 0x1800, 0x1A00, 0x183, 255, [0x10020020, 0x60610008])
    map_pdo(d, 0x1802, 0x1A02, 0x383, 1, [0x60630020, 0x60770010])
    map_pdo(d, 0x1400, 0x1600, 0x203, 255, [0x60400010])
    map_pdo(d, 0x1402, 0x1602, 0x403, 1, [0x607A0020])
    assert sdo_write(d, 0x6060, 0, 8, 1)[0] == 0x60
    d.handle(0x000, b"\x01\x03", 0.0)
    for cw in (0x06, 0x07, 0x0F):
        d.handle(0x203, struct.pack("<H", cw), 0.0)
    assert d.state.value == "operation enabled"


def test_sdo_upload_and_aborts():
    d = drive()
    reply = [f for f in d.handle(0x603, bytes([0x40, 0x00, 0x10, 0, 0, 0, 0, 0]), 0.0)][0][1]
    assert reply == bytes.fromhex("4300100092010200")             # 0x1000 = 0x00020192
    assert abort_code(sdo_write(d, 0x6041, 0, 1, 2)) == ABORT_READ_ONLY
    assert abort_code(sdo_write(d, 0x5555, 0, 1, 2)) == ABORT_NO_OBJECT
    assert abort_code(sdo_write(d, 0x6060, 0, 3, 1)) == ABORT_VALUE_RANGE   # profile velocity: not emulated


def test_mapping_needs_the_pdo_disabled_first():
    d = drive()
    sdo_write(d, 0x1802, 1, 0x383, 4)                                  # valid
    assert abort_code(sdo_write(d, 0x1A02, 1, 0x60630020, 4)) == ABORT_DEVICE_STATE


def test_drive_without_csp_refuses_mode_8():
    d = drive(supports_csp=False)
    assert abort_code(sdo_write(d, 0x6060, 0, 8, 1)) == ABORT_VALUE_RANGE
    reply = d.handle(0x603, bytes([0x40, 0x02, 0x65, 0, 0, 0, 0, 0]), 0.0)[0][1]
    assert struct.unpack_from("<I", reply, 4)[0] == objects.SUPPORTS_PP


def test_csp_follows_targets_at_most_at_max_speed_and_inside_limits():
    d = drive(max_speed=math.radians(30))
    operational_csp(d)
    sdo_write(d, 0x607D, 2, int(0.1 * CPR), 4)                        # max limit 0.1 rad
    d.handle(0x403, struct.pack("<i", int(1.0 * CPR)), 0.0)          # far away
    d.on_sync(0.0)
    out = d.on_sync(0.01)
    assert d.position / CPR == pytest.approx(math.radians(30) * 0.01, rel=1e-6)
    tpdo3 = [data for cob, data in out if cob == 0x383][0]
    assert struct.unpack("<ih", tpdo3) == (d.position_counts, 0)
    t = 0.01
    for _ in range(100):
        t += 0.01
        d.on_sync(t)
    assert d.position / CPR == pytest.approx(0.1, abs=1e-5)          # stopped at the software limit
    assert d.statusword & (1 << 11)                                   # internal limit active


def test_over_current_faults_and_reset_sends_error_reset():
    d = drive()
    operational_csp(d)
    out = d.inject_over_current()
    assert out == [(0x083, bytes.fromhex("1023030000000000"))]
    assert d.state.value == "fault" and d.value(objects.MOTION_ERROR) == 1 << 8
    assert d.value(objects.MANUFACTURER_STATUS) >> 16 & 0x8000       # MSR fault bit
    out = d.handle(0x203, struct.pack("<H", 0x80), 0.1)
    assert (0x083, bytes(8)) in out and d.state.value == "switch on disabled"


def test_heartbeat_and_its_loss():
    d = drive()
    sdo_write(d, 0x1017, 0, 100, 2)
    d.handle(0x000, b"\x01\x00", 0.0)                                 # start all nodes
    assert d.poll(1.0) == [(0x703, b"\x05")]
    assert d.poll(1.05) == []
    d.heartbeat_lost = True
    assert d.poll(1.2) == []


def test_nmt_reset_node_boots_up_with_defaults_keeping_the_joint_where_it_is():
    d = drive()
    operational_csp(d)
    d.position = 1234.0
    out = d.handle(0x000, b"\x81\x03", 0.0)
    assert out == [(0x703, b"\x00")]
    assert d.state.value == "switch on disabled" and d.position == 1234.0
    assert not d.tpdos[3].valid


def test_profile_position_moves_with_the_profile_velocity():
    d = drive(supports_csp=False)
    map_pdo(d, 0x1400, 0x1600, 0x203, 255, [0x60400010])
    sdo_write(d, 0x6060, 0, 1, 1)
    sdo_write(d, 0x6081, 0, int(10 * 1820.444 * 0.001 * 65536), 4)   # 10 deg/s
    d.handle(0x000, b"\x01\x03", 0.0)
    for cw in (0x06, 0x07, 0x2F):
        d.handle(0x203, struct.pack("<H", cw), 0.0)
    sdo_write(d, 0x607A, 0, int(math.radians(5) * CPR), 4)
    d.handle(0x203, struct.pack("<H", 0x3F), 0.0)                     # new set-point edge
    assert d.statusword & (1 << 12)                                    # acknowledged
    t = 0.0
    d.poll(t)
    while t < 2.0:
        t += 0.005
        d.poll(t)
        assert abs(d.velocity / CPR) <= math.radians(10) * 1.001
    assert d.position / CPR == pytest.approx(math.radians(5), abs=1e-4)
    assert d.statusword & (1 << 10)                                    # target reached
