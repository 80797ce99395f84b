"""``Site``'s clearance queries compiled: grid lookup, box culling and each turbine's distance in
one call per query.

The planner asks for the clearance of a few points or legs at a time, thousands of times per
turbine; as numpy code each query paid ~0.1-0.5 ms of array overhead (grid lookup, slab tests,
sample generation) around the compiled turbine distance. The rules are ``clearance``'s module
docstring's, unchanged: the same culling boxes, the same leg samples, the same values;
tests/test_plan.py checks them against every turbine and every sample.

The kernels take the site as ``Site._kernel_grid`` lays it out: box corners, the cell grid, the
stacked turbine parameters of ``Turbine._kernel_params`` and each turbine's geometry uncertainty.
"""

from __future__ import annotations

import math

import numpy as np

from wtcli.geometry.clearance_kernel import _jit, point_clearance


@_jit(inline=True)
def _cell(px: float, py: float, origin: np.ndarray, cell: float, shape: np.ndarray) -> int:
    """The grid cell of a point, or -1 outside the grid (or NaN)."""
    fx = np.floor((px - origin[0]) / cell)  # a float: math.floor's integer overflows far out
    fy = np.floor((py - origin[1]) / cell)
    if not (fx >= 0 and fy >= 0 and fx < shape[0] and fy < shape[1]):
        return -1
    return int(fx) * shape[1] + int(fy)


@_jit(inline=True)
def _inside(t: int, px: float, py: float, pz: float, grow: float, horizon: bool, lo: np.ndarray,
            hi: np.ndarray, part_lo: np.ndarray, part_hi: np.ndarray) -> bool:
    """Whether the point lies in turbine t's box grown by the horizon (``horizon``), else in
    one of its two part boxes grown by ``grow``."""
    if horizon:
        return (lo[t, 0] <= px <= hi[t, 0] and lo[t, 1] <= py <= hi[t, 1]
                and lo[t, 2] <= pz <= hi[t, 2])
    for b in range(2):
        L, U = part_lo[t, b], part_hi[t, b]
        if (L[0] - grow <= px <= U[0] + grow and L[1] - grow <= py <= U[1] + grow
                and L[2] - grow <= pz <= U[2] + grow):
            return True
    return False


@_jit(inline=True)
def _point(px: float, py: float, pz: float, grow: float, horizon: bool, cap: float, lo, hi,
           part_lo, part_hi, origin, cell, shape, start, members, vec, sc, frames, nb,
           unc) -> float:
    """``Site.clearance`` of one point: the least distance of the turbines whose box holds it,
    each less its geometry uncertainty ``unc[t]`` (the distance to the model grown by it, a
    lower bound), at most ``grow``; NaN for a NaN point."""
    if math.isnan(px) or math.isnan(py) or math.isnan(pz):
        return np.nan
    out = grow
    c = _cell(px, py, origin, cell, shape)
    if c < 0:
        return out
    for m in range(start[c], start[c + 1]):
        t = members[m]
        if _inside(t, px, py, pz, grow, horizon, lo, hi, part_lo, part_hi):
            d = point_clearance(px, py, pz, vec, sc, frames, t, nb[t], cap + unc[t]) - unc[t]
            out = min(out, max(d, 0.0))
    return out


@_jit
def clearance(P: np.ndarray, grow: float, horizon: bool, cap: float, lo, hi, part_lo, part_hi,
              origin, cell, shape, start, members, vec, sc, frames, nb, unc) -> np.ndarray:
    out = np.empty(P.shape[0])
    for i in range(P.shape[0]):
        out[i] = _point(P[i, 0], P[i, 1], P[i, 2], grow, horizon, cap, lo, hi, part_lo, part_hi,
                        origin, cell, shape, start, members, vec, sc, frames, nb, unc)
    return out


@_jit
def near(P: np.ndarray, lo, hi, part_lo, part_hi, origin, cell, shape, start,
         members) -> tuple:
    """(point, turbine) of every point inside a turbine's box grown by the horizon, point by
    point, turbines ascending."""
    pp = np.empty(4 * P.shape[0] + 1, np.int64)
    tt = np.empty(4 * P.shape[0] + 1, np.int64)
    n = 0
    for i in range(P.shape[0]):
        c = _cell(P[i, 0], P[i, 1], origin, cell, shape)
        if c < 0:
            continue
        for m in range(start[c], start[c + 1]):
            t = members[m]
            if _inside(t, P[i, 0], P[i, 1], P[i, 2], 0.0, True, lo, hi, part_lo, part_hi):
                if n == pp.shape[0]:  # a point in more boxes than 4 on average: grow
                    pp = np.concatenate((pp, np.empty(n, np.int64)))
                    tt = np.concatenate((tt, np.empty(n, np.int64)))
                pp[n], tt[n] = i, t
                n += 1
    return pp[:n].copy(), tt[:n].copy()


@_jit
def stretches(ax: float, ay: float, az: float, bx: float, by: float, bz: float, m: int,
              slab_lo: np.ndarray, slab_hi: np.ndarray) -> tuple:
    """(first, last) sample index of the runs of the leg a -> b (samples j / m, j = 0..m) that
    pass through a box (slab_lo/hi: the culling boxes with their 1 cm): ascending, merged where
    they touch or overlap.

    Conservative: the entry and exit get a slack of 1e-3 of the leg and one sample each side,
    far beyond the rounding of the slab times (an axis the leg hardly moves along, < 1 um, is
    tested at its start); samples left out are outside every box."""
    K = slab_lo.shape[0]
    j0s = np.empty(K, np.int64)
    j1s = np.empty(K, np.int64)
    n = 0
    A = (ax, ay, az)
    B = (bx, by, bz)
    for k in range(K):
        overlap = True
        for d in range(3):
            if not (min(A[d], B[d]) <= slab_hi[k, d] and max(A[d], B[d]) >= slab_lo[k, d]):
                overlap = False
        if not overlap:
            continue
        t_in, t_out = -np.inf, np.inf
        for d in range(3):
            D = B[d] - A[d]
            lo_k, hi_k = slab_lo[k, d], slab_hi[k, d]
            if abs(D) < 1e-6:
                within = A[d] >= lo_k and A[d] <= hi_k
                t_in = max(t_in, -np.inf if within else np.inf)
                t_out = min(t_out, np.inf if within else -np.inf)
            else:
                ta, tb = (lo_k - A[d]) / D, (hi_k - A[d]) / D
                t_in = max(t_in, min(ta, tb))
                t_out = min(t_out, max(ta, tb))
        t_in = max(t_in, 0.0) - 1e-3
        t_out = min(t_out, 1.0) + 1e-3
        if not t_in <= t_out:
            continue
        j0s[n] = min(max(math.floor(t_in * m) - 1, 0), m)
        j1s[n] = min(max(math.ceil(t_out * m) + 1, 0), m)
        n += 1
    # By first sample (insertion sort: a leg meets a few boxes; np.argsort compiles slowly),
    # then merged.
    for i in range(1, n):
        a, b = j0s[i], j1s[i]
        k = i - 1
        while k >= 0 and j0s[k] > a:
            j0s[k + 1], j1s[k + 1] = j0s[k], j1s[k]
            k -= 1
        j0s[k + 1], j1s[k + 1] = a, b
    runs = 0
    for i in range(n):
        if runs and j0s[i] <= j1s[runs - 1] + 1:
            j1s[runs - 1] = max(j1s[runs - 1], j1s[i])
        else:
            j0s[runs], j1s[runs] = j0s[i], j1s[i]
            runs += 1
    return j0s[:runs], j1s[:runs]


@_jit
def segment_clearance(p0: np.ndarray, p1: np.ndarray, n: np.ndarray, slab_lo: np.ndarray,
                      slab_hi: np.ndarray, grow: float, horizon: bool, cap: float, lo, hi,
                      part_lo, part_hi, origin, cell, shape, start, members, vec, sc, frames,
                      nb, unc) -> np.ndarray:
    """Per leg, the least ``_point`` clearance over its samples j / n (j = 0..n) inside a culling
    box; ``grow`` where none is (the caller subtracts half the sample spacing)."""
    out = np.full(p0.shape[0], grow)
    for i in range(p0.shape[0]):
        ax, ay, az = p0[i, 0], p0[i, 1], p0[i, 2]
        dx, dy, dz = p1[i, 0] - ax, p1[i, 1] - ay, p1[i, 2] - az
        r0, r1 = stretches(ax, ay, az, p1[i, 0], p1[i, 1], p1[i, 2], n[i], slab_lo, slab_hi)
        best = grow
        for r in range(r0.shape[0]):
            for j in range(r0[r], r1[r] + 1):
                t = j / n[i]
                c = _point(ax + dx * t, ay + dy * t, az + dz * t, grow, horizon, cap, lo, hi,
                           part_lo, part_hi, origin, cell, shape, start, members, vec, sc,
                           frames, nb, unc)
                best = min(best, c)
        out[i] = best
    return out


@_jit
def ground_index(P: np.ndarray, G: np.ndarray, origin: np.ndarray, cell: float,
                 shape: np.ndarray, start: np.ndarray, members: np.ndarray,
                 brute: bool) -> np.ndarray:
    """``Site.ground_index``: per point, the index of the ground point nearest in x/y (the lowest
    of equally near ones), from the 3 x 3 cells around the point's cell where the nearest found
    there is within one cell size, else by comparing all (``brute``: always)."""
    out = np.empty(P.shape[0], np.int64)
    for i in range(P.shape[0]):
        px, py = P[i, 0], P[i, 1]
        best, near = G.shape[0], np.inf
        if not brute:
            fx = np.floor((px - origin[0]) / cell) if math.isfinite(px) else -2.0
            fy = np.floor((py - origin[1]) / cell) if math.isfinite(py) else -2.0
            for dx in (-1.0, 0.0, 1.0):
                for dy in (-1.0, 0.0, 1.0):
                    cx, cy = fx + dx, fy + dy
                    if not (cx >= 0 and cy >= 0 and cx < shape[0] and cy < shape[1]):
                        continue
                    c = int(cx) * shape[1] + int(cy)
                    for m in range(start[c], start[c + 1]):
                        g = members[m]
                        ex, ey = px - G[g, 0], py - G[g, 1]
                        d = math.sqrt(ex * ex + ey * ey)
                        if d < near or (d == near and g < best):
                            best, near = g, d
        if brute or not near < cell * (1 - 1e-9) - 1e-9:  # rounding of the cell arithmetic
            best, near = 0, np.inf
            for g in range(G.shape[0]):  # np.argmin's: the first least, or the first NaN
                ex, ey = px - G[g, 0], py - G[g, 1]
                d = math.sqrt(ex * ex + ey * ey)
                if math.isnan(d):
                    best = g
                    break
                if d < near:
                    best, near = g, d
        out[i] = best
    return out
