"""Vectorized ASIBOT FK/IK for many poses (numpy, no Python loop per pose).

Same maths, conventions, selection and tool frame as AsibotSolver.fwd/inv (see
asibot_solver), for workspace sweeps and path checks.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

if TYPE_CHECKING:
    from .asibot_solver import AsibotSolver

_R = np.pi / 180.0
_D = 180.0 / np.pi


def _wrap180(a: np.ndarray) -> np.ndarray:
    a = np.fmod(a, 360.0)
    a = np.where(a > 180.0, a - 360.0, a)
    return np.where(a <= -180.0, a + 360.0, a)


_norm = _wrap180


def _zyz(a: np.ndarray, b: np.ndarray, g: np.ndarray, position: np.ndarray) -> np.ndarray:
    """N x 4 x 4 transforms with rotation Rz(a) Ry(b) Rz(g) (rad)."""
    ca, sa, cb, sb, cg, sg = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(g), np.sin(g)
    h = np.zeros((len(a), 4, 4))
    h[:, 0, 0], h[:, 0, 1], h[:, 0, 2] = ca * cb * cg - sa * sg, -ca * cb * sg - sa * cg, ca * sb
    h[:, 1, 0], h[:, 1, 1], h[:, 1, 2] = sa * cb * cg + ca * sg, -sa * cb * sg + ca * cg, sa * sb
    h[:, 2, 0], h[:, 2, 1], h[:, 2, 2] = -sb * cg, sb * sg, cb
    h[:, :3, 3] = position
    h[:, 3, 3] = 1.0
    return h


def _points(h: np.ndarray, azimuth_deg: np.ndarray) -> np.ndarray:
    """N x 5 points of N transforms (the batch form of asibot_solver.transform_point)."""
    x, y = h[:, 0, 3], h[:, 1, 3]
    a = np.where(np.hypot(x, y) > 1e-12, np.arctan2(y, x), azimuth_deg * _R)
    ca, sa = np.cos(a), np.sin(a)
    r02 = ca * h[:, 0, 2] + sa * h[:, 1, 2]          # (Rz(-a) R)[0, 2]
    r10 = -sa * h[:, 0, 0] + ca * h[:, 1, 0]         # (Rz(-a) R)[1, 0]
    r11 = -sa * h[:, 0, 1] + ca * h[:, 1, 1]         # (Rz(-a) R)[1, 1]
    out = np.empty((len(h), 5))
    out[:, :3] = h[:, :3, 3]
    out[:, 3] = np.arctan2(r02, h[:, 2, 2]) * _D
    out[:, 4] = _wrap180(np.arctan2(r10, r11) * _D)
    return out


def fwd_batch(s: "AsibotSolver", q: np.ndarray) -> np.ndarray:
    """N x 5 points (m, deg) of N x 5 joints (deg), at the tool frame if one is set."""
    out = _flange_batch(s, q)
    tool = s.tool
    if tool is None:
        return out
    r = np.asarray(q, float) * _R
    h = _zyz(r[:, 0], r[:, 1] + r[:, 2] + r[:, 3], r[:, 4], out[:, :3]) @ tool
    return _points(h, np.asarray(q, float)[:, 0])


def _flange_batch(s: "AsibotSolver", q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, float)
    if q.ndim != 2 or q.shape[1] != 5:
        raise ValueError(f"joints must be an N x 5 array in degrees, got shape {q.shape}")
    r = q * _R
    t2 = r[:, 1]
    t23 = t2 + r[:, 2]
    t234 = t23 + r[:, 3]
    rp = s.a1 * np.sin(t2) + s.a2 * np.sin(t23) + s.a3 * np.sin(t234)
    hp = s.a1 * np.cos(t2) + s.a2 * np.cos(t23) + s.a3 * np.cos(t234)
    oyp = q[:, 1] + q[:, 2] + q[:, 3]
    back = rp < -1e-12
    out = np.empty_like(q)
    out[:, 0] = rp * np.cos(r[:, 0])
    out[:, 1] = rp * np.sin(r[:, 0])
    out[:, 2] = hp + s.a0
    out[:, 3] = np.where(back, -oyp, oyp)
    out[:, 4] = _wrap180(np.where(back, q[:, 4] + 180.0, q[:, 4]))
    return out


CHUNK = 16384  # rows per pass: keeps the temporaries in cache, about twice as fast as one pass


def inv_batch(s: "AsibotSolver", x: np.ndarray, q_guess: Sequence[float] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N x 5 joints in deg, ok mask) for N x 5 points; failed rows are NaN."""
    x = np.asarray(x, float)
    if x.ndim != 2 or x.shape[1] != 5:
        raise ValueError(f"points must be an N x 5 array, got shape {x.shape}")
    g = np.broadcast_to(np.asarray(q_guess, float), x.shape)
    tool = s.tool
    if tool is not None:  # solve for the flange that puts the tool at x
        h = _zyz(np.arctan2(x[:, 1], x[:, 0]), x[:, 3] * _R, x[:, 4] * _R, x[:, :3]) @ np.linalg.inv(tool)
        x = _points(h, g[:, 0])
    q = np.empty_like(x)
    ok = np.empty(len(x), bool)
    for a in range(0, len(x), CHUNK):
        q[a:a + CHUNK], ok[a:a + CHUNK] = _inv_chunk(s, x[a:a + CHUNK], g[a:a + CHUNK])
    return q, ok


def _inv_chunk(s: "AsibotSolver", x: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = len(x)
    rpd = np.hypot(x[:, 0], x[:, 1])
    hpd = x[:, 2] - s.a0
    ok = np.hypot(rpd, hpd) <= s.a1 + s.a2 + s.a3 + 1e-12
    q1 = np.where(rpd > 1e-12, np.arctan2(x[:, 1], x[:, 0]) * _D, g[:, 0])
    oyp = x[:, 3] * _R
    rw = rpd - s.a3 * np.sin(oyp)
    hw = hpd - s.a3 * np.cos(oyp)
    l2 = rw * rw + hw * hw
    l = np.sqrt(l2)
    ok &= (l <= s.a1 + s.a2 + 1e-12) & (l >= 1e-9)
    c3 = np.clip((l2 - s.a1 ** 2 - s.a2 ** 2) / (2 * s.a1 * s.a2), -1.0, 1.0)
    s3 = np.sqrt(1.0 - c3 * c3)
    q3 = np.arctan2(s3, c3) * _D
    k1, k2 = s.a1 + s.a2 * c3, s.a2 * s3
    q2u = np.arctan2(k1 * rw - k2 * hw, k1 * hw + k2 * rw) * _D
    q2d = np.arctan2(k1 * rw + k2 * hw, k1 * hw - k2 * rw) * _D
    q4u = x[:, 3] - q2u - q3
    q4d = x[:, 3] - q2d + q3
    q5 = x[:, 4]
    c = np.empty((n, 4, 5))  # order FU, FD, RU, RD
    q1f = _wrap_any(q1)
    q1r = _wrap_any(q1 + 180.0)
    q5f = _wrap_any(q5)
    q5r = _wrap_any(q5 + 180.0)
    c[:, 0, 0] = q1f; c[:, 1, 0] = q1f; c[:, 2, 0] = q1r; c[:, 3, 0] = q1r
    c[:, 0, 4] = q5f; c[:, 1, 4] = q5f; c[:, 2, 4] = q5r; c[:, 3, 4] = q5r
    c[:, 0, 1] = q2u; c[:, 1, 1] = q2d; c[:, 2, 1] = _flip(q2u); c[:, 3, 1] = _flip(q2d)
    c[:, 0, 2] = q3; c[:, 1, 2] = _flip(q3); c[:, 2, 2] = _flip(q3); c[:, 3, 2] = q3
    q4u = _wrap_any(q4u)
    q4d = _wrap_any(q4d)
    c[:, 0, 3] = q4u; c[:, 1, 3] = q4d; c[:, 2, 3] = _flip(q4u); c[:, 3, 3] = _flip(q4d)
    lo = np.array(s.lower) - 1e-3
    hi = np.array(s.upper) + 1e-3
    gg = g[:, None, :]
    for j in (0, 4):  # circular joints: the turn nearest the guess within limits (as AsibotSolver._turn)
        v = c[..., j]
        d = v - gg[..., j]
        v[:] = np.where((d > 180.0) & (v - 360.0 >= lo[j]), v - 360.0,
                        np.where((d < -180.0) & (v + 360.0 <= hi[j]), v + 360.0, v))
    valid = np.all((c >= lo) & (c <= hi), axis=2) & ok[:, None]
    sums = np.where(valid, np.abs(gg - c).sum(2), np.inf)
    rows = np.arange(n)
    bi = np.argmin(sums, 1)  # first of equal minima: FU, FD, RU, RD, as a stable sort
    bs = sums[rows, bi]
    rest = sums.copy()
    rest[rows, bi] = np.inf  # runner-up: the next in the ranking, an equal sum included
    si = np.argmin(rest, 1)
    has2 = np.isfinite(rest[rows, si])
    same_side = (bi < 2) == (si < 2)
    db = np.abs(g[:, 1] - c[rows, bi, 1])
    ds = np.abs(g[:, 1] - c[rows, si, 1])
    swap = has2 & same_side & ((ds < db) | ((ds == db) & (si % 2 == 0)))
    pick = np.where(swap, si, bi)
    q = c[rows, pick]
    good = np.isfinite(bs)
    q[~good] = np.nan
    return q, good


def _wrap_any(a: np.ndarray) -> np.ndarray:
    """Fold into (-180, 180] (cheaper than fmod for arrays)."""
    w = a - 360.0 * np.floor((a + 180.0) / 360.0)  # [-180, 180)
    return np.where(w == -180.0, 180.0, w)


def _flip(a: np.ndarray) -> np.ndarray:
    """-a folded into (-180, 180] (only -180 needs care)."""
    return np.where(a == 180.0, 180.0, -a)
