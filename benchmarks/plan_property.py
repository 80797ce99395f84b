"""The planner's promises over many random sites: plan or refuse in one line, never crash; no
point or leg inside the safe distance; no sortie into the battery reserve; every blade side
covered.

Random sites (``random_site``): 1-4 turbines spread over up to 10 km, 1-5 blades, rotor radius
20-75 m, any yaw; a quarter with a blade pointing straight down in front of the tower, a quarter
with a wide tower (base radius 3-6 m; nine in ten with an overhang that lets the blades pass
it, one in ten with 0.06-0.1 R, which a blade may cut into: refused, exit 4); a third of
the fleets with a gimbal that looks up only 20-60 deg (some also down only to -60); safe
distance 2.5-6 m, tracking margin 0-1.5 m, target GSD 1.2-2.5 mm/px; 1-3 UAVs with a battery
that reaches the far side of the site (25 min plus the round trip at cruise speed); everything
else the packaged defaults (min_side_coverage 0.9). Each site goes through the turbines.yaml
path (``mission_from_dict``) and ``plan_mission``.

Every plan written is checked without the planner's clearance code (``independent_clearance``:
closed-form distances to the hub sphere, nacelle box and tower frustum, and the blade surface
as the union of its elliptic sections, each section's distance found by bisection), on every
waypoint and on every leg sampled every ``LEG_STEP`` m, against the modelled turbines and against
each grown by its ``geometry_uncertainty_m`` (``grown_turbine``: what the real one may be); the
sorties' durations from the route's
own timeline between stops at the launch point; each side's converged coverage
(``turbine_coverage``, the figure the planner gates on) at the planner's sampling and at half of
it, with the largest change between the two.

    python benchmarks/plan_property.py [N] [--start SEED] [--jobs J] [--log cases.jsonl]
    python benchmarks/plan_property.py --from-log cases.jsonl   # summarise a logged run

The full figure is ``python benchmarks/plan_property.py 1000 --jobs 2 --log cases.jsonl`` (about
30-60 min on 2 cores; a stopped run is summarised with ``--from-log``); ``N=100`` is enough while
developing.

writes ``benchmarks/results/plan_property.json`` (``benchmarks/_results.py``: with the command,
date and machine).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
import traceback
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

LEG_STEP = 0.1  # m between leg samples: the distance can dip at most half of it between two
COARSE_STEP = 0.25  # m between blade sections searched first in the independent distance,
SECTION_STEP = 0.01  # then this fine round the nearest of them


# ---- random sites ------------------------------------------------------------------------------
def random_site(rng: np.random.Generator) -> dict:
    """A turbines.yaml mapping (see the module docstring)."""
    n = int(rng.integers(1, 5))
    extent = float(np.exp(rng.uniform(math.log(300.0), math.log(10_000.0))))
    turbines, placed = [], []
    for i in range(n):
        R = float(rng.uniform(20, 75))
        blades = int(rng.integers(1, 6))
        for _ in range(50):  # apart by more than two rotors (a real layout), inside the extent
            xy = rng.uniform(0, extent, 2) if i else np.zeros(2)
            if all(np.linalg.norm(xy - q) > 2 * (R + r) + 20 for q, r in placed):
                break
        placed.append((xy, R))
        t = {"id": f"T{i + 1}", "position": [float(xy[0]), float(xy[1]), float(rng.uniform(0, 20))],
             "hub_height_m": float(rng.uniform(R + 10, R + 60)), "rotor_diameter_m": 2 * R,
             "blades": blades, "yaw_deg": float(rng.uniform(0, 360)),
             "blade_pitch_deg": float(rng.choice([90.0, rng.uniform(60, 90)]))}
        first = 270.0 if rng.random() < 0.25 else float(rng.uniform(0, 360))  # straight down
        t["blade_azimuths_deg"] = [float((first + k * 360.0 / blades) % 360.0) for k in range(blades)]
        if rng.random() < 0.25:  # a wide tower
            rb = float(rng.uniform(3, 6))
            t["tower"] = {"base_radius_m": rb, "top_radius_m": float(rb * rng.uniform(0.6, 1.0))}
            if rng.random() < 0.9:  # with the overhang a real design would give it
                t["overhang_m"] = float(rb + 0.04 * R + rng.uniform(0.5, 3.0))
            else:  # a datasheet's 0.06-0.1 R, too short for this tower: a blade may cut into it
                t["overhang_m"] = float(R * rng.uniform(0.06, 0.1))
        turbines.append(t)
    # One launch point serves the whole site: a battery that reaches the far side and back at
    # cruise speed (8 m/s) on top of the default 25 min, as a wide site needs.
    far = max(float(np.linalg.norm(q)) for q, _ in placed) + 60.0
    fleet = {"uavs": int(rng.integers(1, 4)),
             "battery_minutes": round(25.0 + 2 * far / 8.0 / 60.0, 1)}
    if rng.random() < 1 / 3:
        fleet["gimbal_pitch_max_deg"] = float(rng.uniform(20, 60))
        if rng.random() < 0.5:
            fleet["gimbal_pitch_min_deg"] = float(rng.uniform(-90, -60))
    mission = {"safe_distance_m": float(rng.uniform(2.5, 6)),
               "tracking_margin_m": float(rng.uniform(0, 1.5)),
               "target_gsd_mm": float(rng.uniform(1.2, 2.5))}
    return {"fleet": fleet, "mission": mission, "turbines": turbines}


# ---- the independent distance ------------------------------------------------------------------
def _ellipse_distance(u: np.ndarray, v: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from (u, v) to the ellipse (u/a)^2 + (v/b)^2 = 1 (0 inside), by bisection on
    the Lagrange parameter t of the closest point (a*a*u/(t+a*a), b*b*v/(t+b*b)), t >= 0."""
    u, v = np.abs(u), np.abs(v)
    inside = (u / a) ** 2 + (v / b) ** 2 <= 1.0
    lo = np.zeros_like(u)
    hi = np.hypot(a * u, b * v) + 1.0  # f(hi) < 0: each term below its share of 1
    for _ in range(48):
        t = 0.5 * (lo + hi)
        f = (a * u / (t + a * a)) ** 2 + (b * v / (t + b * b)) ** 2 - 1.0
        lo = np.where(f > 0, t, lo)
        hi = np.where(f > 0, hi, t)
    t = 0.5 * (lo + hi)
    x, y = a * a * u / (t + a * a), b * b * v / (t + b * b)
    return np.where(inside, 0.0, np.hypot(u - x, v - y))


def _structure_clearance(t, P: np.ndarray) -> np.ndarray:
    """(M,) exact distance to the hub sphere, the nacelle box and the tower frustum."""
    out = np.linalg.norm(P - t.hub_center, axis=1) - t.hub_radius
    a = t.axis
    side = np.cross([0.0, 0.0, 1.0], a)
    axes = np.array([a, side, [0.0, 0.0, 1.0]])
    half = np.array([t.nacelle_length, t.nacelle_width, t.nacelle_height]) / 2
    q = np.abs((P - t.nacelle_center) @ axes.T) - half
    out = np.minimum(out, np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0))
    # tower frustum in the (radius, height) half-plane: the slanted side, the top and bottom discs
    rel = P - t.base_xyz
    rho, z = np.hypot(rel[:, 0], rel[:, 1]), rel[:, 2]
    H, rb, rt = t.tower_height, t.tower_base_radius, t.tower_top_radius
    e = np.array([rt - rb, H])
    w = np.stack([rho - rb, z], 1)
    s = np.clip(w @ e / (e @ e), 0, 1)
    d_side = np.linalg.norm(w - s[:, None] * e, axis=1)
    d_top = np.hypot(np.maximum(rho - rt, 0), z - H)
    d_bot = np.hypot(np.maximum(rho - rb, 0), z)
    r_at = rb + (rt - rb) * np.clip(z / H, 0, 1)
    inside = (z >= 0) & (z <= H) & (rho <= r_at)
    out = np.minimum(out, np.where(inside, 0.0, np.minimum(d_side, np.minimum(d_top, d_bot))))
    return np.maximum(out, 0.0)  # 0 inside a part, as the model says


def _blade_distance(t, L: np.ndarray, window: float) -> np.ndarray:
    """(M,) distance from points given in a blade's frame (span, chord, thickness) to the blade
    surface: the union of its elliptic sections, searched within ``window`` m of each point's
    own span position every ``COARSE_STEP`` m, then every ``SECTION_STEP`` m round the nearest."""
    s0, s1 = t.blade_root_offset, t.tip_radius
    coarse = np.arange(-window, window + COARSE_STEP, COARSE_STEP)
    fine = np.arange(-COARSE_STEP, COARSE_STEP + SECTION_STEP, SECTION_STEP)

    def dist(B: np.ndarray, ss: np.ndarray) -> np.ndarray:
        A_, B_ = t.blade_semi_axes((ss - s0) / (s1 - s0))
        e_in = _ellipse_distance(np.broadcast_to(B[:, 1:2], ss.shape),
                                 np.broadcast_to(B[:, 2:3], ss.shape), A_, B_)
        return np.hypot(B[:, :1] - ss, e_in)  # past an end, the span gap counts in full

    ss = np.clip(L[:, :1] + coarse[None, :], s0, s1)
    g = dist(L, ss)
    centre = ss[np.arange(len(L)), g.argmin(axis=1)]
    ss2 = np.clip(centre[:, None] + fine[None, :], s0, s1)
    return np.minimum(g.min(axis=1), dist(L, ss2).min(axis=1))


def independent_min_clearance(turbines, P: np.ndarray, near: float) -> float:
    """The least distance from any point to any part of any turbine, written apart from the
    planner's code: exact for the hub, nacelle and tower (``_structure_clearance``), the blade
    surface as the union of its sections (``_blade_distance``). A blade's sections are searched
    only for points whose lower bound (distance to the cylinder of the largest semi-chord within
    ``near`` m along the span) is below the least distance found so far, nearest first. Values
    above ``near`` are not needed exactly (a result above it means "clear by more")."""
    P = np.atleast_2d(P)
    cur = min(float(_structure_clearance(t, P).min()) for t in turbines)
    cur = min(cur, near)
    for t in turbines:
        s0, s1 = t.blade_root_offset, t.tip_radius
        grid = np.arange(s0, s1 + 0.1, 0.1)
        Ag = t.blade_semi_axes((np.clip(grid, s0, s1) - s0) / (s1 - s0))[0]
        w = int(math.ceil((near + 1) / 0.1)) + 1
        pad = np.r_[np.full(w, Ag[0]), Ag, np.full(w + 1, Ag[-1])]
        a_win = np.max([pad[i:i + len(Ag)] for i in range(2 * w + 1)], axis=0)
        a_win += 0.1 * float(np.abs(np.diff(Ag)).max() / 0.1 + 1e-9)  # between grid nodes
        for k in range(t.n_blades):
            d, c, n = t.blade_frame(k)
            L = (P - t.hub_center) @ np.array([d, c, n]).T
            idx = np.clip(np.round((L[:, 0] - s0) / 0.1).astype(int), 0, len(Ag) - 1)
            beyond = np.maximum(L[:, 0] - s1, 0) + np.maximum(s0 - L[:, 0], 0)
            lb = np.hypot(np.maximum(np.hypot(L[:, 1], L[:, 2]) - a_win[idx], 0), beyond)
            order = np.argsort(lb, kind="stable")
            order = order[lb[order] < cur]
            for i in range(0, len(order), 512):
                sel = order[i:i + 512]
                if lb[sel[0]] >= cur:
                    break
                cur = min(cur, float(_blade_distance(t, L[sel], near + 1).min()))
    return cur


def grown_turbine(t, u: float):
    """The turbine whose surfaces lie outside ``t``'s by up to ``u`` (its
    ``geometry_uncertainty_m``), built as tests/test_turbine_geometry.py's ``true_turbine``:
    blade semi-axes each grown by at most u, hub and tower radii + u, the nacelle box moved u
    forward. A plan must keep the safe distance from this one too, not only from the model."""
    from dataclasses import replace

    if u <= 0:
        return t
    g = 0.98 * u
    f = np.linspace(0, 1, 2001)
    B = t.blade_semi_axes(f)[1]

    def grown(gt: float):
        def ratio(r: float, c: float) -> float:
            return min(1.0, (r * c + 2 * gt) / (c + 2 * g))
        return replace(
            t, blade_root_chord=t.blade_root_chord + 2 * g,
            blade_max_chord=t.blade_max_chord + 2 * g, blade_tip_chord=t.blade_tip_chord + 2 * g,
            blade_root_thickness_ratio=ratio(t.blade_root_thickness_ratio, t.blade_root_chord),
            blade_max_chord_thickness_ratio=ratio(t.blade_max_chord_thickness_ratio, t.blade_max_chord),
            blade_tip_thickness_ratio=ratio(t.blade_tip_thickness_ratio, t.blade_tip_chord),
            hub_radius=t.hub_radius + g, tower_base_radius=t.tower_base_radius + g,
            tower_top_radius=t.tower_top_radius + g, nacelle_ahead=t.nacelle_ahead + g)

    lo, hi = 0.0, g  # the thickness knots' largest growth that keeps every section within u
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if (grown(mid).blade_semi_axes(f)[1] - B).max() <= g:
            lo = mid
        else:
            hi = mid
    return grown(lo)


def enclosing_sphere(t) -> tuple[np.ndarray, float]:
    """(centre, radius) of a sphere round the middle of the tower that holds every part: the
    rotor, nacelle and hub reach at most ``horiz`` sideways and ``vert`` above or below it."""
    a_max = float(np.max(t.blade_semi_axes(np.linspace(0, 1, 101))[0]))
    horiz = max(t.tip_radius + t.overhang + t.nacelle_length + t.hub_radius + a_max,
                t.tower_base_radius, t.tower_top_radius)
    vert = 0.5 * t.hub_height + t.tip_radius + a_max + t.nacelle_height
    return t.base_xyz + np.array([0.0, 0.0, 0.5 * t.hub_height]), math.hypot(horiz, vert)


def leg_samples(pos: np.ndarray, turbines, reach: float) -> np.ndarray:
    """Points every ``LEG_STEP`` m along each leg, only where the leg passes within ``reach`` of
    a turbine's bounding sphere (the rest of a 10 km transit is far from everything)."""
    pts = [pos]
    for t in turbines:
        centre, radius = enclosing_sphere(t)
        radius += reach
        p0, p1 = pos[:-1], pos[1:]
        dv = p1 - p0
        L = np.linalg.norm(dv, axis=1)
        for i in np.nonzero(L > LEG_STEP)[0]:
            u = dv[i] / L[i]
            m = p0[i] - centre
            bq = float(m @ u)
            disc = bq * bq - (float(m @ m) - radius * radius)
            if disc <= 0:
                continue
            a0, a1 = max(0.0, -bq - math.sqrt(disc)), min(L[i], -bq + math.sqrt(disc))
            if a1 <= a0:
                continue
            s = np.arange(a0, a1 + LEG_STEP, LEG_STEP)
            pts.append(p0[i] + np.minimum(s, L[i])[:, None] * u)
    return np.vstack(pts)


def sortie_times(route) -> list[float]:
    """Take-off to landing, between the route's stops at its launch point."""
    g = [i for i in range(len(route)) if np.allclose(route.pos[i], route.pos[0])]
    return [float(route.t[b] - route.t[a]) for a, b in zip(g, g[1:]) if b > a + 1]


# ---- one case ------------------------------------------------------------------------------------
def one(seed: int, coverage: bool = True) -> dict:
    from wtcli.errors import ExitCode, WtError
    from wtcli.geometry.coverage import turbine_coverage
    from wtcli.plan.config import mission_from_dict
    from wtcli.plan.mission import _photos_of, plan_mission

    d = random_site(np.random.default_rng(seed))
    t0 = time.time()
    try:
        mission = mission_from_dict(d, where="site.yaml")
        plan = plan_mission(mission, workers=1)
    except WtError as e:
        return {"seed": seed, "refused": str(e), "exit": int(e.exit_code),
                "one_line": "\n" not in str(e), "seconds": round(time.time() - t0, 2)}
    except Exception as e:  # a crash: exit 1
        return {"seed": seed, "crash": f"{type(e).__name__}: {e}", "exit": int(ExitCode.UNEXPECTED),
                "trace": traceback.format_exc()[-2000:]}
    dt = time.time() - t0
    s, fl = mission.settings, mission.fleet
    worst = worst_grown = math.inf
    grown = [grown_turbine(t, u) for t, u in zip(plan.turbines, mission.geometry_uncertainties())]
    for r in plan.routes:
        P = leg_samples(r.pos, plan.turbines, s.safe_distance_m + 3)
        worst = min(worst, independent_min_clearance(plan.turbines, P, s.safe_distance_m + 2))
        worst_grown = min(worst_grown, independent_min_clearance(grown, P, s.safe_distance_m + 2))
    sorties = [x for r in plan.routes for x in sortie_times(r)]
    limit = 60.0 * (fl.battery_minutes - fl.battery_reserve_minutes) / (1.0 + fl.wind_margin)
    lo, hi = fl.gimbal_pitch_range
    aim_ok = all(lo - 1e-9 <= float(p) <= hi + 1e-9 for r in plan.routes
                 for p in r.gimbal_pitch_deg[r.photo])
    out = {"seed": seed, "turbines": len(plan.turbines), "blades": [t.n_blades for t in plan.turbines],
           "uavs": len(fl.uavs), "gimbal_up_deg": fl.gimbal_pitch_max_deg,
           "safe_m": s.safe_distance_m, "min_clearance_m": worst,
           # leg samples LEG_STEP apart: between two the distance dips at most LEG_STEP / 2
           "clearance_violation": bool(worst - 0.5 * LEG_STEP - 0.01 < s.safe_distance_m),
           # the same against the turbine grown by its geometry_uncertainty_m (grown_turbine)
           "min_clearance_grown_m": worst_grown,
           "clearance_violation_grown": bool(worst_grown - 0.5 * LEG_STEP - 0.01
                                             < s.safe_distance_m),
           "aim_ok": aim_ok,
           # the planner's promise, from the settings: a sortie flown wind_margin longer lands
           # with the reserve
           "longest_sortie_s": max(sorties), "sortie_limit_s": limit,
           "battery_overrun": bool(max(sorties) > limit + 1e-6),
           "plan_seconds": round(dt, 2)}
    if coverage:
        low, low_half, diff = math.inf, math.inf, 0.0
        for t in plan.turbines:
            pos, rot = _photos_of(t, plan.routes)
            figs = [turbine_coverage(t, mission.camera, pos, rot, plan.target_gsd_mm, sp,
                                     s.max_incidence_deg, "blades").by_blade_side()
                    for sp in (s.coverage_spacing_m, s.coverage_spacing_m / 2)]
            for b, sides in figs[1].items():
                for side, v in sides.items():
                    low = min(low, figs[0][b][side])
                    low_half = min(low_half, v)
                    diff = max(diff, abs(v - figs[0][b][side]))
        out.update({"min_side": low, "min_side_fine": low_half,
                    "min_side_coverage": s.min_side_coverage,
                    "coverage_short": bool(min(low, low_half) < s.min_side_coverage),
                    "refinement_change": diff})
    return out


def refusal_kind(message: str) -> str:
    """A refusal message with its numbers, coordinates and names left out, to count alike ones."""
    m = re.sub(r"\[[^\]]*\]", "[..]", message)
    m = re.sub(r"\b(T|U|UAV)\d+\b", r"\1#", m)
    return re.sub(r"-?\d+(\.\d+)?", "#", m)


def summarize(res: list[dict], seconds: float) -> dict:
    ok = [r for r in res if "refused" not in r and "crash" not in r]
    refused = [r for r in res if "refused" in r]
    crashes = [r for r in res if "crash" in r]
    cov = [r for r in ok if "min_side_fine" in r]
    aimed = [r for r in ok if "aim_ok" in r]
    clearance = sum(r["clearance_violation"] for r in ok)
    grown = [r for r in ok if "clearance_violation_grown" in r]
    aim = sum(not r["aim_ok"] for r in aimed)
    return {
        "sites": len(res), "planned": len(ok), "plan_errors": len(refused),
        "crashes_exit_1": len(crashes),
        "refusals_not_one_line": sum(not r["one_line"] for r in refused),
        "refusal_exit_codes": dict(Counter(str(r["exit"]) for r in refused)),
        "violations": clearance + aim + sum(r["clearance_violation_grown"] for r in grown),
        "clearance_violations": clearance,
        "aim_violations": aim, "aim_checked": len(aimed),
        "min_margin_over_safe_distance_m": min((r["min_clearance_m"] - r["safe_m"] for r in ok),
                                               default=None),
        # against each turbine grown by its geometry_uncertainty_m (the "true" turbine)
        "clearance_violations_grown_turbine": sum(r["clearance_violation_grown"] for r in grown),
        "grown_checked": len(grown),
        "min_margin_over_safe_distance_grown_m": min(
            (r["min_clearance_grown_m"] - r["safe_m"] for r in grown), default=None),
        "battery_overruns": sum(r["battery_overrun"] for r in ok),
        "max_sortie_over_limit_s": max((r["longest_sortie_s"] - r["sortie_limit_s"] for r in ok),
                                       default=None),
        # converged coverage (turbine_coverage) at the planner's sampling and at half of it
        "plans_with_a_side_short": sum(r["coverage_short"] for r in cov),
        "plans_with_a_side_short_at_half_spacing": sum(r["min_side_fine"] < r["min_side_coverage"]
                                                       for r in cov),
        "min_side_coverage_converged": min((r.get("min_side", math.inf) for r in cov), default=None),
        "min_side_coverage_at_half_spacing": min((r["min_side_fine"] for r in cov), default=None),
        "max_side_change_spacing_to_half": max((r["refinement_change"] for r in cov), default=None),
        "plans_with_a_side_changing_over_half_a_point": sum(r["refinement_change"] > 0.005
                                                              for r in cov),
        "turbines_planned": sum(r["turbines"] for r in ok),
        "blade_counts": {str(k): v for k, v in sorted(Counter(b for r in ok for b in r["blades"]).items())},
        "with_gimbal_limit": sum(r["gimbal_up_deg"] < 90 for r in ok),
        "seconds": round(seconds, 1),
        "refusals": dict(Counter(refusal_kind(r["refused"]) for r in refused).most_common()),
        "crash_examples": [f"seed {r['seed']}: {r['crash']}" for r in crashes[:5]],
    }


def _write_results(name: str, summary: dict, res: list[dict]) -> Path:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from _results import save  # the shared writer: figures with the command, date and machine

    cases = [{k: v for k, v in r.items() if k != "trace"} for r in res]
    return save(name, {"summary": summary, "cases": cases}, script="benchmarks/plan_property.py")


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog="The full figure: python benchmarks/plan_property.py 1000 --jobs 2 --log cases.jsonl "
               "(about an hour on 2 free cores; a stopped run is summarised with --from-log "
               "cases.jsonl). N=100 is enough while developing.")
    ap.add_argument("n", nargs="?", type=int, default=1000)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--start", type=int, default=0, help="first seed")
    ap.add_argument("--no-coverage", action="store_true", help="skip the coverage re-measure")
    ap.add_argument("--log", default=None, help="append each case's result as a JSON line")
    ap.add_argument("--name", default="plan_property", help="results file name")
    ap.add_argument("--from-log", default=None,
                    help="summarise the cases of a --log file (a run stopped or made elsewhere) "
                         "instead of running any")
    a = ap.parse_args()
    t0 = time.time()
    if a.from_log:
        res = [json.loads(line) for line in Path(a.from_log).read_text().splitlines() if line]
        summary = summarize(res, 0.0)
        print(json.dumps(summary, indent=1))
        print(f"wrote {_write_results(a.name, summary, res)}")
        return
    res = []
    from functools import partial

    with ProcessPoolExecutor(a.jobs) as ex:
        for r in ex.map(partial(one, coverage=not a.no_coverage), range(a.start, a.start + a.n),
                        chunksize=2):
            res.append(r)
            if a.log:
                with open(a.log, "a") as f:
                    f.write(json.dumps({k: v for k, v in r.items() if k != "trace"}) + "\n")
    summary = summarize(res, time.time() - t0)
    print(json.dumps(summary, indent=1))
    print(f"wrote {_write_results(a.name, summary, res)}")


if __name__ == "__main__":
    main()
