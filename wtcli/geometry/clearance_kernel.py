"""``Turbine.clearance`` compiled: the same distance model, point by point, in one call.

The planner asks for the clearance of a few to a few hundred points at a time, tens of thousands
of times for a large site; as numpy array code each such call paid ~40-250 us of per-call
overhead whatever its size, and the clearance was ~40 % of a plan's time. Compiled with numba,
a point costs well under a microsecond (measured: docs/plan.md "Figures").

The model is ``Turbine.clearance_by_part``'s (numpy, kept as the reference): hub sphere,
nacelle box, each blade's elliptical sections with the taper factor, the tower frustum. Parts
are evaluated in the same order with the same pruning (a part's exact distance only where its
cheap bound is below the least exact distance so far and the cap), so values below the cap are
the reference's, to rounding; tests/test_geometry.py checks them against it on random turbines.
A point with a NaN coordinate gets NaN (never a distance that could read as safe).
"""

from __future__ import annotations

import math

import numba
import numpy as np


def _jit(fn=None, *, inline: bool = False):
    """Compiled once per machine (about a second), then loaded from numba's cache (the package's
    __pycache__, else the user's cache folder). Where neither is writable (a read-only install
    and no home) numba refuses to cache: compile in each process instead.

    ``inline``: compiled into each caller (``@_jit(inline=True)``). A per-point helper that
    takes arrays must be: a real call passes each array as a reference-counted structure, which
    cost 3x the distance itself (measured on the site's kernel)."""
    if fn is None:
        return lambda f: _jit(f, inline=inline)
    opts = dict(fastmath=False, nogil=True, inline="always" if inline else "never")
    try:
        return numba.njit(cache=True, **opts)(fn)
    except RuntimeError:
        return numba.njit(cache=False, **opts)(fn)


@_jit
def _ellipse_distance(u: float, v: float, A: float, B: float) -> float:
    """``turbine._ellipse_distance`` for one point: the same Newton iteration from below."""
    u, v = abs(u), abs(v)
    if (u / A) ** 2 + (v / B) ** 2 <= 1.0:
        return 0.0
    A2, B2 = A * A, B * B
    Au, Bv = A * u, B * v
    t = max(math.sqrt(Au * Au + Bv * Bv) - max(A2, B2), 0.0)
    for _ in range(64):
        p, q = Au / (t + A2), Bv / (t + B2)
        step = max(p * p + q * q - 1.0, 0.0) / (2.0 * (p * p / (t + A2) + q * q / (t + B2)))
        t0 = t
        t = t + step
        if not step > 1e-15 * (t0 + A2):
            break
    x, y = A2 * u / (t + A2), B2 * v / (t + B2)
    return math.hypot(u - x, v - y)


@_jit
def _knots(f: float, at: float, y0: float, y1: float, y2: float) -> float:
    """np.interp(f, [0, at, 1], [y0, y1, y2]) for f in [0, 1]."""
    if f <= at:
        return y0 + (y1 - y0) * (f / at)
    return y1 + (y2 - y1) * ((f - at) / (1.0 - at))


@_jit
def _tower(rho: float, h: float, H: float, rb: float, rt: float) -> float:
    """Distance in the (radius, height) half plane to the solid trapezoid (0,0) (rb,0) (rt,H)
    (0,H): ``Turbine._tower_distance``."""
    xs = (0.0, rb, rt, 0.0)
    ys = (0.0, 0.0, H, H)
    d = np.inf
    inside = True
    for e in range(4):
        ax, ay = xs[e], ys[e]
        bx, by = xs[(e + 1) % 4], ys[(e + 1) % 4]
        abx, aby = bx - ax, by - ay
        t = min(max(((rho - ax) * abx + (h - ay) * aby) / (abx * abx + aby * aby), 0.0), 1.0)
        ex, ey = rho - (ax + t * abx), h - (ay + t * aby)
        d = min(d, math.sqrt(ex * ex + ey * ey))
        if abx * (h - ay) - aby * (rho - ax) < 0.0:  # counter-clockwise polygon
            inside = False
    return 0.0 if inside else d


@_jit
def clearance(P: np.ndarray, vec: np.ndarray, sc: np.ndarray, frames: np.ndarray,
              cap: float) -> np.ndarray:
    """(M,) clearance of the points P (M, 3); ``vec``, ``sc``, ``frames`` from
    ``Turbine._kernel_params``; ``cap`` inf for none."""
    out = np.empty(P.shape[0])
    V, S, F = vec.reshape(1, 6, 3), sc.reshape(1, -1), frames.reshape(1, -1, 3, 3)
    for i in range(P.shape[0]):
        out[i] = point_clearance(P[i, 0], P[i, 1], P[i, 2], V, S, F, 0, frames.shape[0], cap)
    return out


@_jit(inline=True)
def point_clearance(px: float, py: float, pz: float, vec: np.ndarray, sc: np.ndarray,
                    frames: np.ndarray, t: int, blades: int, cap: float) -> float:
    """``clearance`` of one point to turbine ``t`` of stacked parameters (vec (T, 6, 3), sc
    (T, 14), frames (T, B, 3, 3), its first ``blades`` real)."""
    if math.isnan(px) or math.isnan(py) or math.isnan(pz):
        return np.nan
    hub_r, H, rb, rt = sc[t, 0], sc[t, 1], sc[t, 2], sc[t, 3]
    s0, s1, taper, at = sc[t, 4], sc[t, 5], sc[t, 6], sc[t, 7]
    c0, c1, c2, r0, r1, r2 = sc[t, 8], sc[t, 9], sc[t, 10], sc[t, 11], sc[t, 12], sc[t, 13]
    # hub and nacelle first: exact and cheap
    dx, dy, dz = px - vec[t, 0, 0], py - vec[t, 0, 1], pz - vec[t, 0, 2]
    best = max(math.sqrt(dx * dx + dy * dy + dz * dz) - hub_r, 0.0)
    qx, qy, qz = px - vec[t, 1, 0], py - vec[t, 1, 1], pz - vec[t, 1, 2]
    e0 = max(abs(qx * vec[t, 2, 0] + qy * vec[t, 2, 1] + qz * vec[t, 2, 2]) - vec[t, 4, 0], 0.0)
    e1 = max(abs(qx * vec[t, 3, 0] + qy * vec[t, 3, 1] + qz * vec[t, 3, 2]) - vec[t, 4, 1], 0.0)
    e2 = max(abs(qz) - vec[t, 4, 2], 0.0)
    best = min(math.sqrt(e0 * e0 + e1 * e1 + e2 * e2), best)
    # blades: exact only where the capsule bound is below what the hub/nacelle give
    limit = min(best, cap)
    blades_d = np.inf
    for k in range(blades):
        s = dx * frames[t, k, 0, 0] + dy * frames[t, k, 0, 1] + dz * frames[t, k, 0, 2]
        u = dx * frames[t, k, 1, 0] + dy * frames[t, k, 1, 1] + dz * frames[t, k, 1, 2]
        v = dx * frames[t, k, 2, 0] + dy * frames[t, k, 2, 1] + dz * frames[t, k, 2, 2]
        f = (min(max(s, s0), s1) - s0) / (s1 - s0)
        chord = _knots(f, at, c0, c1, c2)
        A = chord / 2.0
        beyond = max(s - s1, 0.0) + max(s0 - s, 0.0)
        d = math.hypot(max(math.hypot(u, v) - A, 0.0) * taper, beyond)
        if d < limit:
            B = _knots(f, at, r0, r1, r2) * chord / 2.0
            d = math.hypot(_ellipse_distance(u, v, A, B) * taper, beyond)
        blades_d = min(blades_d, d)
    best = min(best, blades_d)
    # tower: exact only where the bound of its enclosing cylinder (the larger radius) is
    # below the best so far
    tx, ty, tz = px - vec[t, 5, 0], py - vec[t, 5, 1], pz - vec[t, 5, 2]
    rho = math.hypot(tx, ty)
    d = math.hypot(max(rho - max(rb, rt), 0.0), max(max(-tz, tz - H), 0.0))
    if d < min(best, cap):
        d = _tower(rho, tz, H, rb, rt)
    return min(best, d)


@_jit
def trace(eyes: np.ndarray, ray: np.ndarray, stop: np.ndarray, vec: np.ndarray, sc: np.ndarray,
          frames: np.ndarray, hit: float, max_steps: int) -> tuple:
    """``Turbine.line_of_sight``'s sphere tracing, ray by ray: (clear, t, live). From each point
    the ray advances by ``clearance`` (capped at 1 m); blocked where it comes within ``hit``;
    ``live`` where still undecided after ``max_steps`` (the caller finishes those)."""
    n = eyes.shape[0]
    clear = np.ones(n, np.bool_)
    live = np.zeros(n, np.bool_)
    t = np.zeros(n)
    V, S, F = vec.reshape(1, 6, 3), sc.reshape(1, -1), frames.reshape(1, -1, 3, 3)
    for i in range(n):
        if not stop[i] > 0:
            continue
        live[i] = True
        for _ in range(max_steps):
            x = eyes[i, 0] + t[i] * ray[i, 0]
            y = eyes[i, 1] + t[i] * ray[i, 1]
            z = eyes[i, 2] + t[i] * ray[i, 2]
            c = point_clearance(x, y, z, V, S, F, 0, frames.shape[0], 1.0)
            t[i] += c
            if c < hit:
                clear[i] = False
                live[i] = False
                break
            if not t[i] < stop[i]:
                live[i] = False
                break
    return clear, t, live
