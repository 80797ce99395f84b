"""Procedural noise for the renderer: multi-octave value noise, plain and tileable (for world-
space textures sampled with ``cv2.remap(..., borderMode=cv2.BORDER_WRAP)``). numpy + cv2 only;
every function draws from the ``rng`` it is given, so a scene is a pure function of its seed."""

from __future__ import annotations

import cv2
import numpy as np


def value_noise(rng: np.random.Generator, h: int, w: int, cells: float) -> np.ndarray:
    """Smooth noise in [0, 1], float32 (h, w): random values on a grid of about ``cells``
    cells across the longer side, bicubically interpolated."""
    s = max(h, w)
    gh = max(2, int(round(cells * h / s)) + 1)
    gw = max(2, int(round(cells * w / s)) + 1)
    g = rng.random((gh, gw), dtype=np.float32)
    return np.clip(cv2.resize(g, (w, h), interpolation=cv2.INTER_CUBIC), 0.0, 1.0)


def fbm(rng: np.random.Generator, h: int, w: int, cells: float, octaves: int = 4,
        gain: float = 0.5) -> np.ndarray:
    """Fractal (multi-octave) value noise, normalised to about [0, 1], float32 (h, w)."""
    out = np.zeros((h, w), np.float32)
    amp, total = 1.0, 0.0
    for o in range(octaves):
        c = cells * (2 ** o)
        if o > 0 and c > max(h, w) / 1.5:
            break
        out += amp * value_noise(rng, h, w, c)
        total += amp
        amp *= gain
    return out / total


def tile_noise(rng: np.random.Generator, size: int, cells: int) -> np.ndarray:
    """Tileable value noise in [0, 1], float32 (size, size): a random periodic grid of
    ``cells`` x ``cells`` values, bicubically interpolated with wrap-around borders."""
    cells = max(2, int(cells))
    g = rng.random((cells, cells), dtype=np.float32)
    work = min(size, max(32, 8 * cells))  # coarse octaves: interpolate small, then enlarge
    x = ((np.arange(work, dtype=np.float32) + 0.5) * (cells / work) - 0.5)
    mx = np.ascontiguousarray(np.broadcast_to(x[None, :], (work, work)))
    my = np.ascontiguousarray(np.broadcast_to(x[:, None], (work, work)))
    up = cv2.remap(g, mx, my, cv2.INTER_CUBIC, borderMode=cv2.BORDER_WRAP)
    if work < size:
        up = cv2.resize(up, (size, size), interpolation=cv2.INTER_LINEAR)
    return np.clip(up, 0.0, 1.0)


def tile_fbm(rng: np.random.Generator, size: int, cells: int, octaves: int = 4,
             gain: float = 0.5) -> np.ndarray:
    out = np.zeros((size, size), np.float32)
    amp, total = 1.0, 0.0
    for o in range(octaves):
        c = cells * (2 ** o)
        if o > 0 and c > size // 2:
            break
        out += amp * tile_noise(rng, size, c)
        total += amp
        amp *= gain
    out /= total
    # Sums of octaves cluster around 0.5: stretch back to roughly [0, 1].
    m, sd = float(out.mean()), float(out.std())
    return np.clip((out - m) / max(4.6 * sd, 1e-6) + 0.5, 0.0, 1.0)


def noise_1d(rng: np.random.Generator, n: int, cells: int, octaves: int = 4,
             gain: float = 0.55, periodic: bool = True) -> np.ndarray:
    """Fractal 1-D noise of length n in about [0, 1] (periodic by default: for azimuths)."""
    out = np.zeros(n, np.float64)
    amp, total = 1.0, 0.0
    for o in range(octaves):
        c = max(2, cells * (2 ** o))
        g = rng.random(c)
        x = np.arange(n) * c / n
        i0 = np.floor(x).astype(int)
        f = x - i0
        f = f * f * (3 - 2 * f)
        i1 = (i0 + 1) % c if periodic else np.minimum(i0 + 1, c - 1)
        out += amp * (g[i0 % c] * (1 - f) + g[i1] * f)
        total += amp
        amp *= gain
    return out / total


def smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


_BANK: dict[tuple, list[np.ndarray]] = {}
BANK_TILES = 3


def bank_tile(rng: np.random.Generator, size: int, cells: int, octaves: int = 4,
              gain: float = 0.5) -> np.ndarray:
    """A tileable fractal noise tile like ``tile_fbm``, drawn from a small bank made once per
    process from fixed seeds (cheap per scene; scenes stay pure functions of their seed): one of
    the bank's tiles, cyclically shifted, possibly mirrored and transposed, all chosen by
    ``rng``. Read-only view semantics are not relied on: the result is a fresh array."""
    key = (int(size), int(cells), int(octaves), float(gain))
    bank = _BANK.get(key)
    if bank is None:
        seed = [int(size), int(cells), int(octaves), int(gain * 1000)]
        brng = np.random.default_rng(seed)
        bank = [tile_fbm(brng, size, cells, octaves, gain) for _ in range(BANK_TILES)]
        _BANK[key] = bank
    t = bank[int(rng.integers(len(bank)))]
    dy, dx = (int(v) for v in rng.integers(0, size, 2))
    t = np.roll(t, (dy, dx), axis=(0, 1))
    flip = int(rng.integers(8))
    if flip & 1:
        t = t[:, ::-1]
    if flip & 2:
        t = t[::-1]
    if flip & 4:
        t = t.T
    return np.ascontiguousarray(t)
