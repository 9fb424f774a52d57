"""Exact bytes on the wire: start-up (NMT, SDO configuration, PDO mapping, controlwords),
a target position RPDO, SYNC and an EMCY, as the master and the emulated drives send them."""

from __future__ import annotations

import math

from asibot.arm_driver import emcy
from asibot.arm_driver.emcy import Emcy
from asibot.testing import wait_until


def frames(rig, *cob_ids):
    return [(cob, data.hex(" ")) for cob, data, _ in rig.sniffer.seen() if cob in cob_ids]


def test_startup_of_node_1_is_byte_exact(rig):
    m = rig.master
    m.configure(1)
    m.start(1)
    assert m.enable(1) == 0
    requests = [d for cob, d in frames(rig, 0x601)]
    assert requests[:8] == [
        "40 00 10 00 00 00 00 00",   # SDO ping: upload 0x1000 device type
        "40 02 65 00 00 00 00 00",   # upload 0x6502 supported drive modes
        "2f 60 60 00 08 00 00 00",   # 0x6060 = 8 cyclic synchronous position
        "23 7d 60 01 00 00 f6 ff",   # 0x607D:1 min limit -360 deg = -655360 counts
        "23 7d 60 02 00 00 0a 00",   # 0x607D:2 max limit +360 deg
        "23 81 60 00 56 34 12 00",   # 0x6081 profile velocity 10 deg/s = 18.204 counts/ms in 16.16
        "23 83 60 00 a9 04 00 00",   # 0x6083 profile acceleration 10 deg/s^2
        "23 00 18 01 81 01 00 80",   # TPDO1 COB-ID 0x181, disabled while mapping
    ]
    # TPDO3 (position internal + torque, every SYNC): the CiA 301 mapping procedure.
    tpdo3 = requests[requests.index("23 02 18 01 81 03 00 80"):][:7]
    assert tpdo3 == [
        "23 02 18 01 81 03 00 80",   # disable
        "2f 02 18 02 01 00 00 00",   # transmission type 1: every SYNC
        "2f 02 1a 00 00 00 00 00",   # clear the mapping
        "23 02 1a 01 20 00 63 60",   # 0x6063:00, 32 bits
        "23 02 1a 02 10 00 77 60",   # 0x6077:00, 16 bits
        "2f 02 1a 00 02 00 00 00",   # two entries
        "23 02 18 01 81 03 00 00",   # enable
    ]
    assert "2b 00 18 03 2c 01 00 00" in requests          # TPDO1 inhibit 30 ms = 300 x 100 us
    assert "2b 00 18 05 fa 00 00 00" in requests          # TPDO1 event timer 250 ms
    assert "23 02 16 01 20 00 7a 60" in requests          # RPDO3 carries 0x607A target position
    assert requests[-9:] == [
        "2f c2 60 01 0a 00 00 00",   # interpolation period 10 ...
        "2f c2 60 02 fd 00 00 00",   # ... x 10^-3 s
        "2f 60 60 00 08 00 00 00",   # mode CSP
        "2b 17 10 00 64 00 00 00",   # heartbeat producer 100 ms
        "23 16 10 01 2c 01 7f 00",   # heartbeat consumer: node 127 (the master) within 300 ms
        "2b 07 60 00 03 00 00 00",   # abort connection option: quick stop
        "40 41 60 00 00 00 00 00",   # read the statusword: the last TPDO's may be stale
        "40 64 60 00 00 00 00 00",   # read position actual before enabling ...
        "23 7a 60 00 00 00 00 00",   # ... and make it the target, so nothing jumps
    ]
    # Every SDO request got its confirmation.
    replies = [d for cob, d in frames(rig, 0x581)]
    assert len(replies) == len(requests)
    assert replies[requests.index("2b 17 10 00 64 00 00 00")] == "60 17 10 00 00 00 00 00"
    # NMT start node 1, then shutdown -> switch on -> enable operation on RPDO1.
    assert frames(rig, 0x000) == [(0x000, "01 01")]
    assert [d for cob, d in frames(rig, 0x201)] == ["06 00", "07 00", "0f 00"]


def test_target_position_rpdo_and_sync(rig):
    m = rig.master
    for node in (1, 2):
        m.configure(node)
        m.start(node)
        m.enable(node)
    m.start_cyclic()
    q2 = rig.cfg.joints[1].units.to_counts(math.radians(10))
    assert q2 == 18204                         # 10 deg x 1820.44 counts/deg
    m.cycle({1: 0, 2: q2})
    # A period under way as the set-point changed may still deliver its old one: from the first
    # new one on, only new ones (CI: one old 0x402 seen after the clear, under load).
    wait_until(lambda: (0x402, "1c 47 00 00") in frames(rig, 0x402))
    rig.sniffer.clear()
    # Set-points and SYNC repeat every period without further calls; the master's heartbeat too.
    wait_until(lambda: len(frames(rig, 0x080)) >= 3 and frames(rig, 0x77F))
    assert set(frames(rig, 0x401, 0x402, 0x080, 0x77F)) == {
        (0x401, "00 00 00 00"), (0x402, "1c 47 00 00"), (0x080, ""), (0x77F, "05")}
    # The drive answers the SYNC with TPDO3: position internal (i32) + torque (i16).
    wait_until(lambda: frames(rig, 0x382))
    assert len(bytes.fromhex(frames(rig, 0x382)[0][1].replace(" ", ""))) == 6


def test_over_current_emcy_bytes_and_sentence(rig):
    rig.emu.over_current(3)
    wait_until(lambda: frames(rig, 0x083))
    assert frames(rig, 0x083)[0] == (0x083, "10 23 03 00 00 00 00 00")
    e = Emcy.decode(bytes.fromhex("1023030000000000"))
    assert (e.code, e.register, e.is_reset) == (0x2310, 0x03, False)
    assert emcy.sentence(e, 3, "q3") == (
        "Drive 3 (joint q3) reports continuous over-current (EMCY 0x2310). The arm was stopped: "
        "check the load on the joint and the motor wiring, then call reset_fault.")
