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
from wtcli.geometry.turbine import BLADE_SIDES, SurfaceSamples


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
    positions = np.asarray(positions, float).reshape(-1, 3)
    rotations = np.asarray(rotations, float).reshape(-1, 3, 3)
    if len(positions) != len(rotations):
        raise ValueError(f"expected as many rotations as positions, got {len(rotations)} and {len(positions)}")
    if samples.turbine is None:
        raise ValueError("expected samples from Turbine.surface_samples (with their turbine), got "
                         "samples without one: occlusion cannot be checked")
    P, N = samples.points, samples.normals
    max_dist = camera.distance_for_gsd(target_gsd_mm * gsd_tolerance)
    # Every (sample, photo) pair that passes the cheap tests; the line of sight comes after.
    s, p, g = _near_pairs(P, N, positions, rotations, camera, max_dist, max_incidence_deg, border_px)
    covered = np.zeros(len(P), bool)
    best = np.full(len(P), np.inf)
    if not len(s):
        return Coverage(samples, covered, best)
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
    return Coverage(samples, covered, best)


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
