"""Photo -> plan latency: the wall time a user waits for `wtinspect plan turbines.yaml T1=photo`.

Runs the real command in a fresh process (imports, model load, segmentation, pitch, planning,
writing the plan) ``--repeat`` times after one warm-up run (the numba kernels and the OS file
cache are then warm, as after set-up), and reports the median and every run, with and without
``--fast`` (one pass of the network). The target of the faster-inspections issue is a median
under 2 s on the 2-core CPU; the figure is printed beside it as a ratio. The 1-minute load
average before and after is recorded: on a shared CPU the figures are slower than on an idle one.

It also times where the seconds go (``phases``): the same command once more in a fresh
process, its steps timed from outside (wall and CPU seconds of each: imports, model load,
each look of the network, the edge refiner, planning, writing; ``rest``: contours, pitch,
back-projection, the YAML, the CLI).

``--accuracy N``: what ``--fast`` costs, on N held-out front renders (``render_sample(9 000 000
+ 2 i, 640, 480, "front")``, as ``segment_accuracy.py``): right blade count and blade θ error of
the photo chain with and without ``--fast``, and the sample photo's blade azimuths both ways.

    .venv/bin/python benchmarks/plan_latency.py [--repeat 5] [--accuracy 40]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _results import ROOT, save

TARGET_S = 2.0
# The steps ``phases`` times, in the order they run; the first four are imports.
STEPS = {
    "cli": "CLI: numpy, cv2, typer, rich, the commands",
    "torch": "import torch",
    "torchvision": "import torchvision and the segmenter",
    "planner_imports": "import numba and the planner",
    "model": "segmenter: build the network, load the weights",
    "first_look": "segmenter: first look (the photo and its mirror; one pass --fast)",
    "second_look": "segmenter: second look at a small turbine",
    "refiner": "edge refiner: load and refine",
    "plan": "plan_mission: trajectories, legs, routes, coverage",
    "write": "write the plan JSON",
    "rest": "the rest: YAML, contours, pitch, back-projection, output",
}
IMPORTS = ("cli", "torch", "torchvision", "planner_imports")


def run_once(yaml: Path, photo: Path, out: Path, fast: bool = False) -> float:
    cmd = [sys.executable, "-m", "wtcli", "plan", str(yaml), f"T1={photo}", "--out", str(out)]
    t0 = time.perf_counter()
    done = subprocess.run(cmd + (["--fast"] if fast else []), cwd=ROOT, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"plan exited {done.returncode}: {done.stderr.strip()[-400:]}")
    return seconds


def phases(yaml: Path, photo: Path, out: Path, fast: bool = False) -> dict:
    """In THIS process (a fresh one, ``--phases``): `wtinspect plan` with its steps timed."""
    clock = {}
    spans: dict[str, list[float]] = {}
    t_start = (time.perf_counter(), time.process_time())

    def mark(name: str, since: tuple[float, float]) -> tuple[float, float]:
        now = (time.perf_counter(), time.process_time())
        w, c = spans.setdefault(name, [0.0, 0.0])
        spans[name] = [w + now[0] - since[0], c + now[1] - since[1]]
        return now

    t = t_start
    import wtcli.cli  # first, as `wtinspect` does: it sets OMP_WAIT_POLICY before torch loads

    t = mark("cli", t)
    import torch  # noqa: F401

    t = mark("torch", t)
    import wtcli.segment.infer as infer
    import wtcli.segment.refine as refine

    t = mark("torchvision", t)
    import numba  # noqa: F401

    import wtcli.commands.plan as plan_cmd
    import wtcli.plan.mission as mission

    t = mark("planner_imports", t)

    def timed(module, attr: str, name: str):
        fn = getattr(module, attr)

        def wrapper(*a, **k):
            if clock.get("in"):  # inside another timed step (a second look's own passes)
                return fn(*a, **k)
            clock["in"] = True
            t0 = (time.perf_counter(), time.process_time())
            try:
                return fn(*a, **k)
            finally:
                mark(name, t0)
                clock["in"] = False

        setattr(module, attr, wrapper)

    timed(infer, "load_model", "model")
    timed(infer, "predict", "first_look")
    timed(infer, "second_look", "second_look")
    timed(refine, "load_refiner", "refiner")
    timed(refine, "refine_edges", "refiner")
    timed(mission, "plan_mission", "plan")
    timed(plan_cmd, "write_plan", "write")
    t_cmd = (time.perf_counter(), time.process_time())
    try:
        wtcli.cli.main(["plan", str(yaml), f"T1={photo}", "--out", str(out)]
                       + (["--fast"] if fast else []))
    except SystemExit as e:
        if e.code not in (0, None):
            raise
    end = (time.perf_counter(), time.process_time())
    inside = [sum(v[i] for k, v in spans.items() if k not in IMPORTS) for i in (0, 1)]
    spans["rest"] = [
        end[0] - t_cmd[0] - inside[0], end[1] - t_cmd[1] - inside[1]]
    steps = [{"step": k, "what": STEPS[k], "wall_s": spans.get(k, [0.0, 0.0])[0],
              "cpu_s": spans.get(k, [0.0, 0.0])[1]} for k in STEPS]
    return {"steps": steps,
            "total_wall_s": end[0] - t_start[0], "total_cpu_s": end[1] - t_start[1],
            "fast": fast}


def run_phases(yaml: Path, photo: Path, out: Path, fast: bool = False) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--phases", "--yaml", str(yaml),
           "--photo", str(photo), "--phases-out", str(out)] + (["--fast"] if fast else [])
    t0 = time.perf_counter()
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"--phases exited {done.returncode}: {done.stderr.strip()[-800:]}")
    res = json.loads(done.stdout.strip().splitlines()[-1])
    res["process_wall_s"] = wall
    # what the interpreter itself takes to start and stop, beside the steps timed inside it
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "pass"], check=True)
    res["interpreter_start_s"] = time.perf_counter() - t0
    return res


def accuracy(n: int, yaml: Path, photo: Path) -> dict:
    """The photo chain with and without ``fast`` on n held-out front renders and the sample."""
    import numpy as np

    from segment_accuracy import HELDOUT_SEED_BASE, pitch_errors
    from wtcli.plan.angles import blade_azimuths
    from wtcli.plan.config import load_mission
    from wtcli.segment.infer import segment_image
    from wtcli.synth.render import render_sample

    ways = {"default": {"right": 0, "errs": [], "s": 0.0}, "fast": {"right": 0, "errs": [], "s": 0.0}}
    for i in range(n):
        s = render_sample(HELDOUT_SEED_BASE + 2 * i, width=640, height=480, view="front")
        for way, fast in (("default", False), ("fast", True)):
            t0 = time.perf_counter()
            inst = segment_image(s.image, flip=not fast, zoom=not fast)
            ways[way]["s"] += time.perf_counter() - t0
            k, e, _ = pitch_errors(inst, s.truth, completion=True)
            ways[way]["right"] += k == s.truth["blades_visible"]
            ways[way]["errs"] += e
    out = {"renders": n}
    for way, w in ways.items():
        out[way] = {"right_blade_count": w["right"] / max(n, 1),
                    "theta_error_mean_deg": float(np.mean(w["errs"])) if w["errs"] else None,
                    "theta_error_p95_deg": float(np.percentile(w["errs"], 95)) if w["errs"] else None,
                    "segment_s_per_render": w["s"] / max(n, 1)}
    m = load_mission(yaml)
    az = {way: blade_azimuths(m, [f"T1={photo}"], None, fast=fast)[0]["T1"]
          for way, fast in (("default", False), ("fast", True))}
    d = [abs((a - b + 180.0) % 360.0 - 180.0) for a, b in zip(sorted(az["default"]), sorted(az["fast"]))]
    out["sample_photo"] = {"azimuths_deg": az, "max_difference_deg": max(d)}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--yaml", type=Path, default=ROOT / "sample_images" / "turbines.yaml")
    ap.add_argument("--photo", type=Path, default=ROOT / "sample_images" / "images" / "00000.jpg")
    ap.add_argument("--accuracy", type=int, default=0, metavar="N",
                    help="also compare --fast with the default on N held-out front renders")
    ap.add_argument("--phases", action="store_true", help=argparse.SUPPRESS)  # the child run
    ap.add_argument("--phases-out", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--fast", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.phases:
        print(json.dumps(phases(args.yaml, args.photo, args.phases_out, args.fast)))
        return 0
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "plan.json"
        res = {}
        for way, fast in (("default", False), ("fast", True)):
            run_once(args.yaml, args.photo, out, fast)  # warm-up
            runs = [run_once(args.yaml, args.photo, out, fast) for _ in range(args.repeat)]
            res[way] = {"median_s": statistics.median(runs), "runs_s": runs,
                        "phases": run_phases(args.yaml, args.photo, out, fast)}
    load_after = os.getloadavg()[0]
    for way, r in res.items():
        print(f"photo -> plan{' --fast' if way == 'fast' else ''}, median of {len(r['runs_s'])}: "
              f"{r['median_s']:.2f} s wall (runs {', '.join(f'{x:.2f}' for x in r['runs_s'])}); "
              f"target {TARGET_S:.1f} s: {r['median_s'] / TARGET_S:.1f}x the target")
        p = r["phases"]
        print(f"  where it goes (one more run, {p['process_wall_s']:.2f} s wall; the interpreter "
              f"starting and stopping: {p['interpreter_start_s']:.2f} s):")
        for s in p["steps"]:
            print(f"    {s['what']:<55s} {s['wall_s']:6.2f} s wall {s['cpu_s']:6.2f} s CPU")
    print(f"load average (1 min) before / after: {load_before:.2f} / {load_after:.2f} on "
          f"{os.cpu_count()} CPUs")
    figures = {"median_s": res["default"]["median_s"], "runs_s": res["default"]["runs_s"],
               "fast_median_s": res["fast"]["median_s"], "fast_runs_s": res["fast"]["runs_s"],
               "phases": {k: r["phases"] for k, r in res.items()},
               "target_s": TARGET_S, "ratio_to_target": res["default"]["median_s"] / TARGET_S,
               "load_avg_1min": [load_before, load_after],
               "photo": str(args.photo.relative_to(ROOT)) if args.photo.is_relative_to(ROOT)
               else str(args.photo)}
    if args.accuracy:
        acc = accuracy(args.accuracy, args.yaml, args.photo)
        figures["fast_accuracy"] = acc
        for way in ("default", "fast"):
            a = acc[way]
            print(f"{way}: right blade count {a['right_blade_count']:.1%} of {acc['renders']} front "
                  f"renders, theta error mean {a['theta_error_mean_deg']:.2f} deg (p95 "
                  f"{a['theta_error_p95_deg']:.2f}), segmentation {a['segment_s_per_render']:.2f} s "
                  "per render")
        print(f"sample photo: blade azimuths {acc['sample_photo']['azimuths_deg']}, largest "
              f"difference {acc['sample_photo']['max_difference_deg']:.2f} deg")
    save("plan_latency", figures)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
