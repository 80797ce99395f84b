"""WGS84 latitude/longitude/altitude <-> local ENU metres around a site origin (exact, via ECEF).

The site origin ``{"lat", "lon", "alt"}`` (degrees, degrees, metres above mean sea level) is the
ENU point (0, 0, 0). Altitudes are treated as ellipsoidal; over a wind farm the difference is a
constant offset that cancels out of relative altitudes (QGC frame 3).
"""

from __future__ import annotations

import math

import numpy as np

_A = 6378137.0  # WGS84 semi-major axis, m
_F = 1 / 298.257223563
_E2 = _F * (2 - _F)


def _ecef(lat: np.ndarray, lon: np.ndarray, alt: np.ndarray) -> np.ndarray:
    la, lo = np.radians(lat), np.radians(lon)
    n = _A / np.sqrt(1 - _E2 * np.sin(la) ** 2)
    return np.stack([(n + alt) * np.cos(la) * np.cos(lo), (n + alt) * np.cos(la) * np.sin(lo),
                     (n * (1 - _E2) + alt) * np.sin(la)], axis=-1)


def _enu_basis(lat0: float, lon0: float) -> np.ndarray:
    la, lo = math.radians(lat0), math.radians(lon0)
    e = [-math.sin(lo), math.cos(lo), 0.0]
    n = [-math.sin(la) * math.cos(lo), -math.sin(la) * math.sin(lo), math.cos(la)]
    u = [math.cos(la) * math.cos(lo), math.cos(la) * math.sin(lo), math.sin(la)]
    return np.array([e, n, u])


def geodetic_to_enu(lat, lon, alt, origin: dict) -> np.ndarray:
    """(..., 3) ENU metres of WGS84 points relative to ``origin``."""
    lat, lon, alt = (np.asarray(v, float) for v in (lat, lon, alt))
    o = _ecef(np.float64(origin["lat"]), np.float64(origin["lon"]), np.float64(origin["alt"]))
    return (_ecef(lat, lon, alt) - o) @ _enu_basis(origin["lat"], origin["lon"]).T


def enu_to_geodetic(enu: np.ndarray, origin: dict) -> np.ndarray:
    """(M, 3) ENU -> (M, 3) [lat deg, lon deg, alt m]."""
    enu = np.atleast_2d(np.asarray(enu, float))
    o = _ecef(np.float64(origin["lat"]), np.float64(origin["lon"]), np.float64(origin["alt"]))
    X = o + enu @ _enu_basis(origin["lat"], origin["lon"])
    x, y, z = X[:, 0], X[:, 1], X[:, 2]
    lon = np.arctan2(y, x)
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1 - _E2))
    for _ in range(6):  # converges to < 1e-12 rad in a few iterations
        n = _A / np.sqrt(1 - _E2 * np.sin(lat) ** 2)
        alt = p / np.cos(lat) - n
        lat = np.arctan2(z, p * (1 - _E2 * n / (n + alt)))
    n = _A / np.sqrt(1 - _E2 * np.sin(lat) ** 2)
    alt = p / np.cos(lat) - n
    return np.stack([np.degrees(lat), np.degrees(lon), alt], axis=1)
