"""Fly a plan under a scenario and measure what the flight achieved.

``fly_plan(plan, scenario)`` flies every route of the plan with the eq. 10 PID controller
(``automated``) and, if asked, the baselines on the same weather: ``no_compensation`` (the same
plan, feed-forward only), ``fixed_pattern`` (a non-adaptive plan, PID controlled) and
``manual`` (wtcli.fly.pilot). Each route is measured as soon as it is flown, vectorised over
its steps (``measure_flight``: deviation from the planned path, clearance to every turbine part
and height above ground at every step, the violations, battery per sortie), and the report
keeps of it those per-step measures, its times and positions and its photos; then the flights
of a kind are measured together (``measure``: coverage of the blade surfaces from the photos
actually taken, GSD, time, length). So a wide site's memory holds one route's whole
simulation at a time, not every route's (docs/fly.md "Memory").
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from wtcli.console import StageProgress, stage_ticker
from wtcli.errors import InputError, PlanError
from wtcli.fly.pilot import manual_route, ou_series, pilot_inputs
from wtcli.fly.scenario import Scenario
from wtcli.fly.sim import SETTLE_S, G, Reference, Track, fly, make_controller, make_reference
from wtcli.fly.terrain import Ground
from wtcli.fly.navigation import make_navigation, tower_shadow
from wtcli.fly.wake import wake_series
from wtcli.fly.wind import make_wind, mean_speed
from wtcli.geometry import Camera, Turbine
from wtcli.geometry.coverage import Coverage, measure_coverage
from wtcli.plan.clearance import clearance_to_parts
from wtcli.plan_file import Plan, Route

FLIGHT_KINDS = ("automated", "no_compensation", "fixed_pattern", "manual")
SETTLED_M = 0.5
LANDED_M = 0.5  # a set-point this close to the ground (or its launch point) stands on it
LEASH_SLACK_S = 30.0  # room for the set-point to wait (control.leash_m): 30 s plus 30 %
LEASH_SLACK_FRAC = 0.30  # of the route's planned time
# Streams of the seeded random generator, so each source of randomness is independent.
_WIND, _SENSOR, _PILOT, _WAKE = 1, 2, 3, 4


@dataclass(frozen=True)
class UavFlight:
    """One UAV's route, flown. ``fly_route`` returns it whole; in a ``FlightResult`` from
    ``fly_plan`` it is ``kept()``: measured, its reference and all of its track but the times
    and positions let go."""

    uav: str
    route: Route  # the route as flown (the manual pilot's is retimed)
    planned: Route  # the route of the plan (the path deviation is measured against)
    ref: Reference | None  # None once kept()
    track: Track
    photo_step: np.ndarray  # (P,) index into the track
    photo_yaw_deg: np.ndarray  # (P,) camera attitude when each photo was taken
    photo_pitch_deg: np.ndarray
    photo_roll_deg: np.ndarray
    photo_component: np.ndarray  # (P,) str
    wind_summary: dict

    @property
    def photo_pos(self) -> np.ndarray:
        return self.track.pos[self.photo_step]

    def kept(self) -> UavFlight:
        """This flight as a report keeps it once measured (``measure_flight``): the track's
        times and positions (the pictures, each UAV's time and length) and the photos; the
        reference and the rest of the track, ~200 bytes a control step, let go."""
        return replace(self, ref=None, track=self.track.positions())


@dataclass(frozen=True)
class Violation:
    kind: str  # clearance | collision | ground | transit_altitude
    uav: str
    t_start: float
    t_end: float
    worst_m: float  # the smallest clearance / height above ground in the episode
    at: tuple[float, float, float]
    what: str  # turbine part or "ground"

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "uav": self.uav, "t_start_s": self.t_start, "t_end_s": self.t_end,
                "worst_m": self.worst_m, "position": list(self.at), "what": self.what}


@dataclass(frozen=True)
class FlightResult:
    """One way of flying (automated or a baseline) over all routes, with its measurements."""

    kind: str
    controller: str
    uavs: list[UavFlight]
    turbines: list[Turbine]
    camera: Camera
    safe_distance_m: float
    target_gsd_mm: float
    time_s: float  # until the last UAV settles at its last waypoint
    path_length_m: float
    deviation: np.ndarray  # per step (all UAVs): distance to the planned path
    tracking_error: np.ndarray  # per step: distance to the time-reference
    clearance: np.ndarray  # per step: distance to the nearest turbine part
    agl: np.ndarray  # per step: height above ground
    violations: list[Violation]
    coverage: dict[str, Coverage]  # per turbine id, from the photos taken
    planned_coverage: dict[str, Coverage] | None
    photo_gsd_mm: np.ndarray  # (P,) GSD at the nearest surface, per photo
    energy_wh: dict[str, list[float]]  # per UAV, per sortie (split by landings)
    battery_wh: float
    sortie_time_s: dict[str, list[float]] = field(default_factory=dict)  # per UAV, flown
    usable_battery_s: float | None = None  # the plan's battery minus reserve (None: not stated)
    reserve_fraction: float | None = None  # the plan's reserve / battery
    tracking_margin_m: float | None = None  # the plan's tracking margin (None: not stated)
    notes: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        for name in ("deviation", "tracking_error", "clearance", "agl"):
            a = getattr(self, name)
            if not np.isfinite(a).all():
                raise ValueError(f"expected finite {name}, got non-finite values")

    # ---- summary numbers ----------------------------------------------------------------
    @property
    def coverage_average(self) -> float:
        vals = [v for c in self.coverage.values() for s in c.by_blade_side().values()
                for v in s.values()]
        return float(np.mean(vals)) if vals else 0.0

    @property
    def planned_coverage_average(self) -> float | None:
        if not self.planned_coverage:
            return None
        vals = [v for c in self.planned_coverage.values() for s in c.by_blade_side().values()
                for v in s.values()]
        return float(np.mean(vals)) if vals else 0.0

    @property
    def deviation_p999(self) -> float:
        """The 99.9th percentile of the deviation from the planned path (m): what the plan's
        tracking margin must cover."""
        return float(np.percentile(self.deviation, 99.9)) if len(self.deviation) else 0.0

    def sorties_flown(self) -> list[dict[str, Any]]:
        """Per UAV and sortie: flown time, energy, share of the battery, and whether the battery
        reserve stayed intact (None where the plan does not state its battery)."""
        out = []
        for uav, es in self.energy_wh.items():
            for i, e in enumerate(es):
                d = self.sortie_time_s.get(uav, [math.nan] * len(es))[i]
                ok = None
                if self.usable_battery_s is not None:
                    ok = not _reserve_eaten(d, e, self.usable_battery_s, self.reserve_fraction,
                                            self.battery_wh)
                out.append({"uav": uav, "sortie": i + 1, "time_s": d, "energy_wh": e,
                            "battery_used_pct": 100.0 * e / self.battery_wh, "reserve_intact": ok})
        return out

    def warnings(self) -> list[str]:
        """What a user must hear about this flight: every safety violation, a deviation beyond
        the plan's tracking margin, a sortie that ate into the battery reserve."""
        out = [f"{self.kind}: {describe(v)}" for v in self.violations]
        m = self.tracking_margin_m
        if m is not None and self.deviation_p999 > m:
            out.append(f"{self.kind}: 99.9 % of the flight within {self.deviation_p999:.2f} m of "
                       f"the planned path, more than the plan's tracking_margin_m ({m:g} m): plan "
                       "with a larger margin for this wind and positioning (docs/fly.md, Margins)")
        for s in self.sorties_flown():
            if s["reserve_intact"] is False:
                out.append(f"{self.kind}: {s['uav']} sortie {s['sortie']} ate into the battery "
                           f"reserve ({s['time_s'] / 60:.1f} min, {s['battery_used_pct']:.0f} % of "
                           "the battery)")
        return out

    @property
    def photos(self) -> int:
        return int(sum(len(u.photo_step) for u in self.uavs))

    @property
    def min_clearance_m(self) -> float:
        return float(self.clearance.min()) if len(self.clearance) else math.inf

    def summary(self) -> dict[str, Any]:
        """The headline numbers (the paper's Table 1 columns and ours)."""
        return {"time_min": self.time_s / 60.0, "length_m": self.path_length_m,
                "coverage_pct": 100.0 * self.coverage_average,
                "deviation_m": float(self.deviation.mean()),
                "min_clearance_m": self.min_clearance_m, "violations": len(self.violations)}

    def to_dict(self) -> dict[str, Any]:
        dev, trk = self.deviation, self.tracking_error
        cov = {tid: {"blade_sides": c.by_blade_side(), "blade_average": c.blade_average(),
                     "structure": c.structure_fraction()} for tid, c in self.coverage.items()}
        gsd = self.photo_gsd_mm
        per_uav = []
        for u in self.uavs:
            per_uav.append({"uav": u.uav, "photos": int(len(u.photo_step)),
                            "flight_time_s": float(u.track.t[-1] - u.track.t[0]),
                            "path_length_m": _length(u.track.pos),
                            "energy_wh": sum(self.energy_wh[u.uav]),
                            "sorties": len(self.energy_wh[u.uav]),
                            "battery_used_pct_per_sortie": [100.0 * e / self.battery_wh
                                                            for e in self.energy_wh[u.uav]],
                            "wind": u.wind_summary})
        return {
            "kind": self.kind, "controller": self.controller,
            "time_s": self.time_s, "path_length_m": self.path_length_m,
            "deviation_m": {"mean": float(dev.mean()), "rms": float(np.sqrt((dev ** 2).mean())),
                            "p99_9": self.deviation_p999, "max": float(dev.max()),
                            "tracking_margin_m": self.tracking_margin_m,
                            "within_margin": None if self.tracking_margin_m is None
                            else self.deviation_p999 <= self.tracking_margin_m},
            "tracking_error_m": {"mean": float(trk.mean()), "rms": float(np.sqrt((trk ** 2).mean())),
                                 "max": float(trk.max())},
            "clearance": {"min_m": self.min_clearance_m, "safe_distance_m": self.safe_distance_m,
                          "violations": [v.to_dict() for v in self.violations]},
            "min_height_above_ground_m": float(self.agl.min()),
            "coverage": {"blade_average": self.coverage_average,
                         "planned_blade_average": self.planned_coverage_average,
                         "per_turbine": cov},
            "photos": {"count": self.photos, "target_gsd_mm": self.target_gsd_mm,
                       "gsd_nearest_surface_mm": {
                           "mean": float(gsd.mean()) if len(gsd) else None,
                           "median": float(np.median(gsd)) if len(gsd) else None,
                           "max": float(gsd.max()) if len(gsd) else None,
                           "over_target": int((gsd > self.target_gsd_mm * 1.05).sum())}},
            "battery": {"energy_wh": float(sum(sum(v) for v in self.energy_wh.values())),
                        "capacity_wh": self.battery_wh,
                        "sorties": int(sum(len(v) for v in self.energy_wh.values())),
                        "max_used_pct": 100.0 * max(max(v) for v in self.energy_wh.values())
                        / self.battery_wh,
                        "usable_s": self.usable_battery_s,
                        "sorties_flown": self.sorties_flown()},
            "uavs": per_uav, "notes": self.notes,
        }


def _length(pos: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(pos, axis=0), axis=1).sum())


# ---- flying ----------------------------------------------------------------------------------

def _rng(scn: Scenario, uav_index: int, stream: int) -> np.random.Generator:
    return np.random.default_rng([scn.seed, uav_index, stream])


def fly_route(route: Route, scn: Scenario, ground: Ground, uav_index: int, mode: str,
              planned: Route | None = None, turbines: tuple | list = ()) -> UavFlight:
    """Fly one route. ``mode``: pid, feedforward or pilot (the route is retimed for the pilot).
    ``turbines``: the structures whose wake and RTK shadow the flight meets."""
    dt = 1.0 / scn.control.control_hz
    planned = planned or route
    flown = manual_route(route, scn.manual_pilot)[0] if mode == "pilot" else route
    c = scn.control
    # The gimbal stops at its limits: a plan asking for more is flown (and photographed) there.
    lo, hi = scn.vehicle.gimbal_pitch_min_deg, scn.vehicle.gimbal_pitch_max_deg
    # A set-point that waits for the vehicle (control.leash_m) needs room after the route's end:
    # the flight stops once it got there and settled, so unused room costs only precomputation.
    leashed = mode == "pid" and c.leash_m > 0
    slack = LEASH_SLACK_S + LEASH_SLACK_FRAC * float(flown.t[-1] - flown.t[0]) if leashed else 0.0
    ref = make_reference(flown.t, flown.pos, flown.yaw_deg, np.clip(flown.gimbal_pitch_deg, lo, hi),
                         dt, c.reference_smoothing_s, c.reference_accel_ms2, c.corner_deviation_m,
                         speed=flown.speed, yaw_rate=scn.vehicle.yaw_rate_deg_s,
                         pitch_rate=scn.vehicle.gimbal_rate_deg_s, settle_s=SETTLE_S + slack)
    n = len(ref.t)
    g_ref = ground.height(ref.pos)
    agl_ref = ref.pos[:, 2] - g_ref
    h_rep = float(np.median(agl_ref))
    wind = make_wind(scn.wind, scn.terrain.turbulence_factor, n * scn.substeps, dt / scn.substeps,
                     max(h_rep, 3.0), _rng(scn, uav_index, _WIND),
                     heights=np.repeat(np.maximum(agl_ref, 3.0), scn.substeps))
    pilot = None
    prng = _rng(scn, uav_index, _PILOT)
    if mode == "pilot":
        pilot = pilot_inputs(scn.manual_pilot, n, dt, prng)
    pz = scn.positioning
    shadow = None
    if pz.rtk_degrades_near_tower and turbines:
        shadow = tower_shadow(ref.pos, [(np.asarray(t.base, float), t.hub_height) for t in turbines],
                              pz.rtk_degrade_distance_m)
    nav = make_navigation(pz.mode, n, dt, _rng(scn, uav_index, _SENSOR),
                          scn.vehicle.position_noise_m, scn.vehicle.velocity_noise_ms,
                          near_tower=shadow, refix_s=pz.rtk_refix_s)
    wake, wake_info = None, {"steps_in_wake": 0.0, "max_deficit_ms": 0.0}
    if scn.wind.wake and scn.wind.speed_ms > 0 and turbines:
        speed = np.asarray(mean_speed(scn.wind, np.maximum(agl_ref, 1.0)), float)
        wake, wake_info = wake_series(list(turbines), ref.pos, ref.t, wind.unit, speed,
                                      _rng(scn, uav_index, _WAKE))
    track = fly(ref, scn, wind, g_ref, make_controller(mode, ref, scn, pilot), nav, wake)
    if track.progress is not None:  # the set-point's clock was held back: the reference flown
        ref = ref.retimed(track.progress, dt)

    steps = ref.reach_step(np.nonzero(flown.photo)[0])  # photos when the set-point gets there
    yaw = track.yaw_deg[steps].copy()
    pitch = track.pitch_deg[steps].copy()
    if mode == "pilot" and len(steps):
        aim = ou_series(prng, len(steps), 1.0, scn.manual_pilot.aim_sigma_deg, 1e-3, dims=2)
        yaw += aim[:, 0]
        pitch = np.clip(pitch + aim[:, 1], lo, hi)
    roll = _camera_roll(track, steps, yaw, scn.vehicle.gimbal_roll_leak)
    comp = flown.component[flown.photo]
    return UavFlight(uav=route.uav, route=flown, planned=planned, ref=ref, track=track,
                     photo_step=steps, photo_yaw_deg=yaw, photo_pitch_deg=pitch,
                     photo_roll_deg=roll, photo_component=comp,
                     wind_summary={"height_m": h_rep, **wind.summary(), "wake": wake_info,
                                   "positioning": nav.summary()})


def _camera_roll(track: Track, steps: np.ndarray, yaw_deg: np.ndarray, leak: float) -> np.ndarray:
    """Camera roll let through by the gimbal: ``leak`` times the body bank seen along the view."""
    if leak <= 0 or not len(steps):
        return np.zeros(len(steps))
    T = track.thrust[steps] + np.array([0, 0, G])
    y = np.radians(yaw_deg)
    right = np.stack([np.cos(y), -np.sin(y), np.zeros_like(y)], 1)
    bank = np.degrees(np.arctan2((T * right).sum(1), T[:, 2]))
    return leak * bank


# ---- measuring --------------------------------------------------------------------------------

def path_deviation(path: np.ndarray, segment: np.ndarray, pos: np.ndarray, window: int = 8,
                   chunk: int = 8192) -> np.ndarray:
    """Distance from each position to the planned polyline ``path`` (M, 3), searched among the
    ``window`` segments either side of ``segment`` (the one the set-point is on), vectorised."""
    a_all, b_all = path[:-1], path[1:]
    m = len(a_all)
    j = np.clip(np.asarray(segment, int), 0, m - 1)
    offs = np.arange(-window, window + 1)
    out = np.empty(len(pos))
    for s in range(0, len(pos), chunk):
        J = np.clip(j[s:s + chunk, None] + offs, 0, m - 1)
        a, b = a_all[J], b_all[J]
        ab = b - a
        ap = pos[s:s + chunk, None, :] - a
        den = np.maximum((ab * ab).sum(-1), 1e-12)
        u = np.clip((ap * ab).sum(-1) / den, 0.0, 1.0)
        d = np.linalg.norm(ap - u[..., None] * ab, axis=-1)
        out[s:s + chunk] = d.min(1)
    return out


def turbine_clearance(turbines: list[Turbine], pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per point: clearance to the nearest turbine part and its name ("T1/blade2"): the
    project's one clearance, ``wtcli.plan.clearance.clearance_to_parts`` (exact near a turbine,
    capped at its cull distance far away)."""
    return clearance_to_parts(turbines, np.asarray(pos, float))


# ---- the plan, checked before flying ----------------------------------------------------------

PREFLIGHT_STEP_M = 0.25  # spacing of the samples along each planned leg


def plan_violations(plan: Plan) -> list[Violation]:
    """Every place where the planned path itself (waypoints and the straight legs between them,
    sampled every PREFLIGHT_STEP_M) comes closer to a turbine part than the plan's safe distance:
    ``collision`` where it runs inside a part, ``clearance`` elsewhere, with the planned times.
    A plan from ``wtinspect plan`` has none; an edited one may."""
    out: list[Violation] = []
    for r in plan.routes:
        if len(r) == 0:
            continue
        p0, p1 = r.pos[:-1], r.pos[1:]
        L = np.linalg.norm(p1 - p0, axis=1)
        n = np.maximum(1, np.ceil(L / PREFLIGHT_STEP_M).astype(int))
        leg = np.repeat(np.arange(len(L)), n)
        frac = (np.arange(len(leg)) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n, n)
        P = np.concatenate([p0[leg] + frac[:, None] * (p1 - p0)[leg], r.pos[-1:]])
        T = np.concatenate([r.t[:-1][leg] + frac * np.diff(r.t)[leg], r.t[-1:]])
        c, part = turbine_clearance(plan.turbines, P)
        for kind, mask in (("collision", c <= 0.0), ("clearance", (c > 0.0) & (c < plan.safe_distance_m))):
            for a, b in _episodes(mask):
                i = a + int(np.argmin(c[a:b]))
                out.append(Violation(kind, r.uav, float(T[a]), float(T[b - 1]), float(c[i]),
                                     tuple(float(x) for x in P[i]), str(part[i])))
    out.sort(key=lambda v: (v.t_start, v.uav, v.kind))
    return out


def describe(v: Violation) -> str:
    """One violation in words: "collision with T1/tower at t=12.0-13.4 s (UAV1)"."""
    when = f"t={v.t_start:.1f} s" if v.t_end - v.t_start < 0.05 else f"t={v.t_start:.1f}-{v.t_end:.1f} s"
    if v.kind == "collision":
        return f"collision with {v.what} at {when} ({v.uav})"
    if v.kind == "clearance":
        return f"clearance {v.worst_m:.2f} m to {v.what} at {when} ({v.uav})"
    return f"{v.kind}: {v.worst_m:.2f} m above the ground at {when} ({v.uav})"


def _episodes(mask: np.ndarray) -> list[tuple[int, int]]:
    if not mask.any():
        return []
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]))


def _sorties(f: UavFlight, scn: Scenario, ground: Ground) -> list[tuple[float, float]]:
    """(energy Wh, flown time s) of each sortie. Momentum-theory power, P = P_hover (|T| / g)^1.5
    plus climb power m g v_z / eta; zero while the vehicle stands on the ground (``on_ground``,
    the set-point still: motors off, a battery swap), which also separates the sorties. A
    sortie's time runs from its take-off (the start, or the end of a swap) to its landing (the
    last one: the set-point reaching the last waypoint), as the planner counts it against
    battery minus reserve."""
    veh, track, ref = scn.vehicle, f.track, f.ref
    T = np.linalg.norm(track.thrust + np.array([0, 0, G]), axis=1)
    p = veh.hover_power_w * (T / G) ** 1.5
    p += veh.mass_kg * G * np.maximum(track.vel[:, 2], 0.0) / veh.propulsion_efficiency
    dt = float(track.t[1] - track.t[0]) if len(track.t) > 1 else 0.0
    # The plan says so: the set-point stands still on the ground it took off from.
    landed = on_ground(ref.pos, launch_point(f.planned), ground) \
        & (np.linalg.norm(ref.vel, axis=1) < 0.05)
    p = np.where(landed, 0.0, p)
    t = track.t
    sorties, start = [], 0
    for a, b in _episodes(landed):
        if (b - a) * dt >= 5.0:
            sorties.append((float(p[start:a].sum() * dt / 3600.0), float(t[a] - t[start])))
            start = b
    last = min(max(ref.end_index - 1, start), len(t) - 1)
    sorties.append((float(p[start:].sum() * dt / 3600.0), float(t[last] - t[start])))
    kept = [s for s in sorties if s[0] > 0.01 * veh.battery_wh]
    return kept or [(sum(s[0] for s in sorties), sum(s[1] for s in sorties))]


def plan_number(plan: Plan, key: str, lo: float, hi: float) -> float | None:
    """A number the plan's summary states for ``fly`` (tracking margin, battery), checked: None
    where an older plan does not state it; InputError where it is not a number in [lo, hi]."""
    v = plan.summary.get(key) if isinstance(plan.summary, dict) else None
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
            or not lo <= v <= hi:
        raise InputError(f"plan summary.{key}: expected a number in [{lo:g}, {hi:g}], "
                         f"got {str(v)[:40]}")
    return float(v)


MEASURE_BLOCK = 65536  # steps whose clearance and height are found at a time


@dataclass(frozen=True)
class UavMeasures:
    """One UAV's flight measured at every control step until it settled (``measure_flight``):
    what the report needs of its track and reference."""

    uav: str
    time_s: float  # until it settles within SETTLED_M of its last waypoint
    length_m: float  # flown until then
    deviation: np.ndarray  # (K,) distance to the planned path
    tracking_error: np.ndarray  # (K,) distance to the reference flown
    clearance: np.ndarray  # (K,) distance to the nearest turbine part
    agl: np.ndarray  # (K,) height above ground
    violations: list[Violation]
    sorties: list[tuple[float, float]]  # (energy Wh, flown time s) of each sortie


def measure_flight(f: UavFlight, plan: Plan, scn: Scenario, ground: Ground) -> UavMeasures:
    """Measure one UAV's whole flight (``f`` as ``fly_route`` returns it) at every control step:
    deviation, tracking error, clearance to every turbine part, height above ground, the
    violations of them, the sorties' energy and time."""
    tr, ref = f.track, f.ref
    if ref is None:
        raise ValueError(f"expected {f.uav}'s flight as flown (with its reference), got one "
                         "already measured and kept")
    # Time: until it settles within SETTLED_M of its last waypoint after the reference ends (or
    # the end of the settle window).
    end = ref.end_index
    d_end = np.linalg.norm(tr.pos[end:] - f.route.pos[-1], axis=1)
    settled = np.nonzero(d_end < SETTLED_M)[0]
    k_end = end + (int(settled[0]) if len(settled) else len(d_end) - 1)
    sl = slice(0, k_end + 1)
    P, T, REF = tr.pos[sl], tr.t[sl], ref.pos[sl]
    wp = np.floor(ref.wp_index[sl]).astype(int)
    deviation = path_deviation(f.route.pos, wp, P)
    tracking = np.linalg.norm(P - REF, axis=1)
    # Every step, a block at a time (the parts' distances of all steps at once take ~130 bytes
    # a step). Both are per point: the blocks change no clearance, and a hilly ground's height
    # at most in its last bit (its matrix product rounds by how many points it is given).
    n = len(P)
    clearance, agl, ref_agl = np.empty(n), np.empty(n), np.empty(n)
    part = np.empty(n, dtype=object)
    for s0 in range(0, n, MEASURE_BLOCK):
        s1 = min(n, s0 + MEASURE_BLOCK)
        clearance[s0:s1], part[s0:s1] = turbine_clearance(plan.turbines, P[s0:s1])
        agl[s0:s1] = P[s0:s1, 2] - ground.height(P[s0:s1])
        ref_agl[s0:s1] = REF[s0:s1, 2] - ground.height(REF[s0:s1])

    violations: list[Violation] = []

    def add(kind_: str, mask: np.ndarray, values: np.ndarray, what: np.ndarray | str) -> None:
        for a, b in _episodes(mask):
            i = a + int(np.argmin(values[a:b]))
            violations.append(Violation(kind_, f.uav, float(T[a]), float(T[b - 1]),
                                        float(values[i]), tuple(float(x) for x in P[i]),
                                        str(what if isinstance(what, str) else what[i])))

    add("collision", clearance <= 0.0, clearance, part)
    add("clearance", (clearance < plan.safe_distance_m) & (clearance > 0.0), clearance, part)
    planned_low = ref_agl < scn.terrain.min_agl_m + 2.0  # take-off and landing: planned low
    add("ground", (agl < scn.terrain.min_agl_m) & ~planned_low, agl, "ground")
    # The component of the leg the set-point is on.
    transit = np.array(["transit" in str(c) for c in f.route.component], bool)
    transit = transit[np.clip(wp + 1, 0, len(f.route) - 1)]
    level = np.abs(ref.vel[sl, 2]) < 0.5
    # Level transit legs (not the climb out or the descent to land) must keep the terrain's
    # transit height: a plan made for flat ground can be too low over a hill.
    add("transit_altitude", transit & level & ~planned_low & (agl < scn.terrain.min_transit_agl_m),
        agl, "ground")
    return UavMeasures(uav=f.uav, time_s=float(tr.t[k_end] - tr.t[0]), length_m=_length(P),
                       deviation=deviation, tracking_error=tracking, clearance=clearance, agl=agl,
                       violations=violations, sorties=_sorties(f, scn, ground))


def measure(kind: str, controller: str, plan: Plan, flights: list[UavFlight], scn: Scenario,
            ground: Ground, planned_coverage: bool = False, notes: list[str] | None = None,
            measured: list[UavMeasures] | None = None) -> FlightResult:
    """The flights of one kind, measured: ``measured`` (one per flight, in order) where
    ``measure_flight`` has measured them as they were flown, else measured here (``flights``
    then as ``fly_route`` returns them)."""
    if measured is None:
        measured = [measure_flight(f, plan, scn, ground) for f in flights]
    if len(measured) != len(flights):
        raise ValueError(f"expected {len(flights)} measured flights, got {len(measured)}")
    violations = sorted((v for m in measured for v in m.violations),
                        key=lambda v: (v.t_start, v.uav, v.kind))

    # Photos: real poses -> the one coverage measure.
    cam = plan.camera
    ppos = np.concatenate([f.photo_pos for f in flights]) if flights else np.zeros((0, 3))
    rots = np.array([Camera.rotation_from_yaw_pitch(y, p, r) for f in flights
                     for y, p, r in zip(f.photo_yaw_deg, f.photo_pitch_deg, f.photo_roll_deg)]
                    ).reshape(-1, 3, 3)
    coverage = _coverage(plan, cam, ppos, rots, scn)
    pcov = None
    if planned_coverage:
        pp, pr = [], []
        for f in flights:
            r = f.planned
            pp.append(r.pos[r.photo])
            pr += [Camera.rotation_from_yaw_pitch(y, p) for y, p in
                   zip(r.yaw_deg[r.photo], r.gimbal_pitch_deg[r.photo])]
        pcov = _coverage(plan, cam, np.concatenate(pp), np.array(pr).reshape(-1, 3, 3), scn)
    gsd = cam.gsd_mm(turbine_clearance(plan.turbines, ppos)[0]) if len(ppos) else np.zeros(0)
    sorties = {f.uav: m.sorties for f, m in zip(flights, measured)}
    energy = {u: [e for e, _ in v] for u, v in sorties.items()}
    sortie_time = {u: [d for _, d in v] for u, v in sorties.items()}
    notes = list(notes or [])
    asked = np.concatenate([f.route.gimbal_pitch_deg[f.route.photo] for f in flights]) \
        if flights else np.zeros(0)
    lo, hi = scn.vehicle.gimbal_pitch_min_deg, scn.vehicle.gimbal_pitch_max_deg
    beyond = (asked > hi + 1e-6) | (asked < lo - 1e-6)
    if beyond.any():
        worst = float(asked[beyond][np.argmax(np.abs(asked[beyond]))])
        notes.append(f"{kind}: {int(beyond.sum())} of {len(asked)} photos ask the gimbal for pitch "
                     f"beyond the vehicle's [{lo:+g}, {hi:+g}] deg (up to {worst:+.0f}): taken at "
                     "the limit (plan with fleet.gimbal_pitch_*_deg to avoid it)")
    for uav, es in energy.items():
        for i, e in enumerate(es):
            if e > scn.vehicle.battery_wh:
                notes.append(f"{kind}: {uav} sortie {i + 1} needs {100 * e / scn.vehicle.battery_wh:.0f} "
                             f"% of a battery ({math.ceil(e / scn.vehicle.battery_wh) - 1} more "
                             "swap(s); the simulation flies on without landing)")
    battery_min = plan_number(plan, "battery_minutes", 0.1, 1e4)
    reserve_min = plan_number(plan, "battery_reserve_minutes", 0.0, 1e4)
    usable_s = 60.0 * (battery_min - reserve_min) if battery_min is not None \
        and reserve_min is not None else None
    reserve_frac = reserve_min / battery_min if usable_s is not None else None
    if usable_s is not None:
        for uav in sortie_time:
            for i, (d, e) in enumerate(zip(sortie_time[uav], energy[uav])):
                for why in _reserve_eaten(d, e, usable_s, reserve_frac, scn.vehicle.battery_wh):
                    notes.append(f"{kind}: {uav} sortie {i + 1} {why}: the battery reserve "
                                 "was eaten into")
    return FlightResult(
        kind=kind, controller=controller, uavs=flights, turbines=list(plan.turbines), camera=cam,
        safe_distance_m=plan.safe_distance_m, target_gsd_mm=plan.target_gsd_mm,
        time_s=max(m.time_s for m in measured),
        path_length_m=float(sum(m.length_m for m in measured)),
        deviation=np.concatenate([m.deviation for m in measured]),
        tracking_error=np.concatenate([m.tracking_error for m in measured]),
        clearance=np.concatenate([m.clearance for m in measured]),
        agl=np.concatenate([m.agl for m in measured]), violations=violations, coverage=coverage,
        planned_coverage=pcov,
        photo_gsd_mm=np.asarray(gsd, float), energy_wh=energy, battery_wh=scn.vehicle.battery_wh,
        sortie_time_s=sortie_time, usable_battery_s=usable_s, reserve_fraction=reserve_frac,
        tracking_margin_m=plan_number(plan, "tracking_margin_m", 0.0, 1000.0), notes=notes)


def _reserve_eaten(time_s: float, energy_wh: float, usable_s: float, reserve_frac: float,
                   battery_wh: float) -> list[str]:
    """Why a sortie ate into the battery reserve (nothing if it did not): flown longer than
    battery minus reserve (the plan's minutes), or used more energy than the battery less the
    same share held back."""
    out = []
    if time_s > usable_s + 1e-6:
        out.append(f"flew {time_s / 60:.2f} min, more than battery minus reserve "
                   f"({usable_s / 60:.2f} min)")
    usable_wh = battery_wh * (1.0 - reserve_frac)
    if energy_wh > usable_wh + 1e-9:
        out.append(f"used {energy_wh:.0f} Wh, more than the {usable_wh:.0f} Wh of the battery "
                   f"above its reserve")
    return out


def _coverage(plan: Plan, cam: Camera, pos: np.ndarray, rots: np.ndarray,
              scn: Scenario) -> dict[str, Coverage]:
    out = {}
    for t in plan.turbines:
        samples = t.surface_samples(scn.sample_spacing_m)
        out[t.id] = measure_coverage(samples, cam, pos, rots, plan.target_gsd_mm)
    return out


# ---- the whole run ---------------------------------------------------------------------------

def fly_routes(plan: Plan, scn: Scenario, ground: Ground, mode: str,
               tick: Callable[[], None] = lambda: None) -> list[UavFlight]:
    """Every route of ``plan``, flown whole (for ``measure``)."""
    out = []
    for i, r in enumerate(plan.routes):
        out.append(fly_route(r, scn, ground, i, mode, turbines=plan.turbines))
        tick()
    return out


def fly_and_measure(plan: Plan, scn: Scenario, ground: Ground, mode: str,
                    tick: Callable[[], None] = lambda: None
                    ) -> tuple[list[UavFlight], list[UavMeasures]]:
    """Every route of ``plan``, each measured as soon as it is flown and then ``kept()``: a
    wide site's report holds its routes' per-step measures, not every route's whole track and
    reference (docs/fly.md "Memory"). ``measure(..., measured=...)`` takes the pair."""
    flights, measured = [], []
    for i, r in enumerate(plan.routes):
        f = fly_route(r, scn, ground, i, mode, turbines=plan.turbines)
        measured.append(measure_flight(f, plan, scn, ground))
        flights.append(f.kept())
        del f  # not alive beside the next route's simulation
        tick()
    return flights, measured


def launch_point(route: Route) -> np.ndarray | None:
    """Where ``route`` takes off, on the ground: its first waypoint where the plan marks it
    ``launch`` (``wtinspect plan``'s routes start and end at the launch point on the ground,
    docs/plan.md); None for a route that starts in the air (a plan built by hand)."""
    if len(route) == 0 or str(route.component[0]) != "launch":
        return None
    return np.asarray(route.pos[0], float)


def make_ground(plan: Plan, scn: Scenario) -> Ground:
    """The scenario's ground, level with each turbine's base and each route's launch point
    (``wtcli.fly.terrain``: flat ground at the height of the nearest of them, as planned)."""
    pads = [t.base for t in plan.turbines]
    pads += [p for p in (launch_point(r) for r in plan.routes) if p is not None]
    return Ground.build(scn.terrain, np.array(pads, float), scn.seed)


def on_ground(pos: np.ndarray, launch: np.ndarray | None, ground: Ground) -> np.ndarray:
    """(N,) bool: each point stands on the ground: within LANDED_M of the launch point it took
    off from (the plan's, at its own height) or less than LANDED_M above the terrain under it.
    The one notion of landed, for the sorties flown and the plan's sorties checked before."""
    P = np.atleast_2d(np.asarray(pos, float))
    down = (P[:, 2] - ground.height(P)) < LANDED_M
    if launch is not None:
        down |= np.linalg.norm(P - launch, axis=1) < LANDED_M
    return down


@dataclass(frozen=True)
class FlightReport:
    """The automated flight and its baselines under one scenario (schema wtinspect.flight)."""

    scenario: Scenario
    flights: dict[str, FlightResult]
    plan_source: str | None = None
    notes: list[str] = field(default_factory=list)
    preflight: list[Violation] = field(default_factory=list)  # the plan's own, before flying

    def __post_init__(self) -> None:
        if "automated" not in self.flights:
            raise ValueError("expected an 'automated' flight in the report")
        for k in self.flights:
            if k not in FLIGHT_KINDS:
                raise ValueError(f"expected flight kinds in {FLIGHT_KINDS}, got {k!r}")

    @property
    def automated(self) -> FlightResult:
        return self.flights["automated"]

    def violations(self) -> list[Violation]:
        return self.automated.violations

    def to_dict(self) -> dict[str, Any]:
        s = self.scenario
        return {"scenario": {"name": s.name, "description": s.description, "seed": s.seed,
                             "source": str(s.source) if s.source else None,
                             "wind": {"speed_ms": s.wind.speed_ms,
                                      "reference_height_m": s.wind.reference_height_m,
                                      "direction_deg": s.wind.direction_deg,
                                      "turbulence": s.wind.turbulence_model,
                                      "gusts_per_min": s.wind.gust_rate_per_min},
                             "terrain": s.terrain.kind},
                "plan": self.plan_source,
                "flights": {k: f.to_dict() for k, f in self.flights.items()},
                "summary": {k: f.summary() for k, f in self.flights.items()},
                "paper": s.paper, "notes": self.notes,
                "preflight": {"violations": [v.to_dict() for v in self.preflight]}}

    def warnings(self) -> list[str]:
        """Every violation of the plan itself, a tracking margin below the one documented for
        the scenario's positioning, then the automated flight's warnings."""
        out = [f"plan: {describe(v)}" for v in self.preflight]
        m = self.automated.tracking_margin_m
        mode, need = documented_margin(self.scenario)
        if m is not None and need is not None and m < need - 1e-9:
            out.append(f"plan: tracking_margin_m {m:g} m is below the {need:g} m documented for "
                       f"{mode} positioning in wind up to {SAFE_HUB_WIND_MS:g} m/s at hub height "
                       f"(docs/fly.md, Margins)")
        hub = hub_wind_ms(self.scenario, self.automated.turbines)
        if hub > SAFE_HUB_WIND_MS + 1e-9:
            out.append(f"wind: {hub:.1f} m/s mean at hub height is above the {SAFE_HUB_WIND_MS:g} "
                       f"m/s that close inspection was shown safe in; at 12 m/s flights in every "
                       f"positioning mode left the path by up to 23 m (docs/fly.md, Margins): "
                       f"do not fly")
        return out + self.automated.warnings()


# The tracking margin docs/fly.md ("Margins") documents per positioning mode: no clearance
# violation and every flight's 99.9th percentile within it over 20 seeds of paper-s2 at 8 and
# 10 m/s mean wind at hub height (benchmarks/fly_margins.py). RTK that may degrade near the
# tower counts as float. At 12 m/s flights left the path by 21-23 m (gusts beyond the vehicle's
# rated wind), so no margin is documented above SAFE_HUB_WIND_MS and `fly` warns there.
DOCUMENTED_MARGIN_M = {"rtk_fixed": 2.0, "rtk_float": 3.0, "gnss": 4.5}
SAFE_HUB_WIND_MS = 10.0


def hub_wind_ms(scn: Scenario, turbines) -> float:
    """The scenario's mean wind (with its shear) at the highest hub of ``turbines``; at the
    reference height when there is none."""
    heights = [t.hub_height for t in turbines] or [scn.wind.reference_height_m]
    return float(max(mean_speed(scn.wind, h) for h in heights))


def documented_margin(scn: Scenario) -> tuple[str, float | None]:
    """(positioning mode, the margin documented for it; None for ``ideal``)."""
    mode = scn.positioning.mode
    if mode == "rtk_fixed" and scn.positioning.rtk_degrades_near_tower:
        mode = "rtk_float"
    return mode, DOCUMENTED_MARGIN_M.get(mode)


# A plan is refused before flying when a leg needs more than LEG_SLACK_FACTOR times its planned
# time plus LEG_SLACK_S at the vehicle's top speeds (a planner's plan never does; a waypoint
# moved by hand does), or a sortie needs more than SORTIE_BATTERY_FACTOR times the battery's
# hover endurance at top speed: flying either would take minutes and prove nothing.
LEG_SLACK_FACTOR, LEG_SLACK_S, SORTIE_BATTERY_FACTOR = 4.0, 30.0, 2.0


def check_feasible(plan: Plan, scn: Scenario, ground: Ground, source: str) -> None:
    """Raise InputError (exit 3) naming the first waypoint the vehicle cannot reach within the
    plan's timing, or the first sortie far beyond its battery (see LEG_SLACK_FACTOR)."""
    veh = scn.vehicle
    endurance_s = veh.battery_wh * 3600.0 / veh.hover_power_w
    for ri, r in enumerate(plan.routes):
        P = np.asarray(r.pos, float)
        if len(P) < 2:
            continue
        d = np.diff(P, axis=0)
        t_min = np.maximum(np.hypot(d[:, 0], d[:, 1]) / veh.max_speed_ms,
                           np.where(d[:, 2] > 0, d[:, 2] / veh.max_climb_ms,
                                    -d[:, 2] / veh.max_descent_ms))
        planned = np.maximum(np.diff(np.asarray(r.t, float)), 0.0)
        bad = np.nonzero(t_min > LEG_SLACK_FACTOR * planned + LEG_SLACK_S)[0]
        if len(bad):
            i = int(bad[0])
            raise InputError(
                f"{source}: routes[{ri}].waypoints[{i + 1}] is {np.linalg.norm(d[i]):.0f} m from "
                f"waypoints[{i}]: at least {t_min[i]:.0f} s at the vehicle's top speed "
                f"({veh.max_speed_ms:g} m/s), the plan gives the leg {planned[i]:.1f} s; not "
                "flown (a waypoint moved by hand?)")
        # Sorties: split where the plan stands on the ground (a battery swap), as flown.
        down = on_ground(P, launch_point(r), ground)
        start = 0
        for j in range(1, len(P) + 1):
            if j == len(P) or (down[j] and j > start):
                need = float(t_min[start:j].sum()) if j > start else 0.0
                if need > SORTIE_BATTERY_FACTOR * endurance_s:
                    raise InputError(
                        f"{source}: routes[{ri}].waypoints[{start}] to "
                        f"waypoints[{min(j, len(P) - 1)}]: a "
                        f"sortie of at least {need / 60:.0f} min at the vehicle's top speed, the "
                        f"battery ({veh.battery_wh:g} Wh) hovers {endurance_s / 60:.0f} min; "
                        "not flown (a waypoint moved by hand?)")
                start = j


def fly_plan(plan: Plan, scn: Scenario, baselines: bool = False, fixed_plan: Plan | None = None,
             plan_source: str | None = None, progress: StageProgress | None = None) -> FlightReport:
    """Fly ``plan`` (and the baselines the scenario enables, if ``baselines``).

    progress: ``progress(kind, done, total)`` per flight kind (FLIGHT_KINDS), counting its
    routes flown and then its measurement (total: routes + 1)."""
    preflight = plan_violations(plan)
    hits = [v for v in preflight if v.kind == "collision"]
    if hits:
        shown_ = "; ".join(describe(v) for v in hits[:5])
        more = f"; and {len(hits) - 5} more" if len(hits) > 5 else ""
        raise PlanError(f"{plan_source or 'plan'}: the planned path runs inside the turbine "
                        f"{len(hits)} time(s), not flown: {shown_}{more}")
    ground = make_ground(plan, scn)
    check_feasible(plan, scn, ground, plan_source or "plan")
    notes = []
    todo = [("automated", "pid", plan)]
    if baselines and scn.baselines.no_compensation:
        todo.append(("no_compensation", "feedforward", plan))
    if baselines and scn.baselines.fixed_pattern:
        if fixed_plan is None:
            notes.append("fixed_pattern baseline skipped: it needs the scenario's mission to plan")
        else:
            todo.append(("fixed_pattern", "pid", fixed_plan))
    if baselines and scn.baselines.manual:
        todo.append(("manual", "pilot", plan))
    flights = {}
    for kind, mode, p in todo:
        tick = stage_ticker(progress, kind, len(p.routes) + 1)
        flown, measured = fly_and_measure(p, scn, ground, mode, tick)
        flights[kind] = measure(kind, mode, p, flown, scn, ground,
                                planned_coverage=kind == "automated", measured=measured)
        tick()
    return FlightReport(scenario=scn, flights=flights, plan_source=plan_source, notes=notes,
                        preflight=preflight)


__all__ = ["FLIGHT_KINDS", "FlightReport", "FlightResult", "UavFlight", "UavMeasures", "Violation",
           "describe", "fly_and_measure", "launch_point", "make_ground", "on_ground",
           "plan_violations", "fly_plan", "fly_route", "fly_routes", "measure", "measure_flight",
           "path_deviation", "turbine_clearance"]
