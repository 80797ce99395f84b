"""`wtinspect train-refiner`: train the edge refiner (``wtcli.segment.refine``) on renders,
and on labelled photos where given.

Two stages, both resumable:
1. data: ``images`` renders (scenes the segmenter never trained on, half of them with the
   segmenter's own photometric augmentation: blur, noise, JPEG, colour) are segmented by the
   segmenter as ``segment`` runs it; every instance's boundary band gives training pixels
   (features, and whether the true mask of the instance's class covers the pixel). Written
   as OUT/data/part-NNNN.npz, PART images each; a resumed run skips the parts on disk. With
   ``real``, the labelled photos too (the held-out sequences left out), cut at the size the
   refiner works at, as OUT/data/photo-NNNN.npz, PHOTO_PART photos each.
2. fit: the MLP trained on them (at most ``max_pixels`` of the renders', the same share of every
   part's; the photos' pixels drawn to make ``real_share`` of every pass; AdamW, one-cycle
   schedule, ``epochs`` passes; from ``init``'s weights where given), checkpointed after each
   pass to OUT/last.ckpt; then OUT/refiner.pt and OUT/metrics.json, with mask IoU before and
   after refinement on ``eval_count`` held-out renders.
"""

from __future__ import annotations

import io
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from wtcli.errors import ConfigError, InputError, ModelError
from wtcli.jsonio import atomic_write_bytes, document, write_json
from wtcli.outputs import remove_temp_files
from wtcli.segment import refine as R
from wtcli.segment.data import HELDOUT_SEED_BASE, TRAIN_SEED_BASE

# Scenes TRAIN_SEED_BASE + 4_500_000 + 100_000 * seed + i: above the stretches the segmenter's
# runs used (seeds 0-19), so its masks here have the errors it makes on photos it never saw.
SCENE_BASE = TRAIN_SEED_BASE + 4_500_000
SIZES = ((640, 480), (640, 480), (960, 640), (1280, 720))  # the renders' sizes, drawn per image
PART = 50  # images per data file
PHOTO_PART = 10  # labelled photos per data file
PHOTO_STREAM = 2_000_000  # the photos' pixel draws: a stream apart from the renders'
VAL_SAMPLES = 100_000  # band pixels held out of the fit, for its loss and accuracy
REFINER_SCHEMA = "wtinspect.train_refiner"


@dataclass
class RefinerConfig:
    out: str = "runs/refiner"
    images: int = 2400
    model: str | None = None  # the segmenter whose masks are refined; default the shipped one
    seed: int = 0
    epochs: int = 5
    batch_size: int = 4096
    lr: float = 2e-3
    per_instance: int = 1500  # band pixels drawn per instance at most
    max_pixels: int | None = None  # the fit keeps at most this many, drawn evenly from every part
    hidden: tuple[int, int] = (512, 256)  # the MLP's two hidden layers
    eval_count: int = 16
    threads: int | None = None
    resume: bool = False
    init: str | None = None  # refiner weights to start from (default: a fresh MLP)
    real: str | None = None  # labelled photos (as ``train --real``), or none
    real_share: float = 0.25  # the photos' share of each pass's pixels
    real_holdout: tuple[str, ...] = ()  # flight sequences of ``real`` left out

    def check(self) -> None:
        for name in ("images", "epochs", "batch_size", "per_instance", "max_pixels"):
            if getattr(self, name) is not None and getattr(self, name) < 1:
                raise ConfigError(f"--{name.replace('_', '-')} {getattr(self, name)}: must be at least 1")
        if len(self.hidden) != 2 or min(self.hidden) < 1:
            raise ConfigError(f"--hidden {','.join(map(str, self.hidden))}: two layer widths of at least 1")
        if not 0 <= self.seed < 5:
            raise ConfigError(f"--seed {self.seed}: must be 0-4 (each seed has its own 100 000 scenes)")
        if self.images > 100_000:
            raise ConfigError(f"--images {self.images}: at most 100000 per seed")
        if not self.lr > 0:
            raise ConfigError(f"--lr {self.lr}: must be positive")
        if self.eval_count < 0:
            raise ConfigError(f"--eval-count {self.eval_count}: must be 0 or more")
        if not 0 < self.real_share < 1:
            raise ConfigError(f"--real-share {self.real_share}: must be between 0 and 1 (the "
                              "photos' share of the fitted pixels; renders make the rest)")
        if self.real_holdout and self.real is None:
            raise ConfigError("--real-holdout-sequence needs --real (the photos it leaves out)")


def scene(cfg: RefinerConfig, i: int, rng: np.random.Generator):
    """Image ``i`` of the run: a render, augmented half the time."""
    from wtcli.segment.data import augment
    from wtcli.synth.render import render_sample

    w, h = SIZES[int(rng.integers(len(SIZES)))]
    s = render_sample(SCENE_BASE + 100_000 * cfg.seed + i, width=w, height=h,
                      view="front" if i % 2 == 0 else None)
    return augment(s, rng) if rng.random() < 0.5 else s


def class_unions(truth) -> dict[str, np.ndarray]:
    """Each class's true pixels, from a render's instances."""
    H, W = truth.image_size
    return {c: truth.of(c).union() if len(truth.of(c)) else np.zeros((H, W), bool) for c in R.LABELS}


def image_samples(image: np.ndarray, pred, union: dict[str, np.ndarray], per_instance: int,
                  rng: np.random.Generator, ignore: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(features [N, F] float16, targets [N] bool) of the band pixels of each predicted
    instance whose class ``union`` holds; target: ``union`` of the instance's class covers the
    pixel. Pixels in ``ignore`` (a COCO file's crowd and box-only regions: their truth is
    unknown) are left out."""
    xs, ys = [], []
    for k in range(len(pred)):
        if pred.labels[k] not in union:
            continue
        got = R.instance_pixels(image, pred.masks[k])
        if got is None or not len(got[3]):
            continue
        (y0, x0), img, m, px = got
        if ignore is not None:
            px = px[~ignore[y0 + px[:, 0], x0 + px[:, 1]]]
            if not len(px):
                continue
        if len(px) > per_instance:
            px = px[np.sort(rng.choice(len(px), per_instance, replace=False))]
        xs.append(R.features(img, m, pred.labels[k], px[:, 0], px[:, 1]).astype(np.float16))
        ys.append(union[pred.labels[k]][y0 + px[:, 0], x0 + px[:, 1]])
    if not xs:
        return np.zeros((0, R.N_FEATURES), np.float16), np.zeros(0, bool)
    return np.concatenate(xs), np.concatenate(ys)


def _write(path: Path, save: Callable[[io.BytesIO], None]) -> None:
    """``save`` into memory, then onto ``path`` atomically: an interrupted run leaves no part
    file or checkpoint half written."""
    buf = io.BytesIO()
    save(buf)
    atomic_write_bytes(path, buf.getvalue())


def make_data(cfg: RefinerConfig, progress: Callable[[dict[str, Any]], None] | None = None) -> list[Path]:
    """Stage 1: the data parts (made where missing)."""
    from wtcli.segment.infer import load_model, segment_image

    folder = Path(cfg.out) / "data"
    folder.mkdir(parents=True, exist_ok=True)
    parts = []
    model = None
    for p0 in range(0, cfg.images, PART):
        path = folder / f"part-{p0 // PART:04d}.npz"
        parts.append(path)
        n = min(PART, cfg.images - p0)
        if path.is_file():
            for i in range(p0, p0 + n) if progress else ():  # one report per image, as made
                progress({"stage": "data", "done": i + 1, "total": cfg.images, "skipped": True})
            continue
        if model is None:
            model = load_model(cfg.model)
        X, Y = [], []
        for i in range(p0, p0 + n):
            rng = np.random.default_rng([cfg.seed, i])
            s = scene(cfg, i, rng)
            pred = segment_image(s.image, model=model, refine=False)
            x, y = image_samples(s.image, pred, class_unions(s.instances), cfg.per_instance, rng)
            X.append(x)
            Y.append(y)
            if progress:
                progress({"stage": "data", "done": i + 1, "total": cfg.images})
        _write(path, lambda buf: np.savez(buf, X=np.concatenate(X), Y=np.concatenate(Y)))
    return parts


def labelled_photos(cfg: RefinerConfig) -> list[tuple[str, Callable[[], tuple[np.ndarray, dict]]]]:
    """The photos of ``cfg.real`` that are not held out, as (name, loader); a loader gives the
    photo at its own size, the truth of the classes a photo teaches the refiner: blade, and
    tower with nacelle as one (a photo folder's class 2 holds both; the nacelle's own edges come
    from the renders, which label it), and the pixels whose truth is unknown (a COCO file's
    crowd and box-only regions) or None."""
    from wtcli.segment import real as RP
    from wtcli.segment.data import RealDataset

    ds = RealDataset(cfg.real, holdout=tuple(cfg.real_holdout), augment=False)
    out = []
    for k in ds.keep:
        if ds.coco is None:
            photo = ds.photos[k]

            def load(photo=photo):
                img, sem = RP.read_pair(photo, None)
                return img, {"blade": sem == RP.BLADE, "tower": sem == RP.TOWER}, None
            out.append((photo.name, load))
        else:
            def load(k=k):
                smp = ds.coco.load(k)
                u = class_unions(smp.instances)
                return (smp.image, {"blade": u["blade"], "tower": u["tower"] | u["nacelle"]},
                        smp.ignore)
            out.append((Path(str(ds.coco.items[k][0].get("file_name", k))).stem, load))
    return out


def make_photo_data(cfg: RefinerConfig, progress: Callable[[dict[str, Any]], None] | None = None
                    ) -> list[Path]:
    """Stage 1 for the labelled photos: each segmented as ``segment`` runs it (no refinement),
    then its band pixels cut where ``refine_edges`` looks at it (``edges.at_refine_size``), the
    targets from its labels. OUT/data/photos.json names the photos and the segmenter, so that a
    resumed run never mixes pixels of two selections."""
    from wtcli.segment.edges import _resize_mask, at_refine_size
    from wtcli.segment.infer import load_model, segment_image

    folder = Path(cfg.out) / "data"
    folder.mkdir(parents=True, exist_ok=True)
    photos = labelled_photos(cfg)
    said = {"real": str(cfg.real), "real_holdout": sorted(cfg.real_holdout),
            "segmenter": str(cfg.model or "shipped"), "photos": [n for n, _ in photos]}
    listing = folder / "photos.json"
    if listing.is_file():
        try:
            before = json.loads(listing.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            before = None
        if before != said:
            raise ConfigError(f"{listing}: the photo pixels on disk came from other photos or "
                              "another segmenter (--real, --real-holdout-sequence, --model); "
                              "resume with those, or pick another --out")
    else:
        write_json(listing, said)
    parts, model = [], None
    for p0 in range(0, len(photos), PHOTO_PART):
        path = folder / f"photo-{p0 // PHOTO_PART:04d}.npz"
        parts.append(path)
        chunk = photos[p0:p0 + PHOTO_PART]
        if path.is_file():
            for i in range(p0, p0 + len(chunk)) if progress else ():
                progress({"stage": "photos", "done": i + 1, "total": len(photos), "skipped": True})
            continue
        if model is None:
            model = load_model(cfg.model)
        X, Y = [], []
        for i, (name, load) in enumerate(chunk, p0):
            img, truth, ignore = load()
            pred = segment_image(img, model=model, refine=False)
            small, pred = at_refine_size(img, pred)
            if small.shape[:2] != img.shape[:2]:
                h, w = small.shape[:2]
                truth = {c: _resize_mask(m, w, h) for c, m in truth.items()}
                ignore = None if ignore is None else _resize_mask(ignore, w, h)
            rng = np.random.default_rng([cfg.seed, PHOTO_STREAM + i])
            x, y = image_samples(small, pred, truth, cfg.per_instance, rng, ignore)
            X.append(x)
            Y.append(y)
            if progress:
                progress({"stage": "photos", "done": i + 1, "total": len(photos)})
        _write(path, lambda buf: np.savez(buf, X=np.concatenate(X), Y=np.concatenate(Y)))
    return parts


def _load_parts(parts: list[Path], max_pixels: int | None = None, seed: int = 0,
                whole: list[Path] | tuple[Path, ...] = ()) -> tuple[np.ndarray, np.ndarray, int]:
    """(X, Y, pixels on disk): all parts in one array, filled part by part (concatenating a list
    of them would hold every pixel twice at the peak, about 12 GB more at 2 400 renders). With
    ``max_pixels``, each part keeps the same share of its pixels, drawn by ``seed``: more renders
    in the same memory. Neighbouring pixels of one render teach much the same thing: fitted
    twice as long on the same 2 400 renders, band pixels right rose 0.899 -> 0.906 but blade IoU
    on 200 development renders fell 0.8597 -> 0.8581. The ``whole`` parts (the photos') follow,
    every pixel of them, outside the budget; ``made`` counts both."""
    def bad(p: Path, e: Exception) -> InputError:
        return InputError(f"{p}: unreadable training data ({e.__class__.__name__}); delete it "
                          "and run again with --resume to make it anew")

    sizes = []
    for p in [*parts, *whole]:
        try:
            with np.load(p) as d:  # the labels only: one byte per pixel
                sizes.append(len(d["Y"]))
        except Exception as e:  # noqa: BLE001 - a damaged part: say which and how to redo it
            raise bad(p, e) from None
    made = sum(sizes[:len(parts)])
    share = min(1.0, max_pixels / made) if max_pixels and made else 1.0
    keep = [round(n * share) for n in sizes[:len(parts)]] + sizes[len(parts):]
    X = np.empty((sum(keep), R.N_FEATURES), np.float16)
    Y = np.empty(sum(keep), bool)
    at = 0
    for k, (p, n, nk) in enumerate(zip([*parts, *whole], sizes, keep)):
        try:
            with np.load(p) as d:
                x, y = d["X"], d["Y"]
        except Exception as e:  # noqa: BLE001
            raise bad(p, e) from None
        if x.ndim != 2 or x.shape[1] != R.N_FEATURES or len(x) != n or len(y) != n:
            raise InputError(f"{p}: training data of another feature layout; delete {p.parent} "
                             "and run again")
        if nk < n:
            rows = np.sort(np.random.default_rng([seed, 1_000_000 + k]).choice(n, nk, replace=False))
            x, y = x[rows], y[rows]
        X[at:at + nk], Y[at:at + nk] = x, y
        at += nk
    return X, Y, sum(sizes)


def _pass_rows(train: np.ndarray, photo_from: int, share: float, seed: int, epoch: int
               ) -> np.ndarray:
    """One pass's rows in the order fitted: every render row once and, where rows from
    ``photo_from`` on are the photos', as many photo rows drawn (with repeats: a few photos
    hold far fewer pixels than the renders) as make ``share`` of the pass."""
    rng = np.random.default_rng([seed, epoch])
    renders, photos = train[train < photo_from], train[train >= photo_from]
    if not len(photos):
        return train[rng.permutation(len(train))]
    drawn = rng.choice(photos, _photo_draws(len(renders), share), replace=True)
    rows = np.concatenate([renders, drawn])
    return rows[rng.permutation(len(rows))]


def _photo_draws(renders: int, share: float) -> int:
    """Photo rows a pass draws beside ``renders`` render rows, to make ``share`` of it."""
    return round(share / (1 - share) * renders)


def _part_rows(parts: list[Path]) -> int:
    total = 0
    for p in parts:
        with np.load(p) as d:
            total += len(d["Y"])
    return total


def fit(cfg: RefinerConfig, X: np.ndarray, Y: np.ndarray,
        progress: Callable[[dict[str, Any]], None] | None = None,
        photo_rows: int = 0) -> tuple[R.Refiner, dict[str, Any]]:
    """Stage 2: the MLP trained on (X, Y), whose last ``photo_rows`` rows are the photos'
    (``cfg.real_share`` of every pass, ``_pass_rows``); from ``cfg.init``'s weights where given;
    resumes from OUT/last.ckpt after a whole pass."""
    if len(X) < 2 * VAL_SAMPLES // 10:
        more = " or a larger --max-pixels" if cfg.max_pixels else ""
        raise InputError(f"only {len(X)} training pixels: segment more images (--images){more}")
    torch.manual_seed(cfg.seed)
    order = np.random.default_rng(cfg.seed).permutation(len(X))
    nv = min(VAL_SAMPLES, len(X) // 10)
    val, train = np.sort(order[:nv]), order[nv:]
    xv = torch.from_numpy(X[val].astype(np.float32))
    yv = torch.from_numpy(Y[val].astype(np.float32))
    net = R.Refiner(tuple(cfg.hidden))
    if cfg.init:
        start = R.load_refiner(cfg.init, "fp32")
        widths = (start.net[0].out_features, start.net[2].out_features)
        if widths != tuple(cfg.hidden):
            raise ConfigError(f"--init {cfg.init}: a refiner of --hidden {widths[0]},{widths[1]}; "
                              f"train with those, not {','.join(map(str, cfg.hidden))}")
        net.load_state_dict(start.state_dict())
    photo_from = len(X) - photo_rows
    opt = torch.optim.AdamW(net.parameters(), cfg.lr, weight_decay=1e-4)
    n_renders = int((train < photo_from).sum())
    extra = _photo_draws(n_renders, cfg.real_share) if n_renders < len(train) else 0
    steps_per = max(1, (n_renders + extra) // cfg.batch_size)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, cfg.lr, total_steps=cfg.epochs * steps_per,
                                                pct_start=0.05)
    loss_fn = torch.nn.BCEWithLogitsLoss()
    ckpt = Path(cfg.out) / "last.ckpt"
    epoch0, history = 0, []
    if cfg.resume and ckpt.is_file():
        try:
            state = torch.load(ckpt, map_location="cpu", weights_only=True)
            if int(state.get("epochs", cfg.epochs)) != cfg.epochs:
                raise ConfigError(f"{ckpt}: a run of --epochs {state['epochs']} (its learning-rate "
                                  f"schedule); resume it with those, not {cfg.epochs}")
            if state.get("max_pixels") != cfg.max_pixels:
                said = lambda v: f"--max-pixels {v}" if v else "every pixel"  # noqa: E731
                raise ConfigError(f"{ckpt}: a run of {said(state.get('max_pixels'))}; resume it "
                                  f"with that, not {said(cfg.max_pixels)}")
            if tuple(state.get("hidden", cfg.hidden)) != tuple(cfg.hidden):
                raise ConfigError(f"{ckpt}: a run of --hidden {','.join(map(str, state['hidden']))}; "
                                  f"resume it with those, not {','.join(map(str, cfg.hidden))}")
            net.load_state_dict(state["state_dict"])
            opt.load_state_dict(state["optimizer"])
            sched.load_state_dict(state["scheduler"])
        except ConfigError:
            raise
        except Exception as e:  # noqa: BLE001
            raise ModelError(f"{ckpt}: cannot resume from it ({e.__class__.__name__}); delete it to "
                             "train the refiner anew on the data made") from None
        epoch0, history = int(state["epoch"]), list(state.get("history", []))

    def check() -> dict[str, float]:
        net.eval()
        with torch.no_grad():
            lo = net(xv)
        net.train()
        return {"val_loss": loss_fn(lo, yv).item(),
                "val_accuracy": ((lo > 0).float() == yv).float().mean().item()}

    for epoch in range(epoch0, cfg.epochs):
        perm = _pass_rows(train, photo_from, cfg.real_share, cfg.seed, epoch)
        for b in range(steps_per):
            idx = np.sort(perm[b * cfg.batch_size:(b + 1) * cfg.batch_size])
            x = torch.from_numpy(X[idx].astype(np.float32))
            y = torch.from_numpy(Y[idx].astype(np.float32))
            loss = loss_fn(net(x), y)
            if not torch.isfinite(loss):
                raise ModelError(f"refiner training diverged in pass {epoch + 1}; lower --lr (now {cfg.lr})")
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            if progress:
                progress({"stage": "fit", "epoch": epoch + 1, "epochs": cfg.epochs,
                          "done": epoch * steps_per + b + 1, "total": cfg.epochs * steps_per,
                          "loss": loss.item()})
        history.append({"epoch": epoch + 1, **check()})
        state = {"epoch": epoch + 1, "epochs": cfg.epochs, "hidden": list(cfg.hidden),
                 "max_pixels": cfg.max_pixels,
                 "state_dict": net.state_dict(), "optimizer": opt.state_dict(),
                 "scheduler": sched.state_dict(), "history": history}
        _write(ckpt, lambda buf: torch.save(state, buf))
    mask = X[val, R.MASK_CENTRE] > 0  # the network's answer at each held-out pixel
    net.eval()
    return net, {"history": history, **check(), "train_pixels": int(len(train)),
                 "val_accuracy_unrefined": float((mask == Y[val]).mean())}


def evaluate(cfg: RefinerConfig, refiner: R.Refiner) -> dict[str, Any]:
    """Mask IoU and AP50 per class on held-out renders (seeds HELDOUT + 600 000 + i), as
    ``segment`` gives them and refined."""
    from wtcli.segment.evaluate import Evaluator
    from wtcli.segment.infer import load_model, segment_image
    from wtcli.synth.render import render_sample

    model = load_model(cfg.model)
    plain, refined = Evaluator(), Evaluator()
    for i in range(cfg.eval_count):
        s = render_sample(HELDOUT_SEED_BASE + 600_000 + i, width=640, height=480,
                          view="front" if i % 2 == 0 else None)
        pred = segment_image(s.image, model=model, refine=False)
        plain.add(pred, s.instances)
        refined.add(R.refine_edges(refiner, s.image, pred), s.instances)
    return {"unrefined": plain.summary(), "refined": refined.summary()}


def _segmenter_run(model: str | None) -> dict[str, Any]:
    """Which run of the segmenter the masks came from, as its weights file says ("shipped"
    names a different file after every new segmenter); empty where the file says none."""
    from wtcli.segment.model import resolve_weights

    try:
        meta = torch.load(resolve_weights(model), map_location="cpu", weights_only=True).get("meta", {})
    except Exception:  # noqa: BLE001 - the fit is done; a label must not lose it
        return {}
    return {f"segmenter_{k}": meta[k] for k in ("run", "seed", "iterations") if k in meta}


def train_refiner(cfg: RefinerConfig, progress: Callable[[dict[str, Any]], None] | None = None
                  ) -> dict[str, Any]:
    """Both stages (resuming what is on disk with ``resume``); the summary in OUT/metrics.json."""
    cfg.check()
    out = Path(cfg.out)
    if not cfg.resume and (out / "data").is_dir() and any((out / "data").glob("part-*.npz")):
        raise InputError(f"{out}: holds a run already; --resume to continue it, or pick another --out")
    # What a kill mid-write left (.part-0000.npz.k2x9q0ab, .last.ckpt.k2x9q0ab).
    remove_temp_files(out, r"last\.ckpt|refiner\.pt|metrics\.json")
    remove_temp_files(out / "data", r"part-\d{4,}\.npz|photo-\d{4,}\.npz|photos\.json")
    if cfg.threads:
        torch.set_num_threads(int(cfg.threads))
    t0 = time.monotonic()
    parts = make_data(cfg, progress)
    photo_parts = make_photo_data(cfg, progress) if cfg.real else []
    t1 = time.monotonic()
    X, Y, made = _load_parts(parts, cfg.max_pixels, cfg.seed, whole=photo_parts)
    photo_rows = _part_rows(photo_parts)
    net, stats = fit(cfg, X, Y, progress, photo_rows=photo_rows)
    t2 = time.monotonic()
    meta = {"images": cfg.images, "seed": cfg.seed, "epochs": cfg.epochs, "pixels": int(len(X)),
            "segmenter": str(cfg.model or "shipped"), **_segmenter_run(cfg.model),
            "val_accuracy": round(stats["val_accuracy"], 4), "init": cfg.init,
            # as the segmenter's weights say it (segment_real.py refuses a fold a file learned)
            "real": cfg.real, "real_holdout": list(cfg.real_holdout),
            "real_share": cfg.real_share if cfg.real else None, "photo_pixels": photo_rows}
    R.save_refiner(net, out / "refiner.pt", meta)
    summary = {"arch": R.ARCH, "config": asdict(cfg), "data_seconds": t1 - t0, "fit_seconds": t2 - t1,
               "pixels": int(len(X)), "pixels_made": int(made), "photo_pixels": photo_rows, **stats,
               "evaluation": evaluate(cfg, net) if cfg.eval_count else {},
               "weights": str(out / "refiner.pt"), "checkpoint": str(out / "last.ckpt")}
    write_json(out / "metrics.json", document(REFINER_SCHEMA, 1, summary))
    return summary
