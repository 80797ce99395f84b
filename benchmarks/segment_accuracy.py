"""Accuracy and speed of the shipped segmenter (models/wtseg-r18s.pt).

    python benchmarks/segment_accuracy.py [--n 300] [--model PATH] [--real DIR] [--out FILE]

1. Held-out synthetic set: ``render_sample(9_000_000 + i, 640, 480, view)`` — seeds never used
   in training (training uses 1_000_000 + i) — with every other image a front view and the rest
   drawn from the renderer's mix (oblique, side, rear; ground, sea, skies). Reported:
   * mask IoU per class: IoU of the class's union mask (score >= 0.5) with the truth's, per
     image where either has the class, averaged; against the renderer's default "outline"
     labels, and in ``half_labels`` against the half-coverage labels used until 2026-12
     (docs/synth.md);
   * AP50 per class (instances matched greedily by score at mask IoU >= 0.5);
   * front views: share where segment -> contours -> pitch finds exactly the true number of
     visible blades of the main turbine (``truth["blades_visible"]``), as the CLI does it:
     instances scoring >= 0.5 counted, blades down to ``CANDIDATE_FLOOR`` (0.2) offered to
     pitch's rotor completion (docs/pitch.md); ``..._without_completion``: the 0.5 instances
     alone, as before completion existed;
   * front views: end-to-end blade θ error — segment -> ``wtcli.pitch.pitch_from_instances`` —
     each measured blade matched to the true blade of nearest φ; |θ error| mod 180, with and
     without completion, and over the admitted blades alone. The same pitch run on the TRUE
     masks is printed beside it, to separate segmentation error from pitch error.
2. Speed: one 1024 x 683 render, images/s of our model (``predict``, as ``segment`` runs it)
   and of torchvision's stock ``maskrcnn_resnet50_fpn(weights=None, weights_backbone=None)`` on
   the same input tensor, in this one process, same thread count; their ratio, with and without
   the mirrored masks (``segment --no-flip``). (Untrained stock
   weights: its timing includes its usual 100 detections per image.) Our model runs in the
   precision ``--precision`` gives (auto: the backbone in bfloat16 on a CPU that does it
   natively, as ``segment`` does); the stock one in float32, as torchvision ships it; when ours
   runs in bf16, its float32 speed and ratio are reported beside.
3. Real photos, when ``--real`` (default ../shared/real-photos beside the repo) exists: blade and tower IoU
   of the class map (one class a pixel, as ``segment_real.py`` scores it) against its semantic
   masks (0 background, 1 blade, 2 tower incl. nacelle/hub; our tower = tower ∪ nacelle), and
   the blade count on the photos the manifest tags as front
   views (with and without completion); skipped when the model trained on real photos (its
   meta names them), whose figures come from ``segment_real.py``, cross-validated by flight
   sequence. Never copy the photos into the repo.

4. Edge refinement (``wtcli.segment.refine``; ``--no-refine`` skips it): every figure
   of the second look again with the instances' edges refined, as ``segment`` gives them
   (``synthetic.refined``, ``real.refined``), and the speed with it (``speed.ours_refined_...``;
   ``speed.ours_segment_images_per_s``: all that ``segment`` runs by default, the wide look,
   the second look and the refiner, on the speed render and on a distant one, with its ratio to the stock
   network in ``speedup_vs_stock_segment``).

Results are printed and written as JSON (``--out``, default benchmarks/results/segment_accuracy.json),
with the command, date and machine (``benchmarks/_results.py``); ``docs/benchmarks.md`` shows them.

``--dev`` runs part 1 alone on the development seeds (``render_sample(7_000_000 + i, ...)``, the
same mix): where errors are looked into and settings chosen, so the held-out set stays unseen.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from wtcli.errors import WtError  # noqa: E402
from _results import save  # noqa: E402
from wtcli.masks import Instances  # noqa: E402
from wtcli.segment.data import DEV_SEED_BASE, HELDOUT_SEED_BASE, image_tensor  # noqa: E402
from wtcli.segment.evaluate import Evaluator, mask_iou  # noqa: E402
from wtcli.pitch import CANDIDATE_FLOOR, DEFAULT_SCORE_THRESHOLD  # noqa: E402
from wtcli.segment.infer import load_model, predict, second_look, wide_look  # noqa: E402
from wtcli.segment.post import absorb_blade_ends  # noqa: E402
from wtcli.segment.model import resolve_weights  # noqa: E402
from wtcli.segment.refine import load_refiner, refine_edges, resolve_refiner  # noqa: E402
from segment_real import class_parts  # noqa: E402  (the photos scored as segment_real scores them)

ROOT = Path(__file__).resolve().parents[1]
# The blade count is also split by how much of the frame the rotor spans (its diameter /
# frame height). The pipeline's own photo, from S_p at the zone radius, is well above this;
# below it the turbine is small and far (blades a few pixels wide).
FILL_WORKING = 0.35


def looks(model, image, first):
    """The wide look, then the second look, on the first look's instances from the candidate
    floor up: what ``segment_image`` runs before its tip rule and the refiner."""
    return second_look(model, image, wide_look(model, image, first, CANDIDATE_FLOOR, sure=0.5),
                       CANDIDATE_FLOOR)


def theta_diff(a: float, b: float) -> float:
    d = abs(a - b) % 180.0
    return min(d, 180.0 - d)


def phi_diff(a: float, b: float) -> float:
    d = abs(a - b) % 360.0
    return min(d, 360.0 - d)


def theta_stats(errs: list[float]) -> dict:
    """Mean, median and p95 of |θ error| (deg) and how many blades they are over."""
    return {"theta_error_mean_deg": float(np.mean(errs)) if errs else None,
            "theta_error_median_deg": float(np.median(errs)) if errs else None,
            "theta_error_p95_deg": float(np.percentile(errs, 95)) if errs else None,
            "theta_blades_measured": len(errs)}


def pitch_errors(inst: Instances, truth: dict, completion: bool = False
                 ) -> tuple[int, list[float], list[float]]:
    """(blades found, |θ error| of each found blade vs the true blade nearest in φ, the same
    for the blades admitted by rotor completion). ``completion``: ``inst`` holds blades down
    to the candidate floor and pitch counts what scores 0.5 (as the CLI); else all count."""
    from wtcli.pitch import pitch_from_instances

    try:
        res = pitch_from_instances(inst, expected_blades=None,
                                   score_threshold=DEFAULT_SCORE_THRESHOLD if completion else None)
    except WtError:
        return 0, [], []
    true = [b for b in truth["blades"] if b.get("visible")]
    errs, admitted = [], []
    for b in res.blades:
        if true:
            t = min(true, key=lambda tb: phi_diff(tb["phi_deg"], b.phi_deg))
            errs.append(theta_diff(b.theta_deg, t["theta_deg"]))
            if b.admitted_low_score:
                admitted.append(errs[-1])
    return len(res.blades), errs, admitted


def completion_input(pred: Instances) -> Instances:
    """What ``segment_image`` hands pitch: instances >= 0.5 and blades >= the candidate floor."""
    if not len(pred):
        return pred
    return pred[(pred.scores >= DEFAULT_SCORE_THRESHOLD)
                | ((pred.labels == "blade") & (pred.scores >= CANDIDATE_FLOOR))]


def synthetic(model, n: int, width: int, height: int, log, max_minutes: float | None = None,
              seed_base: int = HELDOUT_SEED_BASE, refiner=None) -> dict:
    from wtcli.synth.render import render_sample

    ev = Evaluator(0.5)
    # The same predictions scored against the half-coverage labels too (docs/synth.md, label
    # convention), so figures compare with models trained on those labels.
    ev_half, zev_half = Evaluator(0.5), Evaluator(0.5)
    zoom = {"ev": Evaluator(0.5), "right": 0, "errs": [], "by_fill": {"distant": [0, 0], "working": [0, 0]}}
    # What `segment` gives by default: the wide and second looks' instances, edges refined.
    rf = {"ev": Evaluator(0.5), "half": Evaluator(0.5), "right": 0, "errs": [],
          "by_fill": {"distant": [0, 0], "working": [0, 0]}}
    views: dict[str, int] = {}
    grounds: dict[str, int] = {}
    front_n = front_right = front_right0 = gt_right = 0
    by_fill = {"distant": [0, 0, 0], "working": [0, 0, 0]}  # [front views, right, right w/o]
    errs, errs0, adm_errs, gt_errs = [], [], [], []
    wrong: list[dict] = []  # front views read wrong (second look)
    t0 = time.perf_counter()
    done = 0
    for i in range(n):
        if max_minutes and time.perf_counter() - t0 > 60 * max_minutes:
            log(f"  time limit: stopped after {i} images")
            break
        done = i + 1
        s = render_sample(seed_base + i, width=width, height=height,
                          view="front" if i % 2 == 0 else None)
        views[s.truth["view"]] = views.get(s.truth["view"], 0) + 1
        g = (s.truth.get("environment") or {}).get("ground", "?")
        grounds[g] = grounds.get(g, 0) + 1
        pred = predict(model, s.image, score_threshold=0.0)
        ev.add(pred, s.instances)
        # What segment_image gives (small turbines looked at again), from the candidate floor up.
        zpred = absorb_blade_ends(looks(model, s.image, pred[pred.scores >= CANDIDATE_FLOOR]), 0.5)
        zoom["ev"].add(zpred, s.instances)
        half = render_sample(seed_base + i, width=width, height=height,
                             view="front" if i % 2 == 0 else None, labels="half").instances
        ev_half.add(pred, half)
        zev_half.add(zpred, half)
        rpred = refine_edges(refiner, s.image, zpred) if refiner is not None else None
        if rpred is not None:
            rf["ev"].add(rpred, s.instances)
            rf["half"].add(rpred, half)
        if s.truth["view"] == "front":
            front_n += 1
            conf = pred[pred.scores >= 0.5] if len(pred) else pred
            k0, e0, _ = pitch_errors(conf, s.truth)
            k, e, ea = pitch_errors(completion_input(pred), s.truth, completion=True)
            front_right += k == s.truth["blades_visible"]
            front_right0 += k0 == s.truth["blades_visible"]
            band = by_fill["distant" if s.truth["fill"] < FILL_WORKING else "working"]
            band[0] += 1
            band[1] += k == s.truth["blades_visible"]
            band[2] += k0 == s.truth["blades_visible"]
            errs += e
            errs0 += e0
            kz, ez, _ = pitch_errors(completion_input(zpred), s.truth, completion=True)
            zoom["right"] += kz == s.truth["blades_visible"]
            if kz != s.truth["blades_visible"]:
                wrong.append({"seed": seed_base + i, "blades_visible": s.truth["blades_visible"],
                              "found": kz, "found_first_pass": k, "fill": round(s.truth["fill"], 3)})
            zoom["errs"] += ez
            if rpred is not None:
                kr, er, _ = pitch_errors(completion_input(rpred), s.truth, completion=True)
                rf["right"] += kr == s.truth["blades_visible"]
                rf["errs"] += er
                rb = rf["by_fill"]["distant" if s.truth["fill"] < FILL_WORKING else "working"]
                rb[0] += 1
                rb[1] += kr == s.truth["blades_visible"]
            zb = zoom["by_fill"]["distant" if s.truth["fill"] < FILL_WORKING else "working"]
            zb[0] += 1
            zb[1] += kz == s.truth["blades_visible"]
            adm_errs += ea
            k2, e2, _ = pitch_errors(s.instances, s.truth)
            gt_right += k2 == s.truth["blades_visible"]
            gt_errs += e2
        if (i + 1) % 25 == 0:
            log(f"  {i + 1}/{n} images, {time.perf_counter() - t0:.0f} s")
    out = ev.summary()
    zs = zoom["ev"].summary()
    zs.update({
        "detections_from": CANDIDATE_FLOOR,  # AP counts nothing below it (the plain figures: 0)
        "front_right_blade_count": zoom["right"] / front_n if front_n else None,
        "front_right_blade_count_by_fill": {k: (r / n if n else None) for k, (n, r) in zoom["by_fill"].items()},
        **theta_stats(zoom["errs"]),
        "front_wrong_blade_count": wrong,
    })
    refined = None
    if refiner is not None:
        refined = rf["ev"].summary()
        refined.update({
            "half_labels": rf["half"].summary(),
            "front_right_blade_count": rf["right"] / front_n if front_n else None,
            "front_right_blade_count_by_fill": {k: (r / n if n else None) for k, (n, r) in rf["by_fill"].items()},
            **theta_stats(rf["errs"]),
        })
    out.update({
        "refined": refined,
        "labels": "outline",
        "half_labels": {"first_pass": ev_half.summary(), "zoom": zev_half.summary()},
        "zoom": zs,
        "n": done, "n_asked": n, "width": width, "height": height,
        "seeds": [seed_base, seed_base + done - 1],
        "views": views, "grounds": grounds,
        "front_views": front_n,
        "rotor_completion": {"score_threshold": DEFAULT_SCORE_THRESHOLD,
                             "candidate_floor": CANDIDATE_FLOOR},
        "front_right_blade_count": front_right / front_n if front_n else None,
        "front_right_blade_count_without_completion": front_right0 / front_n if front_n else None,
        "front_right_blade_count_on_true_masks": gt_right / front_n if front_n else None,
        "front_right_blade_count_by_fill": {
            name: {"front_views": n, "right": r / n if n else None,
                   "right_without_completion": r0 / n if n else None,
                   "fill": f"< {FILL_WORKING}" if name == "distant" else f">= {FILL_WORKING}"}
            for name, (n, r, r0) in by_fill.items()},
        "theta_error_mean_deg": float(np.mean(errs)) if errs else None,
        "theta_error_median_deg": float(np.median(errs)) if errs else None,
        "theta_error_p95_deg": float(np.percentile(errs, 95)) if errs else None,
        "theta_blades_measured": len(errs),
        "theta_error_mean_without_completion_deg": float(np.mean(errs0)) if errs0 else None,
        "theta_blades_measured_without_completion": len(errs0),
        "blades_admitted": len(adm_errs),
        "theta_error_mean_admitted_deg": float(np.mean(adm_errs)) if adm_errs else None,
        "theta_error_max_admitted_deg": float(np.max(adm_errs)) if adm_errs else None,
        "theta_error_mean_on_true_masks_deg": float(np.mean(gt_errs)) if gt_errs else None,
        "seconds": time.perf_counter() - t0,
    })
    return out


def speed(model, runs: int, with_stock: bool, fp32_model=None, refiner=None) -> dict:
    from wtcli.synth.render import render_sample

    img = render_sample(HELDOUT_SEED_BASE + 999_999, width=1024, height=683, view="front").image

    def clock(fn) -> float:
        fn()
        t = time.perf_counter()
        for _ in range(runs):
            fn()
        return runs / (time.perf_counter() - t)

    ours = clock(lambda: predict(model, img, score_threshold=0.5))
    # As segment_image runs it: the candidate floor, small turbines looked at again (this render
    # and a distant one, several small turbines in view).
    far = next(r.image for r in (render_sample(HELDOUT_SEED_BASE + 999_998 - k, width=1024, height=683,
                                               view="front") for k in range(500))
               if r.truth["fill"] < FILL_WORKING)
    zoomed = {name: clock(lambda im=im: looks(model, im, predict(model, im, CANDIDATE_FLOOR)))
              for name, im in (("this render", img), ("a distant render", far))}
    out = {"input": "1024x683 BGR render", "runs": runs, "threads": torch.get_num_threads(),
           "precision": getattr(model, "precision", "fp32"),
           "ours_images_per_s": ours, "ours_with_zoom_images_per_s": zoomed}
    if refiner is not None:  # the network, then the edge refiner: what `segment --no-zoom` runs
        out["ours_refined_images_per_s"] = clock(
            lambda: refine_edges(refiner, img, predict(model, img, score_threshold=0.5)))
        # Everything `segment` runs by default: the candidate floor, the wide and second looks, the refiner.
        out["ours_segment_images_per_s"] = {
            name: clock(lambda im=im: refine_edges(refiner, im, looks(
                model, im, predict(model, im, CANDIDATE_FLOOR))))
            for name, im in (("this render", img), ("a distant render", far))}
    # Without the mirrored masks (segment --no-flip), for the record.
    out["ours_no_flip_images_per_s"] = clock(lambda: predict(model, img, score_threshold=0.5, flip=False))
    if fp32_model is not None:  # the same network in float32, for the record
        out["ours_fp32_images_per_s"] = clock(lambda: predict(fp32_model, img, score_threshold=0.5))
    if with_stock:
        from torchvision.models.detection import maskrcnn_resnet50_fpn

        torch.manual_seed(0)
        stock = maskrcnn_resnet50_fpn(weights=None, weights_backbone=None).eval()
        x = image_tensor(img)

        def run_stock():
            with torch.inference_mode():
                stock([x])

        out["stock_r50_fpn_images_per_s"] = clock(run_stock)
        out["speedup_vs_stock"] = ours / out["stock_r50_fpn_images_per_s"]
        if "ours_refined_images_per_s" in out:
            out["speedup_vs_stock_refined"] = out["ours_refined_images_per_s"] / out["stock_r50_fpn_images_per_s"]
        if "ours_segment_images_per_s" in out:
            out["speedup_vs_stock_segment"] = {name: v / out["stock_r50_fpn_images_per_s"]
                                               for name, v in out["ours_segment_images_per_s"].items()}
        out["speedup_vs_stock_no_flip"] = out["ours_no_flip_images_per_s"] / out["stock_r50_fpn_images_per_s"]
        if "ours_fp32_images_per_s" in out:
            out["speedup_vs_stock_fp32"] = out["ours_fp32_images_per_s"] / out["stock_r50_fpn_images_per_s"]
    return out


def _col(fields: list[str], *keys: str) -> str | None:
    for k in keys:
        for f in fields:
            if k in f.lower():
                return f
    return None


def real_photos(model, root: Path, log, refiner=None) -> dict:
    """IoU on the real photos' semantic masks; blade count on their front views."""
    man = root / "manifest.csv"
    rows = list(csv.DictReader(man.open(encoding="utf-8"))) if man.is_file() else []
    fields = list(rows[0].keys()) if rows else []
    c_img = _col(fields, "image", "photo", "file")
    c_mask = _col(fields, "mask", "label")
    c_view = _col(fields, "view", "tag")
    items = []
    if rows and c_img:
        for r in rows:
            ip = root / r[c_img]
            mp = root / r[c_mask] if c_mask and r.get(c_mask) else None
            items.append((ip, mp, (r.get(c_view) or "") if c_view else ""))
    else:  # no usable manifest: pair images/X.* with masks/X.png
        for ip in sorted((root / "images").glob("*")):
            items.append((ip, root / "masks" / (ip.stem + ".png"), ""))
    blade_iou, tower_iou, counts, counts0 = [], [], [], []
    errors, per_photo = [], []
    zoom: dict[str, list] = {"blade_iou": [], "tower_iou": [], "counts": []}
    # refined: the first pass's and the second look's instances with their edges refined
    ref: dict[str, list] = {"blade_iou": [], "tower_iou": [], "zoom_blade_iou": [], "zoom_tower_iou": [],
                            "counts": []}
    for ip, mp, view in items:
        img = cv2.imread(str(ip), cv2.IMREAD_COLOR)
        if mp is None or not mp.is_file():
            cand = sorted((root / "masks").glob(ip.stem + ".*")) if (root / "masks").is_dir() else []
            mp = cand[0] if cand else None
        sem = cv2.imread(str(mp), cv2.IMREAD_UNCHANGED) if mp is not None else None
        if img is None or sem is None:
            errors.append(str(ip))
            continue
        if sem.ndim == 3:
            sem = sem[:, :, 0]
        if sem.shape != img.shape[:2]:
            sem = cv2.resize(sem, (img.shape[1], img.shape[0]), interpolation=cv2.INTER_NEAREST)
        low = predict(model, img, score_threshold=CANDIDATE_FLOOR)
        pred = low[low.scores >= 0.5] if len(low) else low  # = predicting at 0.5
        blade, tower, _ = class_parts(pred)
        blade_iou.append(mask_iou(blade, sem == 1))
        tower_iou.append(mask_iou(tower, sem == 2))
        zlow = absorb_blade_ends(looks(model, img, low), 0.5)
        zpred = zlow[zlow.scores >= 0.5] if len(zlow) else zlow
        zblade, ztower, _ = class_parts(zpred)
        zoom["blade_iou"].append(mask_iou(zblade, sem == 1))
        zoom["tower_iou"].append(mask_iou(ztower, sem == 2))
        if refiner is not None:
            for key, inst in (("", pred), ("zoom_", zpred)):
                r = refine_edges(refiner, img, inst)
                rb, rt, _ = class_parts(r)
                ref[key + "blade_iou"].append(mask_iou(rb, sem == 1))
                ref[key + "tower_iou"].append(mask_iou(rt, sem == 2))
            if "front" in view.lower():
                from wtcli.pitch import pitch_from_instances

                try:
                    ref["counts"].append(len(pitch_from_instances(
                        refine_edges(refiner, img, completion_input(zlow)), expected_blades=None).blades))
                except WtError:
                    ref["counts"].append(0)
        per_photo.append({"image": ip.name, "view": view, "blade_iou": round(blade_iou[-1], 4),
                          "tower_iou": round(tower_iou[-1], 4),
                          "zoom_blade_iou": round(zoom["blade_iou"][-1], 4),
                          "zoom_tower_iou": round(zoom["tower_iou"][-1], 4),
                          **({"refined_blade_iou": round(ref["blade_iou"][-1], 4),
                              "refined_tower_iou": round(ref["tower_iou"][-1], 4)} if refiner is not None else {}),
                          # predicted / true blade pixels: < 1 where blades come out too thin
                          "blade_area_ratio": round(float(blade.sum()) / max(int((sem == 1).sum()), 1), 3)})
        if "front" in view.lower():
            from wtcli.pitch import pitch_from_instances

            for out, inp in ((counts0, pred), (counts, completion_input(low)),
                             (zoom["counts"], completion_input(zlow))):
                try:
                    out.append(len(pitch_from_instances(inp, expected_blades=None).blades))
                except WtError:
                    out.append(0)
    log(f"  real photos: {len(blade_iou)} evaluated, {len(errors)} unreadable")
    far = [r for r in per_photo if "distant" in r["view"].lower()]
    near = [r for r in per_photo if "distant" not in r["view"].lower()]
    refined = None
    if refiner is not None and ref["blade_iou"]:
        refined = {k: float(np.mean(v)) for k, v in ref.items() if k != "counts"}
        refined["blade_iou_distant"] = float(np.mean([r["refined_blade_iou"] for r in far])) if far else None
        refined["front_blade_counts"] = ref["counts"]
        refined["front_blade_count_3"] = (sum(c == 3 for c in ref["counts"]) / len(ref["counts"])
                                          if ref["counts"] else None)
    return {"photos": len(blade_iou), "unreadable": errors, "refined": refined,
            "blade_iou_distant": float(np.mean([r["blade_iou"] for r in far])) if far else None,
            "blade_iou_not_distant": float(np.mean([r["blade_iou"] for r in near])) if near else None,
            "distant_photos": len(far),
            "per_photo": per_photo,
            "zoom": {"blade_iou": float(np.mean(zoom["blade_iou"])) if zoom["blade_iou"] else None,
                     "tower_iou": float(np.mean(zoom["tower_iou"])) if zoom["tower_iou"] else None,
                     "blade_iou_distant": float(np.mean([r["zoom_blade_iou"] for r in far])) if far else None,
                     "front_blade_counts": zoom["counts"],
                     "front_blade_count_3": (sum(c == 3 for c in zoom["counts"]) / len(zoom["counts"]))
                     if zoom["counts"] else None},
            "blade_iou": float(np.mean(blade_iou)) if blade_iou else None,
            "tower_iou": float(np.mean(tower_iou)) if tower_iou else None,
            "front_views": len(counts),
            "front_blade_count_3": (sum(c == 3 for c in counts) / len(counts)) if counts else None,
            "front_blade_counts": counts,
            "front_blade_count_3_without_completion":
                (sum(c == 3 for c in counts0) / len(counts0)) if counts0 else None,
            "front_blade_counts_without_completion": counts0}


def _trained_on_real(model) -> str | None:
    """The real-photo folder a loaded model's (or refiner's) weights trained on (their meta's
    ``real``)."""
    return (getattr(model, "meta", None) or {}).get("real") or None


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--model", default=None)
    ap.add_argument("--real", default=str(ROOT.parent / "shared" / "real-photos"))
    ap.add_argument("--speed-runs", type=int, default=5)
    ap.add_argument("--no-stock", action="store_true", help="skip the stock R50-FPN timing")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--precision", default="auto", help="auto | fp32 | bf16 (segment's --precision)")
    ap.add_argument("--max-minutes", type=float, default=None,
                    help="stop the synthetic part after this long (the N reached is reported)")
    ap.add_argument("--dev", action="store_true",
                    help="the synthetic part on the development seeds (7 000 000 + i) instead of the "
                         "held-out ones, and no speed or real-photo part: for looking into errors "
                         "and choosing settings without spending the held-out set (needs --out)")
    ap.add_argument("--refiner", default=None,
                    help="edge refiner weights (default: the shipped models/wtseg-refine.pt)")
    ap.add_argument("--no-refine", action="store_true", help="skip the refined figures")
    ap.add_argument("--mirror-model", default="auto",
                    help="the network reading the mirror pass: auto (the model's NAME.mirror.pt, "
                         "where there is one) | none (the model itself) | a weights file")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    if a.dev and not a.out:
        ap.error("--dev needs --out (the results file is the held-out benchmark's)")
    a.out = a.out or str(ROOT / "benchmarks" / "results" / "segment_accuracy.json")
    if a.threads:
        torch.set_num_threads(a.threads)

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    def shown(path: Path) -> str:  # the repository's own files by relative path, as in the results file
        return str(path.relative_to(ROOT) if path.is_relative_to(ROOT) else path)

    weights = resolve_weights(a.model)
    model = load_model(weights, "cpu", a.precision, mirror=a.mirror_model)
    result: dict = {"model": shown(weights),
                    "mirror_model": None if model.mirror_weights is None else shown(Path(model.mirror_weights)),
                    # the network's working size (shorter side, longer side at most)
                    "working_size": [int(model.transform.min_size[0]), int(model.transform.max_size)]}
    result["precision"] = model.precision
    refiner = None if a.no_refine else load_refiner(a.refiner, model.precision)
    result["refiner"] = None if refiner is None else shown(resolve_refiner(a.refiner))
    if not a.dev:
        log(f"speed ({a.speed_runs} runs each)")
        result["speed"] = speed(model, a.speed_runs, not a.no_stock,
                                load_model(weights, "cpu", "fp32", mirror=a.mirror_model)
                                if model.precision != "fp32" else None,
                                refiner)
    real = Path(a.real)
    # a refiner fine-tuned on the photos (train-refiner --real) has learned them as much
    learned = _trained_on_real(model) or (_trained_on_real(refiner) if refiner is not None else None)
    if a.dev:
        result["real"] = None
    elif learned:
        # Figures on photos the model learned would say nothing; segment_real.py measures the
        # recipe cross-validated by flight sequence instead.
        result["real"] = None
        log(f"  {shown(weights)} or its refiner trained on the real photos ({learned}): "
            "real-photo figures skipped (benchmarks/segment_real.py cross-validates them)")
    elif real.is_dir():
        result["real"] = real_photos(model, real, log, refiner)
    else:
        result["real"] = None
        log(f"  {real}: not here, real-photo figures skipped")
    if a.n > 0:
        log(f"{'development' if a.dev else 'held-out'} synthetic set: {a.n} images")
        result["synthetic"] = synthetic(model, a.n, a.width, a.height, log, a.max_minutes,
                                        DEV_SEED_BASE if a.dev else HELDOUT_SEED_BASE, refiner)
    save("segment_accuracy", result, argv=argv, out=a.out, script=__file__)
    import json

    print(json.dumps(result, indent=1, default=str))
    return result


if __name__ == "__main__":
    main()
