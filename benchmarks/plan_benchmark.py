"""Planner figures: planning time for 1, 10 and 100 turbines, and the adaptive plan beside the
fixed, non-adaptive pattern that assumes the rotor stopped in a "Y" (blade 1 up), over random
real stop angles.

    python benchmarks/plan_benchmark.py [--cases 30] [--sizes 1,10,100] [--out results.json]
    python benchmarks/plan_benchmark.py --coverage-share 10   # only the share below

``--coverage-share N``: one process plans the N-turbine site under cProfile and reports the CPU
seconds spent in the coverage measure (``turbine_coverage``, the planner's gate, predicted and
per-turbine figures) and in the gap-view search (``gap_plan``) beside the whole plan's. In one
process the per-turbine figure reuses the cells the gate measured (in worker processes it
starts afresh), so the share is a lower bound of a parallel plan's.

Coverage is the planner's prediction (the one coverage measure, wtcli/geometry/coverage.py) at the
plan's GSD and incidence <= 60 deg, judged against the REAL rotor for both patterns; the fixed
pattern's clearance is also judged against the real blades (its violations are counted).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _results import save  # noqa: E402  (figures with the command, date and machine)

from wtcli.errors import PlanError  # noqa: E402
from wtcli.geometry import Camera, Turbine  # noqa: E402
from wtcli.plan.config import Fleet, Mission, Settings  # noqa: E402
from wtcli.plan.mission import plan_mission  # noqa: E402

CAM = Camera(5456, 3632, 16, 23.2)


def site(n: int, rng: np.random.Generator) -> Mission:
    side = int(np.ceil(np.sqrt(n)))
    ts = []
    for i in range(n):
        ts.append(Turbine.with_rotor_azimuth(
            float(rng.uniform(0, 120)), id=f"T{i + 1}",
            base=(400.0 * (i % side), 400.0 * (i // side), float(rng.uniform(0, 10))),
            hub_height=80.0, rotor_diameter=90.0, yaw_deg=float(rng.uniform(0, 360))))
    uavs = tuple(f"UAV{k + 1}" for k in range(max(1, n // 10)))
    # One launch point for the whole site: far turbines need the cruise there and back within a
    # battery, so large sites get a longer-lasting battery (a real team would move the launch).
    battery = 25.0 if n <= 10 else 45.0
    return Mission(tuple(ts), CAM, fleet=Fleet(uavs=uavs, launch=(-100.0, -100.0, 0.0),
                                               battery_minutes=battery),
                   settings=Settings(min_side_coverage=0.0))


def timing(sizes: list[int]) -> list[dict]:
    out = []
    for n in sizes:
        m = site(n, np.random.default_rng(n))
        t0, c0 = time.perf_counter(), os.times()
        marks: dict[str, float] = {}  # wall time at which each stage started (plan_mission's progress)
        plan = plan_mission(m, progress=lambda st, done, total: marks.setdefault(
            st, time.perf_counter()) if done == 0 else None)
        dt = time.perf_counter() - t0
        c1 = os.times()
        # Each stage's wall time runs to the next one's start; "setup" is before the first
        # (site model, launch check), the last stage runs to the end (with the plan's summary).
        ends = list(marks.values())[1:] + [t0 + dt]
        stages = {"setup": round(next(iter(marks.values()), t0 + dt) - t0, 2)}
        stages.update({k: round(e - v, 2) for (k, v), e in zip(marks.items(), ends)})
        cpu = (c1.user - c0.user) + (c1.children_user - c0.children_user)
        s = plan.summary
        out.append({"turbines": n, "uavs": len(m.fleet.uavs), "seconds": round(dt, 2),
                    "cpu_seconds": round(cpu, 2), "cpus": os.cpu_count(),
                    "seconds_per_turbine": round(dt / n, 3), "waypoints": sum(len(r) for r in plan.routes),
                    "photos": s["photos"], "length_km": round(s["total_length_m"] / 1000, 2),
                    "mission_time_min": round(s["total_time_s"] / 60, 1),
                    "min_clearance_m": round(s["min_clearance_m"], 2),
                    "stage_seconds": stages})
        print(f"{n:4d} turbines, {len(m.fleet.uavs)} UAV(s): {dt:6.2f} s wall, {cpu:6.2f} s CPU "
              f"({dt / n:.2f} s/turbine), {s['photos']} photos; wall s by stage: "
              + ", ".join(f"{k} {v:.2f}" for k, v in stages.items()), flush=True)
    return out


def coverage_share(n: int) -> dict:
    """CPU seconds of one process planning ``site(n)``: in all, in ``turbine_coverage`` and in
    ``gap_plan`` (cProfile's cumulative times; the numba kernels compiled first)."""
    import cProfile
    import pstats

    plan_mission(site(1, np.random.default_rng(1)), workers=1)  # compile / load the kernels
    m = site(n, np.random.default_rng(n))
    prof = cProfile.Profile(time.process_time)  # CPU time: wall time counts other processes
    c0 = time.process_time()
    prof.enable()
    plan_mission(m, workers=1)
    prof.disable()
    total = time.process_time() - c0
    st = pstats.Stats(prof).stats  # {(file, line, name): (calls, ..., tottime, cumtime, callers)}

    def cum(name: str) -> tuple[int, float]:
        hits = [(v[1], v[3]) for (f, _, fn), v in st.items() if fn == name and "wtcli" in f]
        return (hits[0][0], hits[0][1]) if hits else (0, 0.0)

    calls, cov = cum("turbine_coverage")
    _, gaps = cum("gap_plan")
    out = {"turbines": n, "cpu_seconds": round(total, 2), "coverage_calls": calls,
           "coverage_cpu_seconds": round(cov, 2), "gap_search_cpu_seconds": round(gaps, 2)}
    print(f"{n} turbines in one process: {total:.2f} CPU s under cProfile; turbine_coverage "
          f"{cov:.2f} s in {calls} calls ({cov / total:.0%}), gap_plan {gaps:.2f} s "
          f"({gaps / total:.0%})", flush=True)
    return out


def compare(cases: int) -> dict:
    rng = np.random.default_rng(7)
    rows = []
    for i in range(cases):
        t = Turbine.with_rotor_azimuth(float(rng.uniform(0, 360)), id="T1", base=(0, 0, 0),
                                       hub_height=80.0, rotor_diameter=90.0,
                                       yaw_deg=float(rng.uniform(0, 360)))
        m = Mission((t,), CAM, settings=Settings(min_side_coverage=0.0))
        row = {"stop_deg": round(t.azimuths_deg[0] % 120.0, 1)}
        for pattern in ("adaptive", "fixed-y"):
            try:
                p = plan_mission(m, pattern=pattern)
            except PlanError as e:
                row[pattern] = {"error": str(e)}
                continue
            s = p.summary
            c = s["predicted_coverage"]["T1"]
            sides = [v for d in c["by_blade_side"].values() for v in d.values()]
            row[pattern] = {"coverage": c["blade_average"], "min_side": min(sides),
                            "length_m": s["total_length_m"], "time_s": s["total_time_s"],
                            "min_clearance_m": s["min_clearance_m"],
                            "violations": sum(s["violations"].values())}
        rows.append(row)
        a, f = row.get("adaptive", {}), row.get("fixed-y", {})
        print(f"stop {row['stop_deg']:5.1f}: adaptive cov {a.get('coverage', float('nan')):.3f} "
              f"(min side {a.get('min_side', float('nan')):.3f}) len {a.get('length_m', 0):.0f} | "
              f"fixed-Y cov {f.get('coverage', float('nan')):.3f} len {f.get('length_m', 0):.0f} "
              f"violations {f.get('violations', 0)} min clearance {f.get('min_clearance_m', 0):.2f}",
              flush=True)

    def agg(pattern: str) -> dict:
        ok = [r[pattern] for r in rows if "error" not in r[pattern]]
        if not ok:
            return {}
        cov = np.array([o["coverage"] for o in ok])
        mins = np.array([o["min_side"] for o in ok])
        return {"cases": len(ok), "coverage_mean": float(cov.mean()), "coverage_min": float(cov.min()),
                "min_side_mean": float(mins.mean()), "min_side_min": float(mins.min()),
                "share_cases_all_sides_ge_98": float((mins >= 0.98).mean()),
                "length_m_mean": float(np.mean([o["length_m"] for o in ok])),
                "time_min_mean": float(np.mean([o["time_s"] for o in ok]) / 60),
                "cases_with_violations": int(sum(o["violations"] > 0 for o in ok)),
                "min_clearance_m": float(min(o["min_clearance_m"] for o in ok))}
    return {"adaptive": agg("adaptive"), "fixed-y": agg("fixed-y"), "rows": rows}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", type=int, default=30)
    ap.add_argument("--sizes", default="1,10,100")
    ap.add_argument("--out", default=None)
    ap.add_argument("--coverage-share", type=int, default=None, metavar="N",
                    help="only: the coverage measure's and the gap search's CPU share of an "
                         "N-turbine plan in one process (cProfile)")
    a = ap.parse_args()
    if a.coverage_share:
        res = coverage_share(a.coverage_share)
        print(f"wrote {save('plan_benchmark_coverage_share', res, script=__file__)}")
        return
    res = {"timing": timing([int(x) for x in a.sizes.split(",") if x]),
           "adaptive_vs_fixed_y": compare(a.cases)}
    summary = {k: v for k, v in res["adaptive_vs_fixed_y"].items() if k != "rows"}
    print(json.dumps({"timing": res["timing"], **summary}, indent=1))
    print(f"wrote {save('plan_benchmark', {'timing': res['timing'], 'adaptive_vs_fixed_y': summary})}")
    if a.out:
        Path(a.out).write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
