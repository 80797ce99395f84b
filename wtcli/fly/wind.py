"""Wind: mean wind with power-law shear, Dryden turbulence and 1-cosine gusts, seeded.

Turbulence is the low-altitude form (h < 1000 ft) of the Dryden model in MIL-HDBK-1797 (also
MIL-F-8785C): scale lengths L_w = h, L_u = L_v = h / (0.177 + 0.000823 h)^1.2 (h in feet),
intensities sigma_w = 0.1 W20, sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4, with W20 the
wind speed at 20 ft. The spectra are turned into time series by Taylor's frozen-turbulence
hypothesis: a hovering multirotor sees the field advected past it at the mean wind speed V. The
series are synthesised at once with an FFT (white noise shaped by the square root of the
Dryden power spectrum and normalised to the exact variance), so the flight loop only reads a
precomputed list. Discrete gusts are the MIL-F-8785C "1-cosine" shape, arriving as a seeded
Poisson process along the mean wind direction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wtcli.fly.scenario import Wind

FT = 0.3048
KT = 0.514444
# MIL-HDBK-1797 low-altitude turbulence severities: wind speed at 20 ft.
W20_MS = {"light": 15 * KT, "moderate": 30 * KT, "severe": 45 * KT}


def wind_unit(direction_from_deg: float) -> np.ndarray:
    """Unit vector the wind blows TOWARDS, for a meteorological 'from' direction."""
    a = math.radians(direction_from_deg)
    return np.array([-math.sin(a), -math.cos(a), 0.0])


def mean_speed(wind: Wind, height_agl_m: float | np.ndarray) -> float | np.ndarray:
    h = np.maximum(np.asarray(height_agl_m, float), 1.0)
    return wind.speed_ms * (h / wind.reference_height_m) ** wind.shear_exponent


@dataclass(frozen=True)
class DrydenParams:
    sigma_u: float
    sigma_v: float
    sigma_w: float
    L_u: float  # m
    L_v: float
    L_w: float
    V: float  # advection speed, m/s

    def to_dict(self) -> dict:
        return {"sigma_ms": [self.sigma_u, self.sigma_v, self.sigma_w],
                "length_scale_m": [self.L_u, self.L_v, self.L_w], "advection_ms": self.V}


def dryden_params(wind: Wind, height_agl_m: float, turbulence_factor: float = 1.0) -> DrydenParams:
    """Dryden low-altitude intensities and scale lengths at a height above ground."""
    h_ft = max(height_agl_m, 10 * FT) / FT
    h_ft = min(h_ft, 1000.0)
    k = 0.177 + 0.000823 * h_ft
    L_w = h_ft * FT
    L_u = h_ft / k ** 1.2 * FT
    ratio = 1.0 / k ** 0.4  # sigma_u / sigma_w
    if wind.turbulence_model == "none":
        s_u = s_w = 0.0
    elif wind.turbulence_sigma_ms is not None:
        s_u = wind.turbulence_sigma_ms
        s_w = s_u / ratio
    else:
        if wind.turbulence_intensity == "auto":
            w20 = float(mean_speed(wind, 20 * FT))
        else:
            w20 = W20_MS[wind.turbulence_intensity]
        s_w = 0.1 * w20
        s_u = s_w * ratio
    s_u *= turbulence_factor
    s_w *= turbulence_factor
    V = max(float(mean_speed(wind, height_agl_m)), 1.0)
    return DrydenParams(s_u, s_u, s_w, L_u, L_u, L_w, V)


def shaped_noise(rng: np.random.Generator, n: int, dt: float, psd) -> np.ndarray:
    """Unit-variance series with the spectral shape ``psd(omega)`` (FFT synthesis)."""
    m = int(2 ** math.ceil(math.log2(max(n, 16) * 1.25)))  # padding: the FFT wraps around
    white = rng.standard_normal(m)
    omega = 2 * math.pi * np.fft.rfftfreq(m, dt)
    g2 = psd(omega)
    full = g2[0] + 2 * g2[1:-1].sum() + g2[-1]  # two-sided sum over all m bins
    g = np.sqrt(g2 * m / full)
    return np.fft.irfft(np.fft.rfft(white) * g, n=m)[:n]


def dryden_series(p: DrydenParams, n: int, dt: float, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) turbulence (u along wind, v lateral, w vertical), m/s."""
    out = np.zeros((n, 3))
    for i, (sigma, L, kind) in enumerate(((p.sigma_u, p.L_u, "u"), (p.sigma_v, p.L_v, "v"),
                                          (p.sigma_w, p.L_w, "w"))):
        T = L / p.V
        if kind == "u":
            def psd(w, T=T):
                return 1.0 / (1.0 + (T * w) ** 2)
        else:
            def psd(w, T=T):
                return (1.0 + 3.0 * (T * w) ** 2) / (1.0 + (T * w) ** 2) ** 2
        series = shaped_noise(rng, n, dt, psd)
        out[:, i] = sigma * series if sigma > 0 else 0.0
    return out


def gust_series(wind: Wind, n: int, dt: float, rng: np.random.Generator) -> tuple[np.ndarray, list]:
    """(n,) 1-cosine gust speed along the mean wind and the list of (t0, duration, amplitude)."""
    out = np.zeros(n)
    T = n * dt
    if wind.gust_rate_per_min <= 0 or wind.gust_amplitude_ms <= 0:
        return out, []
    count = rng.poisson(wind.gust_rate_per_min * T / 60.0)
    starts = np.sort(rng.uniform(0, max(T - wind.gust_duration_s, dt), count))
    t = np.arange(n) * dt
    d = wind.gust_duration_s
    for t0 in starts:
        x = (t - t0) / d
        on = (x >= 0) & (x <= 1)
        out[on] += 0.5 * wind.gust_amplitude_ms * (1 - np.cos(2 * math.pi * x[on]))
    return out, [(float(s), d, wind.gust_amplitude_ms) for s in starts]


@dataclass(frozen=True)
class WindSeries:
    """What one flight sees: w(t, h) = unit * V(h) + turbulence(t) + gust(t) * unit."""

    unit: np.ndarray  # (3,) direction the mean wind blows towards
    dryden: DrydenParams
    gusts: list
    extra: np.ndarray  # (n, 3) turbulence + gusts, ENU, at the physics rate

    def summary(self) -> dict:
        return {"dryden": self.dryden.to_dict(), "gusts": len(self.gusts)}


def make_wind(wind: Wind, turbulence_factor: float, n: int, dt: float, height_agl_m: float,
              rng: np.random.Generator) -> WindSeries:
    unit = wind_unit(wind.direction_deg)
    p = dryden_params(wind, height_agl_m, turbulence_factor)
    turb = dryden_series(p, n, dt, rng)
    gust, gusts = gust_series(wind, n, dt, rng)
    lateral = np.array([-unit[1], unit[0], 0.0])
    if wind.speed_ms <= 0:  # no mean direction: turbulence axes along x/y
        unit_t, lateral = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    else:
        unit_t = unit
    extra = (turb[:, :1] + gust[:, None]) * unit_t + turb[:, 1:2] * lateral
    extra[:, 2] += turb[:, 2]
    return WindSeries(unit=unit, dryden=p, gusts=gusts, extra=extra)
