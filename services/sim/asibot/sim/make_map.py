"""Occupancy map of a world, generated from its MJCF, so the map and the world never disagree.

Output: ROS map_server format (docs/maps.md): a binary PGM (P5) with map_saver's
colours (occupied 0, free 254, unknown 205) and a YAML with resolution, origin (pose of the
lower-left pixel), negate 0, occupied_thresh 0.65, free_thresh 0.196. The image's top row
is the largest y.

A cell is occupied when the footprint of any static, collidable geom whose vertical extent
meets the band [floor + 2 cm, robot height] covers any of its 4x4 sample points. Free
objects (cans, cups) and the robot are not part of the map. Cells off the floor are unknown.

    python -m asibot.sim.make_map                  # regenerate libs/common/asibot/maps/apartment.*
    python -m asibot.sim.make_map --world kitchen --out /tmp
"""

from __future__ import annotations
from importlib import resources

import argparse
import math
from pathlib import Path

import mujoco
import numpy as np

from asibot.sim.scene import world_path

MAPS_DIR = Path(str(resources.files("asibot.maps")))
RESOLUTION_M = 0.05
FLOOR_CLEARANCE_M = 0.02
ROBOT_HEIGHT_M = 1.2
"""P3-AT top plate at 0.274 m (docs/arcos.md "P3-AT parameters") plus the Katana folded
above it, rounded up."""
SAMPLES = 4
MARGIN_M = 0.2
FREE, OCCUPIED, UNKNOWN = 254, 0, 205


def _static_geoms(model: mujoco.MjModel) -> list[int]:
    """Collidable geoms fixed to the world (no joint between them and the world)."""
    return [g for g in range(model.ngeom)
            if model.body_weldid[model.geom_bodyid[g]] == 0
            and (model.geom_contype[g] or model.geom_conaffinity[g])
            and model.geom_type[g] != mujoco.mjtGeom.mjGEOM_PLANE]


def _vertical_half_extent(model: mujoco.MjModel, g: int, rot: np.ndarray) -> float:
    size, t = model.geom_size[g], int(model.geom_type[g])
    if t == mujoco.mjtGeom.mjGEOM_BOX:
        return float(np.abs(rot[2]) @ size)
    if t in (mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_CAPSULE):
        c = abs(rot[2, 2])
        cap = size[0] if t == mujoco.mjtGeom.mjGEOM_CAPSULE else 0.0
        return float(c * size[1] + size[0] * math.sqrt(max(0.0, 1 - c * c)) + cap)
    return float(model.geom_rbound[g])


def _covers(model: mujoco.MjModel, g: int, pos: np.ndarray, rot: np.ndarray,
            px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Boolean mask: which sample points (px, py) lie in the geom's footprint."""
    size, t = model.geom_size[g], int(model.geom_type[g])
    dx, dy = px - pos[0], py - pos[1]
    if t == mujoco.mjtGeom.mjGEOM_BOX:
        # Footprint of an oriented box: the point's line along z meets the box. For boxes
        # rotated only about z (all our furniture) this is the exact rectangle.
        lx = rot[0, 0] * dx + rot[1, 0] * dy
        ly = rot[0, 1] * dx + rot[1, 1] * dy
        ex = size[0] + abs(rot[2, 0]) * size[2]
        ey = size[1] + abs(rot[2, 1]) * size[2]
        return (np.abs(lx) <= ex) & (np.abs(ly) <= ey)
    if t in (mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_CAPSULE) and abs(rot[2, 2]) > 0.999:
        return dx * dx + dy * dy <= size[0] ** 2
    r = model.geom_rbound[g]
    return dx * dx + dy * dy <= r * r


def occupancy(world: str) -> tuple[np.ndarray, tuple[float, float]]:
    """The map as a PGM-ready uint8 image (top row = largest y) and its origin (x, y)."""
    model = mujoco.MjModel.from_xml_path(str(world_path(world)))
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    floors = [g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE]
    if not floors:
        raise ValueError(f"world {world!r} has no floor plane")
    fpos, fsize = data.geom_xpos[floors[0]], model.geom_size[floors[0]]
    geoms = _static_geoms(model)
    lo = np.array([fpos[0] - fsize[0], fpos[1] - fsize[1]])
    hi = np.array([fpos[0] + fsize[0], fpos[1] + fsize[1]])
    for g in geoms:  # walls stand just outside the floor: include them
        r = model.geom_rbound[g]
        lo = np.minimum(lo, data.geom_xpos[g][:2] - min(r, 0.5))
        hi = np.maximum(hi, data.geom_xpos[g][:2] + min(r, 0.5))
    x0 = math.floor((lo[0] - MARGIN_M) / RESOLUTION_M) * RESOLUTION_M
    y0 = math.floor((lo[1] - MARGIN_M) / RESOLUTION_M) * RESOLUTION_M
    w = int(math.ceil((hi[0] + MARGIN_M - x0) / RESOLUTION_M))
    h = int(math.ceil((hi[1] + MARGIN_M - y0) / RESOLUTION_M))
    sub = (np.arange(SAMPLES) + 0.5) / SAMPLES * RESOLUTION_M
    xs = x0 + (np.arange(w)[:, None] * RESOLUTION_M + sub[None, :]).reshape(-1)
    ys = y0 + (np.arange(h)[:, None] * RESOLUTION_M + sub[None, :]).reshape(-1)
    px, py = np.meshgrid(xs, ys)  # (h*S, w*S), row = y
    hit = np.zeros(px.shape, bool)
    for g in geoms:
        pos, rot = data.geom_xpos[g], data.geom_xmat[g].reshape(3, 3)
        half = _vertical_half_extent(model, g, rot)
        if pos[2] + half < FLOOR_CLEARANCE_M or pos[2] - half > ROBOT_HEIGHT_M:
            continue
        hit |= _covers(model, g, pos, rot, px, py)
    occupied = hit.reshape(h, SAMPLES, w, SAMPLES).any(axis=(1, 3))
    cx = x0 + (np.arange(w) + 0.5) * RESOLUTION_M
    cy = y0 + (np.arange(h) + 0.5) * RESOLUTION_M
    on_floor = ((np.abs(cx - fpos[0]) <= fsize[0])[None, :] & (np.abs(cy - fpos[1]) <= fsize[1])[:, None])
    img = np.full((h, w), UNKNOWN, np.uint8)
    img[on_floor] = FREE
    img[occupied] = OCCUPIED
    return np.flipud(img).copy(), (round(x0, 6), round(y0, 6))


def pgm_bytes(img: np.ndarray) -> bytes:
    h, w = img.shape
    return f"P5\n# asibot.sim.make_map\n{w} {h}\n255\n".encode() + img.tobytes()


def yaml_text(image_name: str, origin: tuple[float, float]) -> str:
    return (f"image: {image_name}\nresolution: {RESOLUTION_M}\n"
            f"origin: [{origin[0]}, {origin[1]}, 0.0]\n"
            "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\nmode: trinary\n")


def write(world: str, out_dir: Path = MAPS_DIR) -> tuple[Path, Path]:
    img, origin = occupancy(world)
    out_dir.mkdir(parents=True, exist_ok=True)
    pgm, yml = out_dir / f"{world}.pgm", out_dir / f"{world}.yaml"
    for path, content in ((pgm, pgm_bytes(img)), (yml, yaml_text(pgm.name, origin).encode())):
        tmp = path.with_suffix(path.suffix + ".tmp")
        tmp.write_bytes(content)
        tmp.replace(path)  # atomic: a crash never leaves half a map
    return pgm, yml


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m asibot.sim.make_map", description=__doc__.split("\n")[0])
    p.add_argument("--world", default="apartment", choices=["apartment", "kitchen"])
    p.add_argument("--out", type=Path, default=MAPS_DIR, help="output folder")
    args = p.parse_args(argv)
    pgm, yml = write(args.world, args.out)
    print(f"wrote {pgm} and {yml}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
