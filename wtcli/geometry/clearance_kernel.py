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


def _jit(fn):
    """Compiled once per machine (about a second), then loaded from numba's cache (the package's
    __pycache__, else the user's cache folder). Where neither is writable (a read-only install
    and no home) numba refuses to cache: compile in each process instead."""
    try:
        return numba.njit(cache=True, fastmath=False, nogil=True)(fn)
    except RuntimeError:
        return numba.njit(cache=False, fastmath=False, nogil=True)(fn)


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
    hub, nac, axis, side, half, base = vec[0], vec[1], vec[2], vec[3], vec[4], vec[5]
    hub_r, H, rb, rt = sc[0], sc[1], sc[2], sc[3]
    s0, s1, taper, at = sc[4], sc[5], sc[6], sc[7]
    c0, c1, c2, r0, r1, r2 = sc[8], sc[9], sc[10], sc[11], sc[12], sc[13]
    for i in range(P.shape[0]):
        px, py, pz = P[i, 0], P[i, 1], P[i, 2]
        if math.isnan(px) or math.isnan(py) or math.isnan(pz):
            out[i] = np.nan
            continue
        # hub and nacelle first: exact and cheap
        dx, dy, dz = px - hub[0], py - hub[1], pz - hub[2]
        best = max(math.sqrt(dx * dx + dy * dy + dz * dz) - hub_r, 0.0)
        qx, qy, qz = px - nac[0], py - nac[1], pz - nac[2]
        e0 = max(abs(qx * axis[0] + qy * axis[1] + qz * axis[2]) - half[0], 0.0)
        e1 = max(abs(qx * side[0] + qy * side[1] + qz * side[2]) - half[1], 0.0)
        e2 = max(abs(qz) - half[2], 0.0)
        best = min(math.sqrt(e0 * e0 + e1 * e1 + e2 * e2), best)
        # blades: exact only where the capsule bound is below what the hub/nacelle give
        limit = min(best, cap)
        blades = np.inf
        for k in range(frames.shape[0]):
            F = frames[k]
            s = dx * F[0, 0] + dy * F[0, 1] + dz * F[0, 2]
            u = dx * F[1, 0] + dy * F[1, 1] + dz * F[1, 2]
            v = dx * F[2, 0] + dy * F[2, 1] + dz * F[2, 2]
            f = (min(max(s, s0), s1) - s0) / (s1 - s0)
            chord = _knots(f, at, c0, c1, c2)
            A = chord / 2.0
            beyond = max(s - s1, 0.0) + max(s0 - s, 0.0)
            d = math.hypot(max(math.hypot(u, v) - A, 0.0) * taper, beyond)
            if d < limit:
                B = _knots(f, at, r0, r1, r2) * chord / 2.0
                d = math.hypot(_ellipse_distance(u, v, A, B) * taper, beyond)
            blades = min(blades, d)
        best = min(best, blades)
        # tower: exact only where the bound of its enclosing cylinder (the larger radius) is
        # below the best so far
        tx, ty, tz = px - base[0], py - base[1], pz - base[2]
        rho = math.hypot(tx, ty)
        d = math.hypot(max(rho - max(rb, rt), 0.0), max(max(-tz, tz - H), 0.0))
        if d < min(best, cap):
            d = _tower(rho, tz, H, rb, rt)
        out[i] = min(best, d)
    return out
