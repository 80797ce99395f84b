"""The coverage measure's loops compiled: the pair search and the refinement's boundary search.

``near_pairs``: ``coverage._near_pairs`` hashes the samples into cubes and, photo by photo,
tests the samples of the cubes near the photo. As numpy array code it built every candidate
pair as arrays (indices, offsets, relative vectors) and was ~20 % of a plan's time; here each
candidate is tested where it is found and only the pairs that pass are written. The tests are
``coverage.imaged``'s, in the same arithmetic order; tests/test_occlusion.py checks the result
against every pair.

``boundary_leaves``: which refinement leaves touch a leaf of the other state. As numpy it
compared every pair of neighbouring cells of each blade's finest grid (about a million) at
every level of the refinement; here only the borders of the leaves just measured are walked.
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
    """(sample, photo, distance, facing) of the pairs that pass, photo-major; within a photo cube
    by cube (offsets x, y, z ascending, z fastest) and in ``by_key`` order within a cube. facing:
    the cosine of the incidence angle.

    keys: the samples' cube keys sorted, by_key: the sample indices in that order; cam: fx, cx,
    cy, width, height (pixels) and the border margins mx, my (pixels)."""
    fx, cx, cy, W, H, mx, my = cam[0], cam[1], cam[2], cam[3], cam[4], cam[5], cam[6]
    near2 = max_dist * max_dist * (1 + 1e-9)
    cap = 1024
    out_s = np.empty(cap, np.int64)
    out_p = np.empty(cap, np.int64)
    out_d = np.empty(cap)
    out_f = np.empty(cap)
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
                            out_f = _grow_float(out_f, cap)
                        out_s[n], out_p[n], out_d[n], out_f[n] = s, p, dist, facing
                        n += 1
    return (_grow_int(out_s[:n], n), _grow_int(out_p[:n], n), _grow_float(out_d[:n], n),
            _grow_float(out_f[:n], n))


@_jit
def boundary_leaves(state: np.ndarray, owner: np.ndarray, levels: int, level: np.ndarray,
                    row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """(K, 3) (level, row, col) of the leaves to cut, repeats possible: of the leaves given
    (level, row, col each) and of their neighbours, those below ``levels`` with a fine cell
    next to a fine cell of the other state (both measured, state >= 0).

    state, owner: one blade's finest grid (rows along the span, columns round the section,
    wrapping), the state of the leaf over each fine cell (-1 none) and that leaf's level. A
    leaf's fine cells share its state, so only the cells along its border can differ from a
    neighbour; a pair of cells neither of which was just measured was compared before, and
    then its leaves were cut unless they were at ``levels`` already."""
    R, C = state.shape
    cap = 1024
    out = np.empty((cap, 3), np.int64)
    n = 0
    for q in range(level.shape[0]):
        lv = level[q]
        b = 1 << (levels - lv)
        r0, c0 = row[q] * b, col[q] * b
        mine = state[r0, c0]
        if mine < 0:
            continue
        hit = False
        for side in range(4):
            t = 0
            while t < b:  # along the border, one neighbouring leaf at a time
                if side == 0:
                    ni, nj = r0 - 1, c0 + t
                elif side == 1:
                    ni, nj = r0 + b, c0 + t
                elif side == 2:
                    ni, nj = r0 + t, (c0 - 1 + C) % C
                else:
                    ni, nj = r0 + t, (c0 + b) % C
                if ni < 0 or ni >= R:
                    break
                o = owner[ni, nj]
                sh = levels - o
                # the next fine cell along this border that lies in another leaf
                t = ((((nj >> sh) + 1) << sh) - c0) if side < 2 else ((((ni >> sh) + 1) << sh) - r0)
                other = state[ni, nj]
                if other < 0 or other == mine:
                    continue
                hit = True
                if o < levels:
                    if n + 2 > cap:
                        cap *= 2
                        out = _grow_rows(out, n, cap)
                    out[n, 0], out[n, 1], out[n, 2] = o, ni >> sh, nj >> sh
                    n += 1
        if hit and lv < levels:
            if n + 2 > cap:
                cap *= 2
                out = _grow_rows(out, n, cap)
            out[n, 0], out[n, 1], out[n, 2] = lv, row[q], col[q]
            n += 1
    return _grow_rows(out, n, n)


@_jit(inline=True)
def _grow_rows(a: np.ndarray, n: int, size: int) -> np.ndarray:
    b = np.empty((size, 3), np.int64)
    for i in range(n):
        for j in range(3):
            b[i, j] = a[i, j]
    return b


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


@_jit
def incidence_flags(s: np.ndarray, dist: np.ndarray, facing: np.ndarray, turn: np.ndarray,
                    half: np.ndarray, limit: float, near: np.ndarray, firm: np.ndarray) -> np.ndarray:
    """``coverage._evaluate``'s marginal test for pairs found up to a wider incidence: sets
    ``near[s]`` where the limit is within the cell's margin of the pair's incidence and
    ``firm[s]`` where the whole cell is within the limit (margin: half the normal's turn across
    the cell plus the angle its half size spans at that distance); True for the pairs within
    the limit itself."""
    deg = 180.0 / math.pi
    inside = np.zeros(s.shape[0], np.bool_)
    for k in range(s.shape[0]):
        i = s[k]
        inc = math.acos(min(max(facing[k], -1.0), 1.0)) * deg
        margin = turn[i] / 2 + half[i] / max(dist[k], 1e-9) * deg
        if abs(inc - limit) <= margin:
            near[i] = True
        if inc <= limit - margin:
            firm[i] = True
        inside[k] = inc <= limit
    return inside


@_jit
def by_sample(s: np.ndarray, g: np.ndarray, m: int) -> tuple:
    """(order, start): the pairs grouped by sample, sample i's at order[start[i]:start[i + 1]],
    finest GSD first, ties in the order given (as ``np.lexsort((g, s))``)."""
    start = np.zeros(m + 1, np.int64)
    for k in range(s.shape[0]):
        start[s[k] + 1] += 1
    for i in range(m):
        start[i + 1] += start[i]
    fill = start[:-1].copy()
    order = np.empty(s.shape[0], np.int64)
    for k in range(s.shape[0]):
        i = s[k]
        j = fill[i]
        while j > start[i] and g[order[j - 1]] > g[k]:  # a sample has a few pairs: insertion
            order[j] = order[j - 1]
            j -= 1
        order[j] = k
        fill[i] += 1
    return order, start


@_jit
def round_pairs(order: np.ndarray, start: np.ndarray, covered: np.ndarray, lo: int,
                width: int) -> np.ndarray:
    """The pairs of tracing round (lo, width): each sample not yet covered, its pairs ranked
    lo .. lo + width - 1 (``by_sample``'s order), sample by sample."""
    n = 0
    for i in range(start.shape[0] - 1):
        if not covered[i]:
            n += max(0, min(start[i] + lo + width, start[i + 1]) - (start[i] + lo))
    out = np.empty(n, np.int64)
    n = 0
    for i in range(start.shape[0] - 1):
        if not covered[i]:
            for k in range(start[i] + lo, min(start[i] + lo + width, start[i + 1])):
                out[n] = order[k]
                n += 1
    return out


@_jit
def paint(state: np.ndarray, owner: np.ndarray, levels: int, level: np.ndarray, row: np.ndarray,
          col: np.ndarray, value: np.ndarray, own: np.ndarray) -> None:
    """Set the fine cells of each leaf (level, row, col) of one blade's finest grid: state to
    ``value`` and owner to ``own`` (``turbine_coverage``'s grids)."""
    for q in range(level.shape[0]):
        b = 1 << (levels - level[q])
        r0, c0 = row[q] * b, col[q] * b
        for i in range(r0, r0 + b):
            for j in range(c0, c0 + b):
                state[i, j] = value[q]
                owner[i, j] = own[q]
