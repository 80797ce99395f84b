"""The ground under the flight: flat (z = 0) or a seeded smooth hilly height field.

Hills are a sum of a few seeded plane waves of the given wavelength, scaled to the given
amplitude, and blended to the height of each "pad" within about 60 m of it: the turbines' bases
and the launch points stand on level ground. ``height(x, y)`` is vectorised; the flight loop never calls it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wtcli.fly.scenario import Terrain

PAD_RADIUS_M = 60.0


@dataclass(frozen=True)
class Ground:
    terrain: Terrain
    k: np.ndarray  # (W, 2) wave vectors
    phase: np.ndarray  # (W,)
    scale: float
    pads: np.ndarray  # (T, 3) turbine bases

    @classmethod
    def build(cls, terrain: Terrain, bases: np.ndarray, seed: int) -> Ground:
        rng = np.random.default_rng([seed, 7])
        waves = 6
        ang = rng.uniform(0, 2 * math.pi, waves)
        kmag = 2 * math.pi / terrain.wavelength_m * rng.uniform(0.6, 1.6, waves)
        k = np.stack([kmag * np.cos(ang), kmag * np.sin(ang)], 1)
        phase = rng.uniform(0, 2 * math.pi, waves)
        scale = terrain.amplitude_m / math.sqrt(waves / 2) if terrain.kind == "hilly" else 0.0
        return cls(terrain, k, phase, scale, np.asarray(bases, float).reshape(-1, 3))

    def _raw(self, xy: np.ndarray) -> np.ndarray:
        if self.scale == 0:
            return np.zeros(len(xy))
        return self.scale * np.sin(xy @ self.k.T + self.phase).sum(axis=1)

    def height(self, xy: np.ndarray) -> np.ndarray:
        xy = np.atleast_2d(np.asarray(xy, float))[:, :2]
        if self.terrain.kind == "flat":
            return np.zeros(len(xy))
        h = self._raw(xy)
        # Blend to each pad's height near it.
        for b in self.pads:
            d2 = ((xy - b[:2]) ** 2).sum(axis=1)
            w = np.exp(-d2 / (2 * (PAD_RADIUS_M / 2) ** 2))
            h = (1 - w) * h + w * b[2]
        return h
