"""Navigation logic figures, each beside a simple reference measured in the same run.

Prints one markdown table. Budgets (docs/design.md, issue 13): AMCL update with 2000
particles and 60 beams 10 ms; a global plan across the apartment and on a 20 m x 20 m, 5 cm
map 50 ms. The references are what a straightforward port would do: the likelihood field one
particle at a time, Dijkstra with Python's heapq, the controller one trajectory at a time,
the bare distance transform under the inflation, and a mapping scan raytraced beam by beam
(Bresenham).

    python bench/bench_nav.py [--quick]
"""

from __future__ import annotations

import argparse
import heapq
import math
import statistics
import time
from pathlib import Path

import cv2
import numpy as np

from asibot.messages import LaserScan
from asibot.nav.amcl import Amcl, AmclParams
from asibot.nav.costmap import INSCRIBED, Costmap
from asibot.nav.geometry import Pose
from asibot.nav.grid import GridInfo, OccupancyGrid
from asibot.nav.local import LocalController, arcs
from asibot.nav.mapfile import load_map
from asibot.nav.mapping import Mapper
from asibot.nav.planner import GlobalPlanner
from asibot.nav.places import Places, world_places_file

from table import QUICK_HELP, print_table  # bench/table.py: run as `python bench/<name>.py`

MAP = Path(__file__).resolve().parents[1] / "libs" / "common" / "asibot" / "maps" / "apartment.yaml"
QUICK = False


def p50_ms(fn, repeat: int = 30) -> float:
    times = []
    for _ in range(1 if QUICK else repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3


def scan_from(grid: OccupancyGrid, pose: Pose, beams: int = 360, range_max: float = 8.0) -> LaserScan:
    inc = 2 * math.pi / beams
    a = -math.pi + inc * np.arange(beams)
    t = np.arange(0.05, range_max, 0.01)
    x = pose.x + np.cos(pose.theta + a)[:, None] * t
    y = pose.y + np.sin(pose.theta + a)[:, None] * t
    r, c = grid.info.to_cell(x, y)
    ok = grid.info.inside(r, c)
    hit = np.zeros(x.shape, bool)
    hit[ok] = grid.occupied[r[ok], c[ok]]
    ranges = np.where(hit.any(axis=1), t[hit.argmax(axis=1)], np.inf).astype(np.float32)
    return LaserScan(angle_min=-math.pi, angle_increment=inc, range_min=0.05, range_max=range_max, ranges=ranges)


def house(size_m: float = 20.0, res: float = 0.05, seed: int = 0) -> OccupancyGrid:
    """A 20 m x 20 m flat: 4 x 4 rooms with doors, and furniture, at 5 cm."""
    n = int(size_m / res)
    data = np.zeros((n, n), np.int8)
    rng = np.random.default_rng(seed)
    room = n // 4
    for k in range(5):
        i = min(n - 2, k * room)
        data[i:i + 2, :] = 100
        data[:, i:i + 2] = 100
    for a in range(4):
        for b in range(4):
            r0, c0 = a * room, b * room
            if b < 3:   # a door east
                d = r0 + rng.integers(6, room - 26)
                data[d:d + 20, c0 + room:c0 + room + 2] = 0
            if a < 3:   # a door north
                d = c0 + rng.integers(6, room - 26)
                data[r0 + room:r0 + room + 2, d:d + 20] = 0
            for _ in range(2):   # furniture
                h, w = rng.integers(8, 20, 2)
                rr, cc = r0 + rng.integers(12, room - 12 - h), c0 + rng.integers(12, room - 12 - w)
                data[rr:rr + h, cc:cc + w] = 100
    return OccupancyGrid(GridInfo(n, n, res), data)


def heapq_dijkstra(costmap: Costmap, start: Pose, goal: Pose) -> float:
    """The reference planner: Dijkstra over the same navfn cell costs, one cell at a time."""
    c = costmap.costs
    h, w = c.shape
    cost = (50.0 + 0.8 * c.astype(float)).ravel().tolist()
    blocked = (c >= INSCRIBED).ravel().tolist()
    (sr,), (sc,) = costmap.info.to_cell(np.array([start.x]), np.array([start.y]))
    (gr,), (gc,) = costmap.info.to_cell(np.array([goal.x]), np.array([goal.y]))
    s, g = int(sr) * w + int(sc), int(gr) * w + int(gc)
    dist = {s: 0.0}
    heap = [(0.0, s)]
    steps = [(-1, 0, 1.0), (1, 0, 1.0), (0, -1, 1.0), (0, 1, 1.0),
             (-1, -1, 1.414), (-1, 1, 1.414), (1, -1, 1.414), (1, 1, 1.414)]
    while heap:
        d, u = heapq.heappop(heap)
        if u == g:
            return d
        if d > dist.get(u, math.inf):
            continue
        r, col = divmod(u, w)
        for dr, dc, f in steps:
            rr, cc = r + dr, col + dc
            if 0 <= rr < h and 0 <= cc < w:
                v = rr * w + cc
                if not blocked[v]:
                    nd = d + f * cost[v]
                    if nd < dist.get(v, math.inf):
                        dist[v] = nd
                        heapq.heappush(heap, (nd, v))
    return math.inf


def bresenham_scan(logodds: np.ndarray, info: GridInfo, pose: Pose, scan: LaserScan, max_range: float) -> None:
    """The reference mapper update: each beam's cells walked one at a time (Bresenham), misses
    along the way and a hit at the end, in Python."""
    r0, c0 = (int(v) for v in info.to_cell(pose.x, pose.y))
    for i, rng_ in enumerate(scan.ranges):
        if not math.isfinite(rng_) and not math.isinf(rng_):
            continue
        hit = math.isfinite(rng_) and rng_ < scan.range_max and rng_ <= max_range
        d = min(float(rng_), max_range)
        a = pose.theta + scan.angle_min + i * scan.angle_increment
        r1, c1 = (int(v) for v in info.to_cell(pose.x + d * math.cos(a), pose.y + d * math.sin(a)))
        dr, dc = abs(r1 - r0), abs(c1 - c0)
        sr, sc = (1 if r1 > r0 else -1), (1 if c1 > c0 else -1)
        err, r, c = dc - dr, r0, c0
        while (r, c) != (r1, c1):
            if 0 <= r < info.height and 0 <= c < info.width:
                logodds[r, c] -= 0.4
            e2 = 2 * err
            if e2 > -dr:
                err -= dr
                c += sc
            if e2 < dc:
                err += dc
                r += sr
        if hit and 0 <= r1 < info.height and 0 <= c1 < info.width:
            logodds[r1, c1] += 0.85


def main() -> None:
    global QUICK
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    QUICK = ap.parse_args().quick
    apartment = load_map(MAP).grid
    places = Places(Path("/nonexistent/places.yaml"), world_places_file())
    station = places.get("charging station").pose
    rows = []

    # AMCL: a full forced update (motion, likelihood field, KLD resample, clusters)
    amcl = Amcl(apartment, AmclParams(min_particles=2000, max_particles=2000, max_beams=60), seed=0)
    amcl.set_pose(station)
    scan = scan_from(apartment, station)
    odom = [Pose(0.0, 0.0, 0.0)]

    def amcl_update():
        odom[0] = Pose(odom[0].x + 0.25, 0.0, 0.0)
        amcl._force = True
        amcl.update(odom[0], scan)
    rows.append(("AMCL update, 2000 particles, 60 beams", p50_ms(amcl_update), "ms", "10"))
    r, a = amcl.beams(scan)

    def one_by_one(n=100):
        table = amcl._pz_table(float(scan.range_max))
        for x, y, th in amcl.poses[:n]:
            p = 0.0
            for rng_, ang in zip(r, a):
                ex, ey = x + rng_ * math.cos(th + ang), y + rng_ * math.sin(th + ang)
                row, col = apartment.info.to_cell(ex, ey)
                p += math.log(table[int(row) * apartment.info.width + int(col)])
    rows.append(("reference: likelihood field one particle at a time (Python), 2000 particles",
                 p50_ms(one_by_one, 3) * 20, "ms", "-"))

    # global plans
    cm = Costmap(apartment)
    planner = GlobalPlanner()
    pairs = [(a_.pose, b_.pose) for a_ in places.list() for b_ in places.list() if a_ != b_]
    times = [p50_ms(lambda s=s, g=g: planner.plan(cm, s, g), 5) for s, g in pairs]
    rows.append((f"global plan across the apartment, 11.5 m x 9.5 m at 5 cm (worst of {len(pairs)} place pairs)",
                 max(times), "ms", "50"))
    far = max(pairs, key=lambda sg: sg[0].distance(sg[1]))
    rows.append(("reference: Dijkstra with heapq, same costs, farthest pair", p50_ms(lambda: heapq_dijkstra(cm, *far), 1),
                 "ms", "-"))
    big = Costmap(house())
    corner_a, corner_b = Pose(1.0, 1.0, 0.0), Pose(19.0, 19.0, 0.0)
    rows.append(("global plan on a 20 m x 20 m map at 5 cm, corner to corner",
                 p50_ms(lambda: planner.plan(big, corner_a, corner_b), 10), "ms", "50"))
    rows.append(("reference: Dijkstra with heapq, same map", p50_ms(lambda: heapq_dijkstra(big, corner_a, corner_b), 1),
                 "ms", "-"))

    # local controller
    ctl = LocalController()
    fridge = places.get("fridge").pose
    ctl.set_path(planner.plan(cm, station, fridge))
    here = Pose(2.0, 1.6, 0.0)
    rows.append((f"local controller cycle ({ctl.params.vx_samples} x {ctl.params.wz_samples} samples, "
                 f"{ctl.params.sim_time:g} s ahead)", p50_ms(lambda: ctl.compute(here, (0.3, 0.0), cm)), "ms", "100 (10 Hz)"))
    t = np.arange(1, 16) * 0.1

    def per_trajectory():
        for v in np.linspace(0.2, 0.4, ctl.params.vx_samples):
            for w in np.linspace(-0.2, 0.2, ctl.params.wz_samples):
                xs, ys, ths = arcs(here.x, here.y, here.theta, np.array([v]), np.array([w]), t)
                cm.footprint_cost(xs, ys, ths)
    rows.append(("reference: the same footprint checks one trajectory at a time", p50_ms(per_trajectory, 5), "ms", "-"))

    # costmap update per scan (360 beams): raytrace, mark, and re-inflate
    live = Costmap(apartment)
    scan360 = scan_from(apartment, here)
    clock = [0.0]

    def update():
        clock[0] += 0.1
        live.update_scan(here, scan360, clock[0])
        live.costs
    rows.append(("costmap update per scan (360 beams, raytrace + mark + inflate the whole map)", p50_ms(update), "ms", "-"))
    lethal = (live.costs < 254).astype(np.uint8)
    rows.append(("reference: one cv2.distanceTransform of the same map",
                 p50_ms(lambda: cv2.distanceTransform(lethal, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)), "ms", "-"))

    # mapping: one 360-beam scan matched against the map so far, raytraced and marked (the robot
    # going back and forth across the living room, 0.25 m a scan, after a first pass)
    poses = [Pose(1.0 + 0.25 * i, 1.5 + 0.1 * math.sin(i), 0.05 * i) for i in range(13)]
    scans = [scan_from(apartment, p) for p in poses]
    mapper = Mapper(poses[0])
    for p, s in zip(poses, scans):
        mapper.update(p, s)
    turn = [len(poses) - 1, 1]

    def mapping_update():
        i, step = turn
        if not 0 <= i + step < len(poses):
            step = -step
        turn[:] = [i + step, step]
        assert mapper.update(poses[i + step], scans[i + step])
    rows.append(("mapping update per scan (360 beams: match in x, y, theta + raytrace + mark)",
                 p50_ms(mapping_update), "ms", "-"))
    info = mapper.info
    rows.append(("reference: the same scan raytraced beam by beam (Bresenham, Python), no matching",
                 p50_ms(lambda: bresenham_scan(mapper.logodds.copy(), info, poses[6], scans[6],
                                               mapper.params.max_range), 10), "ms", "-"))
    print_table(rows)


if __name__ == "__main__":
    main()
