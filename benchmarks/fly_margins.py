"""Which tracking margin each positioning mode needs: paper-s2 (complex terrain) over many seeds.

    python benchmarks/fly_margins.py [--seeds 20] [--modes gnss ...] [--winds 8 10 12] [--no-cost]
                                     [--cost-camera 5456,3632,16,23.2]

paper-s2's wind is IEC 61400-1's normal turbulence of category A with complex terrain's
turbulence structure (docs/scenarios.md). For each hub-height wind in ``--winds`` (the paper's
8-12 m/s) and each positioning mode this plans the mission with that mode's margin (MARGINS:
one per mode, the same in every wind, as a plan states its positioning and not the day's
wind), flies the automated flight (the set-point waiting for the vehicle, ``control.leash_m``)
for seeds 0..N-1 and reports the mean / rms / 99.9th-percentile deviation from the planned
path (mean and worst over seeds), the least clearance, the clearance violations and the flights
that failed (the vehicle could not hold the route), with the plan's standoff, GSD and coverage
(``min_side_coverage`` 0.5 so that every margin's plan is made). ``margin_cost`` plans the
mission (no flights) with each of COST_MARGINS: what a margin costs the inspection, with the
mission's camera and (``margin_cost_compare``) with ``--cost-camera``.

Done when: in the scenario's wind plain GNSS's mean deviation is of the paper's order (0.5-2 m)
and RTK fixed's clearly lower; and in the wind whose figures docs/fly.md tabulates per mode
(DOCUMENTED), no clearance violation, no failed flight and every flight's 99.9th percentile
within its margin. Writes benchmarks/results/fly_margins.json: ``winds`` for every wind flown,
``modes`` for DOCUMENTED.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _results import save  # noqa: E402

from wtcli.errors import SimulationError  # noqa: E402
from wtcli.fly.flight import fly_plan  # noqa: E402
from wtcli.fly.scenario import load_scenario, shipped_scenarios  # noqa: E402
from wtcli.geometry import Camera  # noqa: E402
from wtcli.plan.config import load_mission  # noqa: E402
from wtcli.plan.mission import plan_mission  # noqa: E402

# The tracking margin each mode is planned with, per hub-height wind (m/s).
# One margin per mode for every wind (the plan states its positioning, not the day's wind).
_PER_MODE = {"rtk_fixed": 2.0, "rtk_float": 3.0, "gnss": 4.5}
MARGINS = {10.0: dict(_PER_MODE), 8.0: dict(_PER_MODE), 12.0: dict(_PER_MODE)}
# The wind whose margins docs/fly.md recommends (10 m/s is measured to show why not).
DOCUMENTED = 8.0
MODES = ("rtk_fixed", "rtk_float", "gnss")
# Margins whose plans are compared (no flights): what a wider margin costs the inspection.
COST_MARGINS = (1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5)
COST_CAMERA = "5456,3632,16,23.2"  # a 16 mm lens, 1.5 mm/px at 5.6 m: where a margin costs GSD


def _plan_figures(plan) -> dict:
    """What the plan's margin costs: where the camera stands and what its photos resolve."""
    s = plan.summary
    cov = s["predicted_coverage"]["T1"]
    return {"planned_standoff_m": s["standoff_m"], "planned_gsd_mm": s["achieved_gsd_mm"],
            "planned_coverage_gsd_mm": s["coverage_gsd_mm"],
            "planned_blade_average_coverage": cov["blade_average"],
            "planned_min_side_coverage": cov["min_side"], "planned_photos": s["photos"],
            "planned_time_s": s["total_time_s"]}


def _plan(mission, scn, margin: float):
    m = replace(mission, settings=replace(mission.settings, tracking_margin_m=margin,
                                          min_side_coverage=0.5))
    return plan_mission(m, azimuths=scn.azimuths)


def fly_modes(scn, mission, wind_ms: float, modes, seeds: int) -> dict:
    """Per mode: the plan with that mode's margin in this wind, flown for each seed."""
    out = {}
    for mode in modes:
        margin = MARGINS[wind_ms][mode]
        t0 = time.perf_counter()
        plan = _plan(mission, scn, margin)
        rows = []
        for seed in range(seeds):
            s = replace(scn, seed=seed, positioning=replace(scn.positioning, mode=mode),
                        wind=replace(scn.wind, speed_ms=wind_ms))
            try:
                f = fly_plan(plan, s).automated
            except SimulationError as e:  # the vehicle could not hold the route: a failed flight
                rows.append({"seed": seed, "failed": str(e), "mean_m": float("nan"),
                             "rms_m": float("nan"), "p99_9_m": float("inf"),
                             "max_m": float("inf"), "min_clearance_m": float("nan"),
                             "clearance_violations": 0, "within_margin": False})
                continue
            d = f.to_dict()["deviation_m"]
            rows.append({"seed": seed, "mean_m": d["mean"], "rms_m": d["rms"],
                         "p99_9_m": d["p99_9"], "max_m": d["max"],
                         "min_clearance_m": f.min_clearance_m,
                         "clearance_violations": sum(v.kind in ("clearance", "collision")
                                                     for v in f.violations),
                         "within_margin": d["within_margin"]})
        flown = [r for r in rows if "failed" not in r] or [{"mean_m": float("nan"),
                                                            "rms_m": float("nan"),
                                                            "p99_9_m": float("nan"),
                                                            "min_clearance_m": float("nan")}]
        mean = np.array([r["mean_m"] for r in flown])
        p999 = np.array([r["p99_9_m"] for r in flown])
        summary = {"tracking_margin_m": margin, "mean_deviation_m": float(mean.mean()),
                   "mean_deviation_worst_seed_m": float(mean.max()),
                   "rms_deviation_m": float(np.mean([r["rms_m"] for r in flown])),
                   "p99_9_median_seed_m": float(np.median(p999)),
                   "p99_9_worst_seed_m": float(p999.max()),
                   "min_clearance_m": float(min(r["min_clearance_m"] for r in flown)),
                   "failed_flights": sum("failed" in r for r in rows),
                   "safe_distance_m": plan.safe_distance_m,
                   "clearance_violations": sum(r["clearance_violations"] for r in rows),
                   "flights_beyond_margin": sum(not r["within_margin"] for r in rows),
                   **_plan_figures(plan), "seconds": time.perf_counter() - t0}
        print(f"{wind_ms:4.1f} m/s {mode:9s} margin {margin:.1f} m: mean deviation "
              f"{summary['mean_deviation_m']:.3f} m (worst seed "
              f"{summary['mean_deviation_worst_seed_m']:.3f}), rms {summary['rms_deviation_m']:.3f}, "
              f"p99.9 median/worst {summary['p99_9_median_seed_m']:.2f}/"
              f"{summary['p99_9_worst_seed_m']:.2f} m, min clearance "
              f"{summary['min_clearance_m']:.2f} m (safe {plan.safe_distance_m:g}), violations "
              f"{summary['clearance_violations']}, beyond margin "
              f"{summary['flights_beyond_margin']}/{seeds}, failed {summary['failed_flights']}",
              flush=True)
        # Every flight failed: no figures (JSON takes no NaN), the failures say why.
        summary = {k: (None if isinstance(v, float) and not np.isfinite(v) else v)
                   for k, v in summary.items()}
        rows = [{k: (None if isinstance(v, float) and not np.isfinite(v) else v)
                 for k, v in r.items()} for r in rows]
        out[mode] = {"summary": summary, "per_seed": rows}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--modes", nargs="*", default=list(MODES), choices=list(MODES))
    ap.add_argument("--winds", nargs="*", type=float, default=list(MARGINS),
                    help=f"hub-height winds, m/s (each one of {', '.join(map(str, MARGINS))})")
    ap.add_argument("--no-cost", action="store_true", help="skip the margin_cost plans")
    ap.add_argument("--cost-camera", default=COST_CAMERA,
                    help="WIDTH_PX,HEIGHT_PX,FOCAL_MM,SENSOR_WIDTH_MM: margin_cost again with this "
                    "camera ('' for none; default a 16 mm lens on a 23.2 mm sensor)")
    a = ap.parse_args()
    for w in a.winds:
        if w not in MARGINS:
            ap.error(f"--winds: expected winds in {sorted(MARGINS)}, got {w:g}")
    scn = load_scenario(shipped_scenarios()["paper-s2"])
    mission = load_mission(scn.mission)
    res: dict = {"scenario": "paper-s2", "seeds": a.seeds, "wind_ms": scn.wind.speed_ms,
                 "turbulence": {"iec_class": scn.wind.turbulence_class,
                                "lateral_ratio": scn.wind.lateral_ratio,
                                "vertical_ratio": scn.wind.vertical_ratio},
                 "documented_wind_ms": DOCUMENTED, "winds": {}}
    ok = True
    for w in a.winds:
        modes = fly_modes(scn, mission, w, a.modes, a.seeds)
        res["winds"][f"{w:g}"] = modes
        if w == scn.wind.speed_ms:
            if {"gnss", "rtk_fixed"} <= set(modes):
                g, r = modes["gnss"]["summary"], modes["rtk_fixed"]["summary"]
                ok &= (0.5 <= g["mean_deviation_m"] <= 2.0
                       and r["mean_deviation_m"] < 0.5 * g["mean_deviation_m"])
        if w == DOCUMENTED:
            res["modes"] = modes
            ok &= all(m["summary"]["clearance_violations"] == 0
                      and m["summary"]["failed_flights"] == 0
                      and m["summary"]["flights_beyond_margin"] == 0 for m in modes.values())
    cameras = {"margin_cost": None}
    if a.cost_camera:
        w_, h_, f_, s_ = (float(x) for x in a.cost_camera.split(","))
        cameras["margin_cost_compare"] = Camera(int(w_), int(h_), f_, s_)
        res["cost_camera"] = a.cost_camera
    for key, cam in cameras.items() if not a.no_cost else ():
        m = mission if cam is None else replace(mission, camera=cam)
        cost = []
        for margin in COST_MARGINS:
            row = {"tracking_margin_m": margin, **_plan_figures(_plan(m, scn, margin))}
            cost.append(row)
            print(f"{'' if cam is None else a.cost_camera + ': '}margin {margin:.1f} m: standoff "
                  f"{row['planned_standoff_m']:.2f} m, GSD "
                  f"{row['planned_gsd_mm']:.2f} mm (coverage counted at "
                  f"{row['planned_coverage_gsd_mm']:.2f}), blade coverage "
                  f"{row['planned_blade_average_coverage']:.3f}, worst side "
                  f"{row['planned_min_side_coverage']:.3f}", flush=True)
        res[key] = cost
    res["done"] = bool(ok)
    save("fly_margins", res)
    print("done criteria:", "met" if ok else "NOT met")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
