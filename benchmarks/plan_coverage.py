"""Predicted coverage per blade side over random single turbines, and why samples are missed.

    python benchmarks/plan_coverage.py [--cases 20] [--seed 11] [--spacing 0.5] [--why]
                                       [--gimbal-max 30] [--out results.json]

Random turbines: rotor azimuth 0-120 deg, yaw 0-360 deg, rotor diameter 90/120/150 m, hub height
R + 15..45 m; default mission settings (safe distance 3 m + 1 m tracking margin, 1.5 mm/px) with
``min_side_coverage: 0`` so that no plan is refused for coverage, and a 16 mm lens on a 23.2 mm
sensor (``CAM``: the sample site's camera, 5.1 m from the blade, where misses are to be found;
the default camera's coverage is in ``flight_time.py``). Coverage is the planner's own
prediction (``summary.predicted_coverage``: the one coverage measure on the converged sampling,
``turbine_coverage``, blade cells refined where covered and missed meet). ``--gimbal-max``: the
gimbal's upward pitch limit (default 90: it looks straight up; an under-slung gimbal stops near 30).

``--why`` explains every missed blade sample with one reason, the first that applies:

- ``buried``: the sample lies inside (or within 5 cm of) another part (hub, nacelle): no camera
  can see it;
- ``no_safe_view``: no camera position within ``max_incidence_deg`` of its normal and within the
  GSD distance keeps the planner's clearance (safe distance + margin) from every part;
- ``gimbal``: such positions exist, but from none of them can the gimbal aim at the sample
  (it would have to look up more than ``--gimbal-max``);
- ``occluded_only``: such positions exist but from every one another part (or the blade itself)
  is in the way (``Turbine.line_of_sight``, the coverage measure's own test);
- ``planner``: a safe, clear view exists; the planner's photos miss it (the fixable kind).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _results import save  # noqa: E402  (figures with the command, date and machine)

from wtcli.errors import PlanError  # noqa: E402
from wtcli.geometry import BLADE_SIDES, Camera, Turbine  # noqa: E402
from wtcli.plan.config import Fleet, Mission, Settings  # noqa: E402
from wtcli.plan.mission import _photos_of, pass_params, plan_mission  # noqa: E402
from wtcli.geometry.coverage import turbine_coverage  # noqa: E402
from wtcli.plan.clearance import Site  # noqa: E402

CAM = Camera(5456, 3632, 16, 23.2)


def random_turbine(rng: np.random.Generator) -> Turbine:
    D = float(rng.choice([90.0, 120.0, 150.0]))
    return Turbine.with_rotor_azimuth(float(rng.uniform(0, 120)), id="T1", base=(0, 0, 0),
                                      hub_height=float(D / 2 + rng.uniform(15, 45)), rotor_diameter=D,
                                      yaw_deg=float(rng.uniform(0, 360)))


def _view_directions(normal: np.ndarray, max_deg: float) -> np.ndarray:
    """Unit directions within ``max_deg`` of ``normal`` (a cone of rings)."""
    a = np.cross(normal, [0.0, 0.0, 1.0])
    if np.linalg.norm(a) < 1e-6:
        a = np.cross(normal, [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    out = [normal]
    for th in np.radians(np.arange(8.0, max_deg, 8.0)):
        for ph in np.radians(np.arange(0.0, 360.0, 20.0)):
            out.append(np.cos(th) * normal + np.sin(th) * (np.cos(ph) * a + np.sin(ph) * b))
    return np.array(out)


def why_missed(t: Turbine, site: Site, samples, missed: np.ndarray, required: float,
               near: float, far: float, max_inc: float, min_alt: float,
               gimbal_max: float = 90.0) -> list[str]:
    parts = t.part_names()
    out = []
    for i in missed:
        x, nrm, k = samples.points[i], samples.normals[i], int(samples.blade[i])
        others = [j for j in range(len(parts)) if j != k]
        if t.clearance_by_part(x[None])[0, others].min() < 0.05:
            out.append("buried")
            continue
        U = _view_directions(nrm, max_inc - 1.0)
        R = np.linspace(near, far, 6)
        C = (x + R[None, :, None] * U[:, None, :]).reshape(-1, 3)
        ok = (site.clearance(C, required) >= required) & (C[:, 2] >= site.ground_z(C) + min_alt)
        if not ok.any():
            out.append("no_safe_view")
            continue
        # The camera looks from C back at x, along -U: up by asin(-U_z).
        up = np.degrees(np.arcsin(np.clip(-np.repeat(U[:, 2], len(R)), -1.0, 1.0)))
        ok &= up <= gimbal_max + 1e-6
        if not ok.any():
            out.append("gimbal")
            continue
        C = C[ok]
        clear = t.line_of_sight(C, np.tile(x, (len(C), 1)))
        out.append("planner" if clear.any() else "occluded_only")
    return out


def run(cases: int, seed: int, why: bool, spacing: float = Settings().coverage_spacing_m,
        gimbal_max: float = 90.0) -> dict:
    rng = np.random.default_rng(seed)
    rows, refused = [], []
    reasons: Counter = Counter()
    miss_where: Counter = Counter()
    for c in range(cases):
        t = random_turbine(rng)
        m = Mission((t,), CAM, fleet=Fleet(gimbal_pitch_max_deg=gimbal_max),
                    settings=Settings(min_side_coverage=0.0, coverage_spacing_m=spacing))
        t0 = time.perf_counter()
        try:
            plan = plan_mission(m)
        except PlanError as e:
            refused.append({"case": c, "turbine": t.to_dict(), "error": str(e)})
            print(f"case {c:3d}: az {t.azimuths_deg[0]:5.1f} yaw {t.yaw_deg:5.1f} "
                  f"D {t.rotor_diameter:.0f}: REFUSED {e}", flush=True)
            continue
        dt = time.perf_counter() - t0
        s = plan.summary
        cov = s["predicted_coverage"]["T1"]
        sides = cov["by_blade_side"]
        worst_b, worst_s = min(((b, sd) for b in sides for sd in sides[b]),
                               key=lambda x: sides[x[0]][x[1]])
        row = {"case": c, "azimuths_deg": list(t.azimuths_deg), "yaw_deg": t.yaw_deg,
               "rotor_diameter": t.rotor_diameter, "hub_height": t.hub_height,
               "blade_average": cov["blade_average"], "min_side": cov["min_side"],
               "worst": f"{worst_b}/{worst_s}", "by_blade_side": sides, "seconds": dt,
               "photos": s["photos"], "length_m": s["total_length_m"],
               "min_clearance_m": s["min_clearance_m"],
               "max_photo_pitch_deg": max(float(r.gimbal_pitch_deg[r.photo].max())
                                          for r in plan.routes if r.photo.any()),
               "violations": sum(s["violations"].values())}
        extra = ""
        if why:
            pp, gsd, _ = pass_params(m)
            st = m.settings
            pos, rot = _photos_of(t, plan.routes)
            cv = turbine_coverage(t, CAM, pos, rot, gsd, st.coverage_spacing_m,
                                  st.max_incidence_deg, "blades")
            smp = cv.samples
            missed = np.nonzero(~cv.covered)[0]
            rs = why_missed(t, Site([t]), smp, missed, pp.required, pp.min_standoff,
                            CAM.distance_for_gsd(gsd * 1.05), st.max_incidence_deg, st.min_altitude_m,
                            gimbal_max)
            area = Counter()
            for i, r in zip(missed, rs):
                area[r] += float(smp.area[i])
                k = int(smp.blade[i])
                s_m = t.blade_root_offset + smp.span[i] * (t.tip_radius - t.blade_root_offset)
                az = t.azimuths_deg[k]
                where = "root<4m" if s_m < 4 else f"span{int(smp.span[i] * 10) / 10:.1f}"
                miss_where[(BLADE_SIDES[smp.side[i]], r, where, f"az{int(az // 30) * 30}")] += \
                    float(smp.area[i])
            reasons.update(area)
            row["missed_m2"] = dict(area)
            extra = " missed m2 " + ", ".join(f"{k} {v:.2f}" for k, v in sorted(area.items()))
        rows.append(row)
        print(f"case {c:3d}: az {t.azimuths_deg[0]:5.1f} yaw {t.yaw_deg:5.1f} D {t.rotor_diameter:.0f} "
              f"H {t.hub_height:.0f}: blade {row['blade_average']:.3f} worst {row['min_side']:.3f} "
              f"({row['worst']}) {dt:.2f} s{extra}", flush=True)
    per_side = {sd: [r["by_blade_side"][b][sd] for r in rows for b in r["by_blade_side"]]
                for sd in BLADE_SIDES}
    mins = np.array([r["min_side"] for r in rows]) if rows else np.zeros(0)
    summary = {
        "cases": cases, "planned": len(rows), "refused": len(refused),
        "blade_average_mean": float(np.mean([r["blade_average"] for r in rows])) if rows else None,
        "min_side_mean": float(mins.mean()) if rows else None,
        "min_side_min": float(mins.min()) if rows else None,
        "cases_all_sides_ge_98": int((mins >= 0.98).sum()),
        "per_side_mean": {k: float(np.mean(v)) for k, v in per_side.items() if v},
        "per_side_min": {k: float(np.min(v)) for k, v in per_side.items() if v},
        "worst_side_count": dict(Counter(r["worst"].split("/")[1] for r in rows)),
        "gimbal_pitch_max_deg": gimbal_max,
        "max_photo_pitch_deg": float(max(r["max_photo_pitch_deg"] for r in rows)) if rows else None,
        "violations": int(sum(r["violations"] for r in rows)),
        "min_clearance_m": float(min(r["min_clearance_m"] for r in rows)) if rows else None,
        "seconds_mean": float(np.mean([r["seconds"] for r in rows])) if rows else None,
        "seconds_max": float(np.max([r["seconds"] for r in rows])) if rows else None,
        "refusals": [r["error"] for r in refused],
    }
    if why:
        summary["missed_m2_by_reason"] = {k: round(v, 2) for k, v in reasons.items()}
        summary["missed_m2_top"] = [[*k, round(v, 2)] for k, v in miss_where.most_common(15)]
    return {"summary": summary, "rows": rows, "refused": refused}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", type=int, default=20)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--why", action="store_true", help="explain every missed blade sample")
    ap.add_argument("--spacing", type=float, default=Settings().coverage_spacing_m,
                    help="coverage_spacing_m (m); default: the planner's")
    ap.add_argument("--gimbal-max", type=float, default=90.0,
                    help="the gimbal's upward pitch limit, deg (fleet.gimbal_pitch_max_deg)")
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    res = run(a.cases, a.seed, a.why, a.spacing, a.gimbal_max)
    print(json.dumps(res["summary"], indent=1))
    print(f"wrote {save('plan_coverage', {'summary': res['summary'], 'refused': res['refused']})}")
    if a.out:
        Path(a.out).write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
