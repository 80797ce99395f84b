"""The air the structure disturbs: tower wake with vortex shedding, and the nacelle's lee.

An engineering model (docs/fly.md "Tower and nacelle wake"), on by default, acting only where the
vehicle is downwind of a part:

- **Tower** (a circular cylinder of the local diameter D(z), tapering from base to top): in the
  wind frame (x downwind of the tower axis, y across), for x > D/2 the mean velocity deficit is
  the plane-wake law ``dU = U min(1, 0.98 sqrt(C_D D / x)) exp(-y^2 / (2 b^2))`` with the wake's
  half-width ``b = 0.25 sqrt(C_D D x) + D/2`` (Schlichting's far wake, its width held at least the
  cylinder's radius near it; C_D = 0.7, a cylinder at the supercritical Reynolds numbers of
  metres-wide towers in 5-15 m/s wind, Re ~ 1e6-1e7). Vortices shed at the Strouhal frequency
  ``f = St U / D`` with St = 0.2 swing the flow across the wake:
  ``v' = A U sqrt(min(1, 2 D / x)) exp(-y^2 / (2 b^2)) sin(2 pi f t + phase)``, A = 0.3 (a near-
  wake cross-flow of about 0.2 U rms, decaying as the wake spreads), plus half of that along the
  wind at twice the frequency.
- **Nacelle**: behind the nacelle box (downwind of its centre, within its width and height grown
  by half) the wind is reduced by ``0.5 exp(-x / (2 H))`` (H the nacelle height), the recirculating
  lee of a bluff body.
- A stopped rotor's feathered blades are slender; their wake is left out.

The model is evaluated along the set-point, once per control step (the vehicle flies within a
metre or two of it; the wake is metres wide), so the flight loop reads a precomputed series.
"""

from __future__ import annotations

import math

import numpy as np

from wtcli.geometry import Turbine

STROUHAL = 0.2
TOWER_CD = 0.7
SHEDDING_AMPLITUDE = 0.3
NACELLE_DEFICIT = 0.5


def tower_radius_at(t: Turbine, z_rel: np.ndarray) -> np.ndarray:
    """Tower radius at heights above its base (linear taper), NaN above its top."""
    return np.where((z_rel >= 0) & (z_rel <= t.tower_height), t.tower_radius_at(z_rel), np.nan)


def wake_series(turbines: list[Turbine], pos: np.ndarray, t: np.ndarray, unit: np.ndarray,
                speed: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """(n, 3) wind perturbation at the points ``pos`` (n, 3) at times ``t`` (n,), for a mean wind
    blowing towards ``unit`` (3,) with the local mean speed ``speed`` (n,); and a summary (the
    share of steps in a wake, the strongest deficit). Phases of shedding are seeded."""
    n = len(pos)
    out = np.zeros((n, 3))
    if n == 0 or not np.any(speed > 0):
        return out, {"steps_in_wake": 0.0, "max_deficit_ms": 0.0}
    u = np.asarray(unit, float)
    u = u / max(float(np.linalg.norm(u[:2])), 1e-12)
    lat = np.array([-u[1], u[0], 0.0])
    in_wake = np.zeros(n, bool)
    for tb in turbines:
        base = np.asarray(tb.base, float)
        rel = pos - base
        x = rel @ u
        y = rel @ lat
        z = rel[:, 2]
        D = 2.0 * tower_radius_at(tb, z)
        ok = np.isfinite(D) & (x > 0.5 * np.nan_to_num(D))
        if ok.any():
            Dk, xk, yk, U = D[ok], x[ok], y[ok], speed[ok]
            b = 0.25 * np.sqrt(TOWER_CD * Dk * xk) + 0.5 * Dk
            shape = np.exp(-yk ** 2 / (2 * b ** 2))
            deficit = U * np.minimum(1.0, 0.98 * np.sqrt(TOWER_CD * Dk / xk)) * shape
            f = STROUHAL * U / Dk
            phase = rng.uniform(0, 2 * math.pi)
            # The shedding phase advances with the local frequency: integrate f over time.
            tt = t[ok]
            ph = phase + 2 * math.pi * np.cumsum(np.r_[0.0, f[1:] * np.diff(tt)])
            amp = SHEDDING_AMPLITUDE * U * np.sqrt(np.minimum(1.0, 2 * Dk / xk)) * shape
            along = -deficit + 0.5 * amp * np.sin(2 * ph)
            across = amp * np.sin(ph)
            out[ok] += along[:, None] * u + across[:, None] * lat
            in_wake[ok] |= shape > 0.1
        # The nacelle's lee.
        a = tb.axis
        c = tb.nacelle_center
        half = np.array([tb.nacelle_length, tb.nacelle_width, tb.nacelle_height]) / 2.0
        relc = pos - c
        xc = relc @ u
        yc = relc @ lat
        zc = relc[:, 2]
        reach = abs(float(a[:2] @ u[:2])) * half[0] + abs(float(np.cross(a, [0, 0, 1.0])[:2] @ u[:2])) * half[1]
        lee = (xc > reach) & (np.abs(yc) < 1.5 * max(half[0], half[1])) & (np.abs(zc) < 1.5 * half[2])
        if lee.any():
            d = NACELLE_DEFICIT * speed[lee] * np.exp(-(xc[lee] - reach) / (2 * tb.nacelle_height))
            out[lee] -= d[:, None] * u
            in_wake |= lee
    along_u = out @ u
    return out, {"steps_in_wake": float(in_wake.mean()),
                 "max_deficit_ms": float(max(0.0, -along_u.min()))}


__all__ = ["STROUHAL", "TOWER_CD", "tower_radius_at", "wake_series"]
