"""Wind: mean wind with power-law shear, Kaimal (IEC 61400-1) or Dryden turbulence and
1-cosine gusts, seeded.

Kaimal (the default): the IEC 61400-1 normal turbulence model of the scenario's turbulence
category, evaluated along the path's heights (``kaimal_series``). Dryden (an option): the
low-altitude form (h < 1000 ft) of the Dryden model in MIL-HDBK-1797 (also
MIL-F-8785C): scale lengths L_w = h, L_u = L_v = h / (0.177 + 0.000823 h)^1.2 (h in feet),
intensities sigma_w = 0.1 W20, sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4, with W20 the
wind speed at 20 ft. The spectra are turned into time series by Taylor's frozen-turbulence
hypothesis: a hovering multirotor sees the field advected past it at the mean wind speed V. Both
models' series are synthesised at once with an FFT (white noise shaped by the square root of
the power spectrum and normalised to the exact variance), so the flight loop only reads a
precomputed series. Discrete gusts are the MIL-F-8785C "1-cosine" shape, arriving as a seeded
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
    d = wind.gust_duration_s
    for t0 in starts:
        # Only the samples around the gust: a long flight's series is millions of samples.
        a = max(0, int(math.floor(t0 / dt)) - 1)
        b = min(n, int(math.ceil((t0 + d) / dt)) + 2)
        x = (np.arange(a, b) * dt - t0) / d
        on = (x >= 0) & (x <= 1)
        out[a:b][on] += 0.5 * wind.gust_amplitude_ms * (1 - np.cos(2 * math.pi * x[on]))
    return out, [(float(s), d, wind.gust_amplitude_ms) for s in starts]


# ---- IEC 61400-1 Kaimal turbulence -----------------------------------------------------------

# Reference turbulence intensity I_ref at 15 m/s of the IEC 61400-1 turbulence categories
# (ed. 3: A 0.16, B 0.14, C 0.12; ed. 4 adds A+ 0.18).
IEC_IREF = {"A+": 0.18, "A": 0.16, "B": 0.14, "C": 0.12}
KAIMAL_BAND_M = 10.0  # heights at which the spectrum is evaluated (interpolated between)


@dataclass(frozen=True)
class KaimalParams:
    """IEC 61400-1 normal turbulence model at one height: sigma_1 = I_ref (0.75 V + 5.6), the
    lateral and vertical ``lateral_ratio`` and ``vertical_ratio`` of it (0.8 and 0.5 in the
    standard's Kaimal model; larger in complex terrain); Kaimal scales L = 8.1, 2.7, 0.66 Lambda_1 with
    Lambda_1 = 0.7 z below 60 m, 42 m above."""

    height_m: float
    sigma_u: float
    sigma_v: float
    sigma_w: float
    L_u: float
    L_v: float
    L_w: float
    V: float

    def to_dict(self) -> dict:
        return {"height_m": self.height_m, "sigma_ms": [self.sigma_u, self.sigma_v, self.sigma_w],
                "length_scale_m": [self.L_u, self.L_v, self.L_w], "advection_ms": self.V}


def kaimal_params(wind: Wind, height_agl_m: float, turbulence_factor: float = 1.0) -> KaimalParams:
    """The IEC normal turbulence model's sigmas and Kaimal length scales at a height, with the
    mean wind of that height (shear) as V; ``turbulence.sigma_ms`` overrides sigma_1."""
    z = max(float(height_agl_m), 1.0)
    V = float(mean_speed(wind, z))
    lam = 0.7 * z if z < 60.0 else 42.0
    if wind.turbulence_model == "none":
        s1 = 0.0
    elif wind.turbulence_sigma_ms is not None:
        s1 = wind.turbulence_sigma_ms
    else:
        s1 = IEC_IREF[wind.turbulence_class] * (0.75 * V + 5.6) if V > 0 else 0.0
    s1 *= turbulence_factor
    return KaimalParams(z, s1, wind.lateral_ratio * s1, wind.vertical_ratio * s1, 8.1 * lam, 2.7 * lam, 0.66 * lam, max(V, 1.0))


def kaimal_psd(L: float, V: float):
    """Kaimal spectral shape S(f) ~ (L / V) / (1 + 6 f L / V)^(5/3), as a function of omega."""
    def psd(w: np.ndarray) -> np.ndarray:
        return 1.0 / (1.0 + 6.0 * (L / V) * w / (2 * math.pi)) ** (5.0 / 3.0)
    return psd


def kaimal_series(wind: Wind, heights: np.ndarray, dt: float, rng: np.random.Generator,
                  turbulence_factor: float = 1.0) -> tuple[np.ndarray, list[KaimalParams]]:
    """(n, 3) turbulence (u along, v across the wind, w up) seen along a path flown at the
    heights above ground ``heights`` (n,): per component one white noise, shaped by the Kaimal
    spectrum of each height band (every KAIMAL_BAND_M m over the path's range) and scaled by that
    band's sigma, then interpolated in height at each sample. The same noise under every band
    keeps the field coherent in height; climbing changes its scales and strength smoothly."""
    h = np.maximum(np.asarray(heights, float), 1.0)
    n = len(h)
    lo, hi = float(h.min()), float(h.max())
    nb = max(1, int(math.ceil((hi - lo) / KAIMAL_BAND_M)) + 1)
    zs = np.linspace(lo, hi, nb) if nb > 1 else np.array([lo])
    params = [kaimal_params(wind, z, turbulence_factor) for z in zs]
    out = np.zeros((n, 3))
    if all(p.sigma_u <= 0 for p in params) or n == 0:
        return out, params
    m = int(2 ** math.ceil(math.log2(max(n, 16) * 1.25)))
    omega = 2 * math.pi * np.fft.rfftfreq(m, dt)
    if nb > 1:
        x = (h - lo) / (hi - lo) * (nb - 1)
        j = np.clip(np.floor(x).astype(int), 0, nb - 2)
        f = x - j
        del x
        below, above = np.empty(n), np.empty(n)
    for i in range(3):
        spec = np.fft.rfft(rng.standard_normal(m))
        # Each sample needs only the two bands around its height: keep those values as the bands
        # are made, not every band's series (a band is a whole flight at the physics rate).
        for b, p in enumerate(params):
            sigma, L = ((p.sigma_u, p.L_u), (p.sigma_v, p.L_v), (p.sigma_w, p.L_w))[i]
            g2 = kaimal_psd(L, p.V)(omega)
            full = g2[0] + 2 * g2[1:-1].sum() + g2[-1]
            band = sigma * np.fft.irfft(spec * np.sqrt(g2 * m / full), n=m)[:n]
            if nb == 1:
                out[:, i] = band
                continue
            lower = j == b
            below[lower] = band[lower]
            upper = j == b - 1
            above[upper] = band[upper]
        if nb > 1:
            out[:, i] = (1 - f) * below + f * above
    return out, params


@dataclass(frozen=True)
class WindSeries:
    """What one flight sees: w(t, h) = unit * V(h) + turbulence(t) + gust(t) * unit (+ the wake,
    added by the flight from the structure's position)."""

    unit: np.ndarray  # (3,) direction the mean wind blows towards
    dryden: DrydenParams | None  # the Dryden model's parameters (None with Kaimal or none)
    gusts: list
    extra: np.ndarray  # (n, 3) turbulence + gusts, ENU, at the physics rate
    kaimal: tuple = ()  # KaimalParams of each height band (Kaimal turbulence)

    def summary(self) -> dict:
        out: dict = {"gusts": len(self.gusts)}
        if self.dryden is not None:
            out["dryden"] = self.dryden.to_dict()
        if self.kaimal:
            lo, hi = self.kaimal[0], self.kaimal[-1]
            out["kaimal"] = {"bands": len(self.kaimal), "lowest": lo.to_dict(), "highest": hi.to_dict()}
        return out


def make_wind(wind: Wind, turbulence_factor: float, n: int, dt: float, height_agl_m: float,
              rng: np.random.Generator, heights: np.ndarray | None = None) -> WindSeries:
    """The wind of one flight at the physics rate. Dryden: one parameter set at
    ``height_agl_m``; Kaimal: evaluated along ``heights`` (n,) above ground (the path), else at
    ``height_agl_m`` throughout."""
    unit = wind_unit(wind.direction_deg)
    kaimal: tuple = ()
    p = None
    if wind.turbulence_model == "kaimal":
        h = np.full(n, float(height_agl_m)) if heights is None else np.asarray(heights, float)
        turb, bands = kaimal_series(wind, h, dt, rng, turbulence_factor)
        kaimal = tuple(bands)
    else:
        p = dryden_params(wind, height_agl_m, turbulence_factor)
        turb = dryden_series(p, n, dt, rng)
    gust, gusts = gust_series(wind, n, dt, rng)
    lateral = np.array([-unit[1], unit[0], 0.0])
    if wind.speed_ms <= 0:  # no mean direction: turbulence axes along x/y
        unit_t, lateral = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    else:
        unit_t = unit
    # Column by column: (n, 3) temporaries of a long flight at the physics rate add up.
    along = turb[:, 0] + gust
    del gust
    extra = np.empty((n, 3))
    for c in range(3):
        extra[:, c] = along * unit_t[c] + turb[:, 1] * lateral[c]
    extra[:, 2] += turb[:, 2]
    return WindSeries(unit=unit, dryden=p, gusts=gusts, extra=extra, kaimal=kaimal)
