"""Where clearance is checked: points and straight legs to every part of every turbine of a
site, and the ground. The planner (``Site``) and the flight simulator (``clearance_to_parts``)
both ask here; the distance to one turbine's parts is ``Turbine.clearance`` (compiled in
``wtcli/geometry/clearance_kernel.py``), the site's culling and legs are compiled in
``clearance_site_kernel.py``.

The distances are the one turbine model's (``Turbine.clearance``, a lower bound of the true
distance), each less its turbine's geometry uncertainty (``Site(uncertainty=...)``,
``mission.geometry_uncertainty_m``): the distance to the model grown by that much, so a
clearance kept here is kept from every turbine whose surfaces lie within the uncertainty of the
modelled ones (thicker blades, a bigger hub, a nacelle further forward). Below, "the turbine"
means the model so grown; its boxes are grown with it. A turbine far from a point is skipped: its bounding box, which encloses every part,
grown by the cull distance does not contain the point, so the point is farther than that from
every part of it, and the value reported there (the cull distance) is still a lower bound.

The cull distance is ``horizon_m``, or with a ``cap`` just enough that the model's distance to a
skipped turbine is provably above the cap: values below the cap are exactly the model's, values
at or above it are lower bounds (the planner only ever compares them with thresholds up to the
cap).

Speed: the grown boxes are hashed into a grid of square cells in x/y, so a query point only meets
the few turbines whose boxes overlap its cell, and a leg is sampled only where it runs through a
turbine's box; the cost of a query does not grow with the site.
"""

from __future__ import annotations

import math

import numpy as np

from wtcli.geometry import Turbine

# How far beyond a turbine's enclosing box its parts are still evaluated (uncapped queries):
# farther, the reported clearance is this distance, a lower bound. The one cull distance of
# plan and fly.
HORIZON_M = 60.0
MAX_CELLS = 256  # per axis: a site tens of km across still gets a small grid
GROUND_BRUTE_FORCE = 16  # up to this many ground points, the nearest is found by comparing all


def enclosing_box(t: Turbine) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) corners of an axis-aligned box that holds every part of the turbine.

    The horizontal reach is the historical one (rotor radius + overhang + nacelle length + hub
    radius), widened where unusual part sizes need more: blades (a section's largest semi-axis
    around the tip radius), the nacelle box and the tower."""
    a_max = max(t.blade_root_chord, t.blade_max_chord, t.blade_tip_chord) / 2.0
    reach = max(t.tip_radius + t.overhang + t.nacelle_length + t.hub_radius,
                t.overhang + t.tip_radius + a_max,
                math.hypot(abs(t.nacelle_ahead) + 0.5 * t.nacelle_length, 0.5 * t.nacelle_width),
                t.tower_base_radius, t.tower_top_radius)
    b = t.base_xyz
    z_lo = min(b[2], b[2] + t.hub_height - t.tip_radius - a_max)
    z_hi = max(b[2] + t.hub_height + reach,
               b[2] + t.hub_height + t.nacelle_above_hub + 0.5 * t.nacelle_height)
    return np.array([b[0] - reach, b[1] - reach, z_lo]), np.array([b[0] + reach, b[1] + reach, z_hi])


def part_boxes(t: Turbine) -> tuple[np.ndarray, np.ndarray]:
    """(2, 3) lo and hi corners of two boxes that together hold the turbine, tighter than
    ``enclosing_box``: the rotor with nacelle and hub (up there), and the tower (down to the base)."""
    lo, hi = enclosing_box(t)
    a_max = max(t.blade_root_chord, t.blade_max_chord, t.blade_tip_chord) / 2.0
    b = t.base_xyz
    rotor_lo = lo.copy()
    rotor_lo[2] = max(lo[2], b[2] + min(t.hub_height - t.tip_radius - a_max,
                                        t.tower_height,
                                        t.hub_height - t.hub_radius))
    r = max(t.tower_base_radius, t.tower_top_radius)
    return (np.array([rotor_lo, [b[0] - r, b[1] - r, b[2]]]),
            np.array([hi, [b[0] + r, b[1] + r, b[2] + t.tower_height]]))


class Site:
    """The turbines of a site (and its ground) as the planner keeps clear of them.

    ``uncertainty``: each turbine's geometry uncertainty in metres (one number for all, or one
    per turbine; default 0): how far the real surfaces may lie outside the modelled ones. Every
    clearance is then measured to the model grown by it (module docstring)."""

    def __init__(self, turbines: list[Turbine] | tuple[Turbine, ...], horizon_m: float = HORIZON_M,
                 launch: np.ndarray | None = None, uncertainty: float | list[float] | np.ndarray = 0.0):
        self.turbines = list(turbines)
        self.horizon = float(horizon_m)
        u = np.broadcast_to(np.asarray(uncertainty, float), (len(self.turbines),)).copy()
        if not (np.isfinite(u).all() and (u >= 0).all()):
            raise ValueError(f"expected uncertainties >= 0 m, one per turbine, got {u.tolist()}")
        self.uncertainty = u
        self._u_max = float(u.max()) if len(u) else 0.0
        boxes = [enclosing_box(t) for t in self.turbines]
        self.box_lo = np.array([b[0] for b in boxes]).reshape(-1, 3) - u[:, None]
        self.box_hi = np.array([b[1] for b in boxes]).reshape(-1, 3) + u[:, None]
        self.lo = self.box_lo - self.horizon
        self.hi = self.box_hi + self.horizon
        # Capped queries cull with the two tighter boxes per turbine (their grown union lies
        # inside the horizon's box, so the grid built for that serves both).
        parts = [part_boxes(t) for t in self.turbines]
        self.part_lo = np.array([p[0] for p in parts]).reshape(-1, 2, 3) - u[:, None, None]
        self.part_hi = np.array([p[1] for p in parts]).reshape(-1, 2, 3) + u[:, None, None]
        # The model's blade distance is at least this factor times the true distance.
        self._taper = np.array([t._blade_taper_cos() for t in self.turbines])
        self._taper_min = float(self._taper.min()) if len(self._taper) else 1.0
        ground = [t.base_xyz for t in self.turbines]
        if launch is not None:
            ground.append(np.asarray(launch, float))
        self.ground = FlatGround(np.array(ground).reshape(-1, 3))
        self.ground_points = self.ground.points
        self._hubs = np.array([t.hub_center for t in self.turbines]).reshape(-1, 3)
        self._build_grid()
        self._grid_args: tuple | None = None

    # ---- the grid of boxes ------------------------------------------------------------------
    def _build_grid(self) -> None:
        """Cells as large as the largest grown box (so a box overlaps at most 2 x 2 of them), each
        listing the turbines whose grown box overlaps it (CSR: ``_start``, ``_members``)."""
        if not self.turbines:
            self._origin, self._cell, self._shape = np.zeros(2), 1.0, np.array([1, 1])
            self._start, self._members = np.zeros(2, np.int64), np.zeros(0, np.int64)
            return
        lo, hi = self.lo[:, :2], self.hi[:, :2]
        self._origin = lo.min(axis=0)
        extent = float((hi.max(axis=0) - self._origin).max())
        self._cell = max(float((hi - lo).max()), extent / MAX_CELLS, 1e-6)
        # Cells of the box corners with the same expression as the query points': floor and the
        # rounded arithmetic are monotone, so a point inside a box always falls in one of its cells.
        c_lo = np.floor((lo - self._origin) / self._cell).astype(np.int64)
        c_hi = np.floor((hi - self._origin) / self._cell).astype(np.int64)
        self._shape = c_hi.max(axis=0) + 1
        cells, members = [], []
        for i, (a, b) in enumerate(zip(c_lo, c_hi)):
            gx, gy = np.meshgrid(np.arange(a[0], b[0] + 1), np.arange(a[1], b[1] + 1), indexing="ij")
            cells.append((gx * self._shape[1] + gy).ravel())
            members.append(np.full(gx.size, i, np.int64))
        cells_a = np.concatenate(cells)
        order = np.argsort(cells_a, kind="stable")
        self._members = np.concatenate(members)[order]
        self._start = np.searchsorted(cells_a[order], np.arange(int(self._shape.prod()) + 1))

    def cull_distance(self, cap: float) -> float:
        """How far beyond its box a turbine is still evaluated for a query capped at ``cap``.

        Outside, the true distance exceeds it and the model's exceeds ``cap`` (the taper factor
        is the model's only shortfall); the small addition covers rounding. With an uncertainty
        u the true distance to the bare model is beyond g + u, the model's beyond
        taper (g + u), less u that is above taper g - (1 - taper) u: g grows by that."""
        return min(self.horizon, (cap + (1.0 - self._taper_min) * self._u_max) / self._taper_min
                   + 0.01)

    def _kernel_grid(self) -> tuple:
        """The site as ``clearance_site_kernel`` reads it: the boxes and their grid
        (``_kernel_boxes``), then each turbine's ``Turbine._kernel_params`` stacked (blade frames
        padded to the most blades, ``nb`` telling how many are real) and the uncertainties;
        built on the first query."""
        if self._grid_args is None:
            params = [t._cached("kernel_params", t._kernel_params) for t in self.turbines]
            nb = np.array([len(f) for _, _, f in params], np.int64)
            frames = np.zeros((len(params), int(nb.max()) if len(nb) else 0, 3, 3))
            for i, (_, _, f) in enumerate(params):
                frames[i, :len(f)] = f
            vec = np.array([v for v, _, _ in params], float) if params else np.zeros((0, 6, 3))
            sc = np.array([c for _, c, _ in params], float) if params else np.zeros((0, 1))
            self._grid_args = self._kernel_boxes() + (vec, sc, frames, nb, self.uncertainty)
        return self._grid_args

    def _kernel_boxes(self) -> tuple:
        """Box corners (grown by the horizon; part boxes), the grid's origin, cell size and
        shape, and its CSR lists (``_start``, ``_members``), as the kernels take them."""
        return (self.lo, self.hi, self.part_lo, self.part_hi, np.asarray(self._origin, float),
                float(self._cell), np.asarray(self._shape, np.int64), self._start, self._members)

    def near(self, points: np.ndarray) -> list[np.ndarray]:
        """Per turbine, the indices of the points inside its grown bounding box."""
        from wtcli.plan import clearance_site_kernel

        P = np.ascontiguousarray(np.atleast_2d(np.asarray(points, float)))
        pp, tt = clearance_site_kernel.near(P, *self._kernel_boxes())
        order = np.argsort(tt, kind="stable")
        pp, tt = pp[order], tt[order]
        return [pp[tt == i] for i in range(len(self.turbines))]

    def nearest_hub(self, point: np.ndarray) -> Turbine:
        """The turbine whose hub centre is nearest the point (the first such, as ``min`` would)."""
        return self.turbines[int(np.argmin(np.linalg.norm(self._hubs - point, axis=1)))]

    # ---- clearance ------------------------------------------------------------------------------
    def clearance(self, points: np.ndarray, cap: float | None = None) -> np.ndarray:
        """(M,) distance to the nearest part of any turbine (``Turbine.clearance``'s lower bound),
        capped at the horizon, or with ``cap`` at the cull distance (module docstring); NaN for
        a point with a NaN coordinate (never "clear").

        Speed: the query runs compiled (``clearance_site_kernel``), and a part's exact distance is
        computed only for points whose cheap bound (distance to a capsule or cylinder enclosing
        the part) is below ``cap`` (default: the horizon); elsewhere the cheap bound, itself a
        lower bound of the true distance, stands in."""
        from wtcli.plan import clearance_site_kernel  # numba is imported on first use (Turbine.clearance)

        P = np.ascontiguousarray(np.atleast_2d(np.asarray(points, float)))
        cap = self.horizon if cap is None else min(float(cap), self.horizon)
        grow = self.cull_distance(cap)
        return clearance_site_kernel.clearance(P, grow, grow == self.horizon, cap, *self._kernel_grid())

    def nearest_part(self, point: np.ndarray) -> tuple[str, float]:
        """("T1 blade2", 2.3): the part of any turbine nearest a point, and its distance (less
        the turbine's uncertainty, as ``clearance``).

        Turbines are visited nearest box first and the search stops where a box is so far that
        no part inside can beat the best found: the model's distance is at least the blade taper
        factor times the true one, which is at least the distance to the box (``cull_distance``
        has the uncertainty's share)."""
        x = np.asarray(point, float).reshape(3)
        box = np.linalg.norm(np.maximum(np.maximum(self.box_lo - x, x - self.box_hi), 0.0), axis=1)
        bound = (box * self._taper - (1.0 - self._taper) * self.uncertainty) * (1 - 1e-9) - 1e-9
        dist: dict[int, np.ndarray] = {}
        for i in np.argsort(bound, kind="stable"):
            if dist and bound[i] > min(float(c.min()) for c in dist.values()):
                break
            dist[int(i)] = np.maximum(self.turbines[i].clearance_by_part(x[None])[0]
                                      - self.uncertainty[i], 0.0)
        best = ("nothing", np.inf)
        for i in sorted(dist):  # as over the whole site: the first turbine at the least distance
            c = dist[i]
            k = int(np.argmin(c))
            if c[k] < best[1]:
                best = (f"{self.turbines[i].id} {self.turbines[i].part_names()[k]}", float(c[k]))
        return best

    def segment_clearance(self, p0: np.ndarray, p1: np.ndarray, step: float = 0.5,
                          cap: float | None = None) -> np.ndarray:
        """Lower bound of the clearance along each straight leg p0[i] -> p1[i] (capped).

        The same samples and bound as ``segment_lower_bound`` (at most ``step`` apart, minus half
        their spacing), but only the samples inside some turbine's grown box are evaluated: the
        others are at the cull distance, which every evaluated value is capped at anyway."""
        from wtcli.plan import clearance_site_kernel

        p0 = np.ascontiguousarray(np.atleast_2d(np.asarray(p0, float)))
        p1 = np.ascontiguousarray(np.atleast_2d(np.asarray(p1, float)))
        if len(p0) == 0:
            return np.zeros(0)
        cap = self.horizon if cap is None else min(float(cap), self.horizon)
        grow = self.cull_distance(cap)
        length = np.linalg.norm(p1 - p0, axis=1)
        n = np.maximum(1, np.ceil(length / step).astype(np.int64))
        out = clearance_site_kernel.segment_clearance(p0, p1, n, *self._slabs(grow), grow,
                                              grow == self.horizon, cap, *self._kernel_grid())
        return out - 0.5 * length / n

    def lowest_sample(self, p0: np.ndarray, p1: np.ndarray, step: float = 0.5,
                      cap: float | None = None) -> float | None:
        """Where (t in [0, 1]) the leg p0 -> p1's least-clearance sample of ``segment_clearance``
        lies; None where no sample is near a turbine."""
        t, c = self._leg_samples(p0, p1, step, cap)
        return float(t[np.argmin(c)]) if len(t) else None

    def blocked_stretches(self, p0: np.ndarray, p1: np.ndarray, need: float, step: float = 0.5,
                          cap: float | None = None, gap: float = 0.0) -> list[tuple[float, float]]:
        """(first, last) t in [0, 1] of each run of the leg p0 -> p1's samples whose
        ``segment_clearance`` bound is below ``need``; runs closer than ``gap`` metres merged."""
        length = float(np.linalg.norm(np.asarray(p1, float) - np.asarray(p0, float)))
        t, c = self._leg_samples(p0, p1, step, cap)
        n = max(1, math.ceil(length / step))
        bad = np.sort(t[c - 0.5 * length / n < need])
        if len(bad) == 0:
            return []
        cut = np.flatnonzero(np.diff(bad) * length > max(gap, 1.5 * length / n)) + 1
        return [(float(r[0]), float(r[-1])) for r in np.split(bad, cut)]

    def _leg_samples(self, p0: np.ndarray, p1: np.ndarray, step: float,
                     cap: float | None) -> tuple[np.ndarray, np.ndarray]:
        """(t, clearance) of the samples of ``segment_clearance`` on one leg that lie near a
        turbine (the others are at the cull distance)."""
        from wtcli.plan import clearance_site_kernel

        p0, p1 = np.asarray(p0, float).reshape(3), np.asarray(p1, float).reshape(3)
        cap = self.horizon if cap is None else min(float(cap), self.horizon)
        n = max(1, math.ceil(float(np.linalg.norm((p1 - p0)[None], axis=1)[0]) / step))
        j0, j1 = clearance_site_kernel.stretches(*p0, *p1, n, *self._slabs(self.cull_distance(cap)))
        if len(j0) == 0:
            return np.zeros(0), np.zeros(0)
        t = np.concatenate([np.arange(a, b + 1) for a, b in zip(j0, j1)]) / n
        return t, self.clearance(p0 + (p1 - p0) * t[:, None], cap)

    def _slabs(self, grow: float) -> tuple[np.ndarray, np.ndarray]:
        """The boxes a leg is sampled in: with the horizon each turbine's box, with a cap both
        part boxes of every turbine; grown by ``grow`` and 1 cm more (``clearance_site_kernel.stretches``)."""
        if grow == self.horizon:
            return self.box_lo - (grow + 0.01), self.box_hi + (grow + 0.01)
        return (np.ascontiguousarray(self.part_lo.reshape(-1, 3) - (grow + 0.01)),
                np.ascontiguousarray(self.part_hi.reshape(-1, 3) + (grow + 0.01)))

    def legs_above_ground(self, p0: np.ndarray, p1: np.ndarray, height: float) -> np.ndarray:
        """(K,) bool: each straight leg p0[i] -> p1[i] stays ``height`` above the ground model
        (``ground_z``) all along, exactly (no sampling): a leg between two low ends may cross a
        higher base's ground."""
        p0 = np.atleast_2d(np.asarray(p0, float))
        p1 = np.atleast_2d(np.asarray(p1, float))
        if len(p0) == 0:
            return np.zeros(0, bool)
        G = self.ground_points
        top = G[:, 2].max() + height - 1e-6 if len(G) else -np.inf
        ok = np.ones(len(p0), bool)
        # A leg whose lower end is above the site's highest ground stays above all of it: most
        # legs (passes at rotor height) are settled without finding the ground under them.
        low = np.nonzero(np.minimum(p0[:, 2], p1[:, 2]) < top)[0]
        if len(low) == 0:
            return ok
        a, b = p0[low], p1[low]
        i0, i1 = self.ground_index(a), self.ground_index(b)
        ok[low] = (a[:, 2] >= G[i0, 2] + height - 1e-6) & (b[:, 2] >= G[i1, 2] + height - 1e-6)
        # Both ends over the same ground point: its region is convex, so the leg stays in it.
        # Only the other legs need the regions worked out.
        todo = low[ok[low] & (i0 != i1)]
        if len(todo):
            ok[todo] = self._above_each_ground(p0[todo], p1[todo], height)
        return ok

    def _above_each_ground(self, p0: np.ndarray, p1: np.ndarray, height: float) -> np.ndarray:
        """``legs_above_ground`` for legs whose ground may change under them: the part of a leg
        over ground point j is the interval of t where j is at least as near as every other
        ground point (linear in t: |x - g_j|^2 <= |x - g_k|^2; closed, so a boundary counts for
        both sides), and the leg's height is linear, so its lowest point there is at an end of
        that interval."""
        G = self.ground_points
        g = G[:, :2]
        c = (g * g).sum(axis=1)
        Dg = g[None, :, :] - g[:, None, :]  # (j, k, 2): g_k - g_j
        ok = np.ones(len(p0), bool)
        per = max(1, 2_000_000 // max(1, len(G) * len(G)))  # legs per block: bounded memory
        for s0 in range(0, len(p0), per):
            P0, P1 = p0[s0:s0 + per], p1[s0:s0 + per]
            a = 2.0 * np.einsum("li,jki->ljk", (P1 - P0)[:, :2], Dg)  # a t <= b: j not farther than k
            b = (c[None, :] - c[:, None])[None] - 2.0 * np.einsum("li,jki->ljk", P0[:, :2], Dg)
            with np.errstate(divide="ignore", invalid="ignore"):
                r = b / a
            lo = np.maximum(np.where(a < 0, r, -np.inf).max(axis=2), 0.0)
            hi = np.minimum(np.where(a > 0, r, np.inf).min(axis=2), 1.0)
            over = (lo <= hi) & ~((a == 0) & (b < 0)).any(axis=2)  # the leg passes over j
            z0, dz = P0[:, 2:3], (P1 - P0)[:, 2:3]
            lowest = np.minimum(z0 + lo * dz, z0 + hi * dz)  # lo, hi are within [0, 1]
            ok[s0:s0 + per] = ~(over & (lowest < G[None, :, 2] + height - 1e-6)).any(axis=1)
        return ok

    def above_ground(self, points: np.ndarray, height: float) -> np.ndarray:
        """(N,) bool: each point is at least ``height`` above the ground under it (``ground_z``);
        points above the site's highest ground need no lookup."""
        P = np.atleast_2d(np.asarray(points, float))
        G = self.ground_points
        ok = P[:, 2] >= (G[:, 2].max() if len(G) else -np.inf) + height
        low = np.nonzero(~ok)[0]
        if len(low):
            ok[low] = P[low, 2] >= self.ground_z(P[low]) + height
        return ok

    def ground_z(self, points: np.ndarray) -> np.ndarray:
        """Ground level under each point (``FlatGround.z``)."""
        return self.ground.z(points)

    def ground_index(self, points: np.ndarray) -> np.ndarray:
        """Index (into ``ground_points``) of the ground point nearest each point in x/y
        (``FlatGround.index``)."""
        return self.ground.index(points)


class FlatGround:
    """The ground as the planner takes it, and ``fly`` flies over on flat terrain: flat
    around each of its points (turbine bases, launch points), its level under a point the
    height of the point nearest in x/y (the first of equally near ones)."""

    def __init__(self, points: np.ndarray):
        self.points = np.asarray(points, float).reshape(-1, 3)
        self._build_grid()

    def z(self, points: np.ndarray) -> np.ndarray:
        """Ground level under each of ``points`` ((N, 2) or (N, 3); x/y used)."""
        return self.points[self.index(points), 2]

    def index(self, points: np.ndarray) -> np.ndarray:
        """Index (into ``points``) of the ground point nearest each point in x/y, the
        first of equally near ones. The points with one index form a convex region.

        The ground points in the 3 x 3 cells around each point's cell are compared (compiled,
        ``clearance_site_kernel.ground_index``): where the nearest of them is within one cell size, no
        point further out can be nearer (nor as near); elsewhere, and on small sites, all are."""
        from wtcli.plan import clearance_site_kernel

        P = np.atleast_2d(np.asarray(points, float))
        if P.shape[1] == 2:
            P = np.c_[P, np.zeros(len(P))]
        P = np.ascontiguousarray(P)
        G = self.points
        if len(G) == 0:
            return np.argmin(np.zeros((len(P), 0)), axis=1)  # numpy's own error
        return clearance_site_kernel.ground_index(P, G, np.asarray(self._g_origin, float), float(self._g_cell),
                                          np.asarray(self._g_shape, np.int64), self._g_start,
                                          self._g_members, len(G) <= GROUND_BRUTE_FORCE)

    def _build_grid(self) -> None:
        """Cells of the ground points (CSR: ``_g_start``, ``_g_members``), as large as the
        typical spacing of the points, so most queries find their nearest in 3 x 3 cells."""
        G = self.points[:, :2]
        self._g_origin = G.min(axis=0) if len(G) else np.zeros(2)
        span = (G.max(axis=0) - self._g_origin) if len(G) else np.zeros(2)
        extent = float(span.max()) if len(G) else 0.0
        # Half the spacing of an even layout: 3 x 3 cells hold a few points, and the points the
        # planner asks about (within a rotor of a base) find theirs there. Any size is exact;
        # only the speed depends on it.
        cell = 0.5 * math.sqrt(max(float(span[0]), 1.0) * max(float(span[1]), 1.0) / max(len(G), 1))
        self._g_cell = max(cell, extent / MAX_CELLS, 1e-6)
        c = np.floor((G - self._g_origin) / self._g_cell).astype(np.int64)
        self._g_shape = (c.max(axis=0) + 1) if len(G) else np.array([1, 1])
        key = c[:, 0] * self._g_shape[1] + c[:, 1]
        order = np.argsort(key, kind="stable")
        self._g_members = order.astype(np.int64)
        self._g_start = np.searchsorted(key[order], np.arange(int(self._g_shape.prod()) + 1))


def clearance_to_parts(turbines: list[Turbine] | tuple[Turbine, ...] | Site,
                       points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per point: the clearance (m) to the nearest part of any turbine and that part's name.

    The public call for code outside the planner (the flight simulator): ``turbines`` is a
    list of ``Turbine`` (or a ``Site`` already built for them), ``points`` (M, 3) ENU metres.
    Returns ``(distance, part)``: ``distance`` (M,) float, ``Turbine.clearance_by_part``'s
    values (never more than the true distance; 0 inside a part): to the modelled surfaces
    themselves, whatever uncertainty a ``Site`` given here carries; ``part`` (M,) object array of
    names such as ``"T1/blade2"``. Distances are capped at ``HORIZON_M`` (as ``Site.clearance``;
    there a lower bound); a point farther than that beyond every turbine's enclosing box gets
    the part ``""``.
    """
    site = turbines if isinstance(turbines, Site) else Site(turbines)
    P = np.ascontiguousarray(np.atleast_2d(np.asarray(points, float)))
    best = np.full(len(P), np.inf)
    which = np.full(len(P), "", dtype=object)
    for i, idx in enumerate(site.near(P)):
        if not len(idx):
            continue
        t = site.turbines[i]
        by_part = t.clearance_by_part(P[idx])
        k = by_part.argmin(axis=1)
        d = by_part[np.arange(len(idx)), k]
        names = np.array([f"{t.id}/{p}" for p in t.part_names()], dtype=object)
        better = d < best[idx]
        best[idx[better]] = d[better]
        which[idx[better]] = names[k[better]]
    return np.minimum(best, site.horizon), which
