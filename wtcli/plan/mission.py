"""The planner: a Mission (turbines, camera, fleet, settings) -> a checked, timed Plan.

``plan_mission`` builds each turbine's component trajectories (paths.py), orders the turbines to
shorten the flight, splits them across the UAVs to balance flight time, inserts returns to the
launch point for battery swaps, times every waypoint, predicts coverage with the one coverage
measure, and checks clearance to every part of every real turbine and the ground. With
``enforce_safety`` (the default for the adaptive pattern) any violation, unreachable station
or side below ``min_side_coverage`` is a PlanError that says what blocks it.

Patterns: ``adaptive`` follows the blades' real azimuths; ``fixed-y`` is the non-adaptive
baseline that assumes the rotor stopped in a "Y" (blade 1 up at 90 deg, the others evenly
spaced) whatever the real azimuths are. The plan still carries the REAL turbines, so the
baseline's coverage and clearance are judged against reality (its violations are reported in
the summary, not raised).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from wtcli.console import StageProgress, stage_ticker
from wtcli.errors import ConfigError, PlanError
from wtcli.geometry import Camera, Turbine
from wtcli.geometry.coverage import Coverage, turbine_coverage
from wtcli.plan.config import Mission
from wtcli.plan.corners import corner_speeds
from wtcli.plan.paths import (GAP_ROUND_FINE_SAMPLES, WP, Chunk, PassParams, _Blocked,
                              add_gap_views, blade_chunk, connect, gap_plan, gap_views,
                              insert_views, nacelle_chunk, round_corners,
                              tower_chunk, yaw_pitch)
from wtcli.plan.clearance import Site
from wtcli.plan.zone import initial_point, zone
from wtcli.pitch import classify_theta
from wtcli.plan_file import Plan, Route

PATTERNS = ("adaptive", "fixed-y")
GSD_FILL = 0.9  # nominal standoff = this fraction of the distance that gives the target GSD
MAX_LEG_ROUNDS = 8  # dry runs of the routes at most (each connects the legs the last one named)
SPLIT_BELOW = 0.985  # a single-pass flat side below this predicted coverage is flown split
GAP_ROUNDS = 2  # further rounds of gap views for a side still below min_side_coverage
GAP_SIDE_BELOW = 0.995  # extra views for a blade side's misses where it is predicted below
# this: each is a detour of 10-20 s flown at the blur limit of a view nearer than the passes,
# so views chasing the last half percent of every side cost a minute of flight per turbine
Z = np.array([0.0, 0.0, 1.0])


@lru_cache(maxsize=65536)
def _rotation(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """The camera rotation a waypoint's yaw and gimbal pitch give (Camera's own, cached)."""
    return Camera.rotation_from_yaw_pitch(yaw_deg, pitch_deg)


def y_turbine(t: Turbine) -> Turbine:
    """The turbine as the fixed pattern assumes it: blade 1 up (90 deg), the others evenly spaced."""
    return replace(t, azimuths_deg=tuple((90.0 + k * 360.0 / t.n_blades) % 360.0
                                         for k in range(t.n_blades)))


def pass_params(mission: Mission) -> tuple[PassParams, float, float]:
    """(pass parameters, GSD the coverage is judged at, nominal GSD at the standoff)."""
    s, cam = mission.settings, mission.camera
    # The legs' clearance is a sampled lower bound (up to LEG_STEP/2 pessimistic), so waypoints
    # keep at least 0.3 m beyond the safe distance even with no tracking margin.
    req = s.safe_distance_m + max(s.tracking_margin_m, 0.3)
    st_gsd = GSD_FILL * cam.distance_for_gsd(s.target_gsd_mm)
    # Site measures to the model grown by each turbine's geometry uncertainty: the standoff
    # from the bare model keeps the required clearance from the most grown one.
    grown = req + max(mission.geometry_uncertainties())
    st_min = 1.01 * grown + 0.05  # the model's clearance is a slightly conservative lower bound
    if st_gsd >= st_min:
        st, gsd_eval = st_gsd, s.target_gsd_mm
    elif s.allow_coarser_gsd:
        st = st_min
        gsd_eval = float(cam.gsd_mm(st / GSD_FILL))
    else:
        raise PlanError(
            f"target_gsd_mm {s.target_gsd_mm:g} needs the camera within {st_gsd:.2f} m of the "
            f"surface, closer than safe_distance_m + tracking_margin_m + geometry_uncertainty_m "
            f"= {grown:g} m; use a longer "
            f"lens, a coarser target_gsd_mm (>= {float(cam.gsd_mm(st_min / GSD_FILL)):.2f}) or "
            "allow_coarser_gsd: true")
    pp = PassParams(cam, st, 0.97 * cam.distance_for_gsd(gsd_eval), req, st_min, s.overlap,
                    s.min_altitude_m, mission.fleet.gimbal_pitch_range,
                    cam.distance_for_gsd(1.02 * gsd_eval), s.max_incidence_deg)
    return pp, gsd_eval, float(cam.gsd_mm(st))


@dataclass(frozen=True)
class Speeds:
    """The speed of each kind of leg (``leg_speeds``)."""

    capture: float  # photo legs: the fleet's inspection cap and the photo interval's limit
    blur_per_m: float  # motion-blur limit per metre of camera-to-surface distance, m/s per m
    closest: float  # standoff (m) assumed for a photo station that records none
    turn: float  # inspection-speed legs with no photo at either end (arcs, joins, returns)
    cruise: float  # transits
    climb: float  # vertical speed limit
    interval: float = 0.0  # the camera's shortest time between photos, s
    # a leg between two photos longer than this is a join (between passes or faces, to an
    # extra view), flown at the turn speed; its ends are passed at their limits all the same
    pass_leg_m: float = math.inf

    def is_pass_leg(self, length: np.ndarray) -> np.ndarray:
        return np.asarray(length) <= self.pass_leg_m

    def blur(self, standoff: float | None) -> float:
        return self.blur_per_m * (self.closest if standoff is None else standoff)


def speeds(mission: Mission, pp: PassParams) -> Speeds:
    fl, cap = mission.fleet, mission.capture
    v_fleet = min(fl.inspection_speed_m_s, fl.max_speed_m_s)
    # The longest a pass puts between photos is (1 - overlap) of the footprint's longer side
    # (a nacelle row along it) at the farthest standoff; half as much again is a join.
    pass_leg = 1.5 * max(0.25, (1 - pp.overlap) * max(pp.camera.footprint_m(pp.max_standoff)))
    return Speeds(min(v_fleet, cap.interval_speed_m_s(pp.spacing(pp.standoff))),
                  cap.blur_speed_m_s(float(pp.camera.gsd_mm(1.0))),
                  max(pp.min_standoff, pp.standoff - 1.0),  # blade_chunk's closest candidates
                  v_fleet, min(fl.cruise_speed_m_s, fl.max_speed_m_s), fl.climb_rate_m_s,
                  cap.min_photo_interval_s, pass_leg)


def capture_speed(mission: Mission, pp: PassParams,
                  standoff: float | None = None) -> tuple[float, dict[str, float]]:
    """The speed along the photo passes at ``standoff`` (default the nominal one; the plan's
    summary gives the blade passes' median: a ring of oblique passes flies closer), and the
    limits it is the slowest of: the fleet's ``inspection_speed_m_s`` (and ``max_speed_m_s``),
    the photo spacing there over the camera's ``min_photo_interval_s``, and the motion-blur
    limit ``max_blur_px`` * GSD / ``shutter_s`` (a station closer to the surface, a finer GSD,
    is passed slower: ``leg_speeds``)."""
    fl, cap = mission.fleet, mission.capture
    st = pp.standoff if standoff is None else standoff
    limits = {"fleet_m_s": min(fl.inspection_speed_m_s, fl.max_speed_m_s),
              "photo_interval_m_s": cap.interval_speed_m_s(pp.spacing(st)),
              "motion_blur_m_s": cap.blur_speed_m_s(float(pp.camera.gsd_mm(st)))}
    return min(limits.values()), limits


def leg_speeds(wps: list[WP], sp: Speeds) -> np.ndarray:
    """The speed of each leg wps[i] -> wps[i + 1]: cruise (``slow`` False), else the capture
    speed between two photos along a pass (a longer leg between two photos is a join:
    ``Speeds.pass_leg_m``), the turn speed on the others; and no photo station is passed
    faster than its motion-blur limit (nor, between two inspection-speed legs, than the capture
    speed): at least one leg beside it is no faster (the flight's speed at a waypoint is at
    most the slower of its two legs: fly's reference). A leg between
    two photos is held to the looser of its ends' limits (along a pass, their common one); a
    station whose legs are both still faster (an extra view nearer the surface than the pass
    it sits in, a view between turns) has the shorter of them slowed to its limit, the
    tightest limits first (a leg slowed for one station serves its neighbour too)."""
    n = len(wps)
    if n < 2:
        return np.zeros(0)
    slow = np.array([w.slow for w in wps[1:]], bool)
    photo = np.array([w.photo for w in wps], bool)
    vb = np.array([sp.blur(w.standoff) if w.photo else np.inf for w in wps])
    # a photo between two inspection-speed legs (a pass's end photo taken on the arc into
    # the next pass) is passed at no more than the passes' speed either
    slow_both = np.r_[False, slow[:-1] & slow[1:], False]
    vb = np.where(photo & slow_both, np.minimum(vb, sp.capture), vb)
    P = np.array([w.pos for w in wps])
    L = np.linalg.norm(np.diff(P, axis=0), axis=1)
    both = slow & photo[:-1] & photo[1:] & sp.is_pass_leg(L)
    v = np.where(~slow, sp.cruise, np.where(both, sp.capture, sp.turn))
    v = np.where(both, np.minimum(v, np.maximum(vb[:-1], vb[1:])), v)

    def over(i: int) -> bool:
        return min(v[i - 1] if i > 0 else np.inf, v[i] if i < n - 1 else np.inf) > vb[i]

    for i in sorted((i for i in np.nonzero(photo)[0] if over(i)), key=lambda i: vb[i]):
        if over(i):
            legs = [j for j in (i - 1, i) if 0 <= j < n - 1]
            j = min(legs, key=lambda j: L[j])
            v[j] = vb[i]
    return v


LAUNCH_AHEAD_M = 60.0  # the automatic launch point: this far in front of the first rotor (or
# its tip radius + 15 m if farther), on the ground (fleet.launch in turbines-defaults.yaml)


def default_launch(t: Turbine) -> np.ndarray:
    p = t.base_xyz + t.axis * max(LAUNCH_AHEAD_M, t.tip_radius + 15.0)
    return np.array([p[0], p[1], t.base_xyz[2]])


def launch_point(mission: Mission) -> np.ndarray:
    """``fleet.launch``, else the automatic one in front of the first turbine."""
    fl = mission.fleet
    return np.array(fl.launch, float) if fl.launch is not None else \
        default_launch(mission.turbines[0])


# ---- per-turbine chunks ------------------------------------------------------------------------------
def blade_order(t: Turbine) -> list[int]:
    """Clockwise as seen from the front, starting with the blade nearest straight up."""
    return sorted(range(t.n_blades), key=lambda k: (90.0 - t.azimuths_deg[k]) % 360.0)


def turbine_chunks(t: Turbine, site: Site, pp: PassParams, mission: Mission,
                   split: dict[int, set[str]] | None = None,
                   previous: list[Chunk] | None = None, rings: bool = False) -> list[Chunk]:
    """Overview photo, blades, nacelle, tower. With ``previous`` (an earlier result for the same
    turbine), only the blades named in ``split`` are rebuilt. ``rings``: blades flown as a ring of
    oblique passes where one sees every section (``blade_chunk``)."""
    if previous is not None:
        out = []
        try:
            for c in previous:
                if c.name.startswith("blade") and int(c.name[5:]) - 1 in (split or {}):
                    k = int(c.name[5:]) - 1
                    c = blade_chunk(t, k, site, pp, f"{t.id}/blade{k + 1}", split[k])
                out.append(c)
        except _Blocked as e:
            raise PlanError(f"turbine {t.id}: {e} keeping {pp.required:g} m (safe distance + "
                            "tracking margin); lower the margin or check the turbine sizes") from None
        return [_rounded(c, site, pp) for c in out if c.wps]
    ex = mission.extra(t.id)
    z = zone(t, ex.measured_tips)
    sp = initial_point(t, z)
    k = 0
    while site.clearance(sp[None], pp.required)[0] < pp.required and k < 50:  # push S_p out until it is clear
        sp = sp + t.axis * 2.0
        k += 1
    chunks = [Chunk(t.id, "overview", [WP(sp, _unit(z.center - sp), True, f"{t.id}/overview",
                                          standoff=float(site.clearance(sp[None])[0]))])]
    try:
        order = blade_order(t)
        # Each ring starts near where the last chunk ended and ends towards the next blade's
        # root (the last blade: towards the nacelle, then the tower's top).
        roots = [t.hub_center + t.blade_root_offset * t.blade_frame(k)[0] for k in order[1:]]
        after = t.nacelle_center if mission.settings.inspect_nacelle else \
            t.base_xyz + np.array([0.0, 0.0, t.hub_height])
        for k, toward in zip(order, roots + [after]):
            last = next(c for c in reversed(chunks) if c.wps)
            chunks.append(blade_chunk(t, k, site, pp, f"{t.id}/blade{k + 1}",
                                      (split or {}).get(k, set()), rings,
                                      start_near=last.end, end_toward=toward))
        if mission.settings.inspect_nacelle:
            last = next(c for c in reversed(chunks) if c.wps)
            chunks.append(nacelle_chunk(t, site, pp, start_near=last.end))
            _need_stations(chunks[-1], pp, "inspect_nacelle")
        if mission.settings.inspect_tower:
            # the overview photo always has a station, so some chunk before the tower has one
            last = next(c for c in reversed(chunks) if c.wps)
            # A lone turbine's tower is the last thing before the landing: it ends on the
            # launch's side. On a site of several, what follows it is decided with the routes.
            land = launch_point(mission) + Z * mission.settings.takeoff_altitude_m \
                if len(mission.turbines) == 1 else None
            *climb, tower = tower_chunk(t, site, pp, mission.settings.tower_columns,
                                        start_near=last.end, climb_toward=sp, end_toward=land)
            chunks[:0] = climb  # a column flown up on the way to the overview, if any
            chunks.append(tower)
            if not any(w.photo for c in climb + [tower] for w in c.wps):
                _need_stations(tower, pp, "inspect_tower")
    except _Blocked as e:
        raise PlanError(f"turbine {t.id}: {e} keeping {pp.required:g} m (safe distance + tracking "
                        "margin); lower the margin or check the turbine sizes") from None
    return [_rounded(c, site, pp) for c in chunks if c.wps]


def _rounded(chunk: Chunk, site: Site, pp: PassParams) -> Chunk:
    """The chunk's corners rounded (``paths.round_corners``), before coverage is predicted, so
    the extra views make up for what a photo moved onto an arc misses. A pass's end photo moves
    by 1-1.5 m, well within its frame's overlap with the one before; the nacelle's faces are
    tiled to their edges, so its photo corners stay stops."""
    return round_corners(chunk, site, pp.leg_required, pp.min_altitude,
                         move_photos=chunk.name != "nacelle")


def _need_stations(chunk: Chunk, pp: PassParams, key: str) -> None:
    """A component asked for but left without a single photo station is refused by name."""
    if any(w.photo for w in chunk.wps):
        return
    raise PlanError(f"turbine {chunk.turbine} {chunk.name}: no photo station keeps "
                    f"{pp.required:g} m (safe distance + tracking margin) from every part, "
                    f"{pp.min_altitude:g} m above the ground and within {pp.gimbal_text()} "
                    f"at up to {pp.max_standoff:.1f} m (the GSD's reach); check the turbine "
                    f"sizes, or set mission.{key}: false")


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


# ---- timing ------------------------------------------------------------------------------------------
# How an autopilot's mission mode flies a polyline (fly's reference, docs/fly.md): speed changes
# at this acceleration, corners at the "junction deviation" speed for this deviation.
ACCEL_M_S2 = 2.5
CORNER_M = 0.05
# The camera turns at these rates (fly's default vehicle): a leg that turns it is given at least
# the time to turn at half of them, as fly's set-point gives it (the autopilot's yaw and gimbal).
YAW_RATE_DEG_S = 90.0
GIMBAL_RATE_DEG_S = 90.0


def _aims(wps: list[WP], pitch_range: tuple[float, float] = (-90.0, 90.0)
          ) -> tuple[np.ndarray, np.ndarray]:
    """(yaw, gimbal pitch) in degrees at each waypoint: the camera keeps the last aim given
    (none yet: the first given), held at the gimbal's limits."""
    n = len(wps)
    first = next((w.fwd for w in wps if w.fwd is not None), np.array([0.0, 1.0, 0.0]))
    have = np.array([w.fwd is not None for w in wps])
    have[0] = True
    fwds = np.array([w.fwd if w.fwd is not None else first for w in wps], float)
    F = fwds[np.maximum.accumulate(np.where(have, np.arange(n), 0))]
    F = F / np.linalg.norm(F, axis=1)[:, None]
    yaw = np.degrees(np.arctan2(F[:, 0], F[:, 1])) % 360.0
    pitch = np.clip(np.degrees(np.arcsin(np.clip(F[:, 2], -1.0, 1.0))), *pitch_range)
    return yaw, pitch


def _turn_times(yaw: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Each leg's least time for the camera's turn between its ends (s)."""
    yu = np.degrees(np.unwrap(np.radians(yaw)))
    return np.maximum(np.abs(np.diff(yu)) / (0.5 * YAW_RATE_DEG_S),
                      np.abs(np.diff(pitch)) / (0.5 * GIMBAL_RATE_DEG_S))


def _leg_speeds_flown(P: np.ndarray, v: np.ndarray, climb: float,
                     turn_s: np.ndarray | None = None) -> np.ndarray:
    """Each leg's speed ``v`` held to the climb rate and to the time its camera turn takes."""
    D = np.diff(P, axis=0)
    L = np.linalg.norm(D, axis=1)
    dz = np.abs(D[:, 2])
    ve = np.minimum(v, np.divide(climb * L, dz, out=np.full(len(L), np.inf), where=dz > 1e-9))
    if turn_s is not None:
        ve = np.minimum(ve, np.divide(L, turn_s, out=np.full(len(L), np.inf), where=turn_s > 0))
    return np.where(L > 1e-6, ve, 0.0)


def _flown_leg_times(P: np.ndarray, v: np.ndarray, climb: float,
                     turn_s: np.ndarray | None = None) -> np.ndarray:
    """Each leg's time as flown: at its speed ``v`` (and the climb rate, and slow enough for
    the camera turn ``turn_s`` where given), stopping where the aircraft stops
    (``corners.stops``: the ends, zero-length legs, sharp corners) and through the other
    waypoints at the junction-deviation speed, speed changes at ACCEL_M_S2 (trapezoids); a
    zero-length leg takes its turn's time."""
    D = np.diff(P, axis=0)
    L = np.linalg.norm(D, axis=1)
    moving = L > 1e-6
    ve = _leg_speeds_flown(P, v, climb, turn_s)
    a = ACCEL_M_S2
    vc = corner_speeds(P, ve, a, CORNER_M)  # 0 where the aircraft stops
    for j in range(len(L)):  # reachable with |acceleration| <= a
        vc[j + 1] = min(vc[j + 1], math.sqrt(vc[j] ** 2 + 2 * a * L[j]))
    for j in range(len(L) - 1, -1, -1):
        vc[j] = min(vc[j], math.sqrt(vc[j + 1] ** 2 + 2 * a * L[j]))
    v0, v1 = vc[:-1], vc[1:]
    vm = np.maximum(ve, np.maximum(v0, v1))
    d_acc = (vm ** 2 - v0 ** 2) / (2 * a) + (vm ** 2 - v1 ** 2) / (2 * a)
    full = d_acc <= L
    vp = np.sqrt(np.maximum((2 * a * L + v0 ** 2 + v1 ** 2) / 2, 0.0))  # peak of a triangle
    t_full = (vm - v0) / a + (vm - v1) / a + (L - d_acc) / np.maximum(vm, 1e-9)
    t_tri = (vp - v0) / a + (vp - v1) / a
    still = np.zeros(len(L)) if turn_s is None else turn_s
    return np.where(moving, np.where(full, t_full, t_tri), still)


def _flown(P: np.ndarray, v: float, climb: float) -> float:
    """``_flown_leg_times`` of a polyline at one speed, summed (from and to a stop)."""
    return float(_flown_leg_times(P, np.full(len(P) - 1, v), climb).sum())


def chunk_time(ch: Chunk, sp: Speeds) -> float:
    """Flight time of a chunk's legs at ``leg_speeds``, with the photo-interval waits."""
    if len(ch.wps) < 2:
        return 0.0
    turn = _turn_times(*_aims(ch.wps))
    dt = _flown_leg_times(np.array([w.pos for w in ch.wps]), leg_speeds(ch.wps, sp), sp.climb,
                          turn)
    waits = _photo_waits(dt, np.array([w.photo for w in ch.wps]), sp.interval)
    return float(dt.sum() + waits.sum())


# ---- ordering and splitting --------------------------------------------------------------------------
def visit_order(points: np.ndarray, start: np.ndarray) -> list[int]:
    """A short open tour from ``start`` through all points: nearest neighbour, then 2-opt."""
    n = len(points)
    if n <= 2:
        return sorted(range(n), key=lambda i: np.linalg.norm(points[i] - start))
    left = set(range(n))
    order, cur = [], start
    while left:
        i = min(left, key=lambda j: float(np.linalg.norm(points[j] - cur)))
        order.append(i)
        left.remove(i)
        cur = points[i]
    P = np.vstack([start[None], points[order]])
    improved = True
    while improved:
        improved = False
        for i in range(1, len(P) - 2):
            a, b = P[i - 1], P[i]
            c, d = P[i + 1:-1], P[i + 2:]
            gain = (np.linalg.norm(a - b) + np.linalg.norm(c - d, axis=1)
                    - np.linalg.norm(a - c, axis=1) - np.linalg.norm(b - d, axis=1))
            if len(gain) and gain.max() > 1e-6:
                j = i + 1 + int(np.argmax(gain))
                P[i:j + 1] = P[i:j + 1][::-1].copy()
                order[i - 1:j] = order[i - 1:j][::-1]
                improved = True
    return order


def split_balanced(costs: list[float], parts: int) -> list[tuple[int, int]]:
    """Split a sequence into at most ``parts`` contiguous runs minimising the largest run cost."""
    n = len(costs)
    parts = min(parts, n)
    pre = np.concatenate([[0.0], np.cumsum(costs)])
    INF = float("inf")
    best = np.full((parts + 1, n + 1), INF)
    cut = np.zeros((parts + 1, n + 1), int)
    best[0, 0] = 0.0
    for p in range(1, parts + 1):
        for j in range(1, n + 1):
            for i in range(p - 1, j):
                v = max(best[p - 1, i], pre[j] - pre[i])
                if v < best[p, j]:
                    best[p, j], cut[p, j] = v, i
    runs, j = [], n
    for p in range(parts, 0, -1):
        i = cut[p, j]
        runs.append((i, j))
        j = i
    return [r for r in reversed(runs) if r[1] > r[0]]


# ---- routes --------------------------------------------------------------------------------------------


def distinct_vias(vias, p: np.ndarray, q: np.ndarray) -> list[np.ndarray]:
    """A leg's via points without those at its ends or repeating the one before: a detour may
    hold a via at an end (a drop straight down onto the return point), and a second waypoint
    there is a leg of no length, planned at 0 m/s (which DJI waylines refuse)."""
    out, last = [], np.asarray(p, float)
    for v in vias:
        v = np.asarray(v, float)
        if np.linalg.norm(v - last) > 1e-6 and np.linalg.norm(v - np.asarray(q, float)) > 1e-6:
            out.append(v)
            last = v
    return out


def build_route(uav: str, chunks: list[Chunk], launch: np.ndarray, mission: Mission, site: Site,
                pp: PassParams, links: dict | None = None, times: list[float] | None = None,
                missing: list | None = None, cap: float | None = None,
                sorties: list | None = None) -> Route | None:
    """``links``: {(p bytes, q bytes): via points or None} for legs already ``connect``-ed (in
    the workers); any other leg is connected here. ``times``: ``chunk_time`` of each chunk, if
    known. With ``missing``, a dry run: the legs not in ``links`` are appended to it (as (p, q))
    instead of connected, and no route is returned. ``cap``: a battery change once a sortie
    would pass this many seconds (at most the fleet's sortie limit; a chunk longer than it
    flies alone); ``sorties`` gets the number of sorties appended.

    The battery decisions time each transit and return leg along its via points where the leg
    is in ``links`` (straight where not yet connected): a detour round a turbine is flown, so
    it is paid from the battery. ``plan_mission`` repeats the dry run until it asks for no new
    leg, so the real run decides on the legs it flies, and checks every sortie afterwards."""
    fl, s = mission.fleet, mission.settings
    sp = speeds(mission, pp)
    v_fast, climb = sp.cruise, sp.climb
    above = launch + Z * s.takeoff_altitude_m
    usable = fl.sortie_limit_s
    limit = usable if cap is None else min(cap, usable)
    first_fwd = _unit(np.r_[(chunks[0].start - launch)[:2], 0.0] + 1e-9)
    wps: list[WP] = [WP(launch.copy(), first_fwd, False, "launch", False)]
    swaps: list[int] = []  # indices of the waypoints that end a battery swap on the ground

    def link(p: np.ndarray, q: np.ndarray, comp: str, fast: bool, what: str) -> list[WP]:
        key = (p.tobytes(), q.tobytes())
        if links is not None and key in links:
            vias = links[key]
        elif missing is not None:
            missing.append((p, q))
            vias = []
        else:
            vias = connect(site, p, q, pp.leg_required, ground=s.min_altitude_m)
        if vias is None:
            raise PlanError(f"{uav}: no safe straight or detoured path {what} keeping "
                            f"{pp.leg_required:.2f} m from every turbine part and "
                            f"{s.min_altitude_m:g} m above the ground")
        return [WP(v, None, False, comp, not fast) for v in distinct_vias(vias, p, q)]

    def leg_s(p: np.ndarray, q: np.ndarray) -> float:
        """Cruise time of a transit leg, along its via points once connected."""
        vias = links.get((p.tobytes(), q.tobytes())) if links is not None else None
        if not vias:
            return _flown(np.vstack([p, q]), v_fast, climb)
        P = np.vstack([p[None], np.asarray(vias, float).reshape(-1, 3), q[None]])
        return _flown(P, v_fast, climb)

    def takeoff() -> None:
        wps.append(WP(above.copy(), None, False, "launch", False))

    def go_home() -> None:
        wps.extend(link(wps[-1].pos, above, "return", True, "back to the launch point"))
        wps.append(WP(above.copy(), None, False, "return", False))
        wps.append(WP(launch.copy(), None, False, "return", False))

    takeoff()
    sortie = _flown(np.vstack([launch, above]), v_fast, climb)
    for i, ch in enumerate(chunks):
        t_ch = times[i] if times is not None else chunk_time(ch, sp)
        t_to = leg_s(wps[-1].pos, ch.start)
        t_back = leg_s(ch.end, above) + s.takeoff_altitude_m / climb
        if sortie + t_to + t_ch + t_back > limit:
            fresh = _flown(np.vstack([launch, above]), v_fast, climb) + leg_s(above, ch.start)
            if fresh + t_ch + t_back > usable:
                # Mostly the flight out and back when the turbine is far: say which it is.
                away = leg_s(above, ch.start) + t_back
                far = float(np.linalg.norm((ch.start - launch)[:2]))
                hint = (f"; {away / 60:.1f} min of it is the flight to and from the launch point "
                        f"{far / 1000:.1f} km away: launch nearer (fleet.launch), or plan the "
                        "far turbines as a site of their own" if away > t_ch else "")
                raise PlanError(
                    f"{ch.turbine} {ch.name} takes {(fresh + t_ch + t_back) / 60:.1f} min from "
                    f"take-off to landing, more than one battery allows "
                    f"({_battery_words(fl)}){hint}; raise battery_minutes or the speeds")
            if len(wps) > 2:  # not already on a fresh battery at the launch point
                go_home()
                wps.append(WP(launch.copy(), None, False, "launch", False))  # battery swap
                swaps.append(len(wps) - 1)
                takeoff()
                sortie = _flown(np.vstack([launch, above]), v_fast, climb)
            t_to = leg_s(wps[-1].pos, ch.start)
        prev = wps[-1].pos
        wps.extend(link(prev, ch.start, "transit", True, f"to {ch.turbine} {ch.name}"))
        wps.append(replace(ch.wps[0], slow=False))  # the transit leg into the chunk
        wps.extend(ch.wps[1:])
        sortie += t_to + t_ch
    go_home()
    if sorties is not None:
        sorties.append(len(swaps) + 1)
    if missing is not None:
        return None
    return _timed_route(uav, wps, swaps, sp, fl.battery_swap_s, fl.gimbal_pitch_range,
                        sp.interval, sorted({c.turbine for c in chunks}))


def _battery_words(fl) -> str:
    """The sortie limit as the settings make it, for messages."""
    return (f"({fl.battery_minutes:g} battery - {fl.battery_reserve_minutes:g} reserve) / "
            f"(1 + wind_margin {fl.wind_margin:g}) = {fl.sortie_limit_s / 60:.2f} min")


SORTIE_RETRIES = 3  # plannings again of a route whose timed sortie overran the estimate
SORTIE_SHRINK = 0.995  # ... each under the limit times this and its overrun
SORTIE_CAP_STEPS = 12  # bisections of the balanced sorties' cap (sortie limit / 4096)


def _balanced_cap(job: tuple, usable: float) -> float:
    """The least battery cap that flies ``job``'s route in as many sorties as the cap
    ``usable`` (the sortie limit) does (bisected on dry runs): the same battery changes, each
    sortie as short as they allow, so more than the wind margin is left for wind rather than
    the first sortie filled to the brim and the last one short. ``usable`` for a route of one
    sortie."""

    def count(cap: float | None) -> int:  # a chunk too long for any battery raises either way
        n: list = []
        build_route(*job, missing=[], cap=cap, sorties=n)
        return n[0]

    want = count(usable)
    if want <= 1:
        return usable
    lo, hi = 0.0, usable
    for _ in range(SORTIE_CAP_STEPS):
        mid = 0.5 * (lo + hi)
        if count(mid) == want:
            hi = mid
        else:
            lo = mid
    return hi


def _timed_route(uav: str, wps: list[WP], swaps: list[int], sp: Speeds, swap_s: float,
                 pitch_range: tuple[float, float] = (-90.0, 90.0), photo_interval_s: float = 0.0,
                 turbines: list[str] | None = None) -> Route:
    """Times the waypoints. Two photos are never closer in time than ``photo_interval_s`` (the
    camera's): a leg that would be is flown slower (its speed is its length over its time).
    The route's summary carries its ``time_budget`` per turbine id in ``turbines``."""
    n = len(wps)
    pos = np.array([w.pos for w in wps])
    # Photo stations are chosen within the gimbal's range; an aim carried over between them
    # (transits) or the overview's is held at the limit, as the gimbal would.
    yaw, pitch = _aims(wps, pitch_range)
    turn = _turn_times(yaw, pitch)
    v = leg_speeds(wps, sp)
    dt = _flown_leg_times(pos, v, sp.climb, turn)
    L = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    extra = np.zeros(n - 1)
    extra[[i - 1 for i in swaps]] = swap_s
    photo = np.array([w.photo for w in wps], bool)
    wait = _photo_waits(dt + extra, photo, photo_interval_s)
    t = np.r_[0.0, np.cumsum(dt + extra + wait)]
    # The speed commanded on each leg (what the exports send and fly's reference flies, with its
    # own speed changes as ``_flown_leg_times`` times them): the leg's speed under the climb
    # rate and its camera turn; where the camera's interval holds a leg back, its length over
    # its time.
    v_cmd = _leg_speeds_flown(pos, v, sp.climb, turn)
    v_cmd = np.where(wait > 0, np.divide(L, dt + wait, out=np.zeros(n - 1), where=dt + wait > 0),
                     v_cmd)
    speed = np.r_[0.0, np.where(L > 1e-6, v_cmd, 0.0)]
    # Each sortie: from leaving the launch point to landing there (the swap's ground time not
    # included): what the sortie limit (Fleet.sortie_limit_s) must cover.
    starts, ends = [0] + list(swaps), [i - 1 for i in swaps] + [n - 1]
    sorties = [float(t[b] - t[a]) for a, b in zip(starts, ends)]
    comp = np.array([w.component for w in wps], dtype=object)
    budget = _time_budget(wps, dt, wait, extra, turbines or [], sp)
    return Route(uav, t, pos, speed, yaw, pitch, photo, comp,
                 summary={"battery_swaps": len(swaps), "sorties": len(swaps) + 1,
                          "longest_sortie_s": max(sorties), "time_budget": budget})


def _photo_waits(dt: np.ndarray, photo: np.ndarray, interval: float) -> np.ndarray:
    """Extra seconds per leg so that consecutive photos are at least ``interval`` apart."""
    wait = np.zeros(len(dt))
    if interval <= 0 or photo.sum() < 2:
        return wait
    t = np.r_[0.0, np.cumsum(dt)]
    off, last = 0.0, None
    for j in np.nonzero(photo)[0]:
        tj = t[j] + off
        if last is not None and tj - last < interval - 1e-9:
            w = interval - (tj - last)
            wait[j - 1] += w
            off += w
            tj += w
        last = tj
    return wait


# Where a turbine's minutes go (summary.time_budget; docs/plan.md "Time budget").
BUDGET_KEYS = ("capture_s", "turns_s", "hover_s", "transit_s", "climbs_s", "battery_swaps_s")


def _time_budget(wps: list[WP], dt: np.ndarray, wait: np.ndarray, swap: np.ndarray,
                 turbines: list[str], sp: Speeds) -> dict[str, dict[str, float]]:
    """Each leg's time, by turbine and kind: ``capture_s`` along a pass between two photos
    (slowed to the photo interval where it binds), ``turns_s`` the other inspection-speed legs
    (arcs round a blade, joins between passes even from photo to photo, the blade's return leg,
    extra views' detours),
    ``hover_s`` waiting for the camera elsewhere, ``transit_s`` cruise-speed legs (between
    components and turbines, to and from the launch point), ``climbs_s`` the vertical take-off
    and landing at the launch point, ``battery_swaps_s`` on the ground. A leg belongs to the
    turbine of the component it ends in; launch, transit and return legs to the turbine flown
    next (the last return to the last one)."""
    n = len(wps)
    ids = sorted(turbines, key=len, reverse=True)  # the longest id that prefixes a component
    owner: list[str | None] = []
    for w in wps[1:]:
        owner.append(next((tid for tid in ids if w.component.startswith(f"{tid}/")), None))
    nxt = None
    for i in range(n - 2, -1, -1):  # launch/transit/return legs: the next turbine flown
        if owner[i] is None:
            owner[i] = nxt
        nxt = owner[i]
    prev = None
    for i in range(n - 1):  # after the last component: the last turbine
        if owner[i] is None:
            owner[i] = prev
        prev = owner[i]
    out = {tid: dict.fromkeys(BUDGET_KEYS, 0.0) for tid in turbines}
    for i in range(n - 1):
        b = out.get(owner[i])
        if b is None:
            continue
        a, z = wps[i], wps[i + 1]
        if swap[i] > 0:
            b["battery_swaps_s"] += float(swap[i])
        vertical = float(np.linalg.norm(z.pos[:2] - a.pos[:2])) < 1e-6
        if z.component in ("launch", "return") and vertical:
            b["climbs_s"] += float(dt[i])
            b["hover_s"] += float(wait[i])
        elif not z.slow:
            b["transit_s"] += float(dt[i])
            b["hover_s"] += float(wait[i])
        elif a.photo and z.photo and sp.is_pass_leg(float(np.linalg.norm(z.pos - a.pos))):
            b["capture_s"] += float(dt[i] + wait[i])
        else:
            b["turns_s"] += float(dt[i])
            b["hover_s"] += float(wait[i])
    return {tid: {k: round(v, 2) for k, v in b.items()} | {"total_s": round(sum(b.values()), 2)}
            for tid, b in out.items()}


# ---- checks ---------------------------------------------------------------------------------------------
def check_routes(routes: list[Route], site: Site, launch: np.ndarray, safe: float,
                 min_alt: float) -> dict:
    """Clearance of every waypoint and leg to every real turbine part, and height above ground."""
    out = {"min_clearance_m": float("inf"), "waypoint_violations": 0, "leg_violations": 0,
           "ground_violations": 0, "first_violation": None}
    for r in routes:
        c = site.clearance(r.pos, safe + 1.0)
        lb = site.segment_clearance(r.pos[:-1], r.pos[1:], 0.5, safe + 1.0)
        out["min_clearance_m"] = min(out["min_clearance_m"], float(c.min()), float(lb.min()))
        bad_w = np.nonzero(c < safe)[0]
        bad_l = np.nonzero(lb < safe)[0]
        at_launch = np.linalg.norm(r.pos[:, :2] - launch[:2], axis=1) < 0.5
        low_wp = ~site.above_ground(r.pos, min_alt - 1e-6) & ~at_launch
        # Legs too, but not those the take-off and landing fly at the launch point.
        free = np.nonzero(~at_launch[:-1] & ~at_launch[1:])[0]
        low = low_wp.copy()
        low[free[~site.legs_above_ground(r.pos[free], r.pos[free + 1], min_alt)] + 1] = True
        bad_g = np.nonzero(low)[0]  # a leg is counted at the waypoint it ends at
        out["waypoint_violations"] += len(bad_w)
        out["leg_violations"] += len(bad_l)
        out["ground_violations"] += len(bad_g)
        if out["first_violation"] is None:
            if len(bad_w):
                i = int(bad_w[0])
                part, d = site.nearest_part(r.pos[i])
                out["first_violation"] = (f"{r.uav} waypoint {i} ({r.component[i]}) at "
                                          f"{np.round(r.pos[i], 2).tolist()} is {d:.2f} m from {part}")
            elif len(bad_l):
                i = int(bad_l[0])
                out["first_violation"] = (f"{r.uav} leg {i}->{i + 1} ({r.component[i + 1]}) passes "
                                          f"{lb[i]:.2f} m from a turbine part")
            elif len(bad_g):
                i = int(bad_g[0])
                what = f"waypoint {i}" if low_wp[i] else f"leg {i - 1}->{i}"
                out["first_violation"] = (f"{r.uav} {what} ({r.component[i]}) is below "
                                          f"{min_alt:g} m above the ground")
    return out


def predict_coverage(t: Turbine, routes: list[Route], camera: Camera, gsd_mm: float,
                     spacing: float, max_incidence: float) -> Coverage:
    """The plan's photos of ``t`` measured on its converged sampling (``turbine_coverage``)."""
    pos, rot = _photos_of(t, routes)
    return turbine_coverage(t, camera, pos, np.array(rot).reshape(-1, 3, 3), gsd_mm, spacing,
                            max_incidence)


def _coverage_from_chunks(t: Turbine, chunks: list[Chunk], camera: Camera, gsd_mm: float,
                          spacing: float, max_incidence: float, parts: str = "blades") -> Coverage:
    """``turbine_coverage`` of the chunks' photo stations, posed as the routes will record them."""
    pos = np.array([w.pos for c in chunks for w in c.wps if w.photo]).reshape(-1, 3)
    rot = np.array([_rotation(*(round(v, 6) for v in yaw_pitch(w.fwd)))
                    for c in chunks for w in c.wps if w.photo]).reshape(-1, 3, 3)
    return turbine_coverage(t, camera, pos, rot, gsd_mm, spacing, max_incidence, parts)


# ---- per-turbine work (run in worker processes for large sites) ----------------------------------------
def _route(job: tuple) -> Route:
    return build_route(*job)


def _link(job: tuple) -> tuple[tuple[bytes, bytes], list | None]:
    """One leg ``build_route`` will fly, connected ahead of it (``connect`` is a pure function of
    its arguments, so the route is the same as when it connects the leg itself)."""
    site, p, q, leg_required, ground = job
    return (p.tobytes(), q.tobytes()), connect(site, p, q, leg_required, ground=ground)


def _tour(job: tuple) -> tuple[list[Chunk], dict, list[float]]:
    """A turbine's chunks, the links between consecutive ones (``build_route``'s ``links``) and
    each chunk's ``chunk_time``."""
    chunks = _chunks(job)
    site, pp, s, fl = job[1], job[2], job[3].settings, job[3].fleet
    links = dict(_link((site, a.end, b.start, pp.leg_required, s.min_altitude_m))
                 for a, b in zip(chunks, chunks[1:]))
    sp = speeds(job[3], pp)
    times = [chunk_time(c, sp) for c in chunks]
    job[0].forget()  # its coverage memos, kept for a whole site, filled the memory
    return chunks, links, times


def _chunks(job: tuple) -> list[Chunk]:
    t, site, pp, mission, pattern, gsd_eval = job
    s = mission.settings
    chunks = turbine_chunks(t, site, pp, mission, rings=pattern == "adaptive")
    if pattern == "adaptive":
        cov = _coverage_from_chunks(t, chunks, mission.camera, gsd_eval,
                                    s.coverage_spacing_m, s.max_incidence_deg)
        # Extra views for what the passes miss (mostly the trailing edge at the root and facing
        # the tower), within 2 % of the coverage GSD (the measure allows 5 %: the rest is left
        # for the flight's position error); a side still short is flown split.
        reach = mission.camera.distance_for_gsd(1.02 * gsd_eval)
        wanting = {int(b[5:]) - 1: {x for x, v in sides.items() if v < GAP_SIDE_BELOW}
                   for b, sides in cov.by_blade_side().items()}
        wanting = {k: v for k, v in wanting.items() if v}
        views, covered = gap_plan(t, cov.samples, cov.covered, site, pp, s.max_incidence_deg, reach,
                                  wanting)
        split: dict[int, set[str]] = {}
        predicted = Coverage(cov.samples, covered, cov.best_gsd_mm).by_blade_side()
        for b, sides in predicted.items():
            low = {side for side, v in sides.items() if v < SPLIT_BELOW}
            if low:
                split[int(b[5:]) - 1] = low
        if split:
            rings = {int(c.name[5:]) - 1: c for c in chunks
                     if c.name.startswith("blade") and c.pattern.startswith("ring")}
            chunks = turbine_chunks(t, site, pp, mission, split, previous=chunks)
            cov = _coverage_from_chunks(t, chunks, mission.camera, gsd_eval,
                                        s.coverage_spacing_m, s.max_incidence_deg)
            more, covered2 = gap_plan(t, cov.samples, cov.covered, site, pp, s.max_incidence_deg,
                                      reach, set(split))
            # A ring blade short on a side is flown side by side instead (those sides split)
            # only where that sees more (its worst side, with the extra views either way):
            # else the shorter ring.
            again = Coverage(cov.samples, covered2, cov.best_gsd_mm).by_blade_side()
            keep = {k for k in rings if min(predicted[f"blade{k + 1}"].values())
                    >= min(again[f"blade{k + 1}"].values())}
            chunks = [rings[int(c.name[5:]) - 1] if c.name.startswith("blade")
                      and int(c.name[5:]) - 1 in keep else c for c in chunks]
            views.update({k: v for k, v in more.items() if k not in keep})
        add_gap_views(chunks, views, site, pp)
        # The views were chosen on what the passes missed; checked on the converged figure,
        # a side still below min_side_coverage gets views for what is left, round by round.
        last = None
        # The views' own prediction keeps margins (incidence, frame, GSD): where it meets the
        # floor on every side and nothing was rebuilt, the check is not needed.
        sure = not split and all(min(sides.values()) >= s.min_side_coverage
                                 for sides in predicted.values())
        for _ in range(0 if sure else GAP_ROUNDS):
            cov = _coverage_from_chunks(t, chunks, mission.camera, gsd_eval,
                                        s.coverage_spacing_m, s.max_incidence_deg)
            mins = {int(b[5:]) - 1: min(sides.values()) for b, sides in cov.by_blade_side().items()}
            short = {k for k, v in mins.items() if v < s.min_side_coverage}
            if not short or (last is not None and all(mins[k] < last[k] + 0.005 for k in short)):
                break  # met, or the last round gained less than half a point where it is short
            last = mins
            more = gap_plan(t, cov.samples, cov.covered, site, pp, s.max_incidence_deg, reach,
                            short, GAP_ROUND_FINE_SAMPLES)[0]
            if not any(more.values()):
                break
            add_gap_views(chunks, more, site, pp)
        for _ in range(NACELLE_GAP_ROUNDS):
            if not _nacelle_gap_views(t, chunks, mission, site, pp, gsd_eval, reach):
                break
        # the corners the extra views and their detours made, rounded where no photo is
        chunks = [round_corners(c, site, pp.leg_required, pp.min_altitude, move_photos=False)
                  for c in chunks]
    return chunks


NACELLE_GAP_ROUNDS = 2
NACELLE_GAP_VIEWS = 5  # extra photos of the nacelle at most, where its rows leave it short
NACELLE_GAP_BELOW = 0.98  # predicted nacelle coverage under which the extra views are sought:
# the rows alone see 98.8-100 % of the benchmark's nacelles (flight_time); a tower too wide for
# the underside's oblique rows leaves more, and each extra view is a ~5 s detour


def _nacelle_gap_views(t: Turbine, chunks: list[Chunk], mission: Mission, site, pp: PassParams,
                       gsd_eval: float, reach: float) -> bool:
    """Extra views (``gap_views``, as for the blades) of the nacelle surface that no photo of the
    turbine's chunks covers, flown within the nacelle's own chunk. Whether any were added."""
    nac = next((c for c in chunks if c.name == "nacelle" and c.wps), None)
    if nac is None:
        return False
    s = mission.settings
    cov = _coverage_from_chunks(t, chunks, mission.camera, gsd_eval, s.coverage_spacing_m,
                                s.max_incidence_deg, "structure")
    smp = cov.samples
    nac_part = smp.part == t.part_names().index("nacelle")
    if cov.fraction(nac_part) >= NACELLE_GAP_BELOW:
        return False
    miss = np.nonzero(nac_part & ~cov.covered)[0]
    if not len(miss):
        return False
    views = gap_views(t, smp.points[miss], smp.normals[miss], smp.area[miss], site, pp,
                      s.max_incidence_deg, reach, NACELLE_GAP_VIEWS)
    if not views:
        return False
    lost = insert_views(nac, [(p, f, f"{t.id}/nacelle") for p, f, _ in views], site, pp)
    nac.notes.append(f"{t.id}/nacelle: {len(views) - lost} extra view(s) of surface its rows miss"
                     + (f"; {lost} no safe path reaches: dropped" if lost else ""))
    return len(views) > lost


def _photos_of(t: Turbine, routes: list[Route]) -> tuple[np.ndarray, np.ndarray]:
    return _photos_by_turbine([t.id], routes)[t.id]


def _photos_by_turbine(ids: list[str], routes: list[Route]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per turbine id, the positions and camera rotations of the photos of its components (those
    named "ID/..."), in route and waypoint order. One pass over the routes for all turbines."""
    pos: dict[str, list] = {tid: [] for tid in ids}
    rot: dict[str, list] = {tid: [] for tid in ids}
    owners: dict[str, list[str]] = {}
    for r in routes:
        for i in np.nonzero(r.photo)[0]:
            c = str(r.component[i])
            if c not in owners:
                owners[c] = [tid for tid in pos if c.startswith(f"{tid}/")]
            for tid in owners[c]:
                pos[tid].append(r.pos[i])
                rot[tid].append(_rotation(round(float(r.yaw_deg[i]), 6),
                                          round(float(r.gimbal_pitch_deg[i]), 6)))
    return {tid: (np.array(pos[tid]).reshape(-1, 3), np.array(rot[tid]).reshape(-1, 3, 3))
            for tid in ids}


def _side_coverage(job: tuple) -> tuple[dict, float, float]:
    t, (pos, rot), camera, gsd, spacing, incidence = job
    cov = turbine_coverage(t, camera, pos, rot, gsd, spacing, incidence)
    out = cov.by_blade_side(), cov.blade_average(), cov.structure_fraction()
    t.forget()  # as in _tour: one turbine's memos held at a time
    return out


def _map(fn, jobs: list, workers: int | None, tick: Callable[[], None] = lambda: None) -> list:
    """``[fn(j) for j in jobs]``, in worker processes from 8 jobs on (or ``workers`` of them);
    ``tick()`` after each result, in order."""
    if workers is None:
        workers = (os.cpu_count() or 1) if len(jobs) >= 8 else 1
    workers = max(1, min(workers, len(jobs)))

    def collect(results) -> list:
        out = []
        for r in results:
            out.append(r)
            tick()
        return out

    if workers == 1:
        return collect(map(fn, jobs))
    import multiprocessing as mp

    ex = ProcessPoolExecutor(workers, mp_context=mp.get_context("fork"))
    try:
        return collect(ex.map(fn, jobs, chunksize=max(1, len(jobs) // (4 * workers))))
    except BaseException:
        # Ctrl-C, or SIGTERM to this process alone (wtcli.cli turns it into the same
        # KeyboardInterrupt), or a job's error: end the workers now rather than wait for the
        # jobs queued; left running, they would hold stdout and stderr open after we exit.
        # (Python 3.11's executor has no public call for it; 3.14 adds terminate_workers.)
        for p in list((ex._processes or {}).values()):
            p.terminate()
        ex.shutdown(wait=False, cancel_futures=True)
        raise
    finally:
        ex.shutdown(wait=True)


# The stages plan_mission reports to its ``progress`` callback, in order.
STAGES = ("turbines", "legs", "routes", "coverage")


# ---- the planner -----------------------------------------------------------------------------------------
def plan_mission(mission: Mission, azimuths: dict[str, list[float]] | None = None,
                 pattern: str = "adaptive", enforce_safety: bool | None = None,
                 workers: int | None = None,
                 progress: StageProgress | None = None, azimuth_source: str = "photo") -> Plan:
    """Plan every turbine of ``mission`` for its fleet; see the module docstring.

    azimuths: turbine id -> blade rotor azimuths (deg), overriding the YAML; ``azimuth_source``
    names where they came from in ``summary.turbines.<id>.azimuth_source`` ("photo": the
    command line's photos and pitch JSON).
    enforce_safety: raise PlanError on any clearance/ground violation or coverage shortfall
    (default: True for "adaptive", False for the "fixed-y" baseline, which reports them).
    workers: processes for the per-turbine work, the legs between turbines and the routes
    (default: one per CPU from 8 jobs on; the result does not depend on it).
    progress: called as ``progress(stage, done, total)`` when a stage starts (done 0) and after
    each of its jobs; stages ``STAGES``: per-turbine trajectories, legs between turbines, UAV
    routes, coverage per turbine."""
    if pattern not in PATTERNS:
        raise ConfigError(f"pattern: expected one of {', '.join(PATTERNS)}, got {pattern!r}")
    if enforce_safety is None:
        enforce_safety = pattern == "adaptive"
    if azimuths:
        unknown = set(azimuths) - {t.id for t in mission.turbines}
        if unknown:
            raise ConfigError(f"azimuths given for unknown turbine(s) {sorted(unknown)}")
        try:
            mission = mission.with_azimuths(azimuths, azimuth_source)
        except ValueError as e:
            raise ConfigError(str(e)) from None
    s, fl = mission.settings, mission.fleet
    real = list(mission.turbines)
    assumed = real if pattern == "adaptive" else [y_turbine(t) for t in real]
    launch = launch_point(mission)
    site_plan = Site(assumed, launch=launch, uncertainty=mission.geometry_uncertainties())
    site_real = Site(real, launch=launch, uncertainty=mission.geometry_uncertainties())
    lc = float(site_real.clearance(launch[None])[0])
    if lc < s.safe_distance_m:
        part, d = site_real.nearest_part(launch)
        raise PlanError(f"the launch point {np.round(launch, 2).tolist()} is {d:.2f} m from {part}, "
                        f"closer than safe_distance_m {s.safe_distance_m:g}")
    pp, gsd_eval, gsd_nominal = pass_params(mission)

    # Component trajectories per turbine (adaptive: split flat sides that a single pass misses).
    tours: dict[str, list[Chunk]] = {}
    times: dict[str, list[float]] = {}
    links: dict = {}
    notes: list[str] = []
    jobs = [(t, site_plan, pp, mission, pattern, gsd_eval) for t in assumed]
    tours_done = _map(_tour, jobs, workers, stage_ticker(progress, "turbines", len(jobs)))
    for t, (chunks, tour_links, tour_times) in zip(assumed, tours_done):
        tours[t.id], times[t.id] = chunks, tour_times
        links.update(tour_links)
        notes += [n for c in chunks for n in c.notes]
    st_blades = [w.standoff for cs in tours.values() for c in cs if c.name.startswith("blade")
                 for w in c.wps if w.photo and w.standoff is not None]
    st_pass = float(np.median(st_blades)) if st_blades else pp.standoff

    # Visit order and split across UAVs (balanced by estimated flight time).
    v_slow = capture_speed(mission, pp)[0]  # the split's estimate (chunk times are exact)
    v_fast = min(fl.cruise_speed_m_s, fl.max_speed_m_s)
    ids = [t.id for t in assumed]
    starts = np.array([tours[i][0].start for i in ids])
    order = [ids[j] for j in visit_order(starts, launch)]
    cost = []
    for i, tid in enumerate(order):
        inner = sum(times[tid])
        hops = sum(float(np.linalg.norm(a.end - b.start)) for a, b in zip(tours[tid], tours[tid][1:]))
        cost.append(inner + hops / v_slow + 2 * float(np.linalg.norm(tours[tid][0].start - launch)) / v_fast
                    / max(1, len(order)))
    runs = split_balanced(cost, len(fl.uavs))
    assignment, jobs = {}, []
    for u, (a, b) in zip(fl.uavs, runs):
        assignment[u] = order[a:b]
        jobs.append((u, [c for tid in order[a:b] for c in tours[tid]], launch, mission, site_plan,
                     pp, links, [x for tid in order[a:b] for x in times[tid]]))
    # The legs between turbines and to and from the launch point, connected in the workers too:
    # a dry run of each route names them, then the routes are built from them (in parallel).
    # A connected leg's detour can move a battery swap, which asks for other legs: repeated
    # until the dry runs ask for nothing new (the battery decisions then rest on flown legs).
    # Each UAV's sorties balanced: the least cap that keeps its number of battery changes,
    # found again as legs get connected (their detours are flown, so they count).
    # A route is timed more exactly than its battery decisions estimate it (camera turns on the
    # transits): a sortie the timing finds over the limit is planned again under a limit
    # shrunk by its overrun, a few times at most, before the plan is refused.
    limits = {job[0]: fl.sortie_limit_s for job in jobs}
    caps: dict[str, float] = {}
    todo, routes_by = list(jobs), {}
    for _ in range(SORTIE_RETRIES + 1):
        for rounds in range(MAX_LEG_ROUNDS):
            missing: list = []
            for job in todo:
                caps[job[0]] = _balanced_cap(job, limits[job[0]])
                build_route(*job, missing=missing, cap=caps[job[0]])
            legs = {(p.tobytes(), q.tobytes()): (site_plan, p, q, pp.leg_required, s.min_altitude_m)
                    for p, q in missing}
            tick = stage_ticker(progress, "legs", len(legs)) if not routes_by and rounds == 0 \
                else (lambda: None)
            if not legs:
                break
            links.update(_map(_link, list(legs.values()), workers, tick))
        tick = stage_ticker(progress, "routes", len(todo)) if not routes_by else (lambda: None)
        built = _map(_route, [(*job, None, caps[job[0]]) for job in todo], workers, tick)
        routes_by.update((r.uav, r) for r in built)
        over = [r for r in built if r.summary["longest_sortie_s"] > fl.sortie_limit_s + 1e-6]
        for r in over:
            limits[r.uav] *= SORTIE_SHRINK * fl.sortie_limit_s / r.summary["longest_sortie_s"]
        todo = [job for job in todo if job[0] in {r.uav for r in over}]
        if not todo:
            break
    routes = [routes_by[job[0]] for job in jobs]
    over = [(r.uav, r.summary["longest_sortie_s"]) for r in routes
            if r.summary["longest_sortie_s"] > fl.sortie_limit_s + 1e-6]
    if over:
        raise PlanError(f"{over[0][0]}: a sortie takes {over[0][1] / 60:.2f} min, more than "
                        f"{_battery_words(fl)}: in wind the reserve would be flown")

    check = check_routes(routes, site_real, launch, s.safe_distance_m, s.min_altitude_m)
    if enforce_safety and (check["waypoint_violations"] or check["leg_violations"]
                           or check["ground_violations"]):
        raise PlanError(f"unsafe plan refused: {check['first_violation']} (safe distance "
                        f"{s.safe_distance_m:g} m)")

    coverage = {}
    photos = _photos_by_turbine([t.id for t in real], routes)
    sides_all = _map(_side_coverage, [(t, photos[t.id], mission.camera, gsd_eval,
                                       s.coverage_spacing_m, s.max_incidence_deg) for t in real],
                     workers, stage_ticker(progress, "coverage", len(real)))
    short: list[tuple[str, str]] = []  # (turbine id, why) of every turbine refused, in order
    for t, (sides, average, structure) in zip(real, sides_all):
        vals = [v for d in sides.values() for v in d.values()]
        coverage[t.id] = {"by_blade_side": sides, "blade_average": average,
                          "min_side": float(min(vals)) if vals else 0.0, "structure": structure}
        if enforce_safety and vals and min(vals) < s.min_side_coverage:
            worst = min(((b, side, v) for b, d in sides.items() for side, v in d.items()),
                        key=lambda x: x[2])
            said = [n.split(": ", 1)[1] for n in notes
                    if n.startswith(f"{t.id}/{worst[0]}/{worst[1]}:")]
            if any("gimbal" in n for n in said):  # a side facing down, seen from below
                why = (f"; its head-on views need the camera beyond {pp.gimbal_text()} "
                       "(fleet.gimbal_pitch_min_deg / gimbal_pitch_max_deg)")
                fix = "turn the rotor, use a gimbal that reaches further"
            else:
                blocked = [n for n in said if "blocked by" in n]
                why = (f"; {blocked[0]}" if blocked else "") + \
                    f" with {pp.required:g} m clearance (safe distance + tracking margin)"
                fix = "turn the rotor"
            short.append((t.id, f"turbine {t.id} {worst[0]} {worst[1]}: predicted coverage "
                          f"{worst[2]:.1%} < min_side_coverage {100 * s.min_side_coverage:.4g}% "
                          f"at {gsd_eval:.2f} mm/px{why}; {fix}, or lower min_side_coverage to "
                          "accept it"))
    if short:  # every turbine named at once: a site of 100 must not be planned once per refusal
        more = [tid for tid, _ in short[1:]]
        raise PlanError(short[0][1] + (f" ({len(more)} more turbine(s) short too: "
                                       f"{', '.join(more[:20])}{' ...' if len(more) > 20 else ''})"
                                       if more else ""))

    summary = _summary(routes, mission, pattern, check, coverage, assignment, gsd_eval,
                       gsd_nominal, pp, notes, launch, st_pass)
    return Plan(real, Camera(mission.camera.width_px, mission.camera.height_px,
                             mission.camera.focal_mm, mission.camera.sensor_width_mm),
                routes, s.safe_distance_m, gsd_eval, mission.site_origin, summary)


def _summary(routes: list[Route], mission: Mission, pattern: str, check: dict, coverage: dict,
             assignment: dict, gsd_eval: float, gsd_nominal: float, pp: PassParams,
             notes: list[str], launch: np.ndarray, standoff: float | None = None) -> dict:
    per_comp: dict[str, dict] = {}
    per_uav: dict[str, dict] = {}
    for r in routes:
        seg = np.r_[0.0, np.linalg.norm(np.diff(r.pos, axis=0), axis=1)]
        dt = np.r_[0.0, np.diff(r.t)]
        for i in range(len(r)):
            c = per_comp.setdefault(str(r.component[i]), {"length_m": 0.0, "time_s": 0.0, "photos": 0})
            c["length_m"] += float(seg[i])
            c["time_s"] += float(dt[i])
            c["photos"] += int(r.photo[i])
        per_uav[r.uav] = {"length_m": r.length_m, "time_s": r.duration_s, "photos": int(r.photo.sum()),
                          "turbines": assignment.get(r.uav, []), **r.summary}
    for u in mission.fleet.uavs:
        per_uav.setdefault(u, {"length_m": 0.0, "time_s": 0.0, "photos": 0, "turbines": [],
                               "battery_swaps": 0, "sorties": 0})
    budget: dict[str, dict[str, float]] = {}
    for r in routes:
        budget.update(r.summary.get("time_budget", {}))
    v_cap, limits = capture_speed(mission, pp, standoff)
    zones = {}
    for t in mission.turbines:
        z = zone(t, mission.extra(t.id).measured_tips)
        zones[t.id] = {"center": z.center.tolist(), "radius_m": z.radius,
                       "initial_point": initial_point(t, z).tolist(),
                       "azimuths_deg": list(t.azimuths_deg),
                       # the paper's Fig. 4 class of each blade as a front photo shows it
                       "tilt_classes": [classify_theta(a % 180.0) for a in t.azimuths_deg],
                       "azimuth_source": mission.extra(t.id).azimuth_source,
                       "geometry_uncertainty_m": mission.geometry_uncertainty(t.id)}
    s = mission.settings
    return {
        "pattern": pattern,
        "total_length_m": float(sum(r.length_m for r in routes)),
        "total_time_s": float(max(r.duration_s for r in routes)),
        "flight_time_sum_s": float(sum(r.duration_s for r in routes)),
        "photos": int(sum(int(r.photo.sum()) for r in routes)),
        "min_clearance_m": check["min_clearance_m"],
        "violations": {k: check[k] for k in ("waypoint_violations", "leg_violations",
                                             "ground_violations")},
        "first_violation": check["first_violation"],
        "per_uav": per_uav,
        "per_component": per_comp,
        # Per turbine, where its flight time goes (mission._time_budget; docs/plan.md).
        "time_budget": {t.id: budget.get(t.id, dict.fromkeys((*BUDGET_KEYS, "total_s"), 0.0))
                        for t in mission.turbines},
        "capture": {"speed_m_s": v_cap, "limits": limits,
                    "min_photo_interval_s": mission.capture.min_photo_interval_s,
                    "shutter_s": mission.capture.shutter_s,
                    "max_blur_px": mission.capture.max_blur_px,
                    "photo_spacing_m": pp.spacing(pp.standoff if standoff is None else standoff)},
        "predicted_coverage": coverage,
        "requested_gsd_mm": s.target_gsd_mm,
        "achieved_gsd_mm": gsd_nominal,
        "coverage_gsd_mm": gsd_eval,
        "standoff_m": pp.standoff,
        "safe_distance_m": s.safe_distance_m,
        "required_clearance_m": pp.required,
        # read back by `fly` (its margin and battery-reserve checks)
        "tracking_margin_m": s.tracking_margin_m,
        "battery_minutes": mission.fleet.battery_minutes,
        "battery_reserve_minutes": mission.fleet.battery_reserve_minutes,
        "wind_margin": mission.fleet.wind_margin,
        "gimbal_pitch_range_deg": list(pp.pitch_range),
        "launch": launch.tolist(),
        "turbines": zones,
        "notes": notes,
    }
