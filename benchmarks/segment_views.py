"""The shipped segmenter on the wider views an inspection folder holds, on renders no run saw.

    python benchmarks/segment_views.py [--n 20] [--n-sizes 40] [--model PATH] [--threads 2]
                                       [--out FILE]

For each of the renderer's wider views (``wtcli.synth.WIDE_VIEWS``, docs/synth.md: blade
close-ups against ground, sea and sky; nadir and steep-down views with spare blades and tracks
on the ground; close hub views from above; frames cutting the nacelle, hub and blade ends;
side-on broad blades; a blade in front of the tower; distant turbines among distractors),
``--n`` renders at 768 x 576, ``render_sample(9_600_000 + 1000 * k + i, view=VIEW)`` for the
k-th view (seeds no training run uses: those are 1 000 000 +; development 7 000 000 +; the
held-out whole-rotor set 9 000 000 +), segmented as ``segment`` does by default (wide look,
second look, mirror pass, refiner). Per view, averaged over its renders:

- blade / tower / nacelle IoU: the class's union mask (instances scoring >= 0.5) against the
  truth's, over the renders where either has the class;
- tower read as blade: the share of the true tower's pixels under a blade instance, over the
  renders with a tower in the truth, and the share of those renders where it is 10 % or more
  (issue #43: "nadir views no longer produce blades on the tower");
- blade read as tower: the share of the true blades' pixels under a tower or nacelle instance
  (spare blades on the ground taken for towers, a blade in front of the tower read as tower).

Then whole turbines at two photo sizes, the held-out set's mix (every other render a front view,
the rest the renderer's draw): ``--n-sizes`` renders at 1920 x 1080, the size of the real photos
(``render_sample(9_700_000 + i, 1920, 1080, view)``), and as many at 768 x 576, the size the
network trained at (``9_700_500 + i``): the same figures, and the renders where blade instances
cover FALSE_BLADE or more of the frame outside the true blades (a patch of sky, haze or a hill
read as a blade), the comparison printed as a ratio.

Results are printed and written as JSON (``--out``, default
benchmarks/results/segment_views.json) with the command, date and machine; ``docs/benchmarks.md``
shows them (``benchmarks/report.py``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _results import save  # noqa: E402  (figures with the command, date and machine)
from segment_real import iou  # noqa: E402  (the real photos' IoU, the same measure)

SEED_BASE = 9_600_000
WIDTH, HEIGHT = 768, 576
SURE = 0.5  # what segment reports
ON_TOWER = 0.10  # a render "reads its tower as blade" when this share of the tower is under a blade
SIZE_SEED_BASE = 9_700_000
SIZES = {"1920x1080": (1920, 1080, 0), "768x576": (768, 576, 500)}  # width, height, seed offset
FALSE_BLADE = 0.03  # share of the frame under blades outside the true blades: "a false blade"


def _union(inst, labels: tuple[str, ...]) -> np.ndarray:
    keep = (inst.scores >= SURE) & np.isin(inst.labels, labels) if len(inst) else np.zeros(0, bool)
    return inst.masks[keep].any(axis=0) if keep.any() else np.zeros(inst.image_size, bool)


def _share(part: np.ndarray, whole: np.ndarray) -> float | None:
    n = np.count_nonzero(whole)
    return float(np.count_nonzero(part & whole) / n) if n else None


def measure(inst, truth) -> dict:
    """One render's figures: IoU per class, tower read as blade, blade read as tower."""
    pb, pt, pn = _union(inst, ("blade",)), _union(inst, ("tower",)), _union(inst, ("nacelle",))
    tb, tt, tn = (truth.of(c).union() for c in ("blade", "tower", "nacelle"))
    return {"blade_iou": iou(pb, tb), "tower_iou": iou(pt, tt), "nacelle_iou": iou(pn, tn),
            "tower_as_blade": _share(pb, tt), "blade_as_tower": _share(pt | pn, tb),
            "false_blade": float(np.count_nonzero(pb & ~tb) / pb.size)}


def summarise(rows: list[dict]) -> dict:
    out: dict = {"renders": len(rows)}
    for key in ("blade_iou", "tower_iou", "nacelle_iou", "tower_as_blade", "blade_as_tower"):
        v = [r[key] for r in rows if r[key] is not None]
        out[key] = round(float(np.mean(v)), 4) if v else None
    on = [r["tower_as_blade"] for r in rows if r["tower_as_blade"] is not None]
    out["renders_with_tower"] = len(on)
    out["tower_as_blade_renders"] = round(float(np.mean([v >= ON_TOWER for v in on])), 4) if on else None
    out["false_blade_renders"] = int(sum(r["false_blade"] >= FALSE_BLADE for r in rows))
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20, help="renders per view")
    ap.add_argument("--n-sizes", type=int, default=40,
                    help="whole-turbine renders at each photo size")
    ap.add_argument("--model", default=None, help="segmenter weights (default: the shipped model)")
    ap.add_argument("--threads", type=int, default=None, help="torch CPU threads")
    ap.add_argument("--out", default=None,
                    help="results file (default benchmarks/results/segment_views.json; needed "
                         "with --model, another --n or --n-sizes)")
    args = ap.parse_args(argv)
    if args.out is None and (args.model or args.n != 20 or args.n_sizes != 40):
        ap.error("--out FILE is needed with --model, another --n or --n-sizes (the default "
                 "results file holds the shipped model's figures on 20 renders a view, 40 a size)")
    import torch

    from wtcli.segment.infer import load_model, segment_image
    from wtcli.segment.model import resolve_weights
    from wtcli.synth import WIDE_VIEWS
    from wtcli.synth.render import render_sample

    if args.threads:
        torch.set_num_threads(args.threads)
    weights = resolve_weights(args.model)
    model = load_model(weights)
    t0 = time.perf_counter()
    per_view, rows_all = {}, []
    for k, view in enumerate(WIDE_VIEWS):
        rows = []
        for i in range(args.n):
            s = render_sample(SEED_BASE + 1000 * k + i, WIDTH, HEIGHT, view=view)
            rows.append(measure(segment_image(s.image, model), s.instances))
        per_view[view] = summarise(rows)
        rows_all += rows
        v = per_view[view]
        print(f"{view:10s} {args.n} renders  blade {v['blade_iou']}  tower {v['tower_iou']}  "
              f"nacelle {v['nacelle_iou']}  tower as blade {v['tower_as_blade']} "
              f"({v['tower_as_blade_renders']} of renders >= {ON_TOWER:.0%})  "
              f"blade as tower {v['blade_as_tower']}  [{time.perf_counter() - t0:.0f} s]",
              flush=True)
    per_size = {}
    for name, (w, h, offset) in SIZES.items():
        rows = []
        for i in range(args.n_sizes):
            which = "front" if i % 2 == 0 else None  # the held-out set's mix
            s = render_sample(SIZE_SEED_BASE + offset + i, w, h, view=which)
            rows.append(measure(segment_image(s.image, model), s.instances))
        per_size[name] = v = summarise(rows)
        print(f"whole turbines at {name}: {args.n_sizes} renders  blade {v['blade_iou']}  tower "
              f"{v['tower_iou']}  nacelle {v['nacelle_iou']}  with a false blade (>= "
              f"{FALSE_BLADE:.0%} of the frame) {v['false_blade_renders']}  "
              f"[{time.perf_counter() - t0:.0f} s]", flush=True)
    big, small = (per_size[k]["false_blade_renders"] for k in SIZES)
    print(f"false blades at the real photos' size against the training size: {big} / {small}"
          + (f" = {big / small:.1f}x" if small else ""))
    res = {"model": str(weights.relative_to(ROOT) if weights.is_relative_to(ROOT) else weights),
           "settings": {"n_per_view": args.n, "n_per_size": args.n_sizes, "width": WIDTH,
                        "height": HEIGHT, "seed_base": SEED_BASE, "score_threshold": SURE,
                        "on_tower": ON_TOWER, "size_seed_base": SIZE_SEED_BASE, "sizes": SIZES,
                        "false_blade": FALSE_BLADE},
           "per_view": per_view, "pooled": summarise(rows_all), "per_size": per_size,
           "seconds": round(time.perf_counter() - t0, 1)}
    save("segment_views", res, argv=argv, out=args.out, script=__file__)
    return res


if __name__ == "__main__":
    main()
