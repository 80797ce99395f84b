"""The segmenter on labelled real photos, cross-validated by flight sequence, per view type.

    python benchmarks/segment_real.py [--real DIR] [--model PATH | --runs DIR [--train ARGS]
                                      [--fold-refiners [--train-refiner ARGS]]] [--refiner PATH]
                                      [--only SEQ ...] [--limit N] [--out FILE]

Photos: a folder with ``manifest.csv`` and semantic masks (default ``../shared/real-photos``
beside the repository: the WTA dataset, G. Zampokas et al., "WTA/TLA: A UAV-captured Dataset
for Semantic Segmentation of Energy Infrastructure", ICUAS 2022,
doi:10.1109/ICUAS54217.2022.9836096). Its flight sequences (``wtcli.segment.real.sequences``)
are the folds: every photo is measured with a model that trained on none of its sequence,
since consecutive frames are near-duplicates.

* ``--model PATH`` (default the shipped ``models/wtseg-r18s.pt``): one model for every fold. It
  must not have trained on a fold's photos: a file whose meta names ``real`` photos is accepted
  only for the sequences in its ``real_holdout``. The shipped model trained on all of them, so
  its figures are its recipe's, cross-validated with ``--runs``; ``segment_real.json`` holds the
  renders-only model it replaced (``git show 5d1df58:models/wtseg-r18s.pt``).
* ``--runs DIR``: fold ``SEQ`` is measured with ``DIR/SEQ/model.pt``; with ``--train ARGS`` the
  folds missing one are trained first, ``wtinspect train ARGS --real DIR --real-holdout-sequence
  SEQ --out DIR/SEQ`` (a stopped fold resumed), so cross-validation is one command.
* ``--fold-refiners`` (with ``--runs``): fold ``SEQ``'s edges refined by
  ``DIR/SEQ/refiner/refiner.pt``, a refiner fine-tuned on the photos of the other folds; with
  ``--train-refiner ARGS`` those missing are trained first, ``wtinspect train-refiner ARGS
  --model DIR/SEQ/model.pt --real DIR --real-holdout-sequence SEQ --out DIR/SEQ/refiner``.
  Otherwise every fold is refined by ``--refiner`` (default the shipped
  ``models/wtseg-refine.pt``), which must not have learned the fold's photos either (the same
  check on its meta).

Each photo is segmented as ``segment`` does by default (second look for small turbines, mirror
pass, edge refiner) and its class map (``classes/NAME.png``: one class a pixel, nacelle over
tower over blade where masks overlap, ``Instances.class_map``) scored against its semantic mask:
blade IoU (class 1 against class 1), tower IoU (tower and nacelle against class 2, which holds
the nacelle and the hub), and nacelle IoU on the photos where ``split_semantic`` tells a nacelle
apart (a heuristic truth); ``*_iou_union`` beside them score the classes' instance unions
instead (a pixel in masks of two classes counts for both). Two diagnostics of the photos'
hand-drawn outline, which runs about a pixel outside the edge the renders' labels and so the
masks follow (not what ``segment`` writes): ``*_iou_grown`` scores the class map with every
part's region grown by one pixel (``grown``), and ``outline_tint`` gives the quartiles, over
every photo's pixels, of the share of the blade's contrast carried by the photos' blade pixels
beyond ours, by the background just outside theirs and by our masks' own edge. IoU is per photo
where the prediction or the truth has the class, then averaged: per view type
(``wtcli.segment.real.VIEW_TYPES``), per fold and pooled. Front and front-oblique
views whose truth splits into exactly three blades at one hub: the share where pitch reads
exactly three blades, and the blade-angle error against pitch run on the split truth (each true
blade matched to the measured one of nearest phi; theta mod 180, phi mod 360).

Writes ``benchmarks/results/segment_real.json`` (``_results.save``) for the default model on
every photo, ``segment_real_finetune.json`` with ``--runs``; ``--model``, ``--only``,
``--limit``, ``--max-side`` and ``--no-refine`` need ``--out``, so that another model or a
subset never overwrites those figures.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from wtcli.errors import WtError  # noqa: E402
from wtcli.segment import real as R  # noqa: E402
from wtcli.segment.edges import _disk  # noqa: E402  (the refiner's disk, as refine.py takes it)

FRONT_VIEWS = ("front", "front-oblique")


def iou(a: np.ndarray, b: np.ndarray) -> float | None:
    u = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / u) if u else None


def class_parts(conf) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(blade, tower with nacelle, nacelle) as the class map ``segment`` writes shows them (one
    class a pixel, ``Instances.class_map``), to score against a semantic mask."""
    return map_parts(conf.class_map())


def map_parts(cmap: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(blade, tower with nacelle, nacelle) of a class map: the photos' class 2 holds both."""
    return cmap == 1, cmap >= 2, cmap == 3


def grown(cmap: np.ndarray) -> np.ndarray:
    """The class map with each class's region grown by one pixel (3 x 3), painted in the class
    map's order: the outline people draw round a part in a photo, about a pixel outside the
    edge the renders' labels and so the network's masks follow (docs/train.md)."""
    out = cmap.copy()
    kernel = np.ones((3, 3), np.uint8)
    for c in (1, 2, 3):  # blade, tower, nacelle: wtcli.masks.CLASS_MAP_ORDER
        region = cv2.dilate((cmap == c).astype(np.uint8), kernel).astype(bool)
        out[region & (out < c)] = c
    return out


def outline_tint(image_bgr: np.ndarray, truth: np.ndarray, pred: np.ndarray) -> dict[str, np.ndarray]:
    """How much of a blade's contrast with its background the pixels at its edge carry: 0 looks
    like the background just outside, 1 like the blade inside. Per pixel, (grey - local
    background) / (local blade - local background), the local means over the pixels both masks
    hold (eroded by one) within 5 px and the pixels neither holds, 3 px clear of both, within
    7 px; pixels whose blade and background differ by less than 15 grey levels are left out.
    Returns the shares of ``missed`` (the truth's pixels within 2 px of ``pred`` that it leaves
    out), ``edge`` (``pred``'s own boundary pixels inside the truth) and ``beyond`` (the
    pixels just outside the truth and ``pred``: the background, for scale)."""
    grey = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    both = cv2.erode((truth & pred).astype(np.uint8), _disk(1)).astype(np.float32)
    clear = ~cv2.dilate((truth | pred).astype(np.uint8), _disk(3)).astype(bool)

    def local_mean(weight: np.ndarray, r: int) -> tuple[np.ndarray, np.ndarray]:
        k = (2 * r + 1, 2 * r + 1)
        n = cv2.boxFilter(weight, -1, k, normalize=False)
        return cv2.boxFilter(grey * weight, -1, k, normalize=False) / np.maximum(n, 1e-6), n

    inside, n_in = local_mean(both, 5)
    outside, n_out = local_mean(clear.astype(np.float32), 7)
    ok = (n_in > 3) & (n_out > 10) & (np.abs(inside - outside) > 15)
    share = (grey - outside) / np.where(ok, inside - outside, 1.0)
    near = cv2.dilate(pred.astype(np.uint8), _disk(2)).astype(bool)
    rim = pred & ~cv2.erode(pred.astype(np.uint8), _disk(1)).astype(bool)
    ring = ~truth & ~pred & cv2.dilate(truth.astype(np.uint8), _disk(1)).astype(bool)
    return {"missed": share[truth & ~pred & near & ok], "edge": share[rim & truth & ok],
            "beyond": share[ring & ok]}


def tint_summary(parts: list[dict[str, np.ndarray]]) -> dict:
    out = {}
    for key in ("missed", "edge", "beyond"):
        v = np.concatenate([p[key] for p in parts]) if parts else np.zeros(0)
        out[key] = ({"pixels": int(v.size), **{f"p{q}": round(float(np.percentile(v, q)), 3)
                                               for q in (25, 50, 75)}} if v.size else None)
    return out


def model_for_fold(args, seq: str, log) -> Path:
    if args.runs is None:
        path = Path(args.model) if args.model else ROOT / "models" / "wtseg-r18s.pt"
        check_not_trained_on(path, seq)
        return path
    run = Path(args.runs) / seq
    path = run / "model.pt"
    _train_fold(path, seq, "model", args.train, "--train",
                ["train", *(args.train or "").split(), "--real", str(args.real),
                 "--real-holdout-sequence", seq, "--out", str(run)], run / "last.ckpt", log)
    check_not_trained_on(path, seq)
    return path


def refiner_for_fold(args, seq: str, log) -> Path:
    if not args.fold_refiners:
        path = Path(args.refiner) if args.refiner else ROOT / "models" / "wtseg-refine.pt"
        check_not_trained_on(path, seq)
        return path
    run = Path(args.runs) / seq / "refiner"
    path = run / "refiner.pt"
    _train_fold(path, seq, "refiner", args.train_refiner, "--train-refiner",
                ["train-refiner", *(args.train_refiner or "").split(),
                 "--model", str(Path(args.runs) / seq / "model.pt"), "--real", str(args.real),
                 "--real-holdout-sequence", seq, "--out", str(run)], run / "data", log)
    check_not_trained_on(path, seq)
    return path


def _train_fold(path: Path, seq: str, what: str, given: str | None, option: str,
                command: list[str], started: Path, log) -> None:
    """Where fold ``seq`` has no ``path``, run ``wtinspect COMMAND`` (``option`` ARGS given),
    resumed where a stopped run left ``started``."""
    if path.is_file():
        return
    if given is None:
        raise SystemExit(f"{path}: no {what} for fold {seq} (train it: {option} ARGS)")
    cmd = [sys.executable, "-m", "wtcli", *command] + (["--resume"] if started.exists() else [])
    log(f"fold {seq}: {' '.join(cmd[2:])}")
    subprocess.run(cmd, check=True, cwd=ROOT)


def check_not_trained_on(path: Path, seq: str) -> None:
    """A segmenter's or a refiner's weights: refused for fold ``seq`` when their meta says they
    learned real photos without holding ``seq`` out."""
    import torch

    meta = torch.load(path, map_location="cpu", weights_only=True).get("meta", {})
    if meta.get("real") and seq not in (meta.get("real_holdout") or []):
        raise SystemExit(f"{path} trained on real photos ({meta['real']}) without holding out "
                         f"sequence {seq}: its figures on {seq} would be on photos it learned")


def front_truth(split) -> object | None:
    """Pitch on the split truth when it is one rotor of exactly three blades, else None."""
    from wtcli.pitch import pitch_from_instances

    if len(split.hubs) != 1 or sum(h == 0 for h in split.blade_hub) != 3:
        return None
    try:
        res = pitch_from_instances(split.instances, expected_blades=None)
    except WtError:
        return None
    return res if len(res) == 3 else None


def angle_errors(truth, pred) -> list[tuple[float, float]]:
    """(|theta error| mod 180, |phi error| mod 360) per true blade, matched greedily by phi."""
    out, free = [], list(pred.blades)
    for t in truth.blades:
        if not free:
            break
        d = [abs((p.phi_deg - t.phi_deg + 180) % 360 - 180) for p in free]
        k = int(np.argmin(d))
        p = free.pop(k)
        out.append((abs((p.theta_deg - t.theta_deg + 90) % 180 - 90), d[k]))
    return out


def measure(photo: R.RealPhoto, model, args, refiner: Path | None = None) -> dict:
    from wtcli.pitch import pitch_from_instances
    from wtcli.segment.infer import segment_image

    img, sem = R.read_pair(photo, args.max_side)
    inst = segment_image(img, model, refine=not args.no_refine, refiner=refiner)
    conf = inst[inst.scores >= 0.5] if len(inst) else inst
    cmap = conf.class_map()
    blade, tower, nac = map_parts(cmap)  # one class a pixel, as the truth has
    g_blade, g_tower, _ = map_parts(grown(cmap))
    # The classes' unions beside it: a pixel in masks of two classes counts for both.
    u_blade, u_nac = conf.of("blade").union(), conf.of("nacelle").union()
    u_tower = conf.of("tower").union() | u_nac
    rec = {"image": photo.name, "sequence": photo.sequence, "view": photo.view,
           "blade_iou": iou(blade, sem == R.BLADE), "tower_iou": iou(tower, sem == R.TOWER),
           "blade_iou_union": iou(u_blade, sem == R.BLADE),
           "tower_iou_union": iou(u_tower, sem == R.TOWER),
           "blade_iou_grown": iou(g_blade, sem == R.BLADE), "tower_iou_grown": iou(g_tower, sem == R.TOWER)}
    rec["_tint"] = outline_tint(img, sem == R.BLADE, blade)
    split = R.split_semantic(sem)
    true_nac = split.instances.of("nacelle")
    if len(true_nac):
        rec["nacelle_iou"] = iou(nac, true_nac.union())
        rec["nacelle_iou_union"] = iou(u_nac, true_nac.union())
    if photo.view in FRONT_VIEWS:
        truth = front_truth(split)
        if truth is not None:
            try:
                pred = pitch_from_instances(inst, expected_blades=None)
            except WtError:
                pred = None
            rec["front_blades"] = len(pred) if pred is not None else 0
            if pred is not None:
                rec["angle_errors"] = [[round(a, 3), round(b, 3)] for a, b in angle_errors(truth, pred)]
    return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in rec.items()}


def summarise(rows: list[dict]) -> dict:
    out: dict = {"photos": len(rows)}
    for key in ("blade_iou", "tower_iou", "nacelle_iou"):
        v = [r[key] for r in rows if r.get(key) is not None]
        out[key] = round(float(np.mean(v)), 4) if v else None
        out[key.replace("_iou", "_photos")] = len(v)
        u = [r[key + "_union"] for r in rows if r.get(key + "_union") is not None]
        out[key + "_union"] = round(float(np.mean(u)), 4) if u else None
        g = [r[key + "_grown"] for r in rows if r.get(key + "_grown") is not None]
        if g:
            out[key + "_grown"] = round(float(np.mean(g)), 4)
    front = [r for r in rows if "front_blades" in r]
    if front:
        errs = [e for r in front for e in r.get("angle_errors", [])]
        out["front_views_3_true_blades"] = len(front)
        out["front_exactly_3"] = round(sum(r["front_blades"] == 3 for r in front) / len(front), 4)
        out["theta_error_deg_mean"] = round(float(np.mean([e[0] for e in errs])), 3) if errs else None
        out["phi_error_deg_mean"] = round(float(np.mean([e[1] for e in errs])), 3) if errs else None
        out["blades_matched"] = len(errs)
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--real", default=str(ROOT.parent / "shared" / "real-photos"),
                    help="photo folder with manifest.csv and semantic masks")
    ap.add_argument("--model", default=None, help="one model for every fold (default: shipped)")
    ap.add_argument("--runs", default=None, help="fold SEQ uses RUNS/SEQ/model.pt")
    ap.add_argument("--train", default=None, metavar="ARGS",
                    help="train missing folds: wtinspect train ARGS --real ... "
                         "--real-holdout-sequence SEQ --out RUNS/SEQ")
    ap.add_argument("--refiner", default=None,
                    help="edge refiner for every fold (default: the shipped models/wtseg-refine.pt)")
    ap.add_argument("--fold-refiners", action="store_true",
                    help="fold SEQ's edges refined by RUNS/SEQ/refiner/refiner.pt")
    ap.add_argument("--train-refiner", default=None, metavar="ARGS",
                    help="train missing fold refiners: wtinspect train-refiner ARGS --model "
                         "RUNS/SEQ/model.pt --real ... --real-holdout-sequence SEQ --out "
                         "RUNS/SEQ/refiner (implies --fold-refiners)")
    ap.add_argument("--only", nargs="*", default=None, metavar="SEQ", help="these folds only")
    ap.add_argument("--limit", type=int, default=None,
                    help="at most N photos per fold, spread over it (a quicker subset)")
    ap.add_argument("--max-side", type=int, default=None,
                    help="read photos at most this long (default: as they are)")
    ap.add_argument("--no-refine", action="store_true", help="without the edge refiner")
    ap.add_argument("--threads", type=int, default=None, help="torch CPU threads")
    ap.add_argument("--out", default=None,
                    help="results file (default benchmarks/results/segment_real.json, with "
                         "--runs segment_real_finetune.json; needed with --model or a subset)")
    args = ap.parse_args(argv)
    if args.train is not None and args.runs is None:
        ap.error("--train needs --runs (where the fold runs go)")
    if args.model and args.runs:
        ap.error("--model and --runs: one or the other")
    args.fold_refiners = args.fold_refiners or args.train_refiner is not None
    if args.fold_refiners and args.runs is None:
        ap.error("--fold-refiners and --train-refiner need --runs (where the fold runs go)")
    if args.fold_refiners and (args.refiner or args.no_refine):
        ap.error("--fold-refiners: not with --refiner or --no-refine")
    if args.out is None and (args.model or args.only is not None or args.limit or args.refiner
                             or args.max_side or args.no_refine):
        # The default results files hold the figures on every photo, as segment runs it: the
        # shipped model's, and with --runs the cross-validated fine-tune's; another model or a
        # subset must not overwrite them.
        ap.error("--out FILE is needed with --model, --refiner, --only, --limit, --max-side or "
                 "--no-refine (the default results file holds the figures on every photo)")
    default_name = "segment_real_finetune" if args.runs else "segment_real"
    import torch

    from wtcli.segment.infer import load_model

    if args.threads:
        torch.set_num_threads(args.threads)

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    real = Path(args.real)
    if not R.is_photo_folder(real):
        log(f"{real}: no photo folder with manifest.csv; nothing to measure")
        return {}
    photos = R.read_folder(real)
    folds: dict[str, list[R.RealPhoto]] = defaultdict(list)
    for p in photos:
        folds[p.sequence].append(p)
    names = list(folds) if args.only is None else args.only
    unknown = [n for n in names if n not in folds]
    if unknown:
        raise SystemExit(f"--only {unknown[0]}: not a sequence of {real} (it has: {', '.join(folds)})")
    rows, models, mirrors, refiners = [], {}, {}, {}
    secs = 0.0  # measuring only: training a fold and loading its model are not counted
    for seq in names:
        fold = folds[seq]
        if args.limit and len(fold) > args.limit:
            fold = [fold[int(k)] for k in np.linspace(0, len(fold) - 1, args.limit).round()]
        path = model_for_fold(args, seq, log)
        model = load_model(path)
        if model.mirror_weights:  # the network reading its mirror pass (NAME.mirror.pt) too
            check_not_trained_on(Path(model.mirror_weights), seq)
        models[seq] = str(path)
        mirrors[seq] = model.mirror_weights
        refiner = None if args.no_refine else refiner_for_fold(args, seq, log)
        refiners[seq] = None if refiner is None else str(refiner)
        t1 = time.perf_counter()
        for p in fold:
            rows.append(measure(p, model, args, refiner))
        secs += time.perf_counter() - t1
        log(f"fold {seq}: {len(fold)} photos in {time.perf_counter() - t1:.0f} s; "
            f"blade IoU {summarise(rows[-len(fold):])['blade_iou']}")
    tints = [r.pop("_tint") for r in rows]
    res = {
        "data": {"root": str(real), "photos_in_folder": len(photos),
                 "source": "WTA dataset, Zampokas et al., ICUAS 2022, doi:10.1109/ICUAS54217.2022.9836096"},
        "models": models, "mirror_models": mirrors, "refiners": refiners,
        "settings": {"refine": not args.no_refine, "fold_refiners": args.fold_refiners,
                     "max_side": args.max_side, "limit": args.limit,
                     "folds": names},
        "pooled": summarise(rows),
        "per_view": {v: summarise([r for r in rows if r["view"] == v])
                     for v in R.VIEW_TYPES if any(r["view"] == v for r in rows)},
        "per_fold": {s: summarise([r for r in rows if r["sequence"] == s]) for s in names},
        "outline_tint": tint_summary(tints),
        "seconds": round(secs, 1), "seconds_per_photo": round(secs / max(1, len(rows)), 2),
        "per_photo": rows,
    }
    keys = ("blade_iou", "tower_iou", "nacelle_iou")
    print(f"{'view':14s} {'photos':>6s} {'blade':>6s} {'tower':>6s} {'nacelle':>8s}   "
          "(instance unions: blade / tower / nacelle)")
    for v, s in [*res["per_view"].items(), ("pooled", res["pooled"])]:
        f = [("-" if s[k] is None else f"{s[k]:.3f}") for k in keys]
        u = " / ".join("-" if s[k + "_union"] is None else f"{s[k + '_union']:.3f}" for k in keys)
        print(f"{v:14s} {s['photos']:6d} {f[0]:>6s} {f[1]:>6s} {f[2]:>8s}   ({u})")
    p = res["pooled"]
    if "blade_iou_grown" in p:
        print(f"every part a pixel wider (a diagnostic of the photos' outline): blade / tower "
              f"{p['blade_iou_grown']} / {p.get('tower_iou_grown')}")
    t = res["outline_tint"]
    if t["missed"] and t["beyond"] and t["edge"]:
        print(f"share of a blade's contrast, median: pixels the photos' masks hold beyond ours "
              f"{t['missed']['p50']} ({t['missed']['pixels']}), the background just outside theirs "
              f"{t['beyond']['p50']}, our masks' own edge {t['edge']['p50']}")
    if "front_exactly_3" in p:
        print(f"front views with 3 true blades: {p['front_views_3_true_blades']}, exactly 3 read "
              f"{100 * p['front_exactly_3']:.0f} %, mean |theta error| {p['theta_error_deg_mean']} deg, "
              f"|phi error| {p['phi_error_deg_mean']} deg over {p['blades_matched']} blades")
    print(f"{len(rows)} photos in {secs:.0f} s ({res['seconds_per_photo']} s each)")
    try:
        from _results import save
    except ImportError:  # the results writer absent: plain JSON
        from wtcli.jsonio import write_json

        write_json(args.out or ROOT / "benchmarks" / "results" / f"{default_name}.json", res)
    else:
        save("segment_real", res, argv=argv,
             out=args.out or ROOT / "benchmarks" / "results" / f"{default_name}.json")
    return res


if __name__ == "__main__":
    main()
