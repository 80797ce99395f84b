"""Which parts of the surface a set of photos images well enough: the one coverage measure.

``plan`` uses it on the planned camera poses (predicted coverage) and ``fly`` on the poses the
simulated vehicle really had when each photo was taken (measured coverage).

A surface sample counts as covered when at least one photo has it inside the frame (with a
small border margin), in front of the camera, at a ground sampling distance no coarser than the
target (times a tolerance), seen at an incidence angle (between the surface normal and the
direction to the camera) of at most ``max_incidence_deg``, and with nothing in between: the line
from the camera to the sample passes no part of the sample's turbine (tower, nacelle, hub, any
blade; ``Turbine.line_of_sight``). Back faces fail the incidence test, so a blade's far side is
never counted from the near side; a blade behind the tower, or a root behind the hub, is not
counted either. Other turbines are hundreds of metres away and never occlude.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wtcli.geometry.camera import Camera
from wtcli.geometry.turbine import BLADE_SIDES, SurfaceSamples, Turbine


@dataclass(frozen=True)
class Coverage:
    samples: SurfaceSamples
    covered: np.ndarray  # (M,) bool
    best_gsd_mm: np.ndarray  # (M,) finest GSD any photo achieved on the sample (inf if none)

    def __post_init__(self) -> None:
        if self.covered.shape != (len(self.samples),):
            raise ValueError(f"expected covered of shape ({len(self.samples)},), got {self.covered.shape}")

    def fraction(self, mask: np.ndarray) -> float:
        """Area-weighted covered fraction of the samples selected by ``mask``."""
        area = self.samples.area[mask]
        total = area.sum()
        return float((area * self.covered[mask]).sum() / total) if total > 0 else 0.0

    def by_blade_side(self) -> dict[str, dict[str, float]]:
        """{"blade1": {"leading_edge": 0.99, ...}, ...} area-weighted fractions."""
        out: dict[str, dict[str, float]] = {}
        s = self.samples
        for b in sorted(set(s.blade[s.blade >= 0].tolist())):
            out[f"blade{b + 1}"] = {name: self.fraction((s.blade == b) & (s.side == i))
                                    for i, name in enumerate(BLADE_SIDES)}
        return out

    def blade_average(self) -> float:
        """Mean over all blade sides (each side weighs the same, as Table 1 averages sides)."""
        vals = [v for sides in self.by_blade_side().values() for v in sides.values()]
        return float(np.mean(vals)) if vals else 0.0

    def structure_fraction(self) -> float:
        return self.fraction(self.samples.blade < 0)


def imaged(rel: np.ndarray, normals: np.ndarray, rotations: np.ndarray, camera: Camera,
           max_distance: float, max_incidence_deg: float, border: float) -> np.ndarray:
    """The coverage tests short of the line of sight, for any broadcast of cameras and samples.

    rel (..., 3): sample minus camera position; normals (..., 3); rotations (..., 3, 3)
    world->camera. True where the sample is within ``max_distance``, faces the camera within
    the incidence limit, lies in front of it and inside the frame less ``border`` (a fraction of
    the image size) at each edge. The planner's extra-view search asks the same question with
    tighter margins."""
    dist = np.linalg.norm(rel, axis=-1)
    facing = -np.einsum("...j,...j->...", rel, normals) / np.maximum(dist, 1e-9)
    pc = np.einsum("...j,...kj->...k", rel, rotations)
    z = pc[..., 2]
    zs = np.where(z > 0.1, z, 1.0)
    u = camera.fx * pc[..., 0] / zs + camera.cx
    v = camera.fx * pc[..., 1] / zs + camera.cy
    mx, my = border * camera.width_px, border * camera.height_px
    return ((dist <= max_distance) & (facing >= np.cos(np.radians(max_incidence_deg))) & (z > 0.1)
            & (u >= mx) & (u <= camera.width_px - 1 - mx) & (v >= my) & (v <= camera.height_px - 1 - my))


def measure_coverage(samples: SurfaceSamples, camera: Camera, positions: np.ndarray,
                     rotations: np.ndarray, target_gsd_mm: float,
                     max_incidence_deg: float = 60.0, gsd_tolerance: float = 1.05,
                     border_px: float = 0.02) -> Coverage:
    """Coverage of ``samples`` by photos taken with ``camera``'s intrinsics at the given poses.

    positions (P, 3) world; rotations (P, 3, 3) world->camera (as Camera.R). ``border_px`` is a
    fraction of the image size ignored at each edge (lens falloff, framing error). Occlusion is
    by ``samples.turbine`` (the turbine ``Turbine.surface_samples`` took them from)."""
    positions, rotations = _poses(positions, rotations)
    _need_turbine(samples)
    max_dist = camera.distance_for_gsd(target_gsd_mm * gsd_tolerance)
    covered, best, _, _ = _evaluate(samples, None, camera, positions, rotations, max_dist,
                                    max_incidence_deg, border_px)
    return Coverage(samples, covered, best)


def _poses(positions: np.ndarray, rotations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    positions = np.asarray(positions, float).reshape(-1, 3)
    rotations = np.asarray(rotations, float).reshape(-1, 3, 3)
    if len(positions) != len(rotations):
        raise ValueError(f"expected as many rotations as positions, got {len(rotations)} and {len(positions)}")
    return positions, rotations


def _need_turbine(samples: SurfaceSamples) -> None:
    if samples.turbine is None:
        raise ValueError("expected samples from Turbine.surface_samples (with their turbine), got "
                         "samples without one: occlusion cannot be checked")


def _evaluate(samples: SurfaceSamples | _Part, half_size: np.ndarray | None, camera: Camera,
              positions: np.ndarray, rotations: np.ndarray, max_dist: float, limit: float,
              border: float, wide: float | None = None, best_before: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(covered, best GSD (inf if none), near, firm) per sample, from these photos.

    With ``half_size`` (M,) (a sample's distance to its cell's corners, m), which samples are
    marginal: ``near``, some photo that has them in frame and within the GSD distance sees them
    so near the incidence limit that the limit may cross their cell (the normal turns by
    ``samples.turn_deg`` across it, the direction to the camera by up to half_size / distance);
    ``firm``, some photo has the whole cell within the limit. Line of sight is not asked for
    these. ``wide``: the incidence up to which pairs are looked at for them (at least the limit
    plus every sample's margin). ``best_before`` (M,): the finest GSD other photos reached on
    each sample (inf where none); pairs no finer cannot change it and are not traced."""
    from wtcli.geometry import coverage_kernel

    M = len(samples)
    covered, best = np.zeros(M, bool), np.full(M, np.inf)
    near, firm = np.zeros(M, bool), np.zeros(M, bool)
    P, N = samples.points, samples.normals
    if half_size is None:
        s, p, dist, facing = _pairs(P, N, positions, rotations, camera, max_dist, limit, border)
    else:
        s, p, dist, facing = _pairs(P, N, positions, rotations, camera, max_dist, wide, border)
        inside = coverage_kernel.incidence_flags(
            s, dist, facing, np.ascontiguousarray(samples.turn_deg, float),
            np.ascontiguousarray(half_size, float), float(limit), near, firm)
        s, p, dist = s[inside], p[inside], dist[inside]
    g = camera.gsd_mm(dist)
    if best_before is not None:
        finer = g < best_before[s]
        s, p, g = s[finer], p[finer], g[finer]
    if not len(s):
        return covered, best, near, firm
    # Every (sample, photo) pair that passes the cheap tests; the line of sight comes after.
    # Tracing a line of sight costs far more than the tests above, and one clear photo settles a
    # sample: trace each sample's photos finest GSD first, in rounds of 1, 2, 4, ... per sample,
    # and stop at the round where one is clear (its finest clear GSD is then in that round).
    order, start = coverage_kernel.by_sample(s, g, M)
    lo, width = 0, 1
    while True:
        sel = coverage_kernel.round_pairs(order, start, covered, lo, width)
        if len(sel) == 0:
            break
        clear = sel[samples.turbine.line_of_sight(positions[p[sel]], P[s[sel]])]
        np.minimum.at(best, s[clear], g[clear])
        covered[s[clear]] = True
        lo, width = lo + width, 2 * width
    return covered, best, near, firm


BURIED = 2  # the refinement's state of a cell whose middle lies inside another part
_SAMPLE_FIELDS = [k for k in SurfaceSamples.__dataclass_fields__ if k != "turbine"]
REFINE_LEVELS = 3  # blade cells at a coverage boundary are cut in 2 x 2 this many times


def _cell_key(blade: np.ndarray, level: np.ndarray, row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """One int64 per blade cell (blade < 64, level < 16, row and col < 2**20)."""
    return (((blade.astype(np.int64) << 4) + level) << 40) + (row.astype(np.int64) << 20) + col


@dataclass(frozen=True)
class _Part:
    """What ``_evaluate`` reads of samples (a subset of the pool without copying the rest)."""
    points: np.ndarray
    normals: np.ndarray
    turn_deg: np.ndarray
    turbine: Turbine

    def __len__(self) -> int:
        return len(self.points)


class _Cells:
    """One turbine's cells at one sampling, as one measure (camera, GSD, incidence, border)
    sees them: each cell's sample is made once and measured once per photo.

    The planner asks for the coverage of the same turbine several times with a growing set of
    photos (the gate after each round of gap views, then the plan's figure); what a sample's
    photos say combines photo by photo (covered: any photo; finest GSD: the least; near and
    firm: any), so a photo measured before is not measured again, and a cell cut before is not
    made again. Kept on the turbine (``Turbine._cache``). A call without a photo measured
    before (the planner rebuilds a pass) measures again the samples that photo had a pair with."""

    def __init__(self, turbine: Turbine, camera: Camera, spacing: float, max_dist: float,
                 limit: float, border: float, margins: bool) -> None:
        self.turbine, self.camera, self.spacing = turbine, camera, float(spacing)
        self.max_dist, self.limit, self.border, self.margins = max_dist, limit, border, margins
        self.shapes = np.array([turbine.blade_grid(k, spacing) for k in range(turbine.n_blades)],
                               float).reshape(-1, 4)
        # The samples' fields and states, in arrays grown by doubling (``pool``, ``covered`` ...
        # are views of their first ``n`` rows).
        self.n, self.buf = 0, {}
        self.keys, self.at = np.zeros(0, np.int64), np.zeros(0, np.int64)  # sorted; -1: buried
        self.pos, self.rot = np.zeros((0, 3)), np.zeros((0, 3, 3))
        self.photo: dict[bytes, int] = {}
        self.blocks: dict[str, np.ndarray] = {}
        self.blocks["blades"] = self._add(turbine.surface_samples(spacing, "blades"))
        # The incidence up to which pairs are looked at for the marginal test: the limit plus
        # the widest margin any cell may need (a cut cell's turn and size are at most its
        # parent's, and no photo is taken within a metre of the surface).
        b = self.blocks["blades"]
        self.wide = min(limit + float(np.max(self.pool.turn_deg[b], initial=0.0))
                        + float(np.degrees(np.max(self.half[b], initial=0.0) / 1.0)), 89.9)

    _STATE = {"half": (float, 0.0), "covered": (bool, False), "best": (float, np.inf),
              "near": (bool, False), "firm": (bool, False), "seen": (np.int64, 0)}

    @property
    def pool(self) -> SurfaceSamples:
        return SurfaceSamples(**{k: self.buf[k][:self.n] for k in _SAMPLE_FIELDS}, turbine=self.turbine)

    def __getattr__(self, name: str) -> np.ndarray:  # half, covered, best, near, firm, seen
        if name in _Cells._STATE and "buf" in self.__dict__:
            return self.buf[name][:self.n]
        raise AttributeError(name)

    def _add(self, smp: SurfaceSamples) -> np.ndarray:
        """Append samples to the pool; their indices. Blade cells are registered by key."""
        first, m = self.n, len(smp)
        half = np.zeros(m)
        on = smp.blade >= 0
        if on.any():
            r, _, s0, s1 = self.shapes[smp.blade[on]].T
            h = (s1 - s0) / (r * 2.0 ** smp.level[on])
            half[on] = 0.5 * np.hypot(h, smp.area[on] / h)
        new = {k: getattr(smp, k) for k in _SAMPLE_FIELDS}
        new["half"] = half
        for k, (dtype, fill) in _Cells._STATE.items():
            if k != "half":
                new[k] = np.full(m, fill, dtype)
        cap = len(self.buf["points"]) if self.buf else 0
        if first + m > cap:
            cap = max(2 * cap, first + m)
            for k, v in new.items():
                grown = np.empty((cap,) + v.shape[1:], v.dtype)
                if first:
                    grown[:first] = self.buf[k][:first]
                self.buf[k] = grown
        for k, v in new.items():
            self.buf[k][first:first + m] = v
        self.n = first + m
        idx = np.arange(first, first + m)
        self._register(_cell_key(smp.blade[on], smp.level[on], smp.row[on], smp.col[on]), idx[on])
        return idx

    def _register(self, keys: np.ndarray, idx: np.ndarray) -> None:
        """Cells (keys never registered before) at pool indices ``idx`` (-1: buried)."""
        order = np.argsort(keys, kind="stable")
        where = np.searchsorted(self.keys, keys[order])
        self.keys, self.at = np.insert(self.keys, where, keys[order]), np.insert(self.at, where, idx[order])

    def _find(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        i = np.minimum(np.searchsorted(self.keys, keys), max(len(self.keys) - 1, 0))
        found = (self.keys[i] == keys) if len(self.keys) else np.zeros(len(keys), bool)
        return np.where(found, self.at[i] if len(self.keys) else -1, -1), found

    def structure(self) -> np.ndarray:
        if "structure" not in self.blocks:
            self.blocks["structure"] = self._add(self.turbine.surface_samples(self.spacing, "structure"))
        return self.blocks["structure"]

    def cells(self, k: int, level: int, row: np.ndarray, col: np.ndarray) -> np.ndarray:
        """Pool indices of blade k's cells (row, col) at ``level``, made where new; -1 for cells
        buried in another part (they have no sample)."""
        keys = _cell_key(np.full(len(row), k), np.full(len(row), level), row, col)
        idx, found = self._find(keys)
        if not found.all():
            miss = ~found
            smp = self.turbine.blade_cell_samples(k, self.spacing, level, row[miss], col[miss])
            self._add(smp)
            made = np.isin(keys[miss], _cell_key(smp.blade, smp.level, smp.row, smp.col))
            self._register(keys[miss][~made], np.full(int((~made).sum()), -1, np.int64))
            idx, _ = self._find(keys)
        return idx

    def use(self, positions: np.ndarray, rotations: np.ndarray) -> None:
        """Make the photo set these photos: new ones are added; where one measured before is
        not among them, the samples it had a pair with (the only ones it could have changed)
        are measured again."""
        rows = [r.tobytes() for r in np.concatenate([positions, rotations.reshape(-1, 9)], axis=1)]
        now = set(rows)
        kept = np.array([r in now for r in self.photo], bool)
        if not kept.all():
            gone = np.nonzero(~kept)[0]
            s = _pairs(self.pool.points, self.pool.normals, self.pos[gone], self.rot[gone],
                       self.camera, self.max_dist, self.wide if self.margins else self.limit,
                       self.border)[0]
            s = np.unique(s)
            self.covered[s], self.near[s], self.firm[s], self.best[s], self.seen[s] = \
                False, False, False, np.inf, 0
            # The rest were measured against the first ``seen`` photos; of those, the kept ones
            # stay first, in the same order.
            self.seen[:] = np.r_[0, np.cumsum(kept)][self.seen]
            self.pos, self.rot = self.pos[kept], self.rot[kept]
            self.photo = {r: i for i, r in enumerate(r for r, k in zip(self.photo, kept) if k)}
        new = []
        for i, r in enumerate(rows):
            if r not in self.photo:
                self.photo[r] = len(self.pos) + len(new)
                new.append(i)
        if new:
            self.pos = np.concatenate([self.pos, positions[new]])
            self.rot = np.concatenate([self.rot, rotations[new]])

    def measure(self, idx: np.ndarray) -> None:
        """Bring the samples ``idx`` up to date with every photo."""
        K = len(self.pos)
        idx = idx[self.seen[idx] < K]
        for n0 in np.unique(self.seen[idx]):
            g = idx[self.seen[idx] == n0]
            part = _Part(self.buf["points"][g], self.buf["normals"][g], self.buf["turn_deg"][g],
                         self.turbine)
            c, b, near, firm = _evaluate(part, self.half[g] if self.margins else None,
                                         self.camera, self.pos[n0:], self.rot[n0:], self.max_dist,
                                         self.limit, self.border, self.wide, self.best[g])
            self.covered[g] |= c
            self.best[g] = np.minimum(self.best[g], b)
            self.near[g] |= near
            self.firm[g] |= firm
            self.seen[g] = K

    def marginal(self, idx: np.ndarray) -> np.ndarray:
        """Covered with no photo that holds the whole cell within the limit, or missed with a
        photo the limit may cross it for (line of sight not asked of these photos)."""
        return self.near[idx] & ~(self.covered[idx] & self.firm[idx])


def _cells_for(turbine: Turbine, camera: Camera, spacing: float, max_dist: float, limit: float,
               border: float, margins: bool, cache: bool) -> _Cells:
    if not cache:
        return _Cells(turbine, camera, spacing, max_dist, limit, border, margins)
    key = ("coverage_cells", camera.width_px, camera.height_px, camera.focal_mm,
           camera.sensor_width_mm, float(spacing), float(max_dist), float(limit), float(border),
           bool(margins))
    store = turbine._cache.get(key)
    if store is None:
        store = turbine._cache[key] = _Cells(turbine, camera, spacing, max_dist, limit, border, margins)
    return store


def turbine_coverage(turbine: Turbine, camera: Camera, positions: np.ndarray,
                     rotations: np.ndarray, target_gsd_mm: float, spacing: float,
                     max_incidence_deg: float = 60.0, parts: str = "all",
                     levels: int = REFINE_LEVELS, gsd_tolerance: float = 1.05,
                     border_px: float = 0.02, cache: bool = True) -> Coverage:
    """Coverage of ``turbine``'s surface (``parts`` as ``Turbine.surface_samples``), its blades
    sampled finer where the covered and the missed parts meet, so the figure converges.

    A sample stands for its cell of the blade's grid (``Turbine.blade_grid``: ``spacing`` along
    the span, equal arc lengths round each side). A side's covered fraction is a midpoint sum
    over those cells, and where a coverage boundary crosses a cell its error is up to the whole
    cell; the boundaries are lines (a frame edge, the incidence limit running along a thin
    edge), so a fixed grid converges only as fast as its spacing shrinks. Here every cell whose
    state differs from a neighbour's (along the span or round the section, at the finest level
    reached) is cut in 2 x 2 and its four middles measured, ``levels`` times over: the boundary
    is then placed within 1/2**levels of a cell, for little more work than the boundary's
    length. Tower, nacelle and hub samples are measured as sampled.

    ``cache``: keep the cells and what each photo said of them on the turbine, so that a later
    call on the same turbine with more photos measures only the new photos and the new cells
    (the figure is the same either way; tests/test_coverage.py checks it)."""
    positions, rotations = _poses(positions, rotations)
    L = int(levels)
    max_dist = camera.distance_for_gsd(target_gsd_mm * gsd_tolerance)
    store = _cells_for(turbine, camera, spacing, max_dist, float(max_incidence_deg), border_px,
                       L > 0, cache)
    store.use(positions, rotations)
    base = [store.blocks["blades"]] if parts in ("all", "blades") else []
    if parts in ("all", "structure"):
        base.append(store.structure())
    base_idx = np.concatenate(base) if base else np.zeros(0, np.int64)
    store.measure(base_idx)

    def result(idx: np.ndarray) -> Coverage:
        return Coverage(store.pool[idx], store.covered[idx], store.best[idx])

    if L <= 0 or parts == "structure" or not len(positions):
        return result(base_idx)
    pool = store.pool
    # Per blade, the finest grid: the state of the leaf cell over each fine cell (0 missed,
    # 1 covered, BURIED: its middle lies inside another part, so it has no sample; -1 none yet)
    # and that leaf's level. Where the blade runs into the hub or the nacelle the line between
    # buried and sampled cells is a boundary like any other: a cell it crosses counts whole or
    # not at all by its middle, so those cells are cut too.
    shapes = store.shapes.astype(np.int64)
    state = [np.full((r << L, (4 * n) << L), -1, np.int8) for r, n, _, _ in shapes]
    owner = [np.full(st.shape, L, np.int8) for st in state]
    chunks = [base_idx]
    split: list[np.ndarray] = []  # keys of the cells cut (no longer leaves)

    from wtcli.geometry import coverage_kernel

    def paint(idx: np.ndarray, buried: dict[int, list[np.ndarray]]) -> dict[int, np.ndarray]:
        """The leaves ``idx`` and the buried leaves (per blade, (level, row, col) arrays) onto
        their blades' grids; per blade all their (level, row, col)."""
        pool = store.pool
        blade, level, row, col = pool.blade[idx], pool.level[idx], pool.row[idx], pool.col[idx]
        covered = store.covered[idx].astype(np.int8)
        if buried:
            bk = np.concatenate([np.full(len(u), k) for k, us in buried.items() for u in us])
            bu = np.concatenate([u for us in buried.values() for u in us]).reshape(-1, 3)
            blade = np.concatenate([blade, bk]).astype(np.int64)
            level, row, col = (np.concatenate([a, bu[:, c]]) for c, a in enumerate((level, row, col)))
            covered = np.concatenate([covered, np.full(len(bk), BURIED, np.int8)])
        out = {}
        for k in np.unique(blade[blade >= 0]):
            mk = blade == k
            lv, r, c = (a[mk].astype(np.int64) for a in (level, row, col))
            coverage_kernel.paint(state[k], owner[k], L, lv, r, c, covered[mk], lv.astype(np.int8))
            out[int(k)] = np.stack([lv, r, c], axis=1)
        return out

    painted = paint(base_idx, {})
    for k, st in enumerate(state):  # the base cells without a sample: buried
        i, j = np.nonzero(st < 0)
        if len(i):
            u = np.unique(np.stack([np.zeros(len(i), np.int64), i >> L, j >> L], axis=1), axis=0)
            st[st < 0] = BURIED
            owner[k][st == BURIED] = 0
            painted[k] = np.concatenate([painted.get(k, np.zeros((0, 3), np.int64)), u])
    flagged = base_idx
    while True:
        todo = []  # (blade, level, row, col) of the leaves to cut
        # Leaves the incidence limit may cross (their own middle says nothing of it)
        pool = store.pool
        m = store.marginal(flagged) & (pool.blade[flagged] >= 0) & (pool.level[flagged] < L)
        f = flagged[m]
        for k in np.unique(pool.blade[f]):
            fk = f[pool.blade[f] == k]
            todo.append((int(k), np.stack([pool.level[fk], pool.row[fk], pool.col[fk]],
                                          axis=1).astype(np.int64)))
        # Leaves next to a leaf of the other state (along the span or round the section)
        for k, u in painted.items():
            cut = coverage_kernel.boundary_leaves(state[k], owner[k], L,
                                                  *(u[:, c].copy() for c in range(3)))
            if len(cut):
                todo.append((k, cut))
        if not todo:
            break
        by_blade: dict[int, list[np.ndarray]] = {}
        for k, u in todo:
            by_blade.setdefault(k, []).append(u)
        new = []
        buried: dict[int, list[np.ndarray]] = {}
        for k, us in by_blade.items():
            u = np.concatenate(us)
            keys = np.unique(_cell_key(np.full(len(u), k), u[:, 0], u[:, 1], u[:, 2]))
            split.append(keys)
            lv, i, j = (keys >> 40) & 15, (keys >> 20) & 0xFFFFF, keys & 0xFFFFF
            # the parents' fine cells: nothing until the children say
            coverage_kernel.paint(state[k], owner[k], L, lv, i, j, np.full(len(lv), -1, np.int8),
                                  (lv + 1).astype(np.int8))
            for l0 in np.unique(lv):
                m = lv == l0
                ci = (2 * i[m])[:, None] + np.array([0, 0, 1, 1])
                cj = (2 * j[m])[:, None] + np.array([0, 1, 0, 1])
                got = store.cells(k, int(l0) + 1, ci.ravel(), cj.ravel())
                new.append(got[got >= 0])
                gone = got < 0
                if gone.any():
                    buried.setdefault(k, []).append(np.stack(
                        [np.full(int(gone.sum()), l0 + 1), ci.ravel()[gone], cj.ravel()[gone]], axis=1))
        idx = np.concatenate(new)
        store.measure(idx)
        painted = paint(idx, buried)
        chunks.append(idx)
        flagged = idx
    if not split:
        return result(base_idx)
    cut = np.concatenate(split)
    idx = np.concatenate(chunks)
    pool = store.pool
    leaf = ~np.isin(_cell_key(pool.blade[idx], pool.level[idx], pool.row[idx], pool.col[idx]), cut) \
        | (pool.blade[idx] < 0)
    return result(idx[leaf])


CULL_SPLIT = 2  # cubes max_dist / 2 wide: finer ones cull closer but cost more (measured 2-4)


def _near_pairs(P: np.ndarray, N: np.ndarray, positions: np.ndarray, rotations: np.ndarray,
                camera: Camera, max_dist: float, max_incidence_deg: float,
                border: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(sample, photo, GSD) of the pairs ``imaged`` passes, photo by photo (photo-major)."""
    s, p, dist, _ = _pairs(P, N, positions, rotations, camera, max_dist, max_incidence_deg, border)
    return s, p, camera.gsd_mm(dist)


def _pairs(P: np.ndarray, N: np.ndarray, positions: np.ndarray, rotations: np.ndarray,
           camera: Camera, max_dist: float, max_incidence_deg: float,
           border: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(sample, photo, distance, cosine of the incidence) of the pairs ``imaged`` passes, photo
    by photo (photo-major).

    Speed: a photo sees only samples within max_dist and inside its frame, so the samples are
    hashed into cubes (max_dist / CULL_SPLIT wide) and each photo tests only the samples of the
    cubes around its own whose bounding ball reaches into both its max_dist sphere and the cone
    around its optical axis that holds the frame. The cull is conservative: a cube left out
    holds no sample ``imaged`` could pass (tests/test_occlusion.py checks it against every
    pair). The search and the tests run compiled (``coverage_kernel``): as numpy array code
    every candidate pair was built as arrays first, ~20 % of a plan's time."""
    empty = np.zeros(0, np.int64)
    if len(P) == 0 or len(positions) == 0:
        return empty, empty, np.zeros(0), np.zeros(0)
    from wtcli.geometry import coverage_kernel  # numba is imported on first use (as Turbine.clearance)

    cell = max_dist * (1 + 1e-6) / CULL_SPLIT + 1e-6
    origin = P.min(axis=0)
    ci = np.floor((P - origin) / cell).astype(np.int64)
    shape = ci.max(axis=0) + 1
    key = (ci[:, 0] * shape[1] + ci[:, 1]) * shape[2] + ci[:, 2]
    by_key = np.argsort(key, kind="stable")
    # The frame's cone (half-angle ``half``) holds every pixel (fx = fy, so a pixel at radius rho
    # from the principal point is atan(rho / fx) off the axis); a cube's bounding ball seen from
    # distance d spans asin(ball / d) around its centre.
    ball = cell * np.sqrt(3) / 2 * (1 + 1e-6) + 1e-6
    W, H = camera.width_px - 1, camera.height_px - 1
    rho = max(np.hypot(x - camera.cx, y - camera.cy) for x in (0, W) for y in (0, H))
    half = np.arctan(rho / camera.fx) + 1e-6
    cam = np.array([camera.fx, camera.cx, camera.cy, camera.width_px, camera.height_px,
                    border * camera.width_px, border * camera.height_px], float)
    return coverage_kernel.near_pairs(
        np.ascontiguousarray(P, float), np.ascontiguousarray(N, float),
        np.ascontiguousarray(positions, float), np.ascontiguousarray(rotations, float),
        origin.astype(float), float(cell), shape.astype(np.int64), key[by_key], by_key,
        CULL_SPLIT, cam, float(max_dist), float(np.cos(np.radians(max_incidence_deg))),
        float(half), float(ball))
