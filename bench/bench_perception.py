"""Benchmark of perception: prints one markdown table (what, median, p95, unit, budget).

Inputs are the sim's own images: the apartment's front and back depth cameras and its RGB
camera rendered once at the start pose (MuJoCo, OSMesa) at 640x480, and its sonar ring.
Each row is the median and 95th percentile of many calls of the plain classes (no bus), so
it measures the work, not the transport. The references are measured in the same run, on
the same image: depthimage_to_laserscan's centre row (what this replaces) and a bare numpy
minimum down the columns (the floor of any per-column reduction).

Run: `.venv/bin/python bench/bench_perception.py [--quick]`
"""

from __future__ import annotations

import argparse
import math
import os
from typing import Callable

os.environ.setdefault("MUJOCO_GL", "osmesa")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from asibot.perception import finder  # noqa: E402
from asibot.perception.depth_to_scan import DepthToScan, centre_rows  # noqa: E402
from asibot.perception.merge import ScanGrid, merge  # noqa: E402
from asibot.perception.rays import CameraRays  # noqa: E402
from asibot.perception.sonar import SonarRing  # noqa: E402
from asibot.perception.warnings import ObstacleWarner, clearance  # noqa: E402
from asibot.sim.cameras import Camera  # noqa: E402
from asibot.sim.simulation import Simulation  # noqa: E402

from table import QUICK_HELP, print_table, times  # bench/table.py: run as `python bench/<name>.py`

ROWS: list[tuple[str, str, str, str, str]] = []
QUICK = False


def timed(fn: Callable[[], object], runs: int) -> tuple[float, float]:
    """(median, p95) of `runs` calls in ms, after a few warm-up calls."""
    t = times(fn, 2, warmup=1) if QUICK else times(fn, runs, warmup=3)
    return float(np.median(t)) * 1e3, float(np.percentile(t, 95)) * 1e3


def row(what: str, fn: Callable[[], object], budget: str, runs: int = 300) -> None:
    med, p95 = timed(fn, runs)
    ROWS.append((what, f"{med:.3f}", f"{p95:.3f}", "ms", budget))


def main() -> None:
    global QUICK
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    QUICK = ap.parse_args().quick
    sim = Simulation("pioneer-sim", odom_noise=(0.0, 0.0))
    body = sim.scene.base.body
    place = np.array([0.2, 0.9, 0.15])               # in the living room, the coffee table and can ahead
    sim.data.qpos[sim.scene.base.qpos] = place
    mujoco.mj_forward(sim.model, sim.data)
    images, rays = {}, {}
    for name in ("front", "back", "rgb"):
        cam = Camera(sim.model, name, 640, 480, body)
        rays[name] = CameraRays.from_info(cam.info(sim.data))
        images[name] = cam.rgb_jpeg(sim.data) if name == "rgb" else cam.depth(sim.data)
        cam.close()
    small = Camera(sim.model, "rgb", 320, 240, body)
    rgb_small, rgb_small_rays = small.rgb_jpeg(sim.data), CameraRays.from_info(small.info(sim.data))
    small.close()
    small_front = Camera(sim.model, "front", 320, 240, body)
    depth_small, front_small_rays = small_front.depth(sim.data), CameraRays.from_info(small_front.info(sim.data))
    small_front.close()
    sonar = sim.sonar()

    depth = images["front"]
    front, back = DepthToScan(rays["front"]), DepthToScan(rays["back"])
    pitched = DepthToScan(rays["rgb"])               # the RGB camera's pose: pitched 15 deg, "bins"
    row("depth 640x480 -> scan, height band (level camera, 'columns')", lambda: front.convert(depth),
        "<= 2")
    row("  reference: centre row only (depthimage_to_laserscan)", lambda: centre_rows(depth, rays["front"]), "")
    row("  reference: numpy min down the columns, whole image", lambda: depth.min(axis=0), "")
    row("  of which: input check (NaN, inf, negative: min + max)", lambda: rays["front"].check_depth(depth), "")
    row("depth 640x480 -> scan, pitched camera ('bins')", lambda: pitched.convert(depth), "<= 2")
    row("CameraInfo 640x480 -> rays + per-pixel limits (once per CameraInfo)",
        lambda: DepthToScan(CameraRays.from_info(info_of(rays["front"]))), "once", runs=10)

    grid, ring, warner = ScanGrid(), SonarRing.p3at(), ObstacleWarner()
    fs, bs = front.convert(depth), back.convert(images["back"])
    clock = iter(range(10**9))

    def cycle_tail() -> None:
        ranges = ring.fuse(grid, merge(grid, [fs, bs]), sonar)
        warner.update(clearance(ranges, grid, "ahead"), "ahead", float(next(clock)))

    def full_cycle() -> None:
        ranges = merge(grid, [front.convert(depth), back.convert(images["back"])])
        ranges = ring.fuse(grid, ranges, sonar)
        warner.update(clearance(ranges, grid, "ahead"), "ahead", float(next(clock)))

    row("merged 360 scan: merge 2 cameras + sonar fusion + warning", cycle_tail, "")
    row("merged 360 scan, whole cycle: 2 x 640x480 depth + merge + sonar + warning", full_cycle, "<= 5 (2 x 2 + 1)")

    bgr = finder.decode_jpeg(images["rgb"].jpeg, 640, 480)
    row("red finder 640x480: JPEG decode", lambda: finder.decode_jpeg(images["rgb"].jpeg, 640, 480), "", runs=50)
    row("red finder 640x480: HSV threshold + largest blob", lambda: finder.find_blob(bgr, "red"), "", runs=50)
    row("red finder 640x480: front depth points (stride 2)", lambda: rays["front"].points(depth, stride=2), "",
        runs=50)
    row("red finder 640x480, whole find (decode + blob + points + locate)", lambda: finder.find(
        finder.decode_jpeg(images["rgb"].jpeg, 640, 480), "red", rays["rgb"],
        [rays["front"].points(depth, stride=2)]), "<= 100 (an RPC)", runs=50)
    row("red finder 320x240 (the sim's default size), whole find", lambda: finder.find(
        finder.decode_jpeg(rgb_small.jpeg, 320, 240), "red", rgb_small_rays,
        [front_small_rays.points(depth_small)]), "<= 100 (an RPC)", runs=50)
    cloud = rays["front"].points(depth, stride=2)
    answer = finder.find(bgr, "red", rays["rgb"], [cloud])
    if not answer["found"]:
        raise SystemExit(f"the benchmark scene should show the red can: {answer}")
    print(f"perception benchmark: apartment, robot at x={1 + place[0]:.1f} y={1.5 + place[1]:.1f} "
          f"theta={math.degrees(place[2]):.0f} deg; the red can found at {answer['point']} "
          f"({answer['pixels']} pixels); {os.cpu_count()} cores\n")
    print_table(ROWS, header=("what", "median", "p95", "unit", "budget"))


def info_of(r: CameraRays):
    """The CameraInfo a CameraRays was made from (to time building one)."""
    from asibot.messages import CameraInfo
    # The key holds the pose's seven numbers flat (rays._key), so that _same compares each.
    w, h, fx, fy, cx, cy, *pose = r.key
    return CameraInfo(width=w, height=h, fx=fx, fy=fy, cx=cx, cy=cy, pose=pose)


if __name__ == "__main__":
    main()
