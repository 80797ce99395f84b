"""The plan's clearance guarantee over many random cases (the slow half of tests/test_plan.py).

Random sites: 1-3 turbines (rotor radius 20-75 m, any yaw, stop angle and blade pitch 60-90),
1-3 UAVs, safe distance 2.5-6 m, tracking margin 0-1.5 m, target GSD 1.2-2.5 mm/px, a third with a
gimbal that looks up at most 20-60 deg (``random_case(..., gimbal=True)``). Every plan is
checked independently with the one turbine model: Turbine.clearance on every waypoint and
Turbine.segment_clearance on every leg, against every turbine.

    python benchmarks/plan_property.py [N] [--start SEED] [--jobs J] [--out summary.json] [--log cases.jsonl]
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def one(seed: int) -> dict:
    from test_plan import random_case

    from wtcli.errors import PlanError
    from wtcli.plan.mission import plan_mission

    case = random_case(np.random.default_rng(seed), gimbal=True)
    try:
        plan = plan_mission(case)
    except PlanError as e:
        return {"seed": seed, "error": str(e)}
    safe = case.settings.safe_distance_m
    worst = np.inf
    for r in plan.routes:
        for t in plan.turbines:
            worst = min(worst, float(t.clearance(r.pos).min()),
                        float(t.segment_clearance(r.pos[:-1], r.pos[1:], step=0.5).min()))
    up = case.fleet.gimbal_pitch_max_deg
    aim_ok = all(float(r.gimbal_pitch_deg.max()) <= up + 1e-9 for r in plan.routes)
    return {"seed": seed, "margin_m": worst - safe, "violation": bool(worst < safe) or not aim_ok,
            "aim_ok": aim_ok, "gimbal_up_deg": up, "turbines": len(case.turbines),
            "uavs": len(case.fleet.uavs)}


def refusal_kind(message: str) -> str:
    """A refusal message with its numbers, coordinates and names left out, to count alike ones."""
    m = re.sub(r"\[[^\]]*\]", "[..]", message)
    m = re.sub(r"\b(T|U|UAV)\d+\b", r"\1#", m)
    return re.sub(r"\d+(\.\d+)?", "#", m)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("n", nargs="?", type=int, default=1000)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--start", type=int, default=10_000, help="first seed (continue a stopped run)")
    ap.add_argument("--out", default=None)
    ap.add_argument("--log", default=None, help="append each case's result as a JSON line (as they come)")
    a = ap.parse_args()
    t0 = time.time()
    res = []
    with ProcessPoolExecutor(a.jobs) as ex:
        for r in ex.map(one, range(a.start, a.start + a.n), chunksize=4):
            res.append(r)
            if a.log:
                with open(a.log, "a") as f:
                    f.write(json.dumps(r) + "\n")
    ok = [r for r in res if "error" not in r]
    errs = [r for r in res if "error" in r]
    summary = {"cases": a.n, "planned": len(ok), "plan_errors": len(errs),
               "violations": sum(r["violation"] for r in ok),
               "aim_violations": sum(not r["aim_ok"] for r in ok),
               "with_gimbal_limit": sum(r["gimbal_up_deg"] < 90 for r in ok),
               "min_margin_over_safe_distance_m": min((r["margin_m"] for r in ok), default=None),
               "turbines_total": sum(r["turbines"] for r in ok), "seconds": round(time.time() - t0, 1),
               "refusals": dict(Counter(refusal_kind(r["error"]) for r in errs).most_common()),
               "errors": [f"seed {r['seed']}: {r['error']}" for r in errs[:10]]}
    print(json.dumps(summary, indent=1))
    if a.out:
        Path(a.out).write_text(json.dumps({"summary": summary, "cases": res}, indent=1))


if __name__ == "__main__":
    main()
