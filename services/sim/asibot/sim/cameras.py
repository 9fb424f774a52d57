"""Simulated cameras: depth (metres, float32) and RGB (JPEG), both by offscreen rendering.

Measured on this 2-core machine (apartment world, front camera; bench/bench_sim.py prints
the current figures): one depth image by `mujoco.mj_multiRay` (one ray per pixel) costs
40-50 ms at 320x240 and 140-200 ms at 640x480; the same image rendered with MUJOCO_GL=osmesa
and read from the depth buffer costs 7-10 ms and 11-16 ms, and the two agree to 5 um except
on silhouette edges. So depth is rendered (`method="render"`, the default); the ray caster stays
(`depth_ray`) as the reference the tests compare against. Rendering ties a GL context to a
thread, so every render of a camera happens on the one camera thread. Shadows and
reflections are switched off: they quadruple the RGB cost (40 ms -> 9 ms) and no consumer
needs them.

Default resolution 320x240: the render itself is cheap at 640x480, but the depth message is
four times larger (1.2 MB per frame at 10 Hz per camera) and the consumers (depth -> scan)
do not need it. Resolution is a command-line option.

A still world is not rendered again: a picture is sent again, with the new frame's stamp, while
no coordinate of the world (m, rad) moved more than STILL since it was rendered. A kitchen with
a still arm is most of a teaching session, and rendering its colour and depth pictures took 0.3
of a core of the 0.5 the sim used with a page's camera picture open.

Frames: images are in the ROS optical convention (x right, y down, z forward);
CameraInfo.pose is that optical frame in the robot's base frame (x, y, z, qw, qx, qy, qz);
pixel centres are at integer coordinates, so cx = (width - 1) / 2.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import cv2
import mujoco
import numpy as np

from asibot import messages as m
from asibot.depth import Intrinsics
from asibot.poses import quaternion_wxyz
from asibot.sim.scene import ROBOT_GROUP

MAX_DEPTH_M = 8.0
"""Beyond this a depth camera reports 0 (no return), like a structured-light sensor."""
JPEG_QUALITY = 80
STILL = 1e-4
"""A world that moved less than this (m or rad, every coordinate) looks the same at 320x240,
where a pixel is 3.6 mm wide at 1 m: its last picture is sent again. A held arm and a can at
rest settle by about 5e-6 a second."""

# MuJoCo camera frame (x right, y up, z backwards) -> optical frame (x right, y down, z forward)
_MJ_TO_OPTICAL = np.diag([1.0, -1.0, -1.0])


class Camera:
    """One camera of the world, with its intrinsics and its pose on the robot."""

    def __init__(self, model: mujoco.MjModel, name: str, width: int, height: int, robot_body: int) -> None:
        self.model, self.name = model, name
        self.id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name)
        if self.id < 0:
            raise ValueError(f"the world has no camera {name!r}")
        self.intr = Intrinsics.from_fovy(width, height, float(model.cam_fovy[self.id]))
        self.robot_body = robot_body
        self._rays_optical = self.intr.rays()
        self._z = self._rays_optical[:, 2].copy()     # cos of the angle to the optical axis
        self._geomgroup = np.ones(6, np.uint8)
        self._geomgroup[ROBOT_GROUP] = 0
        n = len(self._z)
        self._geomid = np.zeros(n, np.int32)
        self._dist = np.zeros(n)
        self._renderers: dict[str, mujoco.Renderer] = {}
        self._last: dict[str, tuple[np.ndarray, Any]] = {}   # kind -> (qpos rendered, picture)

    # ------------------------------------------------------------------ geometry
    def optical_rotation(self, data: mujoco.MjData) -> np.ndarray:
        return data.cam_xmat[self.id].reshape(3, 3) @ _MJ_TO_OPTICAL

    def info(self, data: mujoco.MjData, stamp: int | None = None) -> m.CameraInfo:
        """The camera as it was in `data`; `stamp` (ns) is when `data` was copied (default: now)."""
        rb = data.xmat[self.robot_body].reshape(3, 3)
        pos = rb.T @ (data.cam_xpos[self.id] - data.xpos[self.robot_body])
        rot = rb.T @ self.optical_rotation(data)
        return self.intr.info(pos.tolist() + quaternion_wxyz(rot), f"{self.name}_optical",
                              m.now_ns() if stamp is None else stamp)

    # ------------------------------------------------------------------ images
    def depth_ray(self, data: mujoco.MjData) -> np.ndarray:
        """Depth (z along the optical axis, metres) by one ray per pixel; 0 = no return."""
        vec = (self._rays_optical @ self.optical_rotation(data).T).reshape(-1)
        mujoco.mj_multiRay(self.model, data, data.cam_xpos[self.id].copy(), vec, self._geomgroup, 1, -1,
                           self._geomid, self._dist, None, len(self._z), MAX_DEPTH_M)
        depth = self._dist * self._z
        depth[(self._geomid < 0) | (depth > MAX_DEPTH_M)] = 0.0
        return depth.astype(np.float32).reshape(self.intr.height, self.intr.width)

    def _renderer(self, kind: str) -> mujoco.Renderer:
        r = self._renderers.get(kind)
        if r is None:
            r = mujoco.Renderer(self.model, self.intr.height, self.intr.width)
            if kind == "depth":
                r.enable_depth_rendering()
            self._renderers[kind] = r
        return r

    def _update(self, r: mujoco.Renderer, data: mujoco.MjData) -> None:
        opt = mujoco.MjvOption()
        opt.geomgroup[ROBOT_GROUP] = 0
        r.update_scene(data, self.id, scene_option=opt)
        r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
        r.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0

    def _still(self, kind: str, data: mujoco.MjData) -> Any:
        """The last `kind` picture, if the world in `data` is where it was rendered; else None."""
        last = self._last.get(kind)
        if last is None or last[0].shape != data.qpos.shape or np.max(np.abs(data.qpos - last[0])) >= STILL:
            return None
        return last[1]

    def _keep(self, kind: str, data: mujoco.MjData, picture: Any) -> Any:
        self._last[kind] = (data.qpos.copy(), picture)
        return picture

    def depth(self, data: mujoco.MjData, method: str = "render") -> np.ndarray:
        """Depth image, H x W float32 metres, 0 = no return."""
        if method not in ("render", "ray"):
            raise ValueError(f"depth method must be 'render' or 'ray', not {method!r}")
        return self.depth_ray(data) if method == "ray" else self.depth_render(data)

    def depth_frame(self, data: mujoco.MjData, method: str = "render") -> tuple[np.ndarray, bool]:
        """The depth image of a camera frame, and whether it was rendered (False: the world is
        still, and this is the last one again; see STILL). Do not write into it."""
        last = self._still("depth", data)
        if last is not None:
            return last, False
        return self._keep("depth", data, self.depth(data, method)), True

    def rgb_frame(self, data: mujoco.MjData, stamp: int) -> tuple[m.RgbImage, bool]:
        """The colour image of a camera frame, stamped `stamp`, and whether it was rendered."""
        last = self._still("rgb", data)
        if last is not None:
            return dataclasses.replace(last, stamp=stamp), False
        return self._keep("rgb", data, self.rgb_jpeg(data, stamp)), True

    def depth_render(self, data: mujoco.MjData) -> np.ndarray:
        """Depth from the OSMesa depth buffer (MuJoCo converts it to metres along the axis)."""
        r = self._renderer("depth")
        self._update(r, data)
        depth = r.render().astype(np.float32)
        depth[depth > MAX_DEPTH_M] = 0.0
        return depth

    def rgb_jpeg(self, data: mujoco.MjData, stamp: int | None = None) -> m.RgbImage:
        """The colour image of `data`, stamped `stamp` (ns: when `data` was copied; default: now)."""
        r = self._renderer("rgb")
        self._update(r, data)
        rgb = r.render()
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        if not ok:
            raise RuntimeError("OpenCV could not encode the camera image as JPEG")
        return m.RgbImage(jpeg=buf.tobytes(), width=self.intr.width, height=self.intr.height,
                          stamp=m.now_ns() if stamp is None else stamp)

    def close(self) -> None:
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()
