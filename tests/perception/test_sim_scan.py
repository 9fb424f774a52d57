"""Against the real sim, in process: the apartment's depth cameras rendered at known poses, turned
into a scan, compared with the geometry of the world file (services/sim/asibot/sim/worlds/apartment.xml)."""

import math
import os
import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "osmesa")

from asibot.perception import finder  # noqa: E402
from asibot.perception.depth_to_scan import BandConfig, DepthToScan  # noqa: E402
from asibot.perception.merge import ScanGrid, merge  # noqa: E402
from asibot.perception.rays import CameraRays  # noqa: E402
from asibot.perception.sonar import SonarRing  # noqa: E402
from asibot.sim.cameras import Camera  # noqa: E402
from asibot.sim.scene import world_path  # noqa: E402
from asibot.sim.simulation import Simulation  # noqa: E402

GRID = ScanGrid()
BAND = BandConfig()
START = (1.0, 1.5)       # the pioneer body's pos in the MJCF: its slide joints are offsets from it


# ---------------------------------------------------------------------- geometry from the MJCF
def obstacles(band=BAND):
    """Boxes (x0, y0, x1, y1) and cylinders (x, y, r) of the world file that reach into the band:
    static geoms and the box on the floor (not the robot, not the objects on furniture), read
    from the XML itself."""
    root = ET.parse(world_path("apartment")).getroot()
    box_classes = {d.get("class") for d in root.iter("default")
                   if d.find("geom") is not None and d.find("geom").get("type") == "box"}
    boxes, cylinders = [], []

    def visit(parent, offset):
        for g in parent.findall("geom"):
            kind = g.get("type") or ("box" if g.get("class") in box_classes else "sphere")
            pos = np.array([float(v) for v in g.get("pos", "0 0 0").split()]) + offset
            size = [float(v) for v in g.get("size").split()]
            half_z = size[2] if kind == "box" else size[1] if kind == "cylinder" else None
            if half_z is None or pos[2] + half_z < band.min_height or pos[2] - half_z > band.max_height:
                continue
            if kind == "box":
                boxes.append((pos[0] - size[0], pos[1] - size[1], pos[0] + size[0], pos[1] + size[1]))
            else:
                cylinders.append((pos[0], pos[1], size[0]))
        for b in parent.findall("body"):
            # the cans and cups stand on furniture; the cardboard box stands on the floor
            if (b.find("freejoint") is None or b.get("name") == "box") and b.get("name") != "pioneer":
                visit(b, offset + np.array([float(v) for v in b.get("pos", "0 0 0").split()]))

    visit(root.find("worldbody"), np.zeros(3))
    return boxes, cylinders


def expected_ranges(x, y, theta, boxes, cylinders):
    """2D ray casting from the base centre along every beam of the scan: first box or cylinder."""
    a = GRID.angles() + theta
    dx, dy = np.cos(a), np.sin(a)
    best = np.full(len(a), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for x0, y0, x1, y1 in boxes:
            tx0, tx1 = (x0 - x) / dx, (x1 - x) / dx
            ty0, ty1 = (y0 - y) / dy, (y1 - y) / dy
            near = np.maximum(np.minimum(tx0, tx1), np.minimum(ty0, ty1))
            far = np.minimum(np.maximum(tx0, tx1), np.maximum(ty0, ty1))
            hit = (near <= far) & (near > 0)
            best = np.where(hit, np.minimum(best, near), best)
        for cx, cy, r in cylinders:
            b = dx * (cx - x) + dy * (cy - y)
            c = (cx - x) ** 2 + (cy - y) ** 2 - r * r
            t = b - np.sqrt(b * b - c)
            best = np.where((b * b >= c) & (t > 0), np.minimum(best, t), best)
    return best


# ---------------------------------------------------------------------- the sim
@pytest.fixture(scope="module")
def apartment():
    sim = Simulation("pioneer-sim", odom_noise=(0.0, 0.0))
    body = sim.scene.base.body
    cams = {n: Camera(sim.model, n, 320, 240, body) for n in ("front", "back", "rgb")}
    yield sim, cams
    for c in cams.values():
        c.close()


def place(sim, x, y, theta):
    sim.data.qpos[sim.scene.base.qpos] = [x - START[0], y - START[1], theta]
    mujoco.mj_forward(sim.model, sim.data)
    assert sim.truth() == pytest.approx((x, y, theta), abs=1e-9)


def sim_scan(sim, cams):
    scans = []
    for name in ("front", "back"):
        rays = CameraRays.from_info(cams[name].info(sim.data))
        conv = DepthToScan(rays, BAND)
        assert conv.mode == "columns"        # the sim's depth cameras are level
        scans.append(conv.convert(cams[name].depth(sim.data), name))
    return merge(GRID, scans)


# Poses where every obstacle in the band is seen whole by the level cameras: no table top
# overhanging the floor near the robot, which the 2D geometry would place where the cameras
# look under it.
@pytest.mark.parametrize("pose", [(1.0, 1.5, 0.0), (3.6, 5.3, 2.4), (7.5, 6.0, 0.0), (8.0, 1.4, -0.4)])
def test_the_scan_of_the_apartment_matches_the_world_file(apartment, pose):
    sim, cams = apartment
    place(sim, *pose)
    ranges = sim_scan(sim, cams)
    distance = expected_ranges(*pose, *obstacles())
    expect = np.where(distance <= GRID.range_max, distance, np.inf)
    # beams watched, without those whose wall lies at the reach of the cameras (8 m from each)
    watched = ~np.isnan(ranges) & ~(np.abs(distance - GRID.range_max) < 0.4)
    assert watched.sum() > 150                     # two cameras of ~58 deg each, +-20 deg watched whole
    got, expect = ranges[watched].astype(float), expect[watched]
    # within 1 cm + 1 %: a beam holds the return nearest to its angle, up to 0.25 deg away, and
    # on a slanted wall that is a few millimetres per metre; silhouette edges and slivers the
    # camera cannot see past a corner (it sits 0.32 m from the base centre) make the rest
    agree = (np.isinf(got) & np.isinf(expect)) | (np.abs(got - expect) < 0.01 + 0.01 * expect)
    assert agree.mean() > 0.95, f"{(~agree).sum()} beams disagree: {np.c_[GRID.angles()[watched][~agree], got[~agree], expect[~agree]][:10]}"
    assert not (np.isfinite(got) & np.isinf(expect)).any()      # the floor is never an obstacle


def test_the_wall_ahead_of_the_start_pose_is_where_the_world_file_puts_it(apartment):
    sim, cams = apartment
    place(sim, *START, 0.0)
    ranges = sim_scan(sim, cams)
    wall = ET.parse(world_path("apartment")).getroot().find(".//geom[@name='wall_mid_s']")
    face = float(wall.get("pos").split()[0]) - float(wall.get("size").split()[0])   # x = 4.95
    ahead = np.abs(GRID.angles()) < math.radians(15)
    np.testing.assert_allclose(ranges[ahead], (face - START[0]) / np.cos(GRID.angles()[ahead]), atol=0.01)
    # and the low charging station behind (0.3 m high) is seen in front of the west wall
    station = ET.parse(world_path("apartment")).getroot().find(".//geom[@name='charging_station']")
    back_face = float(station.get("pos").split()[0]) + float(station.get("size").split()[0])   # x = 0.15
    assert ranges[0] == pytest.approx(START[0] - back_face, abs=0.01)


def test_the_sim_sonar_fills_the_sides_without_moving_what_the_cameras_see(apartment):
    sim, cams = apartment
    place(sim, START[0], 0.55, 0.0)
    ranges = sim_scan(sim, cams)
    fused = SonarRing.p3at().fuse(GRID, ranges, sim.sonar())
    same = np.isfinite(ranges)
    np.testing.assert_array_equal(fused[same], ranges[same])       # every echo there is explained
    right = np.abs(GRID.angles() + math.pi / 2) < math.radians(12)  # the south wall, 0.55 m to the right
    assert np.isnan(ranges[right]).all()
    # sonars 7 and 8 (both facing right, 29 cm apart) lay it in, less the gap between their arcs
    heard = right & np.isfinite(fused)
    assert heard.sum() > 0.5 * right.sum()
    np.testing.assert_allclose(fused[heard], 0.55 / np.cos(GRID.angles()[heard] + math.pi / 2), atol=0.05)
    left = np.abs(GRID.angles() - math.pi / 2) < math.radians(5)    # the sofa, 3 m to the left: too far to lay in
    assert np.isnan(fused[left]).all()


def test_the_red_can_is_found_where_the_sim_has_it(apartment):
    sim, cams = apartment
    place(sim, 0.9, 2.6, 0.2)
    can = sim.object_position("red_can")
    c, s = math.cos(0.2), math.sin(0.2)
    rel = np.array([c * (can[0] - 0.9) + s * (can[1] - 2.6), -s * (can[0] - 0.9) + c * (can[1] - 2.6), can[2]])
    rgb = cams["rgb"].rgb_jpeg(sim.data)
    front = cams["front"]
    front_rays = CameraRays.from_info(front.info(sim.data))
    ans = finder.find(finder.decode_jpeg(rgb.jpeg, rgb.width, rgb.height), "red",
                      CameraRays.from_info(cams["rgb"].info(sim.data)), [front_rays.points(front.depth(sim.data))])
    assert ans["found"], ans
    point = np.array(ans["point"])
    radius, half_height = 0.033, 0.06        # the can's geom in the world file
    assert np.hypot(*(point[:2] - rel[:2])) == pytest.approx(radius, abs=0.015)   # on its surface
    assert abs(point[2] - rel[2]) <= half_height
