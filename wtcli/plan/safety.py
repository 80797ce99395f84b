"""Clearance of points and straight legs to every part of every turbine of a site, and the ground.

The distances are the one turbine model's (``Turbine.clearance``, a lower bound of the true
distance). A turbine far from a point is skipped: its bounding box, grown by ``horizon_m``,
does not contain the point, so its clearance is at least ``horizon_m`` and the reported value
is capped there.
"""

from __future__ import annotations

import numpy as np

from wtcli.geometry import Turbine

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
        out = np.full(len(P), np.inf)
        # Blades: each section lies inside the circle of its chord semi-axis A(f); with the
        # model's taper factor, (radius - A(f)) * taper_cos is a lower bound of the distance that
        # is never above Turbine.clearance (the ellipse distance is at least radius - A).
        s0, s1 = t.blade_root_offset, t.tip_radius
        hc = t.hub_center
        tc = t._blade_taper_cos()
        q = P - hc
        for k in range(t.n_blades):
            d = t.blade_direction(k)
            s = q @ d
            sc = np.clip(s, s0, s1)
            rho = np.linalg.norm(q - s[:, None] * d, axis=1)
            A, _ = t.blade_semi_axes((sc - s0) / (s1 - s0))
            beyond = np.maximum(s - s1, 0.0) + np.maximum(s0 - s, 0.0)
            bound = np.hypot(np.maximum(rho - A, 0.0) * tc, beyond)
            exact = bound < cap
            val = bound
            if exact.any():
                val = bound.copy()
                val[exact] = t._blade_distance(P[exact], k)
            out = np.minimum(out, val)
        # Tower: inside the cylinder of its base radius; nacelle and hub are cheap.
        q = P - t.base_xyz
        rho = np.hypot(q[:, 0], q[:, 1])
        dz = np.maximum(np.maximum(-q[:, 2], q[:, 2] - t.tower_height), 0.0)
        bound = np.hypot(np.maximum(rho - t.tower_base_radius, 0.0), dz)
        exact = bound < cap
        val = bound.copy()
        if exact.any():
            val[exact] = t._tower_distance(P[exact])
        out = np.minimum(out, val)
        out = np.minimum(out, t._nacelle_distance(P))
        return np.minimum(out, t._hub_distance(P))

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
        p0 = np.atleast_2d(np.asarray(p0, float))
        p1 = np.atleast_2d(np.asarray(p1, float))
        if len(p0) == 0:
            return np.zeros(0)
        length = np.linalg.norm(p1 - p0, axis=1)
        n = np.maximum(1, np.ceil(length / step).astype(int))
        seg = np.repeat(np.arange(len(p0)), n + 1)
        start = np.concatenate([[0], np.cumsum(n + 1)[:-1]])
        k = np.arange(len(seg)) - np.repeat(start, n + 1)
        t = k / np.repeat(n, n + 1)
        pts = p0[seg] + (p1 - p0)[seg] * t[:, None]
        c = self.clearance(pts, cap)
        out = np.full(len(p0), np.inf)
        np.minimum.at(out, seg, c)
        return out - 0.5 * length / n

    def ground_z(self, points: np.ndarray) -> np.ndarray:
        """Ground level under each point: the height of the nearest turbine base or launch point
        (a flat site around each of them)."""
        P = np.atleast_2d(points)
        d = np.linalg.norm(P[:, None, :2] - self.ground_points[None, :, :2], axis=2)
        return self.ground_points[np.argmin(d, axis=1), 2]
