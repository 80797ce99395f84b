"""Positioning: what the autopilot believes its position and velocity are.

The controller flies on the navigation estimate; deviation and clearance are measured on the
truth. The estimate's error is, per axis, a slowly wandering bias (first-order Gauss-Markov,
``sigma`` and correlation time ``tau``) plus white noise per control step. The modes and their
numbers (``scenario.positioning``, docs/fly.md "Positioning"):

==========  ====================  ==================  =============  =========================
mode        bias sigma h / v (m)  bias time const (s)  noise h/v (m)  source
==========  ====================  ==================  =============  =========================
rtk_fixed   0.01 / 0.015          300                 0.01 / 0.015   DJI M300 RTK: 1 cm + 1 ppm
                                                                        horizontal, 1.5 cm + 1 ppm
                                                                        vertical (fixed solution)
rtk_float   0.25 / 0.40           120                 0.05 / 0.08    decimetre level (RTK float,
                                                                        DJI's RtkFlag 32-49)
gnss        1.0 / 0.5             300                 0.15 / 0.10    DJI M300 hover accuracy with
                                                                        GPS: +-1.5 m h, +-0.5 m v
                                                                        (height barometer-aided);
                                                                        single-point GNSS wanders
                                                                        ~1 m over minutes
ideal       0 / 0                 -                   vehicle.position_noise_m
==========  ====================  ==================  =============  =========================

``ideal`` is white noise only (``vehicle.position_noise_m``, ``velocity_noise_ms``): the
estimate the simulator had before positioning modes existed. ``rtk_degrades_near_tower``: with
``rtk_fixed``, closer than ``rtk_degrade_distance_m`` to a tower (horizontally, below the hub)
the multipath and sky blockage of the steel tower drop the fix to float, and it is re-fixed
``rtk_refix_s`` after leaving that region. Velocity comes from the inertially aided filter: the
slow bias does not enter it, its noise is ``vehicle.velocity_noise_ms``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MODES = ("rtk_fixed", "rtk_float", "gnss", "ideal")

# mode -> (bias sigma horizontal, vertical (m), bias time constant (s), noise h, v (m))
ERROR_MODEL: dict[str, tuple[float, float, float, float, float]] = {
    "rtk_fixed": (0.01, 0.015, 300.0, 0.01, 0.015),
    "rtk_float": (0.25, 0.40, 120.0, 0.05, 0.08),
    "gnss": (1.0, 0.5, 300.0, 0.15, 0.10),
}


def gauss_markov(rng: np.random.Generator, n: int, dt: float, sigma: float, tau: float) -> np.ndarray:
    """(n,) first-order Gauss-Markov process of stationary std ``sigma`` and correlation time
    ``tau``, started from its stationary distribution (exact discretisation)."""
    if sigma <= 0 or n == 0:
        return np.zeros(n)
    a = math.exp(-dt / tau)
    q = sigma * math.sqrt(1.0 - a * a)
    e = rng.standard_normal(n)
    out = np.empty(n)
    x = sigma * e[0]
    out[0] = x
    # A linear recursion: scipy.signal.lfilter would do, but numpy alone keeps dependencies down.
    for i in range(1, n):
        x = a * x + q * e[i]
        out[i] = x
    return out


def mode_error(mode: str, n: int, dt: float, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) position error of a mode (bias plus white noise), ENU."""
    sh, sv, tau, nh, nv = ERROR_MODEL[mode]
    out = np.empty((n, 3))
    for i, (s, w) in enumerate(((sh, nh), (sh, nh), (sv, nv))):
        out[:, i] = gauss_markov(rng, n, dt, s, tau) + w * rng.standard_normal(n)
    return out


@dataclass(frozen=True)
class Navigation:
    """Per control step: the position and velocity errors the controller's estimate carries,
    and the positioning state (``fixed`` true where an RTK fix is held)."""

    pos_error: np.ndarray  # (n, 3) m
    vel_error: np.ndarray  # (n, 3) m/s
    mode: str
    fixed: np.ndarray  # (n,) bool
    float_error: np.ndarray | None = None  # (n, 3) the float solution's error, where it may drop

    def summary(self) -> dict:
        e = np.linalg.norm(self.pos_error[:, :2], axis=1)
        return {"mode": self.mode, "horizontal_error_m": {"rms": float(np.sqrt((e ** 2).mean()))
                                                            if len(e) else 0.0,
                                                            "max": float(e.max()) if len(e) else 0.0},
                "rtk_fixed_fraction": float(self.fixed.mean()) if len(self.fixed) else 1.0}


def make_navigation(mode: str, n: int, dt: float, rng: np.random.Generator, position_noise_m: float,
                    velocity_noise_ms: float, near_tower: np.ndarray | None = None,
                    refix_s: float = 30.0) -> Navigation:
    """The estimate's errors for ``n`` control steps.

    ``ideal`` draws exactly as the simulator always did: position then velocity white noise,
    ``standard_normal((n, 3))`` each, so flights in that mode are unchanged. ``near_tower``:
    (n,) bool where the planned position is in the tower's RTK shadow (degrade option)."""
    if mode not in MODES:
        raise ValueError(f"expected a positioning mode in {MODES}, got {mode!r}")
    white = rng.standard_normal((n, 3)) * position_noise_m
    vel = rng.standard_normal((n, 3)) * velocity_noise_ms
    if mode == "ideal":
        return Navigation(white, vel, mode, np.ones(n, bool))
    err = mode_error(mode, n, dt, rng)
    fixed = np.full(n, mode == "rtk_fixed")
    flt = None
    if mode == "rtk_fixed" and near_tower is not None and near_tower.any():
        flt = mode_error("rtk_float", n, dt, rng)
        lost = np.asarray(near_tower, bool).copy()
        # The fix comes back refix_s after leaving the shadow.
        hold = int(round(refix_s / dt))
        idx = np.nonzero(near_tower)[0]
        for i in idx:  # vectorised enough: contiguous runs are extended once each
            if i + 1 < n and not near_tower[i + 1]:
                lost[i + 1:i + 1 + hold] = True
        fixed = ~lost
        err = np.where(lost[:, None], flt, err)
    return Navigation(err, vel, mode, fixed, flt)


def tower_shadow(ref_pos: np.ndarray, towers: list[tuple[np.ndarray, float]], distance_m: float
                 ) -> np.ndarray:
    """(n,) bool: the set-point closer than ``distance_m`` to a tower's axis horizontally, below
    its top. ``towers``: (base (3,), hub height above base) per turbine."""
    out = np.zeros(len(ref_pos), bool)
    for base, height in towers:
        d = np.linalg.norm(ref_pos[:, :2] - np.asarray(base, float)[:2], axis=1)
        out |= (d < distance_m) & (ref_pos[:, 2] < float(base[2]) + height)
    return out


__all__ = ["ERROR_MODEL", "MODES", "Navigation", "gauss_markov", "make_navigation", "mode_error",
           "tower_shadow"]
