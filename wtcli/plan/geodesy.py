"""WGS84 latitude/longitude/altitude <-> local ENU metres around a site origin (exact, via ECEF).

The site origin ``{"lat", "lon", "alt"}`` is the ENU point (0, 0, 0); ENU "up" is the ellipsoid
normal there, so the ellipsoid d metres away lies d^2/2R below the ENU plane (1.96 m at 5 km):
an ENU point at z lies about z + d^2/2R above the origin's height. Heights: there is no geoid
model offline, so ``origin.alt`` (metres above mean sea level) is used as the origin's height
and every other height is the origin's plus the exact WGS84 ellipsoid-height difference, i.e.
the geoid is taken as parallel to the ellipsoid across the site (its undulation changes by
centimetres to a few decimetres over 10 km). Exports derive every altitude from these exact
heights (see ``wtcli.plan.exports``).

Planning treats each tower as vertical in the ENU frame, while a real tower stands on its own
local vertical, tilted d/R from ENU up (0.09 deg at 10 km: 0.31 m at a 200 m blade tip). So sites
are limited to ``MAX_SITE_RADIUS_M`` from the origin (``check_site_extent``).
"""

from __future__ import annotations

import math

import numpy as np

from wtcli.errors import ConfigError

_A = 6378137.0  # WGS84 semi-major axis, m
_F = 1 / 298.257223563
_E2 = _F * (2 - _F)
# Farthest a turbine or launch point may lie from site.origin, horizontally: a site up to 20 km
# across with the origin at its centre. The tower-tilt error above stays below 0.31 m.
MAX_SITE_RADIUS_M = 10_000.0


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


def check_site_extent(points: dict[str, np.ndarray], limit_m: float = MAX_SITE_RADIUS_M) -> None:
    """Raise ConfigError naming the first point (key -> ENU xyz) farther than ``limit_m``
    horizontally from the origin, or with a non-finite coordinate."""
    for key, xyz in points.items():
        xyz = np.asarray(xyz, float)
        d = float(np.hypot(xyz[0], xyz[1])) if np.all(np.isfinite(xyz)) else float("inf")
        if not d <= limit_m:
            raise ConfigError(
                f"{key}: {d / 1000:.1f} km from site.origin; the limit is {limit_m / 1000:g} km "
                f"(a site up to {2 * limit_m / 1000:g} km across with the origin at its centre): "
                "the planner treats towers as vertical in one flat frame, which the Earth's "
                "curvature tilts further out. Move site.origin to the centre or split the site")
