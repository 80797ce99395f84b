"""The ground under the flight: flat ground level with the site, or seeded smooth hills.

The ground stands where the plan's turbines and launch points stand (the "pads": each
turbine's base and each route's launch point). Its level under a point is the height of the
nearest pad, horizontally (the first of equally near ones): the planner's own ground
(``wtcli.plan.clearance.FlatGround``, docs/plan.md "Checks before writing"), so a plan
whose bases stand at a real height (``wtinspect site`` writes them so) is flown over the
ground it was planned over, not 40 m above a ground at z = 0. ``flat`` terrain is that level;
``hilly`` adds a sum of a few seeded plane waves of the given wavelength, scaled to the given
amplitude, blended back to each pad's height within about 60 m of it, so the turbines and the
launch points stand on level ground. ``height(x, y)`` is vectorised; the flight loop never
calls it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wtcli.fly.scenario import Terrain
from wtcli.plan.clearance import FlatGround

PAD_RADIUS_M = 60.0


@dataclass(frozen=True)
class Ground:
    terrain: Terrain
    k: np.ndarray  # (W, 2) wave vectors
    phase: np.ndarray  # (W,)
    scale: float
    pads: np.ndarray  # (T, 3) turbine bases, then launch points
    flat: FlatGround  # the pads as the planner's ground

    @classmethod
    def build(cls, terrain: Terrain, pads: np.ndarray, seed: int) -> Ground:
        rng = np.random.default_rng([seed, 7])
        waves = 6
        ang = rng.uniform(0, 2 * math.pi, waves)
        kmag = 2 * math.pi / terrain.wavelength_m * rng.uniform(0.6, 1.6, waves)
        k = np.stack([kmag * np.cos(ang), kmag * np.sin(ang)], 1)
        phase = rng.uniform(0, 2 * math.pi, waves)
        scale = terrain.amplitude_m / math.sqrt(waves / 2) if terrain.kind == "hilly" else 0.0
        pads = np.asarray(pads, float).reshape(-1, 3)
        return cls(terrain, k, phase, scale, pads, FlatGround(pads))

    def _raw(self, xy: np.ndarray) -> np.ndarray:
        if self.scale == 0:
            return np.zeros(len(xy))
        return self.scale * np.sin(xy @ self.k.T + self.phase).sum(axis=1)

    def level(self, xy: np.ndarray) -> np.ndarray:
        """The site's level under each point: the planner's flat ground (the height of the
        nearest pad in x/y, the first of equally near ones); 0 without pads."""
        xy = np.atleast_2d(np.asarray(xy, float))[:, :2]
        if not len(self.pads):
            return np.zeros(len(xy))
        z = self.pads[:, 2]
        if np.all(z == z[0]):  # one level: no search (a whole route's steps at a time)
            return np.full(len(xy), z[0])
        return self.flat.z(xy)

    def height(self, xy: np.ndarray) -> np.ndarray:
        xy = np.atleast_2d(np.asarray(xy, float))[:, :2]
        h = self.level(xy)
        if self.terrain.kind == "flat":
            return h
        h = h + self._raw(xy)
        # Blend to each pad's height near it.
        for b in self.pads:
            d2 = ((xy - b[:2]) ** 2).sum(axis=1)
            w = np.exp(-d2 / (2 * (PAD_RADIUS_M / 2) ** 2))
            h = (1 - w) * h + w * b[2]
        return h
