"""The coverage measure's pair search compiled: which (sample, photo) pairs pass ``imaged``.

``coverage._near_pairs`` hashes the samples into cubes and, photo by photo, tests the samples of
the cubes near the photo. As numpy array code it built every candidate pair as arrays (indices,
offsets, relative vectors) and was ~20 % of a plan's time; here each candidate is tested where
it is found and only the pairs that pass are written. The tests are ``coverage.imaged``'s, in
the same arithmetic order; tests/test_occlusion.py checks the result against every pair.
"""

from __future__ import annotations

import math

import numpy as np

from wtcli.geometry.clearance_kernel import _jit  # one place decides how the kernels compile


@_jit
def near_pairs(P: np.ndarray, N: np.ndarray, positions: np.ndarray, rotations: np.ndarray,
               origin: np.ndarray, cell: float, shape: np.ndarray, keys: np.ndarray,
               by_key: np.ndarray, reach: int, cam: np.ndarray, max_dist: float,
               cos_incidence: float, half: float, ball: float) -> tuple:
    """(sample, photo, distance) of the pairs that pass, photo-major; within a photo cube by cube
    (offsets x, y, z ascending, z fastest) and in ``by_key`` order within a cube.

    keys: the samples' cube keys sorted, by_key: the sample indices in that order; cam: fx, cx,
    cy, width, height (pixels) and the border margins mx, my (pixels)."""
    fx, cx, cy, W, H, mx, my = cam[0], cam[1], cam[2], cam[3], cam[4], cam[5], cam[6]
    near2 = max_dist * max_dist * (1 + 1e-9)
    cap = 1024
    out_s = np.empty(cap, np.int64)
    out_p = np.empty(cap, np.int64)
    out_d = np.empty(cap)
    n = 0
    for p in range(positions.shape[0]):
        ox, oy, oz = positions[p, 0], positions[p, 1], positions[p, 2]
        R = rotations[p]
        if not (math.isfinite(ox) and math.isfinite(oy) and math.isfinite(oz)):
            continue  # no cube is near such a photo (numpy: clipped outside the grid)
        top = float(max(shape[0], shape[1], shape[2]) + reach)  # far photos: no cube near either
        c0 = int(min(max(np.floor((ox - origin[0]) / cell), -reach - 1.0), top))
        c1 = int(min(max(np.floor((oy - origin[1]) / cell), -reach - 1.0), top))
        c2 = int(min(max(np.floor((oz - origin[2]) / cell), -reach - 1.0), top))
        for a in range(c0 - reach, c0 + reach + 1):
            if a < 0 or a >= shape[0]:
                continue
            for b in range(c1 - reach, c1 + reach + 1):
                if b < 0 or b >= shape[1]:
                    continue
                for c in range(c2 - reach, c2 + reach + 1):
                    if c < 0 or c >= shape[2]:
                        continue
                    key = (a * shape[1] + b) * shape[2] + c
                    lo = _first_at_least(keys, key)
                    hi = _first_at_least(keys, key + 1)
                    if hi == lo:
                        continue
                    # The cube's bounding ball: too far, or wholly outside the frame's cone.
                    rx = origin[0] + (a + 0.5) * cell - ox
                    ry = origin[1] + (b + 0.5) * cell - oy
                    rz = origin[2] + (c + 0.5) * cell - oz
                    d = math.sqrt(rx * rx + ry * ry + rz * rz)
                    if d > max_dist + ball:
                        continue
                    if d > ball:
                        cos_off = (rx * R[2, 0] + ry * R[2, 1] + rz * R[2, 2]) / max(d, 1e-12)
                        off_axis = math.acos(min(max(cos_off, -1.0), 1.0))
                        spread = math.asin(min(max(ball / max(d, 1e-12), 0.0), 1.0))
                        if off_axis > half + spread:
                            continue
                    for k in range(lo, hi):
                        s = by_key[k]
                        x, y, z = P[s, 0] - ox, P[s, 1] - oy, P[s, 2] - oz
                        d2 = x * x + y * y + z * z
                        if not d2 <= near2:
                            continue
                        dist = math.sqrt(d2)
                        if not dist <= max_dist:
                            continue
                        facing = -(x * N[s, 0] + y * N[s, 1] + z * N[s, 2]) / max(dist, 1e-9)
                        if not facing >= cos_incidence:
                            continue
                        zc = x * R[2, 0] + y * R[2, 1] + z * R[2, 2]
                        if not zc > 0.1:
                            continue
                        u = fx * (x * R[0, 0] + y * R[0, 1] + z * R[0, 2]) / zc + cx
                        v = fx * (x * R[1, 0] + y * R[1, 1] + z * R[1, 2]) / zc + cy
                        if not (u >= mx and u <= W - 1 - mx and v >= my and v <= H - 1 - my):
                            continue
                        if n == cap:
                            cap *= 2
                            out_s = _grow_int(out_s, cap)
                            out_p = _grow_int(out_p, cap)
                            out_d = _grow_float(out_d, cap)
                        out_s[n], out_p[n], out_d[n] = s, p, dist
                        n += 1
    return _grow_int(out_s[:n], n), _grow_int(out_p[:n], n), _grow_float(out_d[:n], n)


@_jit(inline=True)
def _first_at_least(keys: np.ndarray, key: int) -> int:
    """np.searchsorted(keys, key) on sorted integer keys (a plain bisection compiles in a
    fraction of numba's generic one)."""
    lo, hi = 0, keys.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if keys[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo


@_jit(inline=True)
def _grow_int(a: np.ndarray, size: int) -> np.ndarray:
    b = np.empty(size, np.int64)
    for i in range(a.shape[0]):  # element by element: slice assignment compiles 10x slower
        b[i] = a[i]
    return b


@_jit(inline=True)
def _grow_float(a: np.ndarray, size: int) -> np.ndarray:
    b = np.empty(size)
    for i in range(a.shape[0]):
        b[i] = a[i]
    return b
