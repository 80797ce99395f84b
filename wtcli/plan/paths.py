"""Step 1.5 (eq. 8-9): the trajectories around one turbine's components.

Blades (adaptive, eq. 8): for each blade, passes along its real direction d: a ring of four or
five oblique passes at fixed angles round the blade (``_ring_passes``: the fewest that see every
section whole by coverage's own test), else one per side (leading edge +c, pressure side +n,
trailing edge -c, suction side -n in ``Turbine.blade_frame``), each at the camera-to-surface
standoff that gives the target GSD: the camera sits at the local section's support distance in
the viewing direction plus the standoff, and looks back at the blade axis. Passes alternate
root->tip and tip->root, joined by arcs around the blade axis (around the tip at the outer end);
the flight then returns to the blade's start point S_p,i (eq. 8's return leg).

Where the geometry blocks a pass (a blade pointing down past the tower leaves no room behind it
for the trailing edge; the hub and nacelle crowd the roots), the blocked stations are flown as two
oblique passes at +-alpha around the side's normal (alpha <= 55 deg, so together they still see
every part of that side within 60 deg of incidence), at the smallest alpha that clears.

Extra views (``gap_plan``): for the blade surface the passes still miss (the root's trailing edge
behind the hub and nacelle, a trailing edge facing the tower), single photo stations at an angle
that sees past what blocks the passes, chosen by greedy set cover among viewpoints that keep the
clearance, and flown where they lengthen the blade's trajectory least.

Tower and nacelle (fixed, the paper's "determined in advance"): vertical photo columns around the
tower, flown up and down in turn, each with a view down to the tower's foot; the nacelle's sides,
rear, top and underside in rows of photos that tile each face.
Stations that would come closer than the required clearance to any part are dropped.

Every waypoint keeps ``required`` clearance (safe distance + tracking margin) from every part of
every turbine; every leg ``required - step/2`` (the lower bound's sampling slack).
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from wtcli.geometry import BLADE_SIDES, Camera, Turbine
from wtcli.geometry.coverage import imaged
from wtcli.geometry.turbine import SurfaceSamples
from wtcli.plan.clearance import Site
from wtcli.plan import corners

Z = np.array([0.0, 0.0, 1.0])
ALPHAS_DEG = (15.0, 25.0, 35.0, 45.0, 55.0, 65.0, 75.0)
GIMBAL_ALPHA_MAX_DEG = 115.0  # stations the gimbal cannot aim head-on may turn this far
LEG_STEP = 0.5


@dataclass
class WP:
    pos: np.ndarray
    fwd: np.ndarray | None  # camera viewing direction (unit), None = keep the previous aim
    photo: bool
    component: str
    slow: bool = True  # inspection speed (True) or cruise speed (False) on the leg ending here
    # A photo station's camera-to-surface distance (m), which sets its motion-blur speed limit
    # (mission.capture_speed); None: the closest the passes use (the strictest limit).
    standoff: float | None = None


@dataclass(frozen=True)
class PassParams:
    camera: Camera
    standoff: float  # camera-to-surface distance, m
    max_standoff: float  # farthest camera-to-surface distance still within the target GSD
    required: float  # clearance every waypoint keeps, m
    min_standoff: float  # closest camera-to-surface distance allowed (required + model slack)
    overlap: float
    min_altitude: float
    pitch_range: tuple[float, float] = (-90.0, 90.0)  # camera elevation the gimbal reaches, deg
    reach: float = 0.0  # farthest camera-to-surface distance a view is planned at (GSD + 2 %)
    max_incidence_deg: float = 60.0  # coverage's incidence limit

    @property
    def leg_required(self) -> float:
        return self.required - 0.5 * LEG_STEP

    def spacing(self, distance: float) -> float:
        """Photo spacing: (1 - overlap) of the footprint's shorter side at ``distance``."""
        fw, fh = self.camera.footprint_m(distance)
        return max(0.25, (1.0 - self.overlap) * min(fw, fh))

    def aim_ok(self, fwd: np.ndarray) -> np.ndarray:
        """(K,) bool: the gimbal can point the camera along each viewing direction (its
        elevation within ``pitch_range``; the heading is the airframe's, any)."""
        F = np.atleast_2d(np.asarray(fwd, float))
        el = np.degrees(np.arcsin(np.clip(F[:, 2] / np.linalg.norm(F, axis=1), -1.0, 1.0)))
        return (el >= self.pitch_range[0] - 1e-6) & (el <= self.pitch_range[1] + 1e-6)

    def gimbal_text(self) -> str:
        lo, hi = self.pitch_range
        return f"the gimbal's pitch range [{lo:+g}, {hi:+g}] deg"


@dataclass
class Chunk:
    """One component's waypoints (a blade, the nacelle, the tower, the overview photo)."""

    turbine: str
    name: str  # blade1 | nacelle | tower | overview
    wps: list[WP] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    pattern: str = ""  # a blade's: "ring4"/"ring5" (blade_chunk's ring of passes) or "" (by side)

    @property
    def start(self) -> np.ndarray:
        return self.wps[0].pos

    @property
    def end(self) -> np.ndarray:
        return self.wps[-1].pos


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


# ---- connecting two points safely ----------------------------------------------------------------
def connect(site: Site, p: np.ndarray, q: np.ndarray, leg_required: float,
            hints: list[np.ndarray] | None = None, ground: float | None = None) -> list[np.ndarray] | None:
    """Via points (possibly none) so that p -> vias -> q keeps ``leg_required`` from everything.

    Tries the straight leg; a long one (> LONG_LEG) blocked in short stretches, each of those
    on its own (``_connect_piecewise``); then one via point pushed from the midpoint (or from
    where a long leg is blocked), from p or from q, then two via points pushed from p and q
    (also held at the height of the higher end or ground between uneven grounds), along the
    hint and escape directions by growing distances (a distance's candidates checked together,
    shortest chain first; the first that clears wins); where none does, the same along the 26
    directions of a cube's faces, edges and corners (``LATTICE``): a point tucked between the
    nacelle, the tower and a blade root may have its way out along none of the escapes. None if
    nothing clears.
    """
    p, q = np.asarray(p, float), np.asarray(q, float)
    cap = leg_required + 0.5 * LEG_STEP  # legs subtract up to half a step of sampling slack
    clear = site.segment_clearance(p[None], q[None], LEG_STEP, cap)[0] >= leg_required
    if clear and (ground is None or site.legs_above_ground(p[None], q[None], ground)[0]):
        return []
    if not clear and np.linalg.norm(q - p) > LONG_LEG:
        vias = _connect_piecewise(site, p, q, leg_required, hints, ground)
        if vias is not None:
            return vias
    m = 0.5 * (p + q)
    side = np.cross(Z, q - p)
    side = [_unit(side), -_unit(side)] if np.linalg.norm(side) > 1e-6 else []
    dirs = _escapes(site, (m, p, q), list(hints or []), side)
    # A long leg is often blocked far from its middle and ends (a turbine in line): vias pushed
    # from its least-clearance sample go round what blocks it with short pushes.
    block: list[tuple[np.ndarray, list[np.ndarray]]] = []
    tb = None if clear else site.lowest_sample(p, q, LEG_STEP, cap)
    if tb is not None and min(tb, 1 - tb, abs(tb - 0.5)) * np.linalg.norm(q - p) > 20.0:
        xb = p + tb * (q - p)
        block = [(xb, _escapes(site, (xb,), [], side))]
    gp, gq = _away(site, p), _away(site, q)  # straight away from the nearest part
    # Between grounds of different heights, a chain whose vias drop below the higher end's
    # height, or below higher ground on the way, may dip too low over it: also try each two-via
    # chain with its vias lifted to that height (hold it, then descend at the far end).
    zc = max(p[2], q[2])
    lifted = False
    if ground is not None:
        g = site.ground_z(p + (q - p) * np.linspace(0.0, 1.0, 65)[:, None])  # where to lift to
        lifted = bool(g.max() > g.min())
        zc = max(zc, float(g.max()) + ground + 0.5)

    def lift(v: np.ndarray) -> np.ndarray:
        return np.r_[v[:2], max(v[2], zc)]
    up = lift if lifted else None
    more = [u for u in LATTICE if all(float(u @ v) < 0.999 for v in dirs)]
    return (_search(site, p, q, leg_required, ground, dirs, m, gp, gq, block, up)
            or _search(site, p, q, leg_required, ground, more, m, gp, gq, [], up, with_away=False))


# The 26 directions from a cube's centre to its faces, edges and corners: where none of a
# leg's escape directions leads round what blocks it, one of these does, if a short one does.
LATTICE = [np.array(d, float) / np.linalg.norm(d)
           for d in itertools.product((-1.0, 0.0, 1.0), repeat=3) if any(d)]


def _search(site: Site, p: np.ndarray, q: np.ndarray, leg_required: float, ground: float | None,
            dirs: list[np.ndarray], m: np.ndarray, gp: np.ndarray, gq: np.ndarray,
            block: list, lift, with_away: bool = True) -> list[np.ndarray] | None:
    """``connect``'s candidates along ``dirs`` by growing distances: one via from the middle,
    from p or from q, two from p and q (``lift``-ed too where given), from p and q straight
    away from the nearest part (``gp``, ``gq``; with ``with_away``) with one from the middle
    between, and from where a long leg is blocked (``block``)."""
    cap = leg_required + 0.5 * LEG_STEP
    for dist in (2.0, 4.0, 7.0, 11.0, 16.0, 24.0, 35.0, 50.0, 70.0, 95.0):  # nearest first
        cands = [[m + dist * u] for u in dirs] + [[p + dist * u] for u in dirs] + \
            [[q + dist * u] for u in dirs] + [[p + dist * u, q + dist * u] for u in dirs]
        if with_away:
            cands += [[p + dist * gp, q + dist * gq]]
        cands += [[p + dist * gp, m + dist * u, q + dist * gq] for u in dirs]
        cands += [[xb + dist * u] for xb, ub in block for u in ub]
        if lift:
            cands += [[lift(p + dist * u), lift(q + dist * u)] for u in dirs]
        if not cands:
            return None  # none along any direction, at any distance
        vp = np.array([v for c in cands for v in c])
        vo = np.repeat(np.arange(len(cands)), [len(c) for c in cands])
        if ground is not None:  # height above the local ground (nearest base or launch point)
            okg = np.ones(len(cands), bool)
            np.logical_and.at(okg, vo, site.above_ground(vp, ground))
            cands = [c for c, ok in zip(cands, okg) if ok]
            vp, vo = vp[okg[vo]], vo[okg[vo]]
            vo = np.cumsum(okg)[vo] - 1  # renumbered over the candidates kept
        if not cands:
            continue
        # Via points must clear themselves (cheap) before their legs are checked.
        okv = np.ones(len(cands), bool)
        np.logical_and.at(okv, vo, site.clearance(vp, cap) >= leg_required)
        keep = np.nonzero(okv)[0]
        cands = [cands[i] for i in keep[np.argsort(_chain_lengths(p, q, vp, vo)[keep], kind="stable")]]
        for b0 in range(0, len(cands), 8):  # shortest first, a few at a time
            batch = cands[b0:b0 + 8]
            legs0, legs1, owner = [], [], []
            for i, vias in enumerate(batch):
                chain = [p] + vias + [q]
                legs0 += chain[:-1]
                legs1 += chain[1:]
                owner += [i] * (len(chain) - 1)
            legs0, legs1, owner = np.array(legs0), np.array(legs1), np.array(owner)
            ok = site.segment_clearance(legs0, legs1, LEG_STEP, cap) >= leg_required
            if ground is not None and ok.any():  # legs between high and low ground
                ok[ok] = site.legs_above_ground(legs0[ok], legs1[ok], ground)
            good = np.ones(len(batch), bool)
            np.logical_and.at(good, owner, ok)
            if good.any():
                return batch[int(np.argmax(good))]
    return None


LONG_LEG = 150.0  # m: a longer blocked leg is detoured piece by piece where it is blocked
LOCAL_MARGIN, LOCAL_MAX = 30.0, 130.0  # each detour: from/to this far beyond a blocked stretch


def _connect_piecewise(site: Site, p: np.ndarray, q: np.ndarray, leg_required: float,
                       hints: list[np.ndarray] | None, ground: float | None) -> list[np.ndarray] | None:
    """A long leg (a transit between turbines, to or from the launch point) blocked in a few
    short stretches (mostly near its ends, by the turbines there): straight where it is clear,
    and from LOCAL_MARGIN before to LOCAL_MARGIN after each blocked stretch ``connect``-ed on
    its own, a short leg. The same kind of detours the full search finds, at a fraction of its
    cost (its candidates are chains across the site). None where a stretch is too long, a
    straight piece does not clear (the ground), or a detour is not found."""
    L = float(np.linalg.norm(q - p))
    cap = leg_required + 0.5 * LEG_STEP
    runs = site.blocked_stretches(p, q, leg_required, LEG_STEP, cap, gap=2 * LOCAL_MARGIN)
    if not runs:
        return None
    cuts = []
    for t0, t1 in runs:
        a, b = max(0.0, t0 - LOCAL_MARGIN / L), min(1.0, t1 + LOCAL_MARGIN / L)
        if (b - a) * L > LOCAL_MAX:
            return None
        cuts.append((a, b))
    ends = [p + t * (q - p) for ab in cuts for t in ab]  # A1, B1, A2, B2, ...
    ends[0] = p if cuts[0][0] == 0.0 else ends[0]
    ends[-1] = q if cuts[-1][1] == 1.0 else ends[-1]
    straight0 = np.array([p] + ends[1::2])  # p -> A1, B1 -> A2, ..., Bk -> q
    straight1 = np.array(ends[0::2] + [q])
    keep = np.linalg.norm(straight1 - straight0, axis=1) > 1e-9
    s0, s1 = straight0[keep], straight1[keep]
    if len(s0) and ((site.segment_clearance(s0, s1, LEG_STEP, cap) < leg_required).any() or (
            ground is not None and not site.legs_above_ground(s0, s1, ground).all())):
        return None
    out: list[np.ndarray] = []
    for i in range(len(cuts)):
        A, B = ends[2 * i], ends[2 * i + 1]
        vias = connect(site, A, B, leg_required, hints, ground)  # short: no recursion
        if vias is None:
            return None
        out += ([] if A is p else [A]) + vias + ([] if B is q else [B])
    return out


def _escapes(site: Site, points, first: list[np.ndarray], extra: list[np.ndarray]) -> list[np.ndarray]:
    """Distinct unit directions to push a via point in: ``first``, away from the axis and from
    the tower of the turbine nearest each point, along its axis both ways, round its blades'
    tips (that of the first point), ``extra`` and up."""
    dirs: list[np.ndarray] = list(first)
    for x in points:
        t = site.nearest_hub(x)
        radial = x - t.hub_center
        radial -= (radial @ t.axis) * t.axis
        if np.linalg.norm(radial) > 1e-6:
            dirs.append(_unit(radial))
        out = np.r_[(x - t.base_xyz)[:2], 0.0]
        if np.linalg.norm(out) > 1e-6:
            dirs.append(_unit(out))
        dirs += [t.axis, -t.axis]
    t = site.nearest_hub(points[0])
    dirs += [t.blade_direction(k) for k in range(t.n_blades)]  # around a blade's tip
    dirs += extra + [Z]
    uniq: list[np.ndarray] = []
    for u in dirs:
        if all(float(u @ v) < 0.999 for v in uniq):
            uniq.append(u)
    return uniq


def _away(site: Site, x: np.ndarray, h: float = 0.25) -> np.ndarray:
    """Unit direction in which the clearance grows fastest at x (central differences)."""
    e = np.eye(3) * h
    c = site.clearance(np.vstack([x + e, x - e]))
    g = c[:3] - c[3:]
    n = np.linalg.norm(g)
    return g / n if n > 1e-9 else Z


def _chain_lengths(p: np.ndarray, q: np.ndarray, vp: np.ndarray, vo: np.ndarray) -> np.ndarray:
    """Length of each chain p -> its via points -> q; the via points ``vp`` of chain i are the
    rows where ``vo`` == i, in order (``vo`` sorted, every chain with at least one)."""
    first = np.r_[True, vo[1:] != vo[:-1]]
    last = np.r_[vo[1:] != vo[:-1], True]
    step = np.linalg.norm(vp - np.where(first[:, None], p, np.roll(vp, 1, axis=0)), axis=1)
    step[last] += np.linalg.norm(vp[last] - q, axis=1)
    out = np.zeros(int(vo[-1]) + 1 if len(vo) else 0)
    np.add.at(out, vo, step)
    return out


# ---- blades ------------------------------------------------------------------------------------------
SIDE_DIRS = {"leading_edge": (1, 0), "pressure_side": (0, 1), "trailing_edge": (-1, 0),
             "suction_side": (0, -1)}


def _support(turbine: Turbine, f: np.ndarray, wc: np.ndarray, wn: np.ndarray) -> np.ndarray:
    """Support distance of the blade section at span fraction f in direction (wc, wn) of (c, n)."""
    A, B = turbine.blade_semi_axes(f)
    return np.sqrt((A * wc) ** 2 + (B * wn) ** 2)


def blade_stations(turbine: Turbine, spacing: float) -> np.ndarray:
    """Span distances (m from the hub centre) of the photo stations, root to tip."""
    s0 = max(turbine.blade_root_offset,
             math.sqrt(max(turbine.hub_radius ** 2 - (turbine.blade_root_chord / 2) ** 2, 0.0)))
    s1 = turbine.tip_radius
    n = max(2, int(math.ceil((s1 - s0) / spacing)) + 1)
    return np.linspace(s0 + 0.25 * spacing, s1, n)


def _side_points(turbine: Turbine, k: int, s: np.ndarray, gamma: np.ndarray,
                 offset: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera positions and viewing directions at spans s and angles gamma (rad, in the c-n plane
    from +c towards +n), ``offset`` m beyond the section's support distance."""
    d, c, n = turbine.blade_frame(k)
    wc, wn = np.cos(gamma), np.sin(gamma)
    s0, s1 = turbine.blade_root_offset, turbine.tip_radius
    f = (np.clip(s, s0, s1) - s0) / (s1 - s0)
    h = _support(turbine, f, wc, wn)
    w = wc[:, None] * c + wn[:, None] * n
    pos = turbine.hub_center + s[:, None] * d + (h + offset)[:, None] * w
    return pos, -w


# Rings of views round a blade (deg in the c-n plane from the leading edge towards the pressure
# side), tried fewest first: four on the diagonals between adjacent sides (slender blades), five
# (wide or round sections: four leave the side centres too far or too oblique).
RINGS = ((45.0, 135.0, 225.0, 315.0), (0.0, 72.0, 144.0, 216.0, 288.0))
RING_SHIFT_DEG = (0.0, 10.0, -10.0, 20.0, -20.0, 30.0, -30.0, 45.0, -45.0, 60.0, -60.0, 75.0,
                  -75.0)  # a blocked station's turns, least first
RING_MAX_DROPPED = 3  # blocked stations a ring pass leaves out; more: flown side by side
RING_SECTION_POINTS = 96  # points round a section a ring's views must all see
RING_MARGIN_DEG = 3.0  # kept from the incidence limit when judging a section (flight error)


def _camera_rotations(fwd: np.ndarray) -> np.ndarray:
    """(K, 3, 3) world->camera rotations of photos aimed along ``fwd`` (K, 3) as a route
    records them (compass yaw, gimbal pitch, no roll): what coverage is measured with."""
    F = fwd / np.linalg.norm(fwd, axis=1)[:, None]
    yaw = np.degrees(np.arctan2(F[:, 0], F[:, 1]))
    pitch = np.degrees(np.arcsin(np.clip(F[:, 2], -1.0, 1.0)))
    return np.array([Camera.rotation_from_yaw_pitch(y, p) for y, p in zip(yaw, pitch)])


def _ring_standoffs(turbine: Turbine, k: int, pp: PassParams, S: np.ndarray, angles_deg,
                    E: np.ndarray) -> np.ndarray:
    """Per station (span S), the farthest standoff in E from which views at ``angles_deg`` (in
    the c-n plane, from +c towards +n) see every point round the blade's section by coverage's
    own test (``imaged``: the frame less 5 %, the distance ``pp.reach``, the incidence limit
    less RING_MARGIN_DEG); NaN where none does."""
    s0, s1 = turbine.blade_root_offset, turbine.tip_radius
    f = (np.clip(S, s0, s1) - s0) / (s1 - s0)
    A, B = turbine.blade_semi_axes(f)
    d, c, n = turbine.blade_frame(k)
    t = np.linspace(0.0, 2 * math.pi, RING_SECTION_POINTS, endpoint=False)
    xc, yn = A[:, None] * np.cos(t), B[:, None] * np.sin(t)  # (stations, points round)
    nc, nn = B[:, None] * np.cos(t), A[:, None] * np.sin(t)
    nl = np.hypot(nc, nn)
    P = turbine.hub_center + S[:, None, None] * d + xc[..., None] * c + yn[..., None] * n
    N = (nc / nl)[..., None] * c + (nn / nl)[..., None] * n
    seg = np.hypot(np.diff(xc, axis=1, append=xc[:, :1]), np.diff(yn, axis=1, append=yn[:, :1]))
    reach = pp.reach if pp.reach > 0 else pp.max_standoff
    limit = pp.max_incidence_deg - RING_MARGIN_DEG
    e_best = np.full(len(S), np.nan)
    # a view's direction does not depend on its standoff: its rotation is made once per angle
    rot = {g: _camera_rotations(_side_points(turbine, k, S, np.full(len(S), g),
                                             np.zeros(len(S)))[1])
           for g in np.radians(angles_deg)}
    for e in np.sort(E):  # closest first; a farther standoff that also works replaces it
        seen = np.zeros(P.shape[:2], bool)
        for g in np.radians(angles_deg):
            pos, _ = _side_points(turbine, k, S, np.full(len(S), g), np.full(len(S), e))
            seen |= imaged(P - pos[:, None, :], N, rot[g][:, None], pp.camera, reach, limit, 0.05)
        ok = (seg * ~seen).sum(axis=1) <= 1e-3 * seg.sum(axis=1)
        e_best[ok] = e
    return e_best


def _ring_passes(turbine: Turbine, k: int, site: Site, pp: PassParams, label: str
                 ) -> tuple[int, list[tuple[str, np.ndarray, np.ndarray, np.ndarray]],
                            list[str]] | None:
    """Blade k flown as one of RINGS: passes root -> tip at fixed angles round the blade, each
    imaging parts of two or three sides obliquely, the fewest that see the whole section at
    every station (``_ring_standoffs``, at the farthest standoff between ``pp.min_standoff``
    and ``pp.max_standoff``, the GSD's distance, that works: a looser blur limit, and no finer
    GSD than the section needs). (views per station, passes), each
    pass named after the side nearest its angle, and notes on the stations left out. None if
    no ring sees every section, or a pass
    has more than RING_MAX_DROPPED blocked stations (clearance, ground, gimbal): the blade is
    then flown side by side."""
    E = np.arange(pp.max_standoff, max(pp.min_standoff, pp.standoff - 2.0) - 1e-9, -0.25)
    # Station spacing from the footprint at the closest standoff: overlap never below target.
    S = blade_stations(turbine, pp.spacing(float(E[-1])))
    side_deg = np.array([math.degrees(math.atan2(*SIDE_DIRS[x][::-1])) for x in BLADE_SIDES])
    for ring in RINGS:
        e = _ring_standoffs(turbine, k, pp, S, ring, E)
        if np.isnan(e).any():
            continue
        # The stations again at the footprint of the closest standoff the ring uses (fewer
        # photos where it flies farther), if the ring still sees every section there.
        S2 = blade_stations(turbine, pp.spacing(float(e.min())))
        e2 = _ring_standoffs(turbine, k, pp, S2, ring, E[E >= e.min() - 1e-9])
        if not np.isnan(e2).any():
            S, e = S2, e2
        out, notes = [], []
        for g in ring:
            gg, ee = np.full(len(S), math.radians(g)), e.copy()
            pos, fwd = _side_points(turbine, k, S, gg, ee)
            pos0 = pos.copy()
            blocked = (site.clearance(pos, pp.required) < pp.required) | \
                ~site.above_ground(pos, pp.min_altitude) | ~pp.aim_ok(fwd)
            for j in np.nonzero(blocked)[0]:  # (near the hub) turned or moved until clear
                xs = np.arange(pp.min_standoff, pp.max_standoff + 1e-9, 0.25)
                D, X = np.meshgrid(np.radians(RING_SHIFT_DEG), xs[np.argsort(np.abs(xs - e[j]))],
                                   indexing="ij")
                D, X = D.ravel(), X.ravel()
                cp, cf = _side_points(turbine, k, np.full(len(D), S[j]), gg[j] + D, X)
                ok = (site.clearance(cp, pp.required) >= pp.required) & \
                    site.above_ground(cp, pp.min_altitude) & pp.aim_ok(cf)
                if ok.any():
                    i = int(np.argmax(ok))
                    pos[j], fwd[j], ee[j], blocked[j] = cp[i], cf[i], X[i], False
            if blocked.sum() > RING_MAX_DROPPED:
                return None
            off = np.abs((g - side_deg + 180.0) % 360.0 - 180.0)
            side = BLADE_SIDES[int(np.argmin(off))]
            keep = ~blocked  # a root station wedged against the hub: left out, coverage decides
            if blocked.any():
                parts = sorted({site.nearest_part(pos0[j])[0] for j in np.nonzero(blocked)[0]})
                notes.append(f"{label}/{side}: {int(blocked.sum())} station(s) of the {g:g} deg "
                             f"pass unreachable at a safe distance (blocked by "
                             f"{', '.join(parts)}): dropped")
            out.append((side, pos[keep], fwd[keep], ee[keep]))
        return len(ring), out, notes
    return None


def blade_chunk(turbine: Turbine, k: int, site: Site, pp: PassParams, label: str,
                split_sides: frozenset[str] | set[str] = frozenset(),
                ring_first: bool = False, start_near: np.ndarray | None = None,
                end_toward: np.ndarray | None = None) -> Chunk:
    """All four sides of blade k (index), as passes joined by arcs, ending at its start point.

    ``split_sides``: sides flown as two oblique passes everywhere (a wide chord's flat sides,
    whose edges a single head-on pass sees beyond the incidence limit). ``ring_first``: a ring
    of four or five oblique passes round the blade (``_ring_passes``) where one sees every
    section; side by side where none does. A ring of four given ``start_near`` (where the
    drone comes from) starts at the pass and goes round in the direction that make the way in
    and out (to ``end_toward``) shortest (``_ring_order``), and ends at the root of its last
    pass instead of returning to its start: its ends are already at the root."""
    chunk = Chunk(turbine.id, f"blade{k + 1}")
    d, c, n = turbine.blade_frame(k)
    spacing = pp.spacing(pp.standoff)
    S = blade_stations(turbine, spacing)
    # (side, positions, fwd, standoffs) root -> tip
    passes: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]] = []
    ring = _ring_passes(turbine, k, site, pp, label) if ring_first else None
    if ring is not None:
        chunk.pattern, passes = f"ring{ring[0]}", ring[1]
        chunk.notes += ring[2]
        S = S[:0]
    no_return = ring is not None and len(passes) % 2 == 0 and start_near is not None
    if no_return:
        passes = _ring_order(passes, start_near, end_toward, site, pp)
    extra = [0.0] + [e for e in (0.5, 1.0, 1.5) if pp.standoff + e <= pp.max_standoff]
    closer = [e for e in (-0.5, -1.0) if pp.standoff + e >= pp.min_standoff]
    for side in BLADE_SIDES if len(S) >= 2 else ():
        sc, sn = SIDE_DIRS[side]
        g0 = math.atan2(sn, sc)
        pos0, fwd0 = _side_points(turbine, k, S, np.full(len(S), g0), np.full(len(S), pp.standoff))
        clear0 = site.clearance(pos0, pp.required)
        ground = site.ground_z(pos0) + pp.min_altitude
        aim0 = pp.aim_ok(fwd0)  # a side facing down is seen head-on from below, looking up
        blocked = (clear0 < pp.required) | (pos0[:, 2] < ground) | ~aim0
        forced = side in split_sides
        if forced:
            blocked[:] = True
        if not blocked.any():
            passes.append((side, pos0, fwd0, np.full(len(S), pp.standoff)))
            continue
        if not forced:
            why = f" ({int((~aim0).sum())} beyond {pp.gimbal_text()})" if (~aim0).any() else ""
            chunk.notes.append(f"{label}/{side}: {int(blocked.sum())} of {len(S)} stations blocked "
                               f"head-on{why}; flown as two oblique passes")
        alphas = np.radians(ALPHAS_DEG[1:] if forced else ALPHAS_DEG)
        jj = np.nonzero(blocked)[0]
        for sign in (1.0, -1.0):
            al = alphas
            if (~aim0).any():  # also the least turn that brings the aim within the gimbal's reach
                ag = _gimbal_alpha(c, n, g0, sign, pp.pitch_range)
                al = np.unique(np.r_[alphas, [] if ag is None else [ag]])
            pos, fwd, st = pos0.copy(), fwd0.copy(), np.full(len(S), pp.standoff)
            keep = ~blocked if sign > 0 else np.zeros(len(S), bool)
            # Every candidate (station, alpha, extra standoff) at once, in preference order.
            J, AL, EX = np.meshgrid(jj, al, np.array(closer + extra), indexing="ij")
            J, AL, EX = J.ravel(), AL.ravel(), EX.ravel()
            cp, cf = _side_points(turbine, k, S[J], g0 + sign * AL, pp.standoff + EX)
            safe = (site.clearance(cp, pp.required) >= pp.required) & \
                site.above_ground(cp, pp.min_altitude)
            ok = safe & pp.aim_ok(cf) & ((AL <= math.radians(ALPHAS_DEG[-1]) + 1e-9) | ~aim0[J])
            per = len(al) * len(closer + extra)
            okm = ok.reshape(len(jj), per)
            first = np.argmax(okm, axis=1)
            found = okm.any(axis=1)
            for n_j, j in enumerate(jj):
                if found[n_j]:
                    ci = n_j * per + first[n_j]
                    pos[j], fwd[j], st[j] = cp[ci], cf[ci], pp.standoff + EX[ci]
            keep[jj] = found
            if keep.any():
                passes.append((side, pos[keep], fwd[keep], st[keep]))
            # Dropped: no safe candidate (what blocks them), or only ones the gimbal cannot aim.
            aimless = ~found & safe.reshape(len(jj), per).any(axis=1)
            if aimless.any():
                chunk.notes.append(f"{label}/{side}: {int(aimless.sum())} station(s) seen from the "
                                   f"{'+' if sign > 0 else '-'} side only beyond {pp.gimbal_text()} "
                                   "(blocked by the gimbal): dropped")
            unsafe = ~found & ~aimless
            if unsafe.any():
                parts = sorted({site.nearest_part(pos0[j])[0] for j in jj[unsafe]})
                chunk.notes.append(f"{label}/{side}: {int(unsafe.sum())} station(s) unreachable "
                                   f"from the {'+' if sign > 0 else '-'} side at a safe distance "
                                   f"(blocked by {', '.join(parts)}): dropped")

    # Out and back in turn (each pass from its end nearer the last one's end); joined by arcs
    # around the blade axis.
    for i, (side, pos, fwd, st) in enumerate(passes):
        if not len(pos):
            continue
        if chunk.wps and np.linalg.norm(pos[-1] - chunk.wps[-1].pos) < \
                np.linalg.norm(pos[0] - chunk.wps[-1].pos):
            pos, fwd, st = pos[::-1], fwd[::-1], st[::-1]
        comp = f"{label}/{side}"
        if chunk.wps:
            joined = False
            for attempt in range(4):  # a crowded root end: start the pass one station later
                try:
                    _join(chunk.wps, pos[0], fwd[0], turbine, k, site, pp, comp)
                    joined = True
                    break
                except _Blocked:
                    if len(pos) < 3:
                        break
                    pos, fwd, st = pos[1:], fwd[1:], st[1:]
            if not joined:
                chunk.notes.append(f"{comp}: no safe path from the previous pass (blocked by "
                                   f"{site.nearest_part(pos[0])[0]}): pass dropped")
                continue
            if attempt:
                chunk.notes.append(f"{comp}: {attempt} first station(s) unreachable from the "
                                   "previous pass: dropped")
        # A station no way round the blade or detour reaches (wedged between the root and the
        # nacelle at a large safe distance) is left out with a note; coverage then decides.
        append_chain(chunk, site, pp, [WP(p, f, True, comp, standoff=float(d))
                                       for p, f, d in zip(pos, fwd, st)],
                     droppable=True, blade=(turbine, k))
    wps = chunk.wps
    if not wps:
        chunk.notes.append(f"{label}: no safe station at all")
        return chunk
    if no_return:
        return chunk
    # Eq. 8's return leg: back to the blade's start point S_p,i.
    start = wps[0]
    try:
        _join(wps, start.pos, start.fwd, turbine, k, site, pp, f"{label}/return")
        wps.append(WP(start.pos.copy(), start.fwd, False, f"{label}/return"))
    except _Blocked:
        chunk.notes.append(f"{label}: no safe return to the blade's start point; the flight "
                           "goes on from the last pass")
    return chunk


def _way_length(site: Site, pp: PassParams, p: np.ndarray, q: np.ndarray) -> float:
    """The length of a leg p -> q as it will be flown: straight where that keeps the clearance,
    else along ``connect``'s detour (three times the straight length plus 200 m where it finds
    none)."""
    L = float(np.linalg.norm(q - p))
    if site.segment_clearance(p[None], q[None], LEG_STEP, pp.required)[0] < pp.leg_required:
        vias = connect(site, p, q, pp.leg_required, ground=pp.min_altitude)
        chain = [p] + list(vias or []) + [q]
        L = float(np.linalg.norm(np.diff(np.array(chain), axis=0), axis=1).sum()) \
            if vias is not None else 3 * L + 200.0
    return L


def _ring_order(passes: list, start_near: np.ndarray, end_toward: np.ndarray | None,
                site: Site, pp: PassParams) -> list:
    """An even ring's passes (in ring order, each root -> tip) rotated and maybe reversed so that
    the way in (from ``start_near`` to the first pass's root end), the joins between passes
    (root and tip ends of neighbours, as the order pairs them) and the way out (from the last
    pass's root end, where the ring ends, to ``end_toward``: straight, a point on the next part
    and not one to fly to) are shortest: the others straight where that keeps the clearance,
    else as long as ``connect``'s detour (a root crowded by the hub, the nacelle or the tower
    joins badly on one side)."""
    n = len(passes)
    if not all(len(p[1]) for p in passes):
        return passes
    cache: dict[tuple, float] = {}

    def way(p: np.ndarray, q: np.ndarray) -> float:
        key = (p.tobytes(), q.tobytes())
        if key not in cache:
            cache[key] = _way_length(site, pp, p, q)
        return cache[key]

    best, out = math.inf, passes
    for i0 in range(n):
        for step in (1, -1):
            order = [passes[(i0 + step * j) % n] for j in range(n)]
            cost = way(start_near, order[0][1][0])
            for j in range(n - 1):  # even j ends out at its tip, odd j back at its root
                end = -1 if j % 2 == 0 else 0
                cost += way(order[j][1][end], order[j + 1][1][end])
            if end_toward is not None:
                cost += float(np.linalg.norm(order[-1][1][0] - end_toward))
            if cost < best - 1e-9:
                best, out = cost, order
    return out


def _gimbal_alpha(c: np.ndarray, n: np.ndarray, g0: float, sign: float,
                  pitch_range: tuple[float, float], margin: float = 0.25) -> float | None:
    """The least turn (rad, <= GIMBAL_ALPHA_MAX_DEG) from the side's angle g0, towards ``sign``,
    at which the camera looks back at the blade axis within the gimbal's pitch range (with a
    ``margin`` in deg): a face turned down is seen obliquely from a camera low enough to look up
    within the gimbal's reach, as head-on as that allows. None if no turn does."""
    a = np.radians(np.arange(0.0, GIMBAL_ALPHA_MAX_DEG + 0.25, 0.5))
    g = g0 + sign * a
    up = np.degrees(np.arcsin(np.clip(-(np.cos(g) * c[2] + np.sin(g) * n[2]), -1.0, 1.0)))
    ok = (up >= pitch_range[0] + margin) & (up <= pitch_range[1] - margin)
    return float(a[np.argmax(ok)]) if ok.any() else None


ARC_STEP_DEG = 15.0  # an arc round a blade in steps this fine is flown near the turn speed: the
# timing's junction deviation passes a 15 deg corner at ~3.8 m/s, a 30 deg one at ~1.9 m/s


def _arc(turbine: Turbine, frame: tuple, s: float, g_from: float, g_to: float, radius: float,
         long_way: bool = False, step_deg: float = 30.0) -> list[np.ndarray]:
    d, c, n = frame
    dg = (g_to - g_from + math.pi) % (2 * math.pi) - math.pi
    if long_way:
        dg -= math.copysign(2 * math.pi, dg)
    m = max(1, int(math.ceil(abs(dg) / math.radians(step_deg))))
    if m == 1:
        return []
    g = g_from + dg * np.arange(1, m) / m
    return list(turbine.hub_center + s * d + radius * (np.cos(g)[:, None] * c + np.sin(g)[:, None] * n))


def _join(wps: list[WP], q: np.ndarray, q_fwd: np.ndarray, turbine: Turbine, k: int, site: Site,
          pp: PassParams, comp: str) -> None:
    """Append non-photo via points from wps[-1] to q: an arc around the blade axis at the span of
    the nearer end, moved outwards along the blade until it clears; else ``connect``."""
    p = wps[-1].pos
    d, c, n = turbine.blade_frame(k)
    hc = turbine.hub_center

    def polar(x: np.ndarray) -> tuple[float, float, float]:
        r = x - hc
        s = float(r @ d)
        return s, math.atan2(float(r @ n), float(r @ c)), float(np.linalg.norm(r - s * d))

    sp, gp, rp = polar(p)
    sq, gq, rq = polar(q)
    A, _ = turbine.blade_semi_axes(np.array([1.0]))
    s_end = turbine.tip_radius
    s_arc = max(sp, sq) if abs(sp - sq) < 3 else None
    # Straight where that keeps the clearance (round the tip, a chord is 10 % shorter than the
    # arc); the arc only where the chord would cut in.
    if site.segment_clearance(p[None], q[None], LEG_STEP, pp.required)[0] >= pp.leg_required:
        return

    def candidates():  # nearest the passes' end first; made only as far as they are checked
        if s_arc is not None:
            radius = max(rp, rq)
            spans = [s_arc] + [x for x in np.arange(s_arc + 2.0, s_end + 0.1, 2.0)]
            if s_arc > s_end - 2.0:  # at the tip: go round beyond it too
                spans += [s_end + pp.required]
            for long_way in (False, True):
                for s in spans:
                    vias = []
                    if abs(s - sp) > 1e-6:
                        vias.append(hc + s * d + (p - hc - sp * d))
                    vias += _arc(turbine, (d, c, n), s, gp, gq, radius if s <= s_end else rp, long_way,
                                 step_deg=ARC_STEP_DEG)
                    if abs(s - sq) > 1e-6:
                        vias.append(hc + s * d + (q - hc - sq * d))
                    yield vias
            return
        # Along the span (a pass whose middle stations were dropped, e.g. a trailing edge facing
        # the tower): round the blade at p's span to a free angle, along the blade there, and
        # back round at q's span; nearest angles first.
        lo, hi = sorted((sp, sq))
        A_max = float(turbine.blade_semi_axes(
            (np.clip(np.linspace(lo, hi, 16), turbine.blade_root_offset, s_end)
             - turbine.blade_root_offset) / (s_end - turbine.blade_root_offset))[0].max())
        radius = max(rp, rq, A_max + pp.standoff)
        g_mid = gp + 0.5 * ((gq - gp + math.pi) % (2 * math.pi) - math.pi)
        for dg in (30, -30, 60, -60, 90, -90, 120, -120, 150, -150, 180):
            g = g_mid + math.radians(dg)
            for r in (radius, radius + 2.0):
                w = math.cos(g) * c + math.sin(g) * n
                # Fine arc steps: p and q may keep barely the clearance, a chord would cut in.
                yield (_arc(turbine, (d, c, n), sp, gp, g, rp, step_deg=10.0)
                       + [hc + sp * d + r * w, hc + sq * d + r * w]
                       + _arc(turbine, (d, c, n), sq, g, gq, rq, step_deg=10.0))

    # Candidates checked a few at a time; the first that clears wins.
    cands = candidates()
    while batch := list(itertools.islice(cands, 6)):
        legs0, legs1, owner, pts, pown = [], [], [], [], []
        for i, vias in enumerate(batch):
            chain = [p] + vias + [q]
            legs0 += chain[:-1]
            legs1 += chain[1:]
            owner += [i] * (len(chain) - 1)
            pts += vias
            pown += [i] * len(vias)
        good = np.ones(len(batch), bool)
        lb = site.segment_clearance(np.array(legs0), np.array(legs1), LEG_STEP, pp.required)
        np.logical_and.at(good, np.array(owner), lb >= pp.leg_required)
        if pts:
            P = np.array(pts)
            okp = (site.clearance(P, pp.required) >= pp.required) & \
                site.above_ground(P, pp.min_altitude)
            np.logical_and.at(good, np.array(pown), okp)
        if good.any():
            # The camera kept on the blade axis along the way: its turn spread over the arc
            # (given all at the last leg it would hold that leg to the gimbal's rate).
            vias = batch[int(np.argmax(good))]
            fw = [_unit(-(v - hc - float((v - hc) @ d) * d)) for v in vias]
            wps += [WP(v, f if pp.aim_ok(f[None])[0] else None, False, comp)
                    for v, f in zip(vias, fw)]
            return
    vias = connect(site, p, q, pp.leg_required, hints=[_unit(p - hc - sp * d)],
                   ground=pp.min_altitude)
    if vias is None:
        raise _Blocked(f"no safe way from {np.round(p, 1).tolist()} to {np.round(q, 1).tolist()} "
                       f"around {turbine.id} blade{k + 1}")
    wps += [WP(v, None, False, comp) for v in vias]


class _Blocked(Exception):
    """Raised inside the planner; mission.py turns it into a PlanError naming the component."""


# ---- nacelle and tower (fixed) ------------------------------------------------------------------------
def _filter_stations(site: Site, pp: PassParams, pos: np.ndarray,
                     fwd: np.ndarray | None = None) -> np.ndarray:
    """Stations that keep the clearance and the minimum altitude (and, with ``fwd``, whose
    viewing direction the gimbal reaches)."""
    ok = site.clearance(pos, pp.required) >= pp.required
    ok &= site.above_ground(pos, pp.min_altitude)
    if fwd is not None:
        ok &= pp.aim_ok(fwd)
    return ok


def _back_off(site: Site, pp: PassParams, pos: np.ndarray, fwd: np.ndarray) -> np.ndarray:
    """Stations too close to a part moved back along their line of sight, up to the farthest
    standoff that still gives the GSD (``pp.max_standoff``), in 0.5 m steps: a tower wider
    than the nacelle, or a large hub, reaches into the nacelle's nominal standoff."""
    pos = np.array(pos, float)
    bad = site.clearance(pos, pp.required) < pp.required
    extra = 0.5
    while bad.any() and pp.standoff + extra <= pp.max_standoff:
        trial = pos[bad] - fwd[bad] * extra
        ok = site.clearance(trial, pp.required) >= pp.required
        idx = np.nonzero(bad)[0][ok]
        pos[idx] = trial[ok]
        bad[idx] = False
        extra += 0.5
    return pos


FACE_ROW_LAP = 0.3  # least overlap between neighbouring rows of photos on a nacelle face
FACE_BORDER = 0.05  # frame margin a face's rows keep (coverage itself ignores 0.02)
FACE_TURN_DEG = (15.0, 30.0, 45.0)  # a blocked face station's oblique alternatives (incidence)
FACE_STOP_M = 3.0  # a stop costs about v / a = 1.1 s, what a pass takes to fly 3 m
FACE_AIM_MAX_DEG = 5.0  # a view aimed this far off the face's normal loses under 0.1 m of its
# frame's near edge at a 10 m standoff, inside FACE_BORDER


def _face_rows(center: np.ndarray, normal: np.ndarray, u: np.ndarray, v: np.ndarray,
               half_u: float, half_v: float, pp: PassParams,
               tilt: np.ndarray | None = None, aimed: bool = False
               ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Rows of photo stations (positions, viewing directions) imaging a flat rectangular face
    head-on from ``pp.standoff``: rows along u, as many across v as the frame's extent across
    them needs (FACE_ROW_LAP overlap between rows), stations along each row from the frame's
    extent along it at ``pp.overlap``. Which frame side lies along u is the camera's as a route
    records it (compass yaw, no roll); ``tilt``: a horizontal face's view tipped 1 deg towards
    this direction, which fixes that yaw (image rows along u). ``aimed`` (a vertical face two
    rows tall): one line of stations along the face's middle instead, half a row's spacing
    apart, the camera aimed at either row in turn (one more photo than two rows, no corners:
    a stop at each of the rows' ends costs more than the photo); [] where the face needs
    another number of rows or the rows lie more than FACE_AIM_MAX_DEG either side of it."""
    fwd = -normal if tilt is None else _unit(-normal + 0.02 * tilt)
    R = _camera_rotations(fwd[None])[0]
    fw, fh = pp.camera.footprint_m(pp.standoff)
    along, across = (fw, fh) if abs(R[0] @ u) >= abs(R[1] @ u) else (fh, fw)
    use_a, use_c = (1 - 2 * FACE_BORDER) * along, (1 - 2 * FACE_BORDER) * across
    n_v = 1 if 2 * half_v <= use_c else int(math.ceil((2 * half_v - use_c)
                                                        / ((1 - FACE_ROW_LAP) * use_c))) + 1
    n_u = 1 if 2 * half_u <= use_a else int(math.ceil((2 * half_u - use_a)
                                                        / ((1 - pp.overlap) * along))) + 1
    vs = np.linspace(-1, 1, n_v) * max(half_v - use_c / 2, 0.0)
    us = np.linspace(-1, 1, n_u) * max(half_u - use_a / 2, 0.0)
    if aimed:
        if n_v != 2 or n_u < 2 or tilt is not None or \
                abs(vs[0]) > pp.standoff * math.tan(math.radians(FACE_AIM_MAX_DEG)):
            return []
        # rows: vs[1] at the ends and every other station between, vs[0] between them
        step = 0.5 * (us[1] - us[0])
        x = us[0] - step + step * np.arange(2 * n_u + 1)
        dv = np.where(np.arange(len(x)) % 2 == 0, vs[1], vs[0])
        pos = center + x[:, None] * u + pp.standoff * normal
        aim = -pp.standoff * normal + dv[:, None] * v
        return [(pos, aim / np.linalg.norm(aim, axis=1)[:, None])]
    # each station looks at its own point of the face from the standoff (along the normal):
    # set back along the tipped view so its frame is not moved 0.02 x standoff aside
    back = pp.standoff / float(-(fwd @ normal)) * fwd
    rows = []
    for i, dv in enumerate(vs):
        uu = us if i % 2 == 0 else us[::-1]
        pos = center + dv * v + uu[:, None] * u - back
        rows.append((pos, np.tile(fwd, (len(uu), 1))))
    return rows


def _face_tiling(center: np.ndarray, normal: np.ndarray, u: np.ndarray, v: np.ndarray,
                 half_u: float, half_v: float, pp: PassParams,
                 tilt: np.ndarray | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """``_face_rows`` in the layout quickest to fly, then with the fewest photos: rows along u
    or along v, on a vertical face also one line aimed at two rows in turn, and on a horizontal
    face (``tilt`` given) the frame's longer side along either (the camera's yaw). Quickest:
    the shortest path with FACE_STOP_M for each corner the aircraft stops at. A face a little
    taller than the frame, flown in rows along it, takes two rows about a metre apart, each
    row's end a stop; one line aimed at each row in turn flies straight on."""
    options = []
    for a, b, ha, hb in ((u, v, half_u, half_v), (v, u, half_v, half_u)):
        for t, aimed in ([(None, False), (None, True)] if tilt is None else [(tilt, False), (u, False)]):
            rows = _face_rows(center, normal, a, b, ha, hb, pp, t, aimed)
            if not rows:
                continue
            P = np.vstack([r[0] for r in rows])
            length = float(np.linalg.norm(np.diff(P, axis=0), axis=1).sum())
            options.append((length + FACE_STOP_M * int(corners.stops(P)[1:-1].sum()), len(P), rows))
    return min(options, key=lambda o: o[:2])[2]


def _face_turn(site: Site, pp: PassParams, pos: np.ndarray, fwd: np.ndarray,
               dirs: tuple[np.ndarray, ...], bad: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stations ``bad`` (too close to a part: the tower under the nacelle) turned about the face
    point they look at, towards +- each of ``dirs`` by FACE_TURN_DEG, at the standoff or out to
    ``pp.max_standoff``: the least turn that is clear and within the gimbal's reach.
    (positions, directions, still bad)."""
    pos, fwd, bad = pos.copy(), fwd.copy(), bad.copy()
    dist = np.array([pp.standoff, pp.max_standoff])
    for j in np.nonzero(bad)[0]:
        target = pos[j] + pp.standoff * fwd[j]
        W = np.array([math.cos(math.radians(b)) * -fwd[j] + sg * math.sin(math.radians(b)) * d
                      for b in FACE_TURN_DEG for d in dirs for sg in (1.0, -1.0)])
        W = np.repeat(W, len(dist), axis=0)
        D = np.tile(dist, len(W) // len(dist))
        cp, cf = target + D[:, None] * W, -W
        ok = _filter_stations(site, pp, cp, cf)
        if ok.any():
            i = int(np.argmax(ok))
            pos[j], fwd[j], bad[j] = cp[i], cf[i], False
    return pos, fwd, bad


UNDERSIDE_TILT_DEG = (20.0, 30.0, 40.0, 50.0)  # the underside's halves seen from beside the tower


def _underside_rows(site: Site, pp: PassParams, c: np.ndarray, u: np.ndarray, v: np.ndarray,
                    half_u: float, half_v: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """The nacelle's underside as two rows along it, one each side of the tower top, each
    looking up at its own half tilted out by the least of UNDERSIDE_TILT_DEG whose stations all
    keep the clearance (rows straight below would stand over the tower top), its half's far
    edge within the GSD's reach (``pp.reach``) and the incidence limit. [] if none does."""
    rows = []
    for sign in (1.0, -1.0):
        ctr = c + sign * 0.5 * half_v * v
        for b in np.radians(UNDERSIDE_TILT_DEG):
            nrm = math.cos(b) * -Z + math.sin(b) * sign * v
            (pos, fwd), = _face_rows(ctr, nrm, u, v, half_u, 0.5 * half_v, pp, sign * v)
            # the half's far edge, the underside's middle line, abreast of each station
            far = c + ((pos - c) @ u)[:, None] * u
            rel = pos - far
            dist = np.linalg.norm(rel, axis=1)
            inc = np.degrees(np.arccos(np.clip(-rel[:, 2] / dist, -1.0, 1.0)))
            if (dist > pp.reach).any() or (inc > pp.max_incidence_deg - RING_MARGIN_DEG).any():
                break
            if _filter_stations(site, pp, pos, fwd).all():
                rows.append((pos, fwd))
                break
        else:
            return []
        if len(rows) < (1 if sign > 0 else 2):
            return []
    return rows


def nacelle_chunk(turbine: Turbine, site: Site, pp: PassParams,
                  start_near: np.ndarray | None = None) -> Chunk:
    """The nacelle's left side, rear face, right side, top and underside, each in rows of
    photos that cover the face (``_face_rows``), in the order with the shortest joins (and way
    in from ``start_near``). The front face is the hub's: not flown."""
    chunk = Chunk(turbine.id, "nacelle")
    a = turbine.axis
    side = np.cross(Z, a)
    half = np.array([turbine.nacelle_length, turbine.nacelle_width, turbine.nacelle_height]) / 2
    ctr = turbine.nacelle_center
    comp = f"{turbine.id}/nacelle"
    faces = [  # (face centre, outward normal, along, across, half along, half across, tilt)
        (ctr + side * half[1], side, -a, Z, half[0], half[2], None),  # left, front -> rear
        (ctr - a * half[0], -a, side, Z, half[1], half[2], None),  # rear
        (ctr - side * half[1], -side, a, Z, half[0], half[2], None),  # right, rear -> front
        (ctr + Z * half[2], Z, -a, side, half[0], half[1], side),  # top
        # the underside, looking up: stations over the tower top are dropped (too close to it)
        (ctr - Z * half[2], -Z, a, side, half[0], half[1], side)]
    flown: list[tuple[np.ndarray, np.ndarray]] = []
    for i, (c, nrm, u, v, hu, hv, tilt) in enumerate(faces):
        under = i == len(faces) - 1
        # the underside's two oblique rows are flown as two units (the tower top between them)
        units = _underside_rows(site, pp, c, u, v, hu, hv) if under else []
        if not units:
            rows = _face_tiling(c, nrm, u, v, hu, hv, pp, tilt)
            units = [(np.vstack([r[0] for r in rows]), np.vstack([r[1] for r in rows]))]
        for pos, fwd in units:
            pos = _back_off(site, pp, pos, fwd)
            keep = _filter_stations(site, pp, pos, fwd)
            pos, fwd, bad = _face_turn(site, pp, pos, fwd, (u, v), ~keep)
            keep = ~bad
            if under and keep.sum() < 2:  # a lone underside photo: not worth the detour
                chunk.notes.append(f"{comp}: underside: {int(keep.sum())} station(s) clear of the "
                                   "tower top and within the gimbal's reach: not flown")
                continue
            if (~keep).any():
                aimless = int((~pp.aim_ok(fwd)).sum())
                chunk.notes.append(f"{comp}: {int((~keep).sum())} station(s) too close to a part"
                                   + (f" or beyond {pp.gimbal_text()}" if aimless else "")
                                   + ": dropped")
            if keep.any():
                flown.append((pos[keep], fwd[keep]))
    if not flown:
        return chunk
    # The faces in the order and directions with the shortest joins.
    ends = np.array([f[0][x] for f in flown for x in (0, -1)])  # face i: start 2i, end 2i + 1
    E0, E1 = np.repeat(ends, len(ends), axis=0), np.tile(ends, (len(ends), 1))
    L = np.linalg.norm(E1 - E0, axis=1)
    blocked = site.segment_clearance(E0, E1, LEG_STEP, pp.required) < pp.leg_required
    below = (ends[:, 2] < ctr[2] - half[2])[:, None] & (ends[:, 2] < ctr[2] - half[2])[None, :]
    below = below.ravel()
    for j in np.nonzero(blocked)[0]:
        if not below[j] or j // len(ends) // 2 == j % len(ends) // 2:
            # round the nacelle, counted as twice the straight length plus 20 m; only a join
            # under it (the underside's rows, either side of the tower top) is worked out
            L[j] = 2 * L[j] + 20.0
            continue
        vias = connect(site, E0[j], E1[j], pp.leg_required, ground=pp.min_altitude)
        chain = np.vstack([E0[j][None]] + [np.asarray(v)[None] for v in vias or []] + [E1[j][None]])
        L[j] = np.linalg.norm(np.diff(chain, axis=0), axis=1).sum() if vias is not None \
            else 2 * L[j] + 100.0
    cost = L.reshape(len(ends), len(ends))
    first = np.zeros(len(ends)) if start_near is None else \
        np.linalg.norm(ends - np.asarray(start_near, float), axis=1)
    part = turbine.part_names().index("nacelle")
    for i, flip in _unit_order(cost, first):
        pos, fwd = flown[i] if not flip else (flown[i][0][::-1], flown[i][1][::-1])
        # the blur limit from the nearest nacelle surface: an oblique or backed-off station's
        # distance to it differs from the standoff its face was planned at
        near = turbine.clearance_by_part(pos)[:, part]
        append_chain(chunk, site, pp, [WP(p, f, True, comp, standoff=float(d))
                                       for p, f, d in zip(pos, fwd, near)], droppable=True)
    return chunk


def _unit_order(cost: np.ndarray, first: np.ndarray) -> list[tuple[int, int]]:
    """The order and directions (unit, flipped) of units flown end to end with the least total
    join ``cost`` (node 2i: unit i's first station, 2i + 1: its last; a flipped unit is flown
    from its last) plus ``first`` (the way in to the first node): exact, by dynamic programming
    over subsets (Held-Karp)."""
    n = len(cost) // 2
    full = (1 << n) - 1
    best: dict[tuple[int, int], tuple[float, tuple[int, int] | None]] = {}
    for i in range(n):
        for f in (0, 1):  # (mask, node the drone stands at) -> (cost, previous state)
            key = (1 << i, 2 * i + 1 - f)
            c = float(first[2 * i + f])
            if key not in best or c < best[key][0]:
                best[key] = (c, None)
    for mask in range(1, full + 1):
        for end in range(2 * n):
            if (mask, end) not in best:
                continue
            c0 = best[(mask, end)][0]
            for j in range(n):
                if mask >> j & 1:
                    continue
                for g in (0, 1):
                    key = (mask | 1 << j, 2 * j + 1 - g)
                    c = c0 + float(cost[end, 2 * j + g])
                    if key not in best or c < best[key][0] - 1e-9:
                        best[key] = (c, (mask, end))
    state = min(((full, e) for e in range(2 * n) if (full, e) in best), key=lambda k: best[k][0])
    out = []
    while state is not None:
        mask, end = state
        out.append((end // 2, 1 - end % 2))  # ending at its first station: flown flipped
        state = best[state][1]
    return out[::-1]


TOWER_PHASES = 6  # column phases tried (fractions of the angle between columns)
TOWER_MAX_COLUMNS = 16  # mission.tower_columns' own upper bound
TOWER_GSD_TOLERANCE = 1.05 / 1.02  # pp.reach (the GSD + 2 %) to coverage's own GSD + 5 %
TOWER_FOOT_DEG = 30.0  # each column's lowest view looks down this far, to the tower's foot
FOOT_VIA_M = 1.0  # a foot view that ends or starts the tower's flight is reached through a via


def tower_columns(radius: float, pp: PassParams) -> int:
    """The fewest level columns round a tower section of ``radius`` (the base: the widest) whose
    views, each aimed at the axis from ``pp.standoff``, see its whole girth by coverage's own
    test (``imaged``) with the incidence limit less RING_MARGIN_DEG, the frame less FACE_BORDER
    and the distance coverage counts (the GSD's 5 %: the girth's seams are seen by two columns).
    From close up a view sees less of the girth (perspective, distance): 5 columns at 5.1 m from
    a 2.6 m radius, 4 from 10.8 m; never fewer than 4 (a view sees at most the incidence limit
    either side), never more than TOWER_MAX_COLUMNS."""
    phi = np.radians(np.arange(0.0, 90.0, 0.25))  # round the section from the view's axis
    n = np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], axis=1)
    cam = np.array([radius + pp.standoff, 0.0, 0.0])
    R = _camera_rotations(np.array([[-1.0, 0.0, 0.0]]))[0]
    reach = (pp.reach if pp.reach > 0 else pp.max_standoff) * TOWER_GSD_TOLERANCE
    ok = imaged(radius * n - cam, n, R, pp.camera, reach,
                pp.max_incidence_deg - RING_MARGIN_DEG, FACE_BORDER)
    first_miss = int(np.argmin(ok)) if not ok.all() else len(phi)
    seen = float(phi[first_miss - 1]) if first_miss > 0 else 0.0  # the last angle it sees
    if seen <= 0.0:  # a frame too narrow to see the tower at all: the most the YAML allows
        return TOWER_MAX_COLUMNS
    return min(TOWER_MAX_COLUMNS, max(4, int(math.ceil(math.pi / seen - 1e-9))))


def tower_standoff(radius: float, pp: PassParams, columns: int) -> float:
    """The farthest standoff, from ``pp.standoff`` out to ``pp.max_standoff`` (the GSD's
    distance) in 0.25 m steps, from which ``columns`` columns still see the girth of a section
    of ``radius`` by ``tower_columns``' own test: a coarser GSD on the column's line, still within
    the target where the girth meets the next column's view, is a looser blur limit."""
    best = pp.standoff
    for e in np.arange(pp.standoff + 0.25, pp.max_standoff + 1e-9, 0.25):
        if tower_columns(radius, replace(pp, standoff=float(e))) > columns:
            break
        best = float(e)
    return best


def tower_chunk(turbine: Turbine, site: Site, pp: PassParams, columns: int = 0,
                start_near: np.ndarray | None = None,
                climb_toward: np.ndarray | None = None,
                end_toward: np.ndarray | None = None) -> list[Chunk]:
    """The tower in vertical columns of photos, flown top -> bottom, bottom -> top in turn from
    the column nearest ``start_near``, joined by level arcs round the tower.

    One chunk, or with ``climb_toward`` and an even number of columns (which, flown from the
    top, would end at the top) two: the column nearest that point flown bottom -> top, the climb
    to the rotor made a photo pass, and the others from a column next to it, top -> bottom
    first, so the last one ends at the bottom, by the landing. Round the tower either way: the
    one whose way in from ``start_near`` and way out to ``end_toward`` (the landing) are
    shortest as flown (a way out behind the tower is a detour round it)."""
    rb, H = turbine.tower_base_radius, turbine.tower_height
    if columns <= 0:
        columns = tower_columns(rb, pp)
    pp = replace(pp, standoff=tower_standoff(rb, pp, columns))
    fw, fh = pp.camera.footprint_m(pp.standoff)
    split = climb_toward is not None and columns % 2 == 0
    spacing = max(0.25, (1 - pp.overlap) * fh)
    z_lo = pp.min_altitude + 0.5
    z_hi = H - 0.5 * spacing
    nz = max(2, int(math.ceil((z_hi - z_lo) / spacing)) + 1)
    zs = np.linspace(z_hi, z_lo, nz)  # top -> bottom
    yaw0 = math.atan2(turbine.axis[1], turbine.axis[0])
    toward = climb_toward if split else start_near
    if toward is not None:  # begin with the column nearest that point
        v = np.asarray(toward) - turbine.base_xyz
        yaw0 = math.atan2(v[1], v[0])
    r = turbine.tower_radius_at(zs)

    def column(ang: float) -> tuple[np.ndarray, np.ndarray]:
        """A column's stations top -> bottom; the lowest looks down TOWER_FOOT_DEG from the
        least standoff at the least altitude, to reach the tower's foot."""
        u = np.array([math.cos(ang), math.sin(ang), 0.0])
        pos = turbine.base_xyz + (r + pp.standoff)[:, None] * u + zs[:, None] * Z
        fwd = np.tile(-u, (nz, 1))
        zf = pp.min_altitude + 0.1
        foot = turbine.base_xyz + (turbine.tower_radius_at(zf) + pp.min_standoff) * u + zf * Z
        look = math.radians(TOWER_FOOT_DEG)
        return (np.vstack([pos, foot]),
                np.vstack([fwd, -math.cos(look) * u - math.sin(look) * Z]))

    # The columns' phase: of TOWER_PHASES within a column's angle (nearest the start first), the
    # one that leaves out the fewest stations (a blade down in front of the tower) and whose
    # first station the previous point reaches (the climbing column's: any, it is flown first).
    phases = [yaw0 + 2 * math.pi / columns * f for f in
              sorted(np.arange(TOWER_PHASES) / TOWER_PHASES, key=lambda f: min(f, 1 - f))]
    drops, firsts = [], []
    for ph in phases:
        P = np.vstack([column(ph + 2 * math.pi * j / columns)[0] for j in range(columns)])
        ok = _filter_stations(site, pp, P)
        drops.append(int((~ok).sum()))
        firsts.append(P[int(np.argmax(ok))] if ok.any() else None)
    for i in sorted(range(len(phases)), key=lambda i: (drops[i], i)):
        if split or start_near is None or (firsts[i] is not None and connect(
                site, np.asarray(start_near, float), firsts[i], pp.leg_required,
                ground=pp.min_altitude) is not None):
            yaw0 = phases[i]
            break
    else:
        yaw0 = phases[0]
    comp = f"{turbine.id}/tower"

    def flown(step: int) -> list[int]:  # the climbing column first, if any, then round the tower
        return [0] + [(step * k) % columns for k in range(1, columns)] if split else \
            [(step * k) % columns for k in range(columns)]

    def ends(order: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """The first station after the climb and the last, as ``order`` flies them."""
        out = []
        for n in ((1 if split else 0), len(order) - 1):
            pos = column(yaw0 + 2 * math.pi * order[n] / columns)[0]
            out.append(pos[::-1] if n % 2 == (0 if split else 1) else pos)
        return out[0][0], out[1][-1]

    order = flown(1)
    if columns > 2:
        # the two directions' ways in and home; an end they share costs both the same
        (f0, l0), (f1, l1) = ends(flown(1)), ends(flown(-1))
        cost = np.zeros(2)
        if start_near is not None and not np.allclose(f0, f1):
            a = np.asarray(start_near, float)
            cost += [_way_length(site, pp, a, f0), _way_length(site, pp, a, f1)]
        if end_toward is not None and not np.allclose(l0, l1):
            b = np.asarray(end_toward, float)
            cost += [_way_length(site, pp, l0, b), _way_length(site, pp, l1, b)]
        if cost[1] < cost[0] - 1e-9:
            order = flown(-1)
    climb, chunk = Chunk(turbine.id, "tower"), Chunk(turbine.id, "tower")
    for n, j in enumerate(order):
        target = climb if split and n == 0 else chunk
        ang = yaw0 + 2 * math.pi * j / columns
        pos, fwd = column(ang)
        if n % 2 == (0 if split else 1):  # bottom -> top: the climb, and every other column
            pos, fwd = pos[::-1], fwd[::-1]
        keep = _filter_stations(site, pp, pos, fwd)
        if (~keep).any():
            target.notes.append(f"{comp}: column {n + 1}: {int((~keep).sum())} station(s) too "
                                "close to a part: dropped")
        new: list[WP] = []
        first = pos[keep][0] if keep.any() else None
        chord_clear = first is not None and target.wps and site.segment_clearance(
            target.wps[-1].pos[None], first[None], LEG_STEP, pp.required)[0] >= pp.leg_required
        if target.wps and keep.any() and not chord_clear:
            # round the tower at constant height to the next column where the straight leg
            # (a tenth shorter) would cut in
            prev = target.wps[-1].pos
            a0 = math.atan2(prev[1] - turbine.base_xyz[1], prev[0] - turbine.base_xyz[0])
            da = (ang - a0 + math.pi) % (2 * math.pi) - math.pi
            steps = max(1, int(math.ceil(abs(da) / math.radians(ARC_STEP_DEG))))
            rr = float(np.hypot(*(prev[:2] - turbine.base_xyz[:2])))
            angs = a0 + da * np.arange(1, steps) / steps
            arc = turbine.base_xyz + np.column_stack([rr * np.cos(angs), rr * np.sin(angs),
                                                      np.full(len(angs), prev[2]
                                                              - turbine.base_xyz[2])])
            # the camera kept on the tower's axis: its turn spread over the arc
            look = -np.column_stack([np.cos(angs), np.sin(angs), np.zeros(len(angs))])
            if len(arc):
                ok = _filter_stations(site, pp, arc)  # clear of every part and the ground
                arc, look = arc[ok], look[ok]
            new += [WP(v, f, False, comp) for v, f in zip(arc, look)]
        # the blur limit from the nearest tower surface (the foot view's is much nearer)
        near = turbine.clearance_by_part(pos[keep])[:, turbine.part_names().index("tower")]
        new += [WP(p, f, True, comp, standoff=float(d))
                for p, f, d in zip(pos[keep], fwd[keep], near)]
        append_chain(target, site, pp, new, droppable=True)
    # A foot view, a few metres from the tower, is passed slowly (its blur limit): where it
    # ends or starts a chunk (the landing's transit, the launch's) a via a metre out from it
    # takes that slow leg instead of the column's 7 m leg to its lowest station.
    for ch, at in ((climb, 0), (chunk, -1)):
        if ch.wps and ch.wps[at].photo and ch.wps[at].standoff is not None \
                and ch.wps[at].standoff < pp.standoff - 1.0:
            w = ch.wps[at]
            out = np.r_[w.pos[:2] - turbine.base_xyz[:2], 0.0]
            via = w.pos + _unit(out) * FOOT_VIA_M
            if _filter_stations(site, pp, via[None])[0]:
                ch.wps.insert(0 if at == 0 else len(ch.wps), WP(via, None, False, comp))
    return [climb, chunk] if split else [chunk]


def append_chain(chunk: Chunk, site: Site, pp: PassParams, new: list[WP],
                 droppable: bool = False, blade: tuple[Turbine, int] | None = None) -> None:
    """Append waypoints in order; legs that do not keep the clearance get via points (with
    ``blade`` = (turbine, index), first a way round that blade, ``_join``). A station no safe
    detour reaches is an error, or with ``droppable`` (tower, nacelle) left out."""
    if not new:
        return
    pts = np.array(([chunk.wps[-1].pos] if chunk.wps else []) + [w.pos for w in new])
    bad = np.zeros(len(new), bool)
    if len(pts) > 1:
        lb = site.segment_clearance(pts[:-1], pts[1:], LEG_STEP, pp.required)
        bad[len(new) - len(lb):] = (lb < pp.leg_required) | \
            ~site.legs_above_ground(pts[:-1], pts[1:], pp.min_altitude)
    dropped = False
    for w, b in zip(new, bad):
        if dropped and chunk.wps:  # the previous station was left out: check this leg afresh
            prev = chunk.wps[-1].pos
            b = site.segment_clearance(prev[None], w.pos[None], LEG_STEP, pp.required)[0] \
                < pp.leg_required or not site.legs_above_ground(prev[None], w.pos[None],
                                                                 pp.min_altitude)[0]
        dropped = False
        if b:
            p = chunk.wps[-1].pos
            if blade is not None:
                n0 = len(chunk.wps)
                try:  # round the blade first; _join falls back on connect itself
                    _join(chunk.wps, w.pos, w.fwd, blade[0], blade[1], site, pp, w.component)
                    vias = [v.pos for v in chunk.wps[n0:]]
                    del chunk.wps[n0:]
                except _Blocked:
                    vias = None
            else:
                vias = connect(site, p, w.pos, pp.leg_required, ground=pp.min_altitude)
            if vias is None:
                if droppable:
                    near = site.nearest_part(0.5 * (p + w.pos))[0]  # what the leg runs into
                    chunk.notes.append(f"{w.component}: a station no safe path reaches "
                                       f"(blocked by {near}): dropped")
                    dropped = True
                    continue
                raise _Blocked(f"no safe way between two {w.component} stations")
            chunk.wps += [WP(v, None, False, w.component) for v in vias]
        chunk.wps.append(w)


# ---- gap filling ----------------------------------------------------------------------------------
GAP_MAX_VIEWS = 12  # per blade: a handful of extra photos, never a second survey
GAP_CANDIDATES = 12000  # candidate viewpoints per blade at most (seeds x directions x distances)
# Candidate grids, finest first: (off-normal step, step around the normal (deg), distances).
GAP_GRIDS = ((3.0, 10.0, 8), (4.0, 15.0, 6), (6.0, 20.0, 6))
GAP_BORDER = 0.05  # frame margin the candidates keep (coverage itself uses 0.02)
# Last resort, one sample at a time: where the root's trailing edge meets the nacelle the views
# that keep the clearance are a shell a few centimetres thick at high incidence, which the
# grids above step over.
GAP_FINE_GRID = ((2.0, 6.0, 12),)
GAP_FINE_CANDIDATES = 24000
GAP_FINE_SAMPLES = 8  # at most this many samples searched one by one, per blade
# ... and in the rounds for a side still short, where each view decides between a plan and a
# refusal (searched on the ray-walked clearance, a sample costs a few milliseconds)
GAP_ROUND_FINE_SAMPLES = 24
GAP_SPAN_BINS = 8  # what the grids leave is searched again in this many stretches of the span
GAP_BIN_AREA = 0.05  # m^2: a stretch missing less is not worth a view
GAP_POINTS = 150  # missed samples of a blade the search is asked about at most


@functools.lru_cache(maxsize=32)
def _cone_dirs(ring: float, around: float, lim: float) -> tuple[np.ndarray, np.ndarray]:
    """The gap search's viewing directions round a sample's normal, in degrees: the normal, then
    rings every ``ring`` deg off it below ``lim``, each every ``around`` deg round it (the same
    grids are asked for again and again: made once)."""
    dirs = [(0.0, 0.0)] + [(th, ph) for th in np.arange(ring, lim, ring)
                            for ph in np.arange(0.0, 360.0, around)]
    th, ph = np.array([d[0] for d in dirs]), np.array([d[1] for d in dirs])
    th.flags.writeable = ph.flags.writeable = False
    return th, ph


def _cross_z(v: np.ndarray) -> np.ndarray:
    """``np.cross(v, Z)`` for rows of v, without its per-call overhead: (v_y, -v_x, 0)."""
    return np.stack([v[:, 1], -v[:, 0], np.zeros(len(v))], axis=1)


def _clear_along_rays(site: Site, C: np.ndarray, R: np.ndarray, pp: PassParams) -> np.ndarray:
    """(rays, dists) bool: which candidates C (rays, dists, 3), at distances R along each ray,
    are above the minimum altitude and keep ``pp.required`` from every part.

    Most candidates of a hard gap are inside the required distance (the clear ones are a thin
    shell), and the clearance is a distance: where a candidate reads f < required, every point
    within required - f of it reads below required too (a distance changes by at most the step).
    So each ray is walked outwards and the candidates that close to a failed one are not
    measured: the same answer for a fraction of the queries."""
    ok = site.above_ground(C.reshape(-1, 3), pp.min_altitude).reshape(C.shape[:2])
    clear = np.zeros(ok.shape, bool)
    known_inside = np.full(len(C), -np.inf)  # along each ray, up to here is inside (exclusive)
    for j in range(len(R)):
        todo = np.nonzero(ok[:, j] & (R[j] >= known_inside))[0]
        if len(todo) == 0:
            continue
        f = site.clearance(C[todo, j], pp.required)
        good = f >= pp.required
        clear[todo, j] = good
        short = ~good & np.isfinite(f)
        # 0.999 and 1 mm: rounding never lets a skip reach a point that could be clear.
        known_inside[todo[short]] = R[j] + 0.999 * (pp.required - f[short]) - 1e-3
    return clear


def gap_views(turbine: Turbine, pts: np.ndarray, nrm: np.ndarray, area: np.ndarray,
              site: Site, pp: PassParams, max_incidence_deg: float, max_distance: float,
              max_views: int = GAP_MAX_VIEWS, grids=GAP_GRIDS, budget: int = GAP_CANDIDATES
              ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Extra photo stations for one blade's surface samples (pts, nrm, area) that the passes miss.

    Where the passes cannot go (the root's trailing edge faces the hub and nacelle; a blade
    pointing down has its trailing edge facing the tower), a view from further along the span, or
    from aside, at an angle up to the incidence limit, may still see the sample while keeping
    the clearance. Candidates: from each of a few missed samples, directions in a cone around its
    normal, at distances from the smallest standoff to ``max_distance`` (the caller's GSD limit),
    each aimed at its sample; only those that keep ``pp.required`` from every part and the
    minimum altitude. Greedy set cover by missed area, with margins (incidence 1 deg inside the
    limit, frame border 5 %); a view's claim counts only samples it has a line of sight to
    (``Turbine.line_of_sight``, the coverage measure's own test). Returns [(position, viewing
    direction, covered mask)].
    """
    if len(pts) == 0:
        return []
    lim = max_incidence_deg - 1.0
    # The views that clear are a thin shell (clearance vs GSD): the fewer samples are missed,
    # the finer the grid each is searched with, within one budget of candidates.
    for ring, around, n_dist in grids:
        th_deg, ph_deg = _cone_dirs(ring, around, lim)
        if len(pts) * len(th_deg) * n_dist <= budget:
            break
    R = np.linspace(pp.min_standoff, max_distance, n_dist)
    n_seeds = max(1, min(len(pts), budget // (len(th_deg) * len(R))))
    seeds = np.unique(np.linspace(0, len(pts) - 1, n_seeds).round().astype(int))
    S, N = pts[seeds], nrm[seeds]
    a = _cross_z(N)
    flat = np.linalg.norm(a, axis=1) < 1e-6
    a[flat] = np.cross(N[flat], [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(N, a)
    th = np.radians(th_deg)[None, :, None]
    ph = np.radians(ph_deg)[None, :, None]
    U = np.cos(th) * N[:, None] + np.sin(th) * (np.cos(ph) * a[:, None] + np.sin(ph) * b[:, None])
    C = S[:, None, None, :] + R[None, None, :, None] * U[:, :, None, :]  # (seed, dir, dist, 3)
    target = np.broadcast_to(S[:, None, None, :], C.shape).reshape(-1, 3)
    ok = _clear_along_rays(site, C.reshape(-1, len(R), 3), R, pp).reshape(-1)
    C, target = C.reshape(-1, 3)[ok], target[ok]
    if len(C) == 0:
        return []
    F = target - C
    F /= np.linalg.norm(F, axis=1, keepdims=True)
    right = _cross_z(F)
    rn = np.linalg.norm(right, axis=1, keepdims=True)
    keep = rn[:, 0] > 1e-3  # straight up or down: the yaw is ill-defined, leave those out
    keep &= pp.aim_ok(F)
    C, F, right, rn = C[keep], F[keep], right[keep], rn[keep]
    if len(C) == 0:
        return []
    right /= rn
    down = np.cross(F, right)
    # Which missed samples each candidate images (the coverage rules, with margins).
    R = np.stack([right, down, F], axis=1)[:, None]  # (cand, 1, 3, 3) world->camera
    sees = np.zeros((len(C), len(pts)), bool)
    for c0 in range(0, len(C), 1024):
        sl = slice(c0, c0 + 1024)
        sees[sl] = imaged(pts[None, :, :] - C[sl, None, :], nrm, R[sl], pp.camera, max_distance,
                          lim, GAP_BORDER)
    left = np.ones(len(pts), bool)
    views: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    checked = np.zeros(len(C), bool)
    while len(views) < max_views and left.any():
        gain = (sees & left) @ area
        i = int(np.argmax(gain))
        if gain[i] <= 1e-9:
            break
        if not checked[i]:  # line of sight to each claimed sample, once per candidate (lazy)
            claim = np.nonzero(sees[i])[0]
            clear = turbine.line_of_sight(np.tile(C[i], (len(claim), 1)), pts[claim])
            sees[i, claim[~clear]] = False
            checked[i] = True
            continue
        views.append((C[i], F[i], sees[i] & left))
        left &= ~sees[i]
    return views


def insert_views(chunk: Chunk, views: list[tuple[np.ndarray, np.ndarray, str]], site: Site,
                 pp: PassParams) -> int:
    """Insert photo stations into a chunk where they lengthen it least (cheapest insertion between
    two consecutive waypoints whose legs to the station keep the clearance; else with
    ``connect`` detours). Returns how many could not be reached safely (left out)."""
    missed = 0
    for pos, fwd, comp in views:
        P = np.array([w.pos for w in chunk.wps])
        if len(P) < 2:
            missed += 1
            continue
        cost = (np.linalg.norm(P[:-1] - pos, axis=1) + np.linalg.norm(P[1:] - pos, axis=1)
                - np.linalg.norm(P[1:] - P[:-1], axis=1))
        order = np.argsort(cost)[:8]
        lb = site.segment_clearance(np.r_[P[order], np.tile(pos, (len(order), 1))],
                                    np.r_[np.tile(pos, (len(order), 1)), P[order + 1]],
                                    LEG_STEP, pp.required)
        good = (lb[:len(order)] >= pp.leg_required) & (lb[len(order):] >= pp.leg_required)
        # the blur limit from the nearest surface (a view may stand well inside the standoff)
        new = WP(pos, fwd, True, comp, standoff=float(site.clearance(pos[None])[0]))
        if good.any():
            i = int(order[np.argmax(good)])
            chunk.wps.insert(i + 1, new)
            continue
        i = int(order[0])
        v1 = connect(site, P[i], pos, pp.leg_required, ground=pp.min_altitude)
        v2 = None if v1 is None else connect(site, pos, P[i + 1], pp.leg_required,
                                             ground=pp.min_altitude)
        if v2 is None:
            missed += 1
            continue
        chunk.wps[i + 1:i + 1] = ([WP(v, None, False, comp) for v in v1] + [new]
                                  + [WP(v, None, False, comp) for v in v2])
    return missed


def gap_plan(turbine: Turbine, samples: SurfaceSamples, covered: np.ndarray, site: Site,
             pp: PassParams, max_incidence_deg: float, max_distance: float,
             blades: set[int] | dict[int, set[str]] | None = None,
             fine_samples: int = GAP_FINE_SAMPLES
             ) -> tuple[dict[int, list[tuple[np.ndarray, np.ndarray, str]]], np.ndarray]:
    """``gap_views`` for each blade (all, or those in ``blades``; a dict: only its sides named
    there) over its samples that
    ``covered`` misses (``samples``: the turbine's blade ``SurfaceSamples``); what the grids leave,
    up to ``fine_samples`` samples a blade, is searched one sample at a time. Returns
    {blade index: [(position, viewing direction, component)]} and ``covered`` with what the views
    add (predicted with the margins of ``gap_views``)."""
    covered = covered.copy()
    out: dict[int, list[tuple[np.ndarray, np.ndarray, str]]] = {}
    for k in range(turbine.n_blades):
        mine = (samples.blade == k) & ~covered
        if isinstance(blades, dict) and k in blades:
            mine &= np.isin(samples.side, [BLADE_SIDES.index(x) for x in blades[k]])
        idx = np.nonzero(mine)[0]
        if (blades is not None and k not in blades) or len(idx) == 0:
            continue
        out[k] = []
        # The search's cost grows with the samples it is asked about: of many, an even spread
        # along the span stands for the rest (each for its share of the area); what the views
        # found see of the rest is marked afterwards.
        everything = idx
        if len(idx) > GAP_POINTS:
            idx = idx[np.argsort(samples.span[idx], kind="stable")]
            idx = np.unique(idx[np.linspace(0, len(idx) - 1, GAP_POINTS).round().astype(int)])
        # A second round searches what the first left, on the finer grid fewer samples allow.
        for _ in range(2):
            views = gap_views(turbine, samples.points[idx], samples.normals[idx],
                              samples.area[idx], site, pp, max_incidence_deg, max_distance,
                              GAP_MAX_VIEWS - len(out[k]))
            for pos, fwd, got in views:
                side_area = np.bincount(samples.side[idx][got], samples.area[idx][got],
                                        len(BLADE_SIDES))
                side = BLADE_SIDES[int(np.argmax(side_area))]
                out[k].append((pos, fwd, f"{turbine.id}/blade{k + 1}/{side}"))
                covered[idx[got]] = True
            idx = idx[~covered[idx]]
            if not views or len(idx) == 0 or len(out[k]) >= GAP_MAX_VIEWS:
                break
        # A strip along the span (a thin edge seen only near the incidence limit) needs a view
        # every few metres, which a search over all it misses steps over: what is left, span
        # bin by span bin, each on the finer grid its fewer samples allow.
        if len(idx) > GAP_FINE_SAMPLES:
            bins = np.minimum((samples.span[idx] * GAP_SPAN_BINS).astype(int), GAP_SPAN_BINS - 1)
            for b in np.unique(bins):
                sel = idx[(bins == b) & ~covered[idx]]
                if samples.area[sel].sum() < GAP_BIN_AREA or len(out[k]) >= GAP_MAX_VIEWS:
                    continue
                for pos, fwd, got in gap_views(turbine, samples.points[sel], samples.normals[sel],
                                               samples.area[sel], site, pp, max_incidence_deg,
                                               max_distance, 1,
                                               budget=GAP_CANDIDATES // GAP_SPAN_BINS * 2):
                    side_area = np.bincount(samples.side[sel][got], samples.area[sel][got],
                                            len(BLADE_SIDES))
                    out[k].append((pos, fwd, f"{turbine.id}/blade{k + 1}/"
                                   f"{BLADE_SIDES[int(np.argmax(side_area))]}"))
                    covered[sel[got]] = True
            idx = idx[~covered[idx]]
        # Then what is left, largest first, one sample at a time on the fine grid.
        for i in idx[np.argsort(-samples.area[idx], kind="stable")][:fine_samples]:
            if covered[i] or len(out[k]) >= GAP_MAX_VIEWS:
                continue
            views = gap_views(turbine, samples.points[[i]], samples.normals[[i]],
                              samples.area[[i]], site, pp, max_incidence_deg, max_distance, 1,
                              GAP_FINE_GRID, GAP_FINE_CANDIDATES)
            for pos, fwd, _ in views:
                side = BLADE_SIDES[int(samples.side[i])]
                out[k].append((pos, fwd, f"{turbine.id}/blade{k + 1}/{side}"))
                covered[i] = True
        rest = everything[~covered[everything]]
        for pos, fwd, _ in out[k]:
            if not len(rest):
                break
            right = np.cross(fwd, Z)
            right /= max(float(np.linalg.norm(right)), 1e-9)
            R = np.stack([right, np.cross(fwd, right), fwd])
            seen = imaged(samples.points[rest] - pos, samples.normals[rest], R, pp.camera,
                          max_distance, max_incidence_deg - 1.0, GAP_BORDER)
            seen[seen] = turbine.line_of_sight(np.tile(pos, (int(seen.sum()), 1)),
                                               samples.points[rest[seen]])
            covered[rest[seen]] = True
            rest = rest[~seen]
    return out, covered


def add_gap_views(chunks: list[Chunk], views: dict[int, list[tuple[np.ndarray, np.ndarray, str]]],
                  site: Site, pp: PassParams) -> None:
    """Fly each blade's gap views within that blade's own trajectory (``insert_views``)."""
    for ch in chunks:
        if not ch.name.startswith("blade") or not views.get(int(ch.name[5:]) - 1):
            continue
        vs = views[int(ch.name[5:]) - 1]
        lost = insert_views(ch, vs, site, pp)
        ch.notes.append(f"{ch.turbine}/{ch.name}: {len(vs) - lost} extra view(s) of surface the "
                        "passes miss" + (f"; {lost} no safe path reaches: dropped" if lost else ""))


# ---- rounding the corners ---------------------------------------------------------------------
ARC_PHOTO_SHIFT = 0.15  # a corner's photo moves onto its arc by at most this much of its
# standoff: it sees the surface from within 9 deg of where it was planned (1.6 m at the default
# camera's 10.8 m; a 16 mm lens's 5.1 m leaves no arc fast enough: its photo corners stop)


def yaw_pitch(fwd: np.ndarray) -> tuple[float, float]:
    """A viewing direction as the route records it: compass yaw (0-360 deg, 0 = north) and
    elevation (deg, positive up); ``Camera.rotation_from_yaw_pitch`` is its inverse."""
    f = _unit(fwd)
    yaw = math.degrees(math.atan2(f[0], f[1])) % 360.0
    pitch = math.degrees(math.asin(max(-1.0, min(1.0, float(f[2])))))
    return yaw, pitch


def round_corners(chunk: Chunk, site: Site, leg_required: float, min_altitude: float,
                  move_photos: bool = True) -> Chunk:
    """``chunk`` with its corners of PASS_TURN_DEG to ROUND_MAX_DEG (``wtcli.plan.corners``)
    replaced by ``corners.arc``s of radius ARC_RADIUS_M or as much as fits: the arc may start
    (and end) at the waypoint beside the corner, else leaves a leg of at least ARC_MIN_LEG_M to
    it, and takes at most the first half of a leg to another corner. Every new leg keeps
    ``leg_required`` from every part and every arc waypoint ``min_altitude``, and a waypoint
    flown through beside an arc stays so; else a smaller arc (x 0.75, down to
    ARC_MIN_RADIUS_M), else the corner stays a stop. A photo at a corner is taken at the arc's
    waypoint nearest it, at most ARC_PHOTO_SHIFT of its standoff away, aimed as before, its
    ``standoff`` (the blur limit) a lower bound of its new distance to the surface: the planned
    one less the shift, or the clearance there if nearer than planned. With ``move_photos``
    False a photo corner stays a stop. The camera turns evenly along the path between the aimed
    waypoints either side of an arc. The chunk's first and last waypoints stay (where it meets
    its neighbours)."""
    through, sharpest = corners.PASS_TURN_DEG, corners.ROUND_MAX_DEG
    min_leg, min_r = corners.ARC_MIN_LEG_M, corners.ARC_MIN_RADIUS_M
    wps = chunk.wps
    if len(wps) < 3:
        return chunk
    P = np.array([w.pos for w in wps])
    turn = corners.turn_angles(P)
    cand = {i for i in range(1, len(P) - 1) if through < turn[i] <= sharpest
            and (move_photos or not wps[i].photo)}
    if not cand:
        return chunk
    out: list[WP] = [wps[0]]
    made: set[int] = set()  # indices in ``out`` of the arcs' new waypoints

    def kept_bend(before: np.ndarray, at: np.ndarray, after: np.ndarray, was: float) -> bool:
        """A waypoint beside an arc stays flown through if it was."""
        return was > through or corners.turn_angles(np.array([before, at, after]))[1] <= through

    for i in range(1, len(P) - 1):
        w = wps[i]
        if i not in cand:
            out.append(w)
            continue
        a, c, b = out[-1].pos, P[i], P[i + 1]
        la, lb = float(np.linalg.norm(c - a)), float(np.linalg.norm(b - c))
        tan = math.tan(math.radians(turn[i]) / 2)
        # A tangent point lands on the waypoint beside the corner (the arc starts there) or
        # leaves at least min_leg to it; on a leg to a corner still to be rounded, in its
        # first half less that.
        share = i + 1 in cand
        t_b = lb / 2 - min_leg / 2 if share else lb
        radii = [min(corners.ARC_RADIUS_M, min(la, t_b) / tan)]
        r = min(corners.ARC_RADIUS_M, min(la - min_leg, t_b if share else lb - min_leg) / tan)
        while r >= min_r:
            radii.append(r)
            r *= 0.75
        pts = None
        for r in radii:
            q = corners.arc(a, c, b, r) if r >= min_r else None
            if q is None:
                continue
            t = r * tan
            on_a, on_b = t >= la - 1e-6, not share and t >= lb - 1e-6
            if (not on_a and la - t < min_leg - 1e-9) or \
                    (not share and not on_b and lb - t < min_leg - 1e-9):
                continue
            q = q[1 if on_a else 0:len(q) - 1 if on_b else len(q)]
            chain = np.vstack([a, q, b])
            if not ((site.segment_clearance(chain[:-1], chain[1:], LEG_STEP,
                                            leg_required + LEG_STEP) >= leg_required).all()
                    and site.above_ground(q, min_altitude).all()):
                continue
            if on_a and len(out) > 1 and not kept_bend(out[-2].pos, a, q[0], turn[i - 1]):
                continue
            if on_b and i + 2 < len(P) and not kept_bend(q[-1], b, P[i + 2], turn[i + 1]):
                continue
            if w.photo and np.linalg.norm(q - c, axis=1).min() > ARC_PHOTO_SHIFT * (
                    w.standoff if w.standoff is not None else 0.0):
                continue
            pts = q
            break
        if pts is None:
            out.append(w)
            continue
        mid = int(np.argmin(np.linalg.norm(pts - c, axis=1)))
        for k, p in enumerate(pts):
            if k == mid and w.photo:
                # its distance to what it images: at least the planned one less the shift, and
                # at least the clearance there where that is nearer than planned
                shift = float(np.linalg.norm(p - c))
                near = min(w.standoff, float(site.clearance(p[None])[0])) \
                    if w.standoff is not None else None
                out.append(replace(w, pos=p, standoff=None if w.standoff is None
                                   else max(w.standoff - shift, near, 0.1)))
            else:
                made.add(len(out))
                out.append(WP(p, None, False, w.component, w.slow))
    out.append(wps[-1])
    # the camera turns evenly along the path between the aimed waypoints round each arc
    Q = np.array([w.pos for w in out])
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(Q, axis=0), axis=1))]
    aimed = [j for j, w in enumerate(out) if w.fwd is not None]
    for j in sorted(made):
        lo = max((k for k in aimed if k < j), default=None)
        hi = min((k for k in aimed if k > j), default=None)
        if lo is None or hi is None:
            continue
        (y0, p0), (y1, p1) = yaw_pitch(out[lo].fwd), yaw_pitch(out[hi].fwd)
        dy = (y1 - y0 + 180.0) % 360.0 - 180.0
        f = (s[j] - s[lo]) / max(s[hi] - s[lo], 1e-9)
        aim = Camera.rotation_from_yaw_pitch(y0 + f * dy, p0 + f * (p1 - p0))[2]  # its forward
        out[j] = replace(out[j], fwd=aim)
    return replace(chunk, wps=out)
