"""The emulated P3-AT controller, driven with explicit time (no sockets, no sleeping)."""

import hashlib
import math

import cv2
import numpy as np
import pytest

from asibot.base_driver import codec
from asibot.base_driver.codec import Cmd, Deframer
from asibot.base_driver.emulator import gridmap
from asibot.base_driver.emulator.robot import EmulatedP3at, Pose
from asibot.base_driver.params import P3AT
from asibot.base_driver.sip import parse_sip, parse_sync2


def sips(data: bytes):
    return [parse_sip(p) for p in Deframer().feed(data) if p[0] in (0x32, 0x33)]


def opened(robot=None, t=0.0) -> EmulatedP3at:
    r = robot or EmulatedP3at()
    for c in (0, 1, 2):
        r.receive(codec.command(c), t)
    r.receive(codec.command(Cmd.OPEN), t)
    r.receive(codec.command_int(Cmd.ENABLE, 1), t)
    return r


def run(r: EmulatedP3at, t0: float, t1: float, dt: float = 0.01, keepalive: float | None = 0.5) -> bytes:
    out = bytearray()
    t, last = t0, t0
    while t < t1 - 1e-9:
        t += dt
        if keepalive and t - last >= keepalive:
            r.receive(codec.command(Cmd.PULSE), t)
            last = t
        out += r.step(t)
    return bytes(out)


def test_sync_is_echoed_and_sync2_names_the_robot():
    r = EmulatedP3at(params=P3AT, name="rob")
    assert r.receive(codec.command(0), 0) == codec.command(0)
    assert r.receive(codec.command(1), 0) == codec.command(1)
    reply = r.receive(codec.command(2), 0)
    assert parse_sync2(codec.payload_of(reply)) == ("rob", "Pioneer", "p3at")
    assert not r.is_open
    r.receive(codec.command(Cmd.OPEN), 0)
    assert r.is_open


def test_out_of_order_sync_starts_over():
    r = EmulatedP3at()
    assert r.receive(codec.command(1), 0) == b""          # SYNC1 before SYNC0: ignored
    assert r.receive(codec.command(2), 0) == b""
    r.receive(codec.command(Cmd.OPEN), 0)
    assert not r.is_open


def test_a_sip_every_100_ms_once_open():
    r = EmulatedP3at()
    assert run(r, 0, 1.0) == b""                           # not open: silent
    r = opened()
    assert 10 <= len(sips(run(r, 0, 1.0))) <= 11       # one at OPEN, then every 100 ms


def test_velocity_is_integrated_with_acceleration_limits():
    r = opened()
    r.receive(codec.command_int(Cmd.VEL, 300), 0)
    out = sips(run(r, 0, 0.15))
    assert 0 < out[-1].left_vel < 300                      # still accelerating after 100 ms
    run(r, 0.15, 2.0)
    assert r.vel == 300
    assert r.pose.x == pytest.approx(0.6 - 0.3 * 0.3 / 2, abs=0.01)   # 1000 mm/s^2 ramp
    r.receive(codec.command_int(Cmd.RVEL, -90), 2.0)
    run(r, 2.0, 3.0)
    assert r.rot == -90 and r.pose.theta < 0


def test_missing_keepalive_trips_the_2s_watchdog_and_commands_resume_motion():
    r = opened()
    r.receive(codec.command_int(Cmd.VEL, 200), 0)
    run(r, 0, 1.9, keepalive=None)
    assert r.vel == 200 and not r.watchdog_tripped
    out = sips(run(r, 1.9, 3.0, keepalive=None))
    assert r.watchdog_tripped and r.vel == 0
    assert not out[-1].moving and out[-1].left_vel == 0
    r.receive(codec.command(Cmd.PULSE), 3.0)               # ARCOS resumes the old setpoint
    run(r, 3.0, 3.5)
    assert r.vel == 200


def test_e_stop_overrides_deceleration_and_close_ends_the_session():
    r = opened()
    r.receive(codec.command_int(Cmd.VEL, 500), 0)
    run(r, 0, 1.0)
    r.receive(codec.command(Cmd.E_STOP), 1.0)
    assert r.vel == 0 and r.target_vel == 0
    r.receive(codec.command_int(Cmd.VEL, 500), 1.0)
    r.receive(codec.command(Cmd.CLOSE), 1.0)
    assert not r.is_open and r.target_vel == 0 and not r.motors_enabled
    assert run(r, 1.0, 1.5) == b""


def test_motors_disabled_do_not_move():
    r = opened()
    r.receive(codec.command_int(Cmd.ENABLE, 0), 0)
    r.receive(codec.command_int(Cmd.VEL, 300), 0)
    out = sips(run(r, 0, 1.0))
    assert r.pose.x == 0 and not out[-1].motors_enabled


def test_vel2_sets_translation_and_rotation():
    r = opened()
    r.receive(codec.vel2(200, 400), 0)
    assert r.target_vel == pytest.approx(300)
    assert r.target_rot == pytest.approx(math.degrees(100 * 0.0034))


def test_negative_velocity_and_limits():
    r = opened()
    r.receive(codec.command_int(Cmd.VEL, -5000), 0)
    assert r.target_vel == -1200                           # MaxVelocity (docs/arcos.md "P3-AT parameters")
    r.receive(codec.command_int(Cmd.SETV, 400), 0)
    r.receive(codec.command_int(Cmd.VEL, -5000), 0)
    assert r.target_vel == -400


def test_hitting_a_wall_stalls_and_bumps():
    r = opened(EmulatedP3at(gridmap.room(4.0, 4.0)))
    r.receive(codec.command_int(Cmd.VEL, 600), 0)
    out = sips(run(r, 0, 4.0))
    assert r.pose.x < 2.0 - 0.1 - 0.3
    assert any(s.stall_left and s.stall_right and any(s.front_bumpers) for s in out)
    assert not any(any(s.rear_bumpers) for s in out)


def test_odometry_positions_wrap_at_15_bits():
    r = opened()
    r.odom_x = 32767.0 - 50
    r.receive(codec.command_int(Cmd.VEL, 500), 0)
    out = sips(run(r, 0, 0.6))
    xs = [s.xpos for s in out]
    assert max(xs) > 32000 and min(xs) < 1000


def test_sonar_sees_the_walls_of_the_room():
    r = opened(EmulatedP3at(gridmap.room(8.0, 6.0)))
    ranges = r.sonar_ranges()
    assert ranges[0] == pytest.approx((2.9 - 0.136) * 1000, abs=30)          # left, 90 deg
    assert ranges[3] == pytest.approx((3.9 - 0.245) / math.cos(math.radians(10)) * 1000, abs=30)
    assert ranges[8] == pytest.approx((2.9 - 0.136) * 1000, abs=30)          # right rear, -90 deg
    r2 = opened(EmulatedP3at(gridmap.room(20.0, 20.0)))
    assert r2.sonar_ranges()[3] == 4335                                     # max range


def test_start_inside_an_obstacle_is_refused():
    with pytest.raises(ValueError, match="obstacle"):
        EmulatedP3at(gridmap.room(4.0, 4.0), Pose(1.9, 0, 0))


# ------------------------------------------------------------------ map_server maps
def write_map(tmp_path, pixels: np.ndarray, resolution=0.1, origin=(-1.0, -2.0), negate=0):
    h, w = pixels.shape
    (tmp_path / "m.pgm").write_bytes(b"P5\n# made by a test\n%d %d\n255\n" % (w, h) + pixels.tobytes())
    (tmp_path / "m.yaml").write_text(
        f"image: m.pgm\nresolution: {resolution}\norigin: [{origin[0]}, {origin[1]}, 0.0]\n"
        f"negate: {negate}\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    return tmp_path / "m.yaml"


def test_map_server_pgm_and_yaml_are_read_with_row_0_at_the_top(tmp_path):
    px = np.full((40, 20), 254, np.uint8)
    px[0, :] = 0                       # top row black: the wall at max y
    m = gridmap.load(write_map(tmp_path, px))
    assert m.is_occupied(-0.95, -2.0 + 3.95)          # top row
    assert not m.is_occupied(-0.95, -2.0 + 0.05)      # bottom row
    assert m.is_occupied(5.0, 5.0)                    # outside the map
    assert m.raycast(0.0, 0.0, math.pi / 2, 5.0) == pytest.approx(1.9, abs=0.06)


def test_ascii_pgm_and_negate(tmp_path):
    (tmp_path / "a.pgm").write_text("P2\n2 2\n255\n0 255\n255 255\n")
    (tmp_path / "a.yaml").write_text("image: a.pgm\nresolution: 1.0\norigin: [0, 0, 0]\nnegate: 1\n")
    m = gridmap.load(tmp_path / "a.yaml")
    # negated: white (255) is occupied; the only black pixel is top-left
    assert not m.is_occupied(0.5, 1.5) and m.is_occupied(1.5, 1.5) and m.is_occupied(0.5, 0.5)


@pytest.mark.parametrize("yaml_text,match", [
    ("resolution: 0.1\norigin: [0, 0, 0]\n", "image"),
    ("image: nope.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n", "names the image 'nope.pgm', which cannot be read"),
    ("image: m.pgm\nresolution: 0.1\norigin: [0, 0]\n", "origin must be"),
    ("- just a list\n", "mapping"),
])
def test_bad_maps_are_refused_with_a_reason(tmp_path, yaml_text, match):
    (tmp_path / "bad.yaml").write_text(yaml_text)
    with pytest.raises(ValueError, match=match):
        gridmap.load(tmp_path / "bad.yaml")


def test_a_broken_image_is_refused(tmp_path):
    (tmp_path / "x.pgm").write_bytes(b"\x89PNG\r\n\x1a\n0000")
    (tmp_path / "x.yaml").write_text("image: x.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n")
    with pytest.raises(ValueError, match="looks like a PNG image but cannot be decoded.*PGM, PNG or BMP"):
        gridmap.load(tmp_path / "x.yaml")


def test_a_png_world_is_the_pgm_world(tmp_path):
    px = np.full((30, 20), 254, np.uint8)
    px[5:9, 3:15] = 0
    px[20, :] = 205                    # unknown is not an obstacle
    pgm = gridmap.load(write_map(tmp_path, px))
    ok, png = cv2.imencode(".png", np.stack([px] * 3, axis=2))   # a colour PNG of grey pixels
    assert ok
    (tmp_path / "w.png").write_bytes(png.tobytes())
    (tmp_path / "w.yaml").write_text("image: w.png\nresolution: 0.1\norigin: [-1.0, -2.0, 0.0]\n")
    world = gridmap.load(tmp_path / "w.yaml")
    assert np.array_equal(world.occupied, pgm.occupied) and world.occupied.sum() == 4 * 12
    assert (world.resolution, world.origin) == (pgm.resolution, pgm.origin)


def test_the_shipped_apartment_is_the_world_it_was():
    world = gridmap.load("apartment")
    assert world.occupied.shape == (190, 230) and (world.resolution, world.origin) == (0.05, (-0.75, -0.75))
    # the obstacles the hand-written PGM reader gave before maps were read by asibot.rosmap
    assert hashlib.sha256(np.packbits(world.occupied).tobytes()).hexdigest() == \
        "0f392b8578e700c9aad85287beec26970d19926cdd4e152b2fad76786628da7c"
