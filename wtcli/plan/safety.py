"""Clearance of points and straight legs to every part of every turbine of a site, and the ground.

The distances are the one turbine model's (``Turbine.clearance``, a lower bound of the true
distance). A turbine far from a point is skipped: its bounding box, grown by ``horizon_m``,
does not contain the point, so its clearance is at least ``horizon_m`` and the reported value
is capped there.
"""

from __future__ import annotations

import numpy as np

from wtcli.geometry import Turbine
from wtcli.geometry.turbine import segment_lower_bound

HORIZON_M = 60.0


class Site:
    def __init__(self, turbines: list[Turbine] | tuple[Turbine, ...], horizon_m: float = HORIZON_M,
                 launch: np.ndarray | None = None):
        self.turbines = list(turbines)
        self.horizon = float(horizon_m)
        lo, hi = [], []
        for t in self.turbines:
            reach = t.tip_radius + t.overhang + t.nacelle_length + t.hub_radius
            b = t.base_xyz
            lo.append([b[0] - reach, b[1] - reach, b[2]])
            hi.append([b[0] + reach, b[1] + reach, b[2] + t.hub_height + reach])
        self.lo = np.array(lo) - self.horizon
        self.hi = np.array(hi) + self.horizon
        ground = [t.base_xyz for t in self.turbines]
        if launch is not None:
            ground.append(np.asarray(launch, float))
        self.ground_points = np.array(ground)

    def near(self, points: np.ndarray) -> list[np.ndarray]:
        """Per turbine, the indices of the points inside its grown bounding box."""
        P = np.atleast_2d(points)
        return [np.nonzero(((P >= lo) & (P <= hi)).all(axis=1))[0] for lo, hi in zip(self.lo, self.hi)]

    def clearance(self, points: np.ndarray, cap: float | None = None) -> np.ndarray:
        """(M,) distance to the nearest part of any turbine (``Turbine.clearance``'s lower bound),
        capped at the horizon.

        Speed: a part's exact distance is computed only for points whose cheap bound (distance
        to a capsule or cylinder enclosing the part) is below ``cap`` (default: the horizon);
        elsewhere the cheap bound, itself a lower bound of the true distance, stands in."""
        P = np.atleast_2d(np.asarray(points, float))
        cap = self.horizon if cap is None else min(cap, self.horizon)
        out = np.full(len(P), self.horizon)
        for t, idx in zip(self.turbines, self.near(P)):
            if len(idx):
                out[idx] = np.minimum(out[idx], self._turbine_clearance(t, P[idx], cap))
        return out

    def _turbine_clearance(self, t: Turbine, P: np.ndarray, cap: float) -> np.ndarray:
        return t.clearance(P, cap=cap)

    def nearest_part(self, point: np.ndarray) -> tuple[str, float]:
        """("T1 blade2", 2.3): the part of any turbine nearest a point, and its distance."""
        best = ("nothing", np.inf)
        for t in self.turbines:
            c = t.clearance_by_part(np.atleast_2d(point))[0]
            k = int(np.argmin(c))
            if c[k] < best[1]:
                best = (f"{t.id} {t.part_names()[k]}", float(c[k]))
        return best

    def segment_clearance(self, p0: np.ndarray, p1: np.ndarray, step: float = 0.5,
                          cap: float | None = None) -> np.ndarray:
        """Lower bound of the clearance along each straight leg p0[i] -> p1[i] (capped)."""
        return segment_lower_bound(lambda pts: self.clearance(pts, cap), p0, p1, step)

    def ground_z(self, points: np.ndarray) -> np.ndarray:
        """Ground level under each point: the height of the nearest turbine base or launch point
        (a flat site around each of them)."""
        P = np.atleast_2d(points)
        d = np.linalg.norm(P[:, None, :2] - self.ground_points[None, :, :2], axis=2)
        return self.ground_points[np.argmin(d, axis=1), 2]
