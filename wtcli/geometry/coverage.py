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
    return _measure(samples, camera, positions, rotations, target_gsd_mm, max_incidence_deg,
                    gsd_tolerance, border_px)[0]


def _measure(samples: SurfaceSamples, camera: Camera, positions: np.ndarray,
             rotations: np.ndarray, target_gsd_mm: float, max_incidence_deg: float,
             gsd_tolerance: float, border_px: float, half_size: np.ndarray | None = None
             ) -> tuple[Coverage, np.ndarray]:
    """``measure_coverage``, and with ``half_size`` (M,) (a sample's distance to its cell's
    corners, m) which samples are marginal: some photo that has them in frame and within the
    GSD distance sees them so near the incidence limit that the limit may cross their cell (the
    normal turns by ``samples.turn_deg`` across it, the direction to the camera by up to
    half_size / distance). Occlusion is not asked for these."""
    positions = np.asarray(positions, float).reshape(-1, 3)
    rotations = np.asarray(rotations, float).reshape(-1, 3, 3)
    if len(positions) != len(rotations):
        raise ValueError(f"expected as many rotations as positions, got {len(rotations)} and {len(positions)}")
    if samples.turbine is None:
        raise ValueError("expected samples from Turbine.surface_samples (with their turbine), got "
                         "samples without one: occlusion cannot be checked")
    P, N = samples.points, samples.normals
    max_dist = camera.distance_for_gsd(target_gsd_mm * gsd_tolerance)
    marginal = np.zeros(len(P), bool)
    if half_size is None:
        s, p, g = _near_pairs(P, N, positions, rotations, camera, max_dist, max_incidence_deg, border_px)
    else:
        # The pairs within the incidence limit plus the widest margin any sample may need (no
        # photo is taken within a metre of the surface).
        wide = min(max_incidence_deg + float(np.max(samples.turn_deg, initial=0.0)) / 2
                   + float(np.degrees(np.max(half_size, initial=0.0) / 1.0)), 89.9)
        s, p, g = _near_pairs(P, N, positions, rotations, camera, max_dist, wide, border_px)
        rel = P[s] - positions[p]
        dist = np.linalg.norm(rel, axis=1)
        inc = np.degrees(np.arccos(np.clip(-np.einsum("ij,ij->i", rel, N[s]) / np.maximum(dist, 1e-9),
                                           -1.0, 1.0)))
        margin = samples.turn_deg[s] / 2 + np.degrees(half_size[s] / np.maximum(dist, 1e-9))
        near = np.zeros(len(P), bool)  # a photo the limit may cross the cell for
        near[s[np.abs(inc - max_incidence_deg) <= margin]] = True
        firm = np.zeros(len(P), bool)  # a photo that has the whole cell within the limit
        firm[s[inc <= max_incidence_deg - margin]] = True
        inside = inc <= max_incidence_deg
        s, p, g = s[inside], p[inside], g[inside]
    # Every (sample, photo) pair that passes the cheap tests; the line of sight comes after.
    covered = np.zeros(len(P), bool)
    best = np.full(len(P), np.inf)
    if not len(s):
        return Coverage(samples, covered, best), marginal
    # Tracing a line of sight costs far more than the tests above, and one clear photo settles a
    # sample: trace each sample's photos finest GSD first, in rounds of 1, 2, 4, ... per sample,
    # and stop at the round where one is clear (its finest clear GSD is then in that round).
    order = np.lexsort((g, s))
    s, p, g = s[order], p[order], g[order]
    i = np.arange(len(s))
    rank = i - np.maximum.accumulate(np.where(np.r_[True, s[1:] != s[:-1]], i, 0))
    lo, width = 0, 1
    while lo <= rank.max():
        sel = np.nonzero((rank >= lo) & (rank < lo + width) & ~covered[s])[0]
        if len(sel) == 0:
            break
        clear = sel[samples.turbine.line_of_sight(positions[p[sel]], P[s[sel]])]
        np.minimum.at(best, s[clear], g[clear])
        covered[s[clear]] = True
        lo, width = lo + width, 2 * width
    if half_size is not None:
        # Covered with no photo that holds the whole cell within the limit, or missed with a
        # photo the limit may cross it for (line of sight not asked of these photos).
        marginal = near & ~(covered & firm)
    return Coverage(samples, covered, best), marginal


REFINE_LEVELS = 3  # blade cells at a coverage boundary are cut in 2 x 2 this many times


def turbine_coverage(turbine: Turbine, camera: Camera, positions: np.ndarray,
                     rotations: np.ndarray, target_gsd_mm: float, spacing: float,
                     max_incidence_deg: float = 60.0, parts: str = "all",
                     levels: int = REFINE_LEVELS, gsd_tolerance: float = 1.05,
                     border_px: float = 0.02) -> Coverage:
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
    length. Tower, nacelle and hub samples are measured as sampled."""
    L = int(levels)
    shapes = [turbine.blade_grid(k, spacing) for k in range(turbine.n_blades)]

    def half_size(smp: SurfaceSamples) -> np.ndarray:
        """Each blade sample's distance to its cell's corners (0 off blades)."""
        out = np.zeros(len(smp))
        on = smp.blade >= 0
        r, _, s0, s1 = np.array(shapes, float)[smp.blade[on]].T
        h = (s1 - s0) / (r * 2.0 ** smp.level[on])
        out[on] = 0.5 * np.hypot(h, smp.area[on] / h)
        return out

    def measure(smp: SurfaceSamples) -> tuple[Coverage, np.ndarray]:
        return _measure(smp, camera, positions, rotations, target_gsd_mm, max_incidence_deg,
                        gsd_tolerance, border_px, half_size(smp) if L > 0 else None)

    base = turbine.surface_samples(spacing, parts)
    cov, marginal = measure(base)
    if L <= 0 or parts == "structure" or not len(positions):
        return cov
    # Per blade, the finest grid: the state of the leaf cell over each fine cell (-1 none:
    # buried, or nothing sampled) and that leaf's level.
    state = [np.full((r << L, (4 * n) << L), -1, np.int8) for r, n, _, _ in shapes]
    owner = [np.full(st.shape, L, np.int8) for st in state]
    chunks = [(cov.samples, cov.covered, cov.best_gsd_mm)]
    split: list[np.ndarray] = []  # keys of the cells cut (no longer leaves)

    def key(k: np.ndarray, level: np.ndarray, row: np.ndarray, col: np.ndarray) -> np.ndarray:
        return ((k.astype(np.int64) * (L + 1) + level) << 40) + (row.astype(np.int64) << 20) + col

    def paint(smp: SurfaceSamples, covered: np.ndarray) -> None:
        for k in np.unique(smp.blade[smp.blade >= 0]):
            for lv in np.unique(smp.level[smp.blade == k]):
                m = (smp.blade == k) & (smp.level == lv)
                b = 1 << (L - int(lv))
                st, ow = state[k], owner[k]
                st.reshape(st.shape[0] // b, b, st.shape[1] // b, b)[smp.row[m], :, smp.col[m], :] = \
                    covered[m][:, None, None]
                ow.reshape(ow.shape[0] // b, b, ow.shape[1] // b, b)[smp.row[m], :, smp.col[m], :] = lv

    paint(cov.samples, cov.covered)
    flagged = [(cov.samples, marginal)]
    while True:
        todo = []  # (blade, level, row, col) of the leaves to cut
        # Leaves the incidence limit may cross (their own middle says nothing of it)
        for smp, m in flagged:
            m = m & (smp.blade >= 0) & (smp.level < L)
            for k in np.unique(smp.blade[m]):
                mk = m & (smp.blade == k)
                todo.append((int(k), np.stack([smp.level[mk], smp.row[mk], smp.col[mk]],
                                              axis=1).astype(np.int64)))
        for k, (st, ow) in enumerate(zip(state, owner)):
            ok = st >= 0
            edge = np.zeros(st.shape, bool)
            d = ok & np.roll(ok, -1, axis=1) & (st != np.roll(st, -1, axis=1))  # round the section
            edge |= d | np.roll(d, 1, axis=1)
            d = ok[:-1] & ok[1:] & (st[:-1] != st[1:])  # along the span
            edge[:-1] |= d
            edge[1:] |= d
            edge &= ow < L
            if not edge.any():
                continue
            i, j = np.nonzero(edge)
            lv = ow[i, j].astype(np.int64)
            i, j = i >> (L - lv), j >> (L - lv)
            todo.append((k, np.stack([lv, i, j], axis=1)))
        if not todo:
            break
        by_blade: dict[int, list[np.ndarray]] = {}
        for k, u in todo:
            by_blade.setdefault(k, []).append(u)
        new = []
        for k, us in by_blade.items():
            u = np.unique(np.concatenate(us), axis=0)
            lv, i, j = u[:, 0], u[:, 1], u[:, 2]
            split.append(key(np.full(len(u), k), lv, i, j))
            for l0 in np.unique(lv):  # the parents' fine cells: nothing until the children say
                m = lv == l0
                bb = 1 << (L - int(l0))
                st = state[k]
                st.reshape(st.shape[0] // bb, bb, st.shape[1] // bb, bb)[i[m], :, j[m], :] = -1
                ow = owner[k]
                ow.reshape(ow.shape[0] // bb, bb, ow.shape[1] // bb, bb)[i[m], :, j[m], :] = l0 + 1
            for l0 in np.unique(lv):
                m = lv == l0
                ci = (2 * i[m])[:, None] + np.array([0, 0, 1, 1])
                cj = (2 * j[m])[:, None] + np.array([0, 1, 0, 1])
                new.append(turbine.blade_cell_samples(k, spacing, int(l0) + 1, ci.ravel(), cj.ravel()))
        smp = SurfaceSamples.concatenate(new)
        c, marginal = measure(smp)
        paint(smp, c.covered)
        chunks.append((smp, c.covered, c.best_gsd_mm))
        flagged = [(smp, marginal)]
    if not split:
        return cov
    cut = np.concatenate(split)
    keep = []
    for smp, covered, best in chunks:
        leaf = ~np.isin(key(smp.blade, smp.level, smp.row, smp.col), cut) | (smp.blade < 0)
        keep.append((smp[leaf], covered[leaf], best[leaf]))
    return Coverage(SurfaceSamples.concatenate([c[0] for c in keep]),
                    np.concatenate([c[1] for c in keep]), np.concatenate([c[2] for c in keep]))


CULL_SPLIT = 2  # cubes max_dist / 2 wide: finer ones cull closer but cost more (measured 2-4)


def _near_pairs(P: np.ndarray, N: np.ndarray, positions: np.ndarray, rotations: np.ndarray,
                camera: Camera, max_dist: float, max_incidence_deg: float,
                border: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(sample, photo, GSD) of the pairs ``imaged`` passes, photo by photo (photo-major).

    Speed: a photo sees only samples within max_dist and inside its frame, so the samples are
    hashed into cubes (max_dist / CULL_SPLIT wide) and each photo tests only the samples of the
    cubes around its own whose bounding ball reaches into both its max_dist sphere and the cone
    around its optical axis that holds the frame. The cull is conservative: a cube left out
    holds no sample ``imaged`` could pass (tests/test_occlusion.py checks it against every
    pair). The search and the tests run compiled (``coverage_kernel``): as numpy array code
    every candidate pair was built as arrays first, ~20 % of a plan's time."""
    empty = np.zeros(0, np.int64)
    if len(P) == 0 or len(positions) == 0:
        return empty, empty, np.zeros(0)
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
    s, p, dist = coverage_kernel.near_pairs(
        np.ascontiguousarray(P, float), np.ascontiguousarray(N, float),
        np.ascontiguousarray(positions, float), np.ascontiguousarray(rotations, float),
        origin.astype(float), float(cell), shape.astype(np.int64), key[by_key], by_key,
        CULL_SPLIT, cam, float(max_dist), float(np.cos(np.radians(max_incidence_deg))),
        float(half), float(ball))
    return s, p, camera.gsd_mm(dist)
