"""The one turbine model: tower frustum, nacelle box, hub sphere and N tapered blades.

Every other part of wtinspect (renderer, planner, coverage, simulator) asks this model for
geometry; nothing else may keep a private copy of the shapes.

Frames (DESIGN.md): world is local ENU metres (x east, y north, z up). ``yaw_deg`` is the
compass heading the rotor faces (0 = north, 90 = east), so the rotor axis unit vector ``axis``
points from the nacelle out through the hub towards a viewer standing in front of the rotor.
A blade's rotor azimuth is measured in the rotor plane as that front viewer sees it,
counter-clockwise from the viewer's right (0 = right, 90 = up, 270 = down): the same convention
as the image angle φ that ``pitch`` reports from a front photo.

Blade cross-sections are ellipses: semi-axis chord/2 along the chord direction (leading edge at
+chord) and thickness/2 along the thickness direction (pressure side at +thickness). With
``blade_pitch_deg`` = 90 (feathered, the usual parked state) the leading edge faces the front.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

Z = np.array([0.0, 0.0, 1.0])

BLADE_SIDES = ("leading_edge", "pressure_side", "trailing_edge", "suction_side")

# Default blade and nacelle proportions (docs/turbines-yaml.md, "Turbine geometry the clearance
# rests on", has their sources): chosen on the large side of published 2-10 MW designs (NREL
# 5 MW, DTU 10 MW, IEA 3.4 MW reference turbines) so that a turbine without a datasheet is
# modelled no thinner than it is. Chord rises from the circular root to its maximum at
# ``MAX_CHORD_AT`` of the span, then tapers straight to the tip.
MAX_CHORD_AT = 0.2  # NREL 5 MW 0.23, DTU 10 MW 0.22: the chord there is still ~99 % of its max
ROOT_THICKNESS_RATIO = 1.0  # thickness / chord: a circular root
MAX_CHORD_THICKNESS_RATIO = 0.45  # NREL 5 MW 0.35-0.40 (DU 40/35) there; thicker modern roots
TIP_THICKNESS_RATIO = 0.21  # NACA 64-618 (0.18) on NREL 5 MW, DU 93-W-210 / FFA-W3-211 elsewhere
ROOT_CHORD_R = 0.06  # root chord / rotor radius: NREL 5 MW 0.056, DTU 10 MW 0.060
MAX_CHORD_R = 0.075  # NREL 5 MW 0.074, DTU 10 MW 0.070, IEA 3.4 MW 0.069
# The chord the straight taper from the maximum reaches at the tip: NREL 5 MW's chord runs
# straight to 1.9 m (0.030 R) there before its rounded tip; a smaller value would put the
# straight model inside the real blade at mid-span.
TIP_CHORD_R = 0.03
NACELLE_AHEAD_OF_LENGTH = 0.1  # nacelle box centre ahead of the tower axis, x its length


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass(frozen=True)
class Turbine:
    """A horizontal-axis wind turbine with its rotor stopped.

    Sizes left as None are filled from typical proportions of the rotor radius and hub height.
    """

    id: str
    base: tuple[float, float, float]  # tower base on the ground, ENU metres
    hub_height: float  # hub centre above the tower base, m
    rotor_diameter: float  # m; the blade tip radius is half of it
    yaw_deg: float  # compass heading the rotor faces
    azimuths_deg: tuple[float, ...]  # rotor azimuth of each blade (see module docstring)
    blade_pitch_deg: float = 90.0  # 0 = chord in the rotor plane, 90 = feathered
    tower_base_radius: float | None = None
    tower_top_radius: float | None = None
    nacelle_length: float | None = None
    nacelle_width: float | None = None
    nacelle_height: float | None = None
    hub_radius: float | None = None
    overhang: float | None = None  # tower axis -> hub centre, along the rotor axis, m
    blade_root_chord: float | None = None
    blade_max_chord: float | None = None
    blade_tip_chord: float | None = None
    blade_max_chord_at: float = MAX_CHORD_AT  # span fraction (0 root, 1 tip) of the max chord
    blade_root_thickness_ratio: float = ROOT_THICKNESS_RATIO  # thickness / chord at the root
    blade_max_chord_thickness_ratio: float = MAX_CHORD_THICKNESS_RATIO  # ... at the max chord
    blade_tip_thickness_ratio: float = TIP_THICKNESS_RATIO  # ... at the tip
    nacelle_ahead: float | None = None  # nacelle box centre ahead of the tower axis (rotor axis), m
    nacelle_above_hub: float = 0.0  # nacelle box centre above the hub centre, m
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        R = self.rotor_diameter / 2.0
        defaults = {
            "tower_base_radius": max(1.0, 0.026 * self.hub_height),
            "nacelle_length": 0.25 * R,
            "nacelle_width": 0.09 * R,
            "nacelle_height": 0.09 * R,
            "hub_radius": 0.05 * R,
            "blade_root_chord": ROOT_CHORD_R * R,
            "blade_max_chord": MAX_CHORD_R * R,
            "blade_tip_chord": TIP_CHORD_R * R,
        }
        for k, v in defaults.items():
            if getattr(self, k) is None:
                object.__setattr__(self, k, float(v))
        if self.tower_top_radius is None:
            object.__setattr__(self, "tower_top_radius", 0.6 * self.tower_base_radius)
        if self.overhang is None:
            # At least what lets the widest blade section pass the tower's base radius: a small
            # rotor on a tall tower would otherwise turn through its own tower.
            object.__setattr__(self, "overhang", max(
                0.5 * self.nacelle_length + 0.8 * self.hub_radius,
                self.tower_base_radius + 0.5 * max(self.blade_root_chord, self.blade_max_chord) + 0.5))
        if self.nacelle_ahead is None:
            object.__setattr__(self, "nacelle_ahead", NACELLE_AHEAD_OF_LENGTH * self.nacelle_length)
        object.__setattr__(self, "base", tuple(float(x) for x in self.base))
        object.__setattr__(self, "azimuths_deg", tuple(float(a) % 360.0 for a in self.azimuths_deg))
        self._check()

    def _check(self) -> None:
        def need(cond: bool, what: str) -> None:
            if not cond:
                raise ValueError(f"turbine {self.id!r}: {what}")

        need(len(self.base) == 3 and all(math.isfinite(x) for x in self.base),
             f"expected base as 3 finite numbers, got {self.base}")
        need(self.rotor_diameter > 0, f"expected rotor_diameter > 0, got {self.rotor_diameter}")
        need(len(self.azimuths_deg) >= 1, "expected at least one blade")
        for name in ("tower_base_radius", "tower_top_radius", "nacelle_length", "nacelle_width",
                     "nacelle_height", "hub_radius", "blade_root_chord", "blade_max_chord",
                     "blade_tip_chord"):
            need(getattr(self, name) > 0, f"expected {name} > 0, got {getattr(self, name)}")
        need(self.overhang >= 0, f"expected overhang >= 0, got {self.overhang}")
        need(0.0 < self.blade_max_chord_at < 1.0,
             f"expected blade_max_chord_at in (0, 1), got {self.blade_max_chord_at}")
        for name in ("blade_root_thickness_ratio", "blade_max_chord_thickness_ratio",
                     "blade_tip_thickness_ratio"):
            need(0.0 < getattr(self, name) <= 1.0,
                 f"expected {name} in (0, 1], got {getattr(self, name)}")
        for name in ("nacelle_ahead", "nacelle_above_hub"):
            need(math.isfinite(getattr(self, name)), f"expected {name} finite, got {getattr(self, name)}")
        need(self.tower_height > 0,
             f"expected the nacelle's bottom (hub_height + nacelle_above_hub - nacelle_height / 2 "
             f"= {self.tower_height:g} m) above the tower base")
        # A blade pointing straight down must stay clear of the ground.
        need(self.hub_height > self.tip_radius + 1.0,
             f"expected hub_height ({self.hub_height}) > blade tip radius ({self.tip_radius}) + 1 m")
        need(self.hub_radius < self.tip_radius / 2, "expected hub_radius < a quarter of the rotor diameter")

    # ---- frame --------------------------------------------------------------------------
    @classmethod
    def with_rotor_azimuth(cls, rotor_azimuth_deg: float, blades: int = 3, **kw: Any) -> Turbine:
        """Blades evenly spaced, blade 1 at ``rotor_azimuth_deg``."""
        az = tuple(rotor_azimuth_deg + k * 360.0 / blades for k in range(blades))
        return cls(azimuths_deg=az, **kw)

    @property
    def n_blades(self) -> int:
        return len(self.azimuths_deg)

    @property
    def tip_radius(self) -> float:
        return self.rotor_diameter / 2.0

    def __getstate__(self) -> dict:
        # Pickled (to the planner's worker processes) without the cache: recomputed there, its
        # arrays are read-only again, so the compiled kernels see the same types in every
        # process (a writable copy would make numba compile a second version).
        return {**self.__dict__, "_cache": {}}

    def forget(self) -> None:
        """Drop what the turbine has memoised (its frames, its coverage cells: ~16 MB once its
        coverage is measured); whatever asks again makes it again, the same. The planner calls
        it when it is done with a turbine, so one process holds one turbine's memos at a time."""
        self._cache.clear()

    def _cached(self, key: Any, make: Any) -> Any:
        """The frame vectors, computed once per turbine (the planner asks for them hundreds of
        thousands of times). Arrays come back read-only: a caller that changed one in place
        would change the turbine."""
        v = self._cache.get(key)
        if v is None:
            v = make()
            for a in (v if isinstance(v, tuple) else (v,)):
                a.setflags(write=False)
            self._cache[key] = v
        return v

    @property
    def axis(self) -> np.ndarray:
        """Unit rotor axis: from the nacelle towards a viewer in front of the rotor."""
        def make() -> np.ndarray:
            y = math.radians(self.yaw_deg)
            return np.array([math.sin(y), math.cos(y), 0.0])
        return self._cached("axis", make)

    @property
    def right(self) -> np.ndarray:
        """The front viewer's right, horizontal, in the rotor plane."""
        return self._cached("right", lambda: np.cross(-self.axis, Z))

    @property
    def base_xyz(self) -> np.ndarray:
        return self._cached("base_xyz", lambda: np.array(self.base, dtype=float))

    @property
    def hub_center(self) -> np.ndarray:
        return self._cached("hub_center",
                            lambda: self.base_xyz + Z * self.hub_height + self.axis * self.overhang)

    @property
    def tower_height(self) -> float:
        """The tower's top: the nacelle box's bottom."""
        return self.hub_height + self.nacelle_above_hub - 0.5 * self.nacelle_height

    @property
    def nacelle_center(self) -> np.ndarray:
        # The box sits on the tower top, ``nacelle_ahead`` ahead of the tower axis along the
        # rotor axis, its centre ``nacelle_above_hub`` above the hub centre's height.
        return self._cached("nacelle_center", lambda: self.base_xyz
                            + Z * (self.hub_height + self.nacelle_above_hub)
                            + self.axis * self.nacelle_ahead)

    def blade_direction(self, k: int) -> np.ndarray:
        return self.blade_frame(k)[0]

    def blade_frame(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(span direction d, chord direction c towards the leading edge, thickness direction n
        towards the pressure side), orthonormal."""
        def make() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            a = math.radians(self.azimuths_deg[k])
            d = math.cos(a) * self.right + math.sin(a) * Z
            t = np.cross(self.axis, d)
            p = math.radians(self.blade_pitch_deg)
            c = math.cos(p) * t + math.sin(p) * self.axis
            n = np.cross(d, c)
            return d, c, n
        return self._cached(("blade_frame", k), make)

    @property
    def blade_root_offset(self) -> float:
        """Distance from the hub centre where the blade body starts (inside the hub)."""
        return 0.8 * self.hub_radius

    def blade_tips(self) -> np.ndarray:
        """(N, 3) tip points: the paper's eq. 2 input."""
        return np.array([self.hub_center + self.tip_radius * self.blade_direction(k)
                         for k in range(self.n_blades)])

    def blade_roots(self) -> np.ndarray:
        return np.array([self.hub_center + self.blade_root_offset * self.blade_direction(k)
                         for k in range(self.n_blades)])

    # ---- blade planform -------------------------------------------------------------------
    def blade_semi_axes(self, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Semi-axes (chord/2, thickness/2) at span fraction f in [0, 1] (root -> tip)."""
        f = np.clip(np.asarray(f, dtype=float), 0.0, 1.0)
        chord = self._blade_chord(f)
        ratio = np.interp(f, [0.0, self.blade_max_chord_at, 1.0],
                          [self.blade_root_thickness_ratio, self.blade_max_chord_thickness_ratio,
                           self.blade_tip_thickness_ratio])
        return chord / 2.0, ratio * chord / 2.0

    def _blade_chord(self, f: np.ndarray) -> np.ndarray:
        """Chord at span fraction f in [0, 1] (the planform; the clearance bound needs only it)."""
        return np.interp(f, *self._cached("chord_knots", lambda: (
            np.array([0.0, self.blade_max_chord_at, 1.0]),
            np.array([self.blade_root_chord, self.blade_max_chord, self.blade_tip_chord]))))

    def _blade_taper_cos(self) -> float:
        """cos of the steepest taper of the blade surface: in-section distance times this is
        never more than the true distance (keeps the clearance conservative)."""
        if "taper_cos" not in self._cache:
            L = self.tip_radius - self.blade_root_offset
            f = np.linspace(0, 1, 201)
            A, B = self.blade_semi_axes(f)
            ds = L * (f[1] - f[0])
            slope = max(np.abs(np.diff(A)).max(), np.abs(np.diff(B)).max()) / ds
            self._cache["taper_cos"] = 1.0 / math.sqrt(1.0 + slope * slope)
        return self._cache["taper_cos"]

    # ---- clearance --------------------------------------------------------------------------
    def part_names(self) -> list[str]:
        return [f"blade{k + 1}" for k in range(self.n_blades)] + ["tower", "nacelle", "hub"]

    def clearance_by_part(self, points: np.ndarray, cap: float | None = None) -> np.ndarray:
        """Distance (m, >= 0, 0 inside) from each point to each part: shape (M, n_parts), columns
        in ``part_names()`` order. Never more than the true distance (conservative).

        With ``cap``, blade and tower distances are computed exactly only where a cheap bound
        (distance to an enclosing capsule / cylinder, itself a lower bound) is below ``cap``;
        elsewhere that bound stands in. Values below ``cap`` are then the same as without it."""
        P = np.atleast_2d(np.asarray(points, dtype=float))
        blades, local, bound = self._blade_bounds(P)
        near = np.ones(bound.shape, bool) if cap is None else bound < cap
        self._blade_exact(blades, local, near)
        tower = self._tower_bound(P)
        near_t = np.ones(len(P), bool) if cap is None else tower < cap
        if near_t.any():
            tower[near_t] = self._tower_distance(P[near_t])
        return np.column_stack([blades, tower, self._nacelle_distance(P), self._hub_distance(P)])

    def clearance(self, points: np.ndarray, cap: float | None = None) -> np.ndarray:
        """Distance (m) from each point to the nearest part of the turbine; (M,) for (M, 3).

        The same values as ``clearance_by_part(points, cap).min(axis=1)``, cheaper: compiled
        (``clearance_kernel``), and a part's exact distance is skipped where its bound is
        already at least the least exact distance of the parts done before it (the hub and
        nacelle, exact and cheap, go first), since that part cannot be the nearest."""
        P = np.ascontiguousarray(np.atleast_2d(np.asarray(points, dtype=float)))
        if P.ndim != 2 or P.shape[1] != 3:
            raise ValueError(f"expected points of shape (M, 3), got {P.shape}")
        # Imported here: numba takes ~0.2 s to load, which commands that never ask for a
        # clearance (segment, contours, pitch) need not pay.
        from wtcli.geometry import clearance_kernel

        vec, sc, frames = self._cached("kernel_params", self._kernel_params)
        return clearance_kernel.clearance(P, vec, sc, frames, math.inf if cap is None else float(cap))

    def _kernel_params(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The turbine as ``clearance_kernel.clearance`` reads it: points (hub, nacelle centre,
        rotor axis, nacelle side, nacelle half sizes, tower base), scalars, blade frames."""
        a, side, half = self._cached("nacelle_frame", self._nacelle_frame)
        vec = np.array([self.hub_center, self.nacelle_center, a, side, half, self.base_xyz])
        sc = np.array([self.hub_radius, self.tower_height, self.tower_base_radius,
                       self.tower_top_radius, self.blade_root_offset, self.tip_radius,
                       self._blade_taper_cos(), self.blade_max_chord_at, self.blade_root_chord,
                       self.blade_max_chord, self.blade_tip_chord, self.blade_root_thickness_ratio,
                       self.blade_max_chord_thickness_ratio, self.blade_tip_thickness_ratio],
                      dtype=float)
        frames = np.array([self.blade_frame(k) for k in range(self.n_blades)],
                          dtype=float).reshape(-1, 3, 3)
        return vec, sc, frames

    def _blade_bounds(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(values, local, bound), each (M, n_blades) or (M, n_blades, 3): the blade bounds of
        every point (``values`` starts as a copy, for ``_blade_exact`` to refine), and the points
        in each blade's frame (span s, chord u, thickness v), all blades in one product.

        Each section lies inside the circle of its chord semi-axis A(f), and the ellipse distance
        is at least (radius - A): with the taper factor, never above the exact distance."""
        F = self._cached("blade_frames", lambda: np.array(
            [v for k in range(self.n_blades) for v in self.blade_frame(k)]).reshape(-1, 3))
        local = ((P - self.hub_center) @ F.T).reshape(len(P), self.n_blades, 3)
        s = local[..., 0]
        s0, s1 = self.blade_root_offset, self.tip_radius
        rho = np.hypot(local[..., 1], local[..., 2])
        A = self._blade_chord((np.clip(s, s0, s1) - s0) / (s1 - s0)) / 2.0  # blade_semi_axes' A
        beyond = np.maximum(s - s1, 0.0) + np.maximum(s0 - s, 0.0)
        bound = np.hypot(np.maximum(rho - A, 0.0) * self._blade_taper_cos(), beyond)
        return bound.copy(), local, bound

    def _blade_exact(self, values: np.ndarray, local: np.ndarray, near: np.ndarray) -> None:
        """Set ``values`` to the exact blade distance where ``near``: the section ellipse's
        in-plane distance (times the taper factor) with the distance beyond the blade's ends."""
        if not near.any():
            return
        s, u, v = local[near].T
        s0, s1 = self.blade_root_offset, self.tip_radius
        A, B = self.blade_semi_axes((np.clip(s, s0, s1) - s0) / (s1 - s0))
        inplane = _ellipse_distance(u, v, A, B) * self._blade_taper_cos()
        beyond = np.maximum(s - s1, 0.0) + np.maximum(s0 - s, 0.0)
        values[near] = np.hypot(inplane, beyond)

    def _tower_bound(self, P: np.ndarray) -> np.ndarray:
        # The frustum lies inside the cylinder of its larger radius (the base's, unless a
        # turbines.yaml gives a wider top: the base's alone was then no lower bound).
        q = P - self.base_xyz
        rho = np.hypot(q[:, 0], q[:, 1])
        dz = np.maximum(np.maximum(-q[:, 2], q[:, 2] - self.tower_height), 0.0)
        r = max(self.tower_base_radius, self.tower_top_radius)
        return np.hypot(np.maximum(rho - r, 0.0), dz)

    def segment_clearance(self, p0: np.ndarray, p1: np.ndarray, step: float = 0.5) -> np.ndarray:
        """A lower bound of the clearance along each straight segment p0[i] -> p1[i].

        Samples every ``step`` metres at most; between samples the distance function (1-Lipschitz)
        can dip by at most half the sample spacing, which is subtracted.
        """
        return segment_lower_bound(self.clearance, p0, p1, step)

    def line_of_sight(self, eyes: np.ndarray, targets: np.ndarray, end_gap: float = 0.05,
                      hit: float = 0.01, max_steps: int = 64) -> np.ndarray:
        """(K,) bool: True where the straight segment eyes[i] -> targets[i] passes no part.

        The segment stops ``end_gap`` metres short of the target, so that the surface a target
        sample lies on does not hide it (seen within 60 deg of its normal, that end is at least
        end_gap / 2 off a convex surface). A segment "passes" a part when it comes within ``hit``
        of it. Sphere tracing: from each point the segment advances by the clearance there, a
        lower bound of the distance to every part, so no part can be stepped over. A segment
        still undecided after ``max_steps`` (it runs along a surface at a few centimetres) is
        finished with samples every ``hit`` metres (``segment_lower_bound``).
        """
        eyes = np.atleast_2d(np.asarray(eyes, dtype=float))
        targets = np.atleast_2d(np.asarray(targets, dtype=float))
        if eyes.shape != targets.shape or eyes.shape[1:] != (3,):
            raise ValueError(f"expected eyes and targets of the same shape (K, 3), got "
                             f"{eyes.shape} and {targets.shape}")
        ray = targets - eyes
        stop = np.linalg.norm(ray, axis=1)
        ray /= np.maximum(stop, 1e-12)[:, None]
        stop -= end_gap
        from wtcli.geometry import clearance_kernel

        # Any lower bound of the distance keeps the tracing exact; cheaper ones cost steps: the
        # enclosing-shape bounds stand in beyond 1 m (the cap).
        vec, sc, frames = self._cached("kernel_params", self._kernel_params)
        clear, t, undecided = clearance_kernel.trace(np.ascontiguousarray(eyes), ray,
                                                     np.ascontiguousarray(stop), vec, sc, frames,
                                                     float(hit), int(max_steps))
        live = np.nonzero(undecided)[0]
        if len(live) == 0:
            return clear

        def dist(X: np.ndarray) -> np.ndarray:
            return self.clearance(X, cap=1.0)

        p0 = eyes[live] + t[live, None] * ray[live]
        p1 = eyes[live] + stop[live, None] * ray[live]
        lb = segment_lower_bound(dist, p0, p1, hit)
        clear[live[lb < 0.5 * hit]] = False
        return clear

    def _hub_distance(self, P: np.ndarray) -> np.ndarray:
        return np.maximum(np.linalg.norm(P - self.hub_center, axis=1) - self.hub_radius, 0.0)

    def _nacelle_distance(self, P: np.ndarray) -> np.ndarray:
        a, side, half = self._cached("nacelle_frame", self._nacelle_frame)
        q = P - self.nacelle_center
        local = np.stack([q @ a, q @ side, q @ Z], axis=1)
        e = np.maximum(np.abs(local) - half, 0.0)
        return np.sqrt((e * e).sum(axis=1))

    def _nacelle_frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return (self.axis, np.cross(Z, self.axis),
                np.array([self.nacelle_length, self.nacelle_width, self.nacelle_height]) / 2.0)

    def _tower_distance(self, P: np.ndarray) -> np.ndarray:
        q = P - self.base_xyz
        rho = np.hypot(q[:, 0], q[:, 1])
        h = q[:, 2]
        H, rb, rt = self.tower_height, self.tower_base_radius, self.tower_top_radius
        # 2-D distance in the (radius, height) half plane to the solid trapezoid.
        poly = np.array([[0.0, 0.0], [rb, 0.0], [rt, H], [0.0, H]])
        X = np.stack([rho, h], axis=1)
        d = np.full(len(P), np.inf)
        inside = np.ones(len(P), dtype=bool)
        for i in range(4):
            a, b = poly[i], poly[(i + 1) % 4]
            ab = b - a
            t = np.clip(((X - a) @ ab) / (ab @ ab), 0.0, 1.0)
            d = np.minimum(d, np.linalg.norm(X - (a + t[:, None] * ab), axis=1))
            cross = ab[0] * (X[:, 1] - a[1]) - ab[1] * (X[:, 0] - a[0])
            inside &= cross >= 0  # counter-clockwise polygon
        return np.where(inside, 0.0, d)

    def tower_radius_at(self, h: np.ndarray) -> np.ndarray:
        """The tower's radius at height ``h`` above its base (clipped to the frustum's ends)."""
        f = np.clip(np.asarray(h, float) / self.tower_height, 0.0, 1.0)
        return self.tower_base_radius + (self.tower_top_radius - self.tower_base_radius) * f

    def blade_outline(self, k: int, step: float = 0.1, around: int = 72) -> np.ndarray:
        """(M, 3) points on blade k's whole modelled surface, a section every ``step`` m from
        root to tip, ``around`` points each; unlike ``surface_samples``, the parts buried in the
        hub, nacelle or tower are kept (what a check of the model's own consistency needs)."""
        d, c, n = self.blade_frame(k)
        r0 = self.blade_root_offset
        f = np.linspace(0.0, 1.0, max(2, int((self.tip_radius - r0) / step) + 1))[:, None]
        A, B = self.blade_semi_axes(f)
        a = np.linspace(0.0, 2 * np.pi, around, endpoint=False)[None, :]
        return (self.hub_center + (r0 + f * (self.tip_radius - r0))[..., None] * d
                + (A * np.cos(a))[..., None] * c + (B * np.sin(a))[..., None] * n).reshape(-1, 3)

    # ---- surface samples -------------------------------------------------------------------
    def surface_samples(self, spacing: float = 0.5, parts: str = "all") -> SurfaceSamples:
        """Points on the surface with outward normals, area weights and labels.

        ``parts``: "all", "blades" or "structure" (tower, nacelle, hub). Blade samples carry the
        blade index, the side (index into ``BLADE_SIDES``) and the span fraction.
        """
        chunks: list[dict[str, np.ndarray]] = []
        if parts in ("all", "blades"):
            for k in range(self.n_blades):
                chunks.append(self._blade_samples(k, spacing))
        if parts in ("all", "structure"):
            chunks.append(self._outer(self._tower_samples(spacing)))
            chunks.append(self._outer(self._nacelle_samples(spacing)))
            chunks.append(self._outer(self._hub_samples(spacing)))
        cat = {key: np.concatenate([ch[key] for ch in chunks]) for key in chunks[0]}
        return SurfaceSamples(**cat, turbine=self)

    def blade_grid(self, k: int, spacing: float) -> tuple[int, int, float, float]:
        """(rows, per_side, s_start, s_end): how blade k's surface is cut into sample cells at
        ``spacing``. ``rows`` span cells of equal length, at most ``_ROW_SPACING`` * spacing,
        between ``s_start`` and ``s_end`` (m from the hub centre: from where the blade leaves the
        hub sphere to the tip) and ``per_side``
        cells of equal arc length round each of the four sides of every section (the longest
        side's arc at ``spacing``, odd, at least ``_SIDE_SAMPLES_MIN``); columns run round the
        section side after side (``BLADE_SIDES`` order). At refinement level l each cell is cut
        in 2 x 2: rows << l by (4 * per_side) << l."""
        key = ("blade_grid", float(spacing))  # the same for every blade (they share the planform)
        if key not in self._cache:
            s0, s1 = self.blade_root_offset, self.tip_radius
            s_start = max(s0, math.sqrt(max(self.hub_radius ** 2 - (self.blade_root_chord / 2) ** 2, 0)))
            rows = max(2, int(math.ceil((s1 - s_start) / (spacing * _ROW_SPACING))))
            f = (s_start + (np.arange(rows) + 0.5) * (s1 - s_start) / rows - s0) / (s1 - s0)
            A, B = self.blade_semi_axes(f)
            longest = float((A[:, None] * _side_tables(B / A)[2]).max())
            n = max(_SIDE_SAMPLES_MIN, int(math.ceil(longest / spacing)))
            self._cache[key] = (rows, n + 1 - n % 2, s_start, s1)
        return self._cache[key]

    def blade_cell_samples(self, k: int, spacing: float, level: int, row: np.ndarray,
                           col: np.ndarray) -> SurfaceSamples:
        """Samples at the middles of blade k's cells (``blade_grid``) at refinement ``level``,
        (row, col) each, with the cell's area; cells buried in another part are left out."""
        rows, per_side, s_start, s_end = self.blade_grid(k, spacing)
        row, col = np.asarray(row, np.int64), np.asarray(col, np.int64)
        nr, nc = rows << level, per_side << level
        d, c, n = self.blade_frame(k)
        s0, s1 = self.blade_root_offset, self.tip_radius
        h = (s_end - s_start) / nr
        s = s_start + (row + 0.5) * h
        f = (s - s0) / (s1 - s0)
        A, B = self.blade_semi_axes(f)
        side = col // nc
        # Round a section by arc length, side by side (each side: normal within 45 deg of +c,
        # +n, -c, -n), so the thin edges get as many samples as the flat sides and one lies on
        # each side's middle line (the leading and trailing edge lines themselves).
        uniq, inv = np.unique(row, return_inverse=True)
        fu = (s_start + (uniq + 0.5) * h - s0) / (s1 - s0)
        Au, Bu = self.blade_semi_axes(fu)
        # The arc-length tables of each row, made once per turbine: every blade has the same
        # sections, and the refinement asks for the same rows again and again.
        memo = self._cache.setdefault(("side_tables", float(spacing), int(level)), {})
        todo = [i for i, r in enumerate(uniq.tolist()) if r not in memo]
        if todo:
            for r, *tables in zip(uniq[todo].tolist(), *_side_tables(Bu[todo] / Au[todo])):
                memo[r] = tables
        grid, cumn, total = (np.stack(t) for t in zip(*(memo[r] for r in uniq.tolist())))
        table = inv * 4 + side
        keys = cumn.reshape(-1, cumn.shape[-1]) + 2.0 * np.arange(len(uniq) * 4)[:, None]
        psi = np.interp((col % nc + 0.5) / nc + 2.0 * table, keys.ravel(),
                        grid.reshape(-1, grid.shape[-1]).ravel())
        cu, sv = np.cos(psi), np.sin(psi)
        pts = (self.hub_center + s[:, None] * d + (A * cu)[:, None] * c + (B * sv)[:, None] * n)
        nrm = _unit((cu / A)[:, None] * c + (sv / B)[:, None] * n)
        area = h * A * total.reshape(-1)[table] / nc
        # How far the normal turns across the cell round the section: its arc over the radius of
        # curvature there, (A^2 sin^2 + B^2 cos^2)^1.5 / (A B).
        rho = (A * A * sv * sv + B * B * cu * cu) ** 1.5 / (A * B)
        turn = np.degrees(area / h / rho)
        m = len(row)
        out = {"points": pts.reshape(m, 3), "normals": nrm.reshape(m, 3), "area": area,
               "part": np.full(m, k, np.int16), "blade": np.full(m, k, np.int16),
               "side": side.astype(np.int8), "span": f, "row": row.astype(np.int32),
               "col": col.astype(np.int32), "level": np.full(m, level, np.int8), "turn_deg": turn}
        # Where the root runs into another part (its trailing edge into the nacelle's front face,
        # which sits less than a root semi-chord behind the rotor plane), that stretch is inside
        # the turbine, not on its outer surface: no camera can see it, so it is not sampled.
        # (``clearance_by_part(points, cap=1e-6)`` without blade k's column: its own surface's
        # exact distance, the costliest column, is not needed)
        P = out["points"]
        blades, local, bound = self._blade_bounds(P)
        bound[:, k] = np.inf
        self._blade_exact(blades, local, bound < 1e-6)
        blades[:, k] = np.inf
        tower = self._tower_bound(P)
        near_t = tower < 1e-6
        if near_t.any():
            tower[near_t] = self._tower_distance(P[near_t])
        buried = np.minimum.reduce([blades.min(axis=1), tower, self._nacelle_distance(P),
                                    self._hub_distance(P)]) <= 0.0
        return SurfaceSamples(**{key: v[~buried] for key, v in out.items()}, turbine=self)

    def _blade_samples(self, k: int, spacing: float) -> dict[str, np.ndarray]:
        rows, per_side, _, _ = self.blade_grid(k, spacing)
        R, C = np.meshgrid(np.arange(rows), np.arange(4 * per_side), indexing="ij")
        smp = self.blade_cell_samples(k, spacing, 0, R.ravel(), C.ravel())
        return {key: getattr(smp, key) for key in SurfaceSamples.__dataclass_fields__ if key != "turbine"}

    def _tower_samples(self, spacing: float) -> dict[str, np.ndarray]:
        H, rb, rt = self.tower_height, self.tower_base_radius, self.tower_top_radius
        nh = max(2, int(math.ceil(H / spacing)))
        h = (np.arange(nh) + 0.5) * H / nh
        r = self.tower_radius_at(h)
        m = max(16, int(math.ceil(2 * math.pi * rb / spacing)))
        ang = (np.arange(m) + 0.5) * 2 * math.pi / m
        Hh, Aa = np.meshgrid(np.arange(nh), ang, indexing="ij")
        rr = r[Hh]
        pts = self.base_xyz + np.stack([rr * np.cos(Aa), rr * np.sin(Aa), h[Hh]], axis=-1)
        slope = (rb - rt) / H
        nrm = _unit(np.stack([np.cos(Aa), np.sin(Aa), np.full_like(Aa, slope)], axis=-1))
        area = rr * (2 * math.pi / m) * (H / nh)
        return self._structure(pts.reshape(-1, 3), nrm.reshape(-1, 3), area.reshape(-1),
                               self.n_blades + 0)

    def _nacelle_samples(self, spacing: float) -> dict[str, np.ndarray]:
        a = self.axis
        side = np.cross(Z, a)
        axes = [a, side, Z]
        half = np.array([self.nacelle_length, self.nacelle_width, self.nacelle_height]) / 2.0
        pts, nrm, area = [], [], []
        for i in range(3):
            j, l = [x for x in range(3) if x != i]
            nj = max(1, int(math.ceil(2 * half[j] / spacing)))
            nl = max(1, int(math.ceil(2 * half[l] / spacing)))
            uj = (np.arange(nj) + 0.5) / nj * 2 - 1
            ul = (np.arange(nl) + 0.5) / nl * 2 - 1
            J, L = np.meshgrid(uj, ul, indexing="ij")
            for sign in (1.0, -1.0):
                p = (self.nacelle_center + sign * half[i] * axes[i]
                     + (J * half[j])[..., None] * axes[j] + (L * half[l])[..., None] * axes[l])
                pts.append(p.reshape(-1, 3))
                nrm.append(np.tile(sign * axes[i], (nj * nl, 1)))
                area.append(np.full(nj * nl, 4 * half[j] * half[l] / (nj * nl)))
        return self._structure(np.concatenate(pts), np.concatenate(nrm), np.concatenate(area),
                               self.n_blades + 1)

    def _hub_samples(self, spacing: float) -> dict[str, np.ndarray]:
        r = self.hub_radius
        n = max(32, int(math.ceil(4 * math.pi * r * r / spacing ** 2)))
        i = np.arange(n) + 0.5  # Fibonacci sphere: even spread
        zc = 1 - 2 * i / n
        ang = math.pi * (1 + 5 ** 0.5) * i
        rr = np.sqrt(1 - zc * zc)
        nrm = np.stack([rr * np.cos(ang), rr * np.sin(ang), zc], axis=1)
        return self._structure(self.hub_center + r * nrm, nrm, np.full(n, 4 * math.pi * r * r / n),
                               self.n_blades + 2)

    def _outer(self, smp: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """A structure part's samples less those inside or on another part: the nacelle's front
        face within the hub sphere, its underside on the tower's top, the hub's back within the
        nacelle and its surface within the blade roots. As with a blade root, that is not the
        turbine's outer surface, and no camera sees it."""
        if not len(smp["points"]):
            return smp
        d = self.clearance_by_part(smp["points"], cap=1e-6)
        d[:, int(smp["part"][0])] = np.inf
        keep = d.min(axis=1) > 0.0
        return {key: v[keep] for key, v in smp.items()}

    @staticmethod
    def _structure(pts: np.ndarray, nrm: np.ndarray, area: np.ndarray, part: int) -> dict:
        n = len(pts)
        return {"points": pts, "normals": nrm, "area": area, "part": np.full(n, part, np.int16),
                "blade": np.full(n, -1, np.int16), "side": np.full(n, -1, np.int8),
                "span": np.full(n, -1.0), "row": np.full(n, -1, np.int32),
                "col": np.full(n, -1, np.int32), "level": np.full(n, -1, np.int8),
                "turn_deg": np.zeros(n)}

    # ---- mesh for rendering -----------------------------------------------------------------
    def mesh(self, around: int = 20, spans: int = 40, round_tip: float = 0.0) -> Mesh:
        """Triangles for the renderer. ``face_part``: 0..N-1 blades, N tower, N+1 nacelle+hub
        (the instance classes of segmentation), faces kept small so painter's order works.
        ``round_tip``: each blade's end rounded off over this many tip chords of span (a
        quarter ellipse in planform and thickness, as a real blade's tip), instead of ending
        on its tip section; the blade still reaches ``tip_radius``."""
        V: list[np.ndarray] = []
        F: list[np.ndarray] = []
        part: list[np.ndarray] = []

        def add(verts: np.ndarray, faces: np.ndarray, p: int) -> None:
            off = sum(len(v) for v in V)
            V.append(verts)
            F.append(faces + off)
            part.append(np.full(len(faces), p, np.int16))

        for k in range(self.n_blades):
            d, c, n = self.blade_frame(k)
            s0, s1 = self.blade_root_offset, self.tip_radius
            f = np.concatenate([np.linspace(0, 0.25, spans // 4, endpoint=False),
                                np.linspace(0.25, 1, spans - spans // 4)])
            A, B = self.blade_semi_axes(f)
            s = s0 + f * (s1 - s0)
            if round_tip > 0:
                ell = min(round_tip * self.blade_tip_chord, 0.25 * (s1 - s0))
                keep = s < s1 - ell
                q = np.linspace(0.0, 1.0, 10)[:-1]  # the cap's point closes the last ring
                sq = np.sqrt(1.0 - q ** 2)
                se = s1 - ell + q * ell
                Ae, Be = self.blade_semi_axes((se - s0) / (s1 - s0))
                A = np.concatenate([A[keep], Ae * sq])
                B = np.concatenate([B[keep], Be * sq])
                s = np.concatenate([s[keep], se])
            psi = np.arange(around) * 2 * math.pi / around
            rings = (self.hub_center + s[:, None, None] * d
                     + (A[:, None] * np.cos(psi))[..., None] * c
                     + (B[:, None] * np.sin(psi))[..., None] * n)
            verts = np.concatenate([rings.reshape(-1, 3), [self.hub_center + s1 * d]])
            add(verts, _tube_faces(len(s), around, cap_end=len(verts) - 1), k)

        # Tower: frustum split into height bands.
        H = self.tower_height
        bands = 16
        h = np.linspace(0, H, bands + 1)
        r = self.tower_radius_at(h)
        ang = np.arange(around * 2) * math.pi / around
        rings = self.base_xyz + np.stack([r[:, None] * np.cos(ang), r[:, None] * np.sin(ang),
                                          np.broadcast_to(h[:, None], (bands + 1, len(ang)))], -1)
        add(rings.reshape(-1, 3), _tube_faces(bands + 1, len(ang), cap_end=None), self.n_blades)

        # Nacelle: box with each face split into a grid; hub: a UV sphere. One instance.
        add(*_box_mesh(self.nacelle_center, [self.axis, np.cross(Z, self.axis), Z],
                       np.array([self.nacelle_length, self.nacelle_width, self.nacelle_height]) / 2,
                       4), self.n_blades + 1)
        add(*_sphere_mesh(self.hub_center, self.hub_radius, 8, 12), self.n_blades + 1)
        return Mesh(np.concatenate(V), np.concatenate(F), np.concatenate(part))

    # ---- serialisation ----------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("_cache", None)
        d["base"] = list(self.base)
        d["azimuths_deg"] = list(self.azimuths_deg)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Turbine:
        known = {k for k in cls.__dataclass_fields__ if not k.startswith("_")}
        extra = set(d) - known
        if extra:
            raise ValueError(f"unknown turbine fields {sorted(extra)}")
        kw = dict(d)
        kw["base"] = tuple(kw["base"])
        kw["azimuths_deg"] = tuple(kw["azimuths_deg"])
        return cls(**kw)


@dataclass(frozen=True)
class SurfaceSamples:
    points: np.ndarray  # (M, 3)
    normals: np.ndarray  # (M, 3) unit, outward
    area: np.ndarray  # (M,) m^2 each sample stands for
    part: np.ndarray  # (M,) index into Turbine.part_names()
    blade: np.ndarray  # (M,) blade index, -1 for tower/nacelle/hub
    side: np.ndarray  # (M,) index into BLADE_SIDES, -1 off blades
    span: np.ndarray  # (M,) span fraction 0 root .. 1 tip, -1 off blades
    # A blade sample's cell in Turbine.blade_grid: row, column and refinement level (-1 off
    # blades; None: all -1), and how far the normal turns across it round the section (deg).
    row: np.ndarray | None = None
    col: np.ndarray | None = None
    level: np.ndarray | None = None
    turn_deg: np.ndarray | None = None
    # The turbine the samples lie on: its parts are what can hide a sample from a camera.
    turbine: Turbine | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        m = len(self.points)
        if self.points.shape != (m, 3) or self.normals.shape != (m, 3):
            raise ValueError(f"expected points and normals (M, 3), got {self.points.shape}, "
                             f"{self.normals.shape}")
        for name, fill, dtype in (("row", -1, np.int32), ("col", -1, np.int32),
                                  ("level", -1, np.int8), ("turn_deg", 0.0, float)):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.full(m, fill, dtype))
        for name in ("area", "part", "blade", "side", "span", "row", "col", "level", "turn_deg"):
            if getattr(self, name).shape != (m,):
                raise ValueError(f"expected {name} of shape ({m},), got {getattr(self, name).shape}")

    def __len__(self) -> int:
        return len(self.points)

    def __getitem__(self, idx: Any) -> SurfaceSamples:
        return SurfaceSamples(**{k: getattr(self, k)[idx] for k in self.__dataclass_fields__
                                 if k != "turbine"}, turbine=self.turbine)

    @staticmethod
    def concatenate(parts: list[SurfaceSamples]) -> SurfaceSamples:
        """One set from several of the same turbine (in order)."""
        return SurfaceSamples(**{k: np.concatenate([getattr(p, k) for p in parts])
                                 for k in SurfaceSamples.__dataclass_fields__ if k != "turbine"},
                              turbine=parts[0].turbine if parts else None)


@dataclass(frozen=True)
class Mesh:
    vertices: np.ndarray  # (V, 3) world
    faces: np.ndarray  # (F, 3) vertex indices
    face_part: np.ndarray  # (F,) 0..N-1 blades, N tower, N+1 nacelle (incl. hub)

    def face_normals(self) -> np.ndarray:
        tri = self.vertices[self.faces]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(nrm, axis=1, keepdims=True)
        return nrm / np.where(length > 0, length, 1.0)


def segment_lower_bound(clearance, p0: np.ndarray, p1: np.ndarray, step: float = 0.5) -> np.ndarray:
    """A lower bound of ``clearance`` (any 1-Lipschitz distance function of points) along each
    straight segment p0[i] -> p1[i]: samples at most ``step`` apart, minus half the spacing."""
    p0 = np.atleast_2d(np.asarray(p0, dtype=float))
    p1 = np.atleast_2d(np.asarray(p1, dtype=float))
    if len(p0) == 0:
        return np.zeros(0)
    length = np.linalg.norm(p1 - p0, axis=1)
    n = np.maximum(1, np.ceil(length / step).astype(int))
    seg = np.repeat(np.arange(len(p0)), n + 1)
    start = np.repeat(np.concatenate([[0], np.cumsum(n + 1)[:-1]]), n + 1)
    t = (np.arange(len(seg)) - start) / np.repeat(n, n + 1)
    pts = p0[seg] + (p1 - p0)[seg] * t[:, None]
    out = np.full(len(p0), np.inf)
    np.minimum.at(out, seg, clearance(pts))
    return out - 0.5 * length / n


def _ellipse_distance(u: np.ndarray, v: np.ndarray, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Distance from (u, v) to the solid ellipse (u/A)^2 + (v/B)^2 <= 1, vectorised.

    Closest point x = A^2 u / (t + A^2), y = B^2 v / (t + B^2) where t >= 0 solves
    F(t) = (A u / (t + A^2))^2 + (B v / (t + B^2))^2 - 1 = 0. F is convex and decreasing for
    t >= 0, so Newton's method started left of the root climbs to it from below and never
    passes it (each tangent meets zero before F does); the distance grows with t, so every
    iterate gives a lower bound. The start, sqrt((Au)^2 + (Bv)^2) - max(A, B)^2, is itself left
    of the root (F >= that sum / (t + max^2)^2 - 1). Converges to float precision in at most
    ~15 steps (the 60-step bisection it replaces agreed to 1e-13 m, tests/test_geometry.py).
    """
    u, v = np.abs(u), np.abs(v)
    A = np.broadcast_to(A, u.shape).astype(float)
    B = np.broadcast_to(B, u.shape).astype(float)
    out = np.zeros(u.shape)
    live = np.nonzero((u / A) ** 2 + (v / B) ** 2 > 1.0)
    if len(live[0]) == 0:
        return out
    u, v, A2, B2 = u[live], v[live], A[live] ** 2, B[live] ** 2
    Au, Bv = np.sqrt(A2) * u, np.sqrt(B2) * v
    t = np.maximum(np.sqrt(Au * Au + Bv * Bv) - np.maximum(A2, B2), 0.0)
    idx = np.arange(len(t))
    for _ in range(64):  # a cap far beyond the ~15 steps needed; stopped points are still bounds
        ti, a2, b2 = t[idx], A2[idx], B2[idx]
        p, q = Au[idx] / (ti + a2), Bv[idx] / (ti + b2)
        # F < 0 only by rounding at the root: no step back.
        step = np.maximum(p * p + q * q - 1.0, 0.0) / (2.0 * (p * p / (ti + a2) + q * q / (ti + b2)))
        t[idx] = ti + step
        idx = idx[step > 1e-15 * (ti + a2)]
        if len(idx) == 0:
            break
    x = A2 * u / (t + A2)
    y = B2 * v / (t + B2)
    out[live] = np.hypot(u - x, v - y)
    return out


_SIDE_SAMPLES_MIN = 9  # cells round each side of a section at least, odd (its middle line sampled)
_ROW_SPACING = 0.5  # span cells this fraction of the spacing long (frame edges and the gaps
# between neighbouring views cross the span: at the full spacing a gap of a few dm between two
# views fell between rows, 0.6 points of a trailing edge)
_SIDE_TABLE = 64  # steps of the arc-length table of each side (arc within 0.1 %)


def _side_tables(ratio: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Arc length round the four sides of ellipses of semi-axes 1 (chord) and ``ratio``
    (thickness / chord), (R,): ``grid`` (R, 4, T + 1) ellipse angles psi (point cos psi along
    the chord, ratio sin psi along the thickness) from each side's start to its end, ``cumn``
    the arc length up to each as a fraction of the side's, ``total`` (R, 4) each side's arc.
    A side is where the normal is within 45 deg of +chord (leading edge), +thickness, -chord,
    -thickness (``BLADE_SIDES``); a section's are these times its chord semi-axis."""
    r = np.asarray(ratio, float).reshape(-1)
    p1 = np.arctan(r)  # the normal is at 45 deg where tan(psi) = ratio * tan(45 deg)
    bounds = np.stack([-p1, p1, math.pi - p1, math.pi + p1, 2 * math.pi - p1], axis=1)
    u = np.linspace(0.0, 1.0, _SIDE_TABLE + 1)
    lo, hi = bounds[:, :4, None], bounds[:, 1:, None]
    grid = lo + (hi - lo) * u
    speed = np.hypot(np.sin(grid), r[:, None, None] * np.cos(grid))
    cum = np.concatenate([np.zeros(grid.shape[:2] + (1,)),
                          np.cumsum(0.5 * (speed[..., 1:] + speed[..., :-1]) * np.diff(grid, axis=-1),
                                    axis=-1)], axis=-1)
    total = cum[..., -1]
    return grid, cum / total[..., None], total


def _tube_faces(rings: int, around: int, cap_end: int | None) -> np.ndarray:
    faces = []
    for i in range(rings - 1):
        for j in range(around):
            a, b = i * around + j, i * around + (j + 1) % around
            c_, d_ = a + around, b + around
            faces += [[a, b, d_], [a, d_, c_]]
    if cap_end is not None:
        last = (rings - 1) * around
        faces += [[last + j, last + (j + 1) % around, cap_end] for j in range(around)]
    return np.array(faces, dtype=np.int64)


def _box_mesh(center: np.ndarray, axes: list[np.ndarray], half: np.ndarray,
              grid: int) -> tuple[np.ndarray, np.ndarray]:
    verts, faces = [], []
    g = np.linspace(-1, 1, grid + 1)
    for i in range(3):
        j, l = [x for x in range(3) if x != i]
        for sign in (1.0, -1.0):
            J, L = np.meshgrid(g, g, indexing="ij")
            p = (center + sign * half[i] * axes[i] + (J * half[j])[..., None] * axes[j]
                 + (L * half[l])[..., None] * axes[l]).reshape(-1, 3)
            off = sum(len(v) for v in verts)
            for a in range(grid):
                for b in range(grid):
                    v0 = off + a * (grid + 1) + b
                    faces += [[v0, v0 + 1, v0 + grid + 2], [v0, v0 + grid + 2, v0 + grid + 1]]
            verts.append(p)
    return np.concatenate(verts), np.array(faces, dtype=np.int64)


def _sphere_mesh(center: np.ndarray, r: float, n_lat: int, n_lon: int) -> tuple[np.ndarray, np.ndarray]:
    lat = np.linspace(-math.pi / 2, math.pi / 2, n_lat + 1)
    lon = np.arange(n_lon) * 2 * math.pi / n_lon
    LA, LO = np.meshgrid(lat, lon, indexing="ij")
    verts = center + r * np.stack([np.cos(LA) * np.cos(LO), np.cos(LA) * np.sin(LO), np.sin(LA)], -1)
    return verts.reshape(-1, 3), _tube_faces(n_lat + 1, n_lon, cap_end=None)
