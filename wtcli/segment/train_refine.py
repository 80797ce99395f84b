"""`wtinspect train-refiner`: train the edge refiner (``wtcli.segment.refine``) on renders.

Two stages, both resumable:
1. data: ``images`` renders (scenes the segmenter never trained on, half of them with the
   segmenter's own photometric augmentation: blur, noise, JPEG, colour) are segmented by the
   segmenter as ``segment`` runs it; every instance's boundary band gives training pixels
   (features, and whether the true mask of the instance's class covers the pixel). Written
   as OUT/data/part-NNNN.npz, PART images each; a resumed run skips the parts on disk.
2. fit: the MLP trained on them (at most ``max_pixels``, the same share of every part's; AdamW,
   one-cycle schedule, ``epochs`` passes), checkpointed after each pass to OUT/last.ckpt; then
   OUT/refiner.pt and OUT/metrics.json, with mask IoU before and after refinement on
   ``eval_count`` held-out renders.
"""

from __future__ import annotations

import io
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from wtcli.errors import ConfigError, InputError, ModelError
from wtcli.jsonio import atomic_write_bytes, document, write_json
from wtcli.segment import refine as R
from wtcli.segment.data import HELDOUT_SEED_BASE, TRAIN_SEED_BASE

# Scenes TRAIN_SEED_BASE + 4_500_000 + 100_000 * seed + i: above the stretches the segmenter's
# runs used (seeds 0-19), so its masks here have the errors it makes on photos it never saw.
SCENE_BASE = TRAIN_SEED_BASE + 4_500_000
SIZES = ((640, 480), (640, 480), (960, 640), (1280, 720))  # the renders' sizes, drawn per image
PART = 50  # images per data file
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


def scene(cfg: RefinerConfig, i: int, rng: np.random.Generator):
    """Image ``i`` of the run: a render, augmented half the time."""
    from wtcli.segment.data import augment
    from wtcli.synth.render import render_sample

    w, h = SIZES[int(rng.integers(len(SIZES)))]
    s = render_sample(SCENE_BASE + 100_000 * cfg.seed + i, width=w, height=h,
                      view="front" if i % 2 == 0 else None)
    return augment(s, rng) if rng.random() < 0.5 else s


def image_samples(image: np.ndarray, pred, truth, per_instance: int, rng: np.random.Generator
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(features [N, F] float16, targets [N] bool) of the band pixels of each predicted
    instance; target: the true mask of the instance's class covers the pixel."""
    H, W = image.shape[:2]
    union = {c: truth.of(c).union() if len(truth.of(c)) else np.zeros((H, W), bool) for c in R.LABELS}
    xs, ys = [], []
    for k in range(len(pred)):
        got = R.instance_pixels(image, pred.masks[k])
        if got is None or not len(got[3]):
            continue
        (y0, x0), img, m, px = got
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
            x, y = image_samples(s.image, pred, s.instances, cfg.per_instance, rng)
            X.append(x)
            Y.append(y)
            if progress:
                progress({"stage": "data", "done": i + 1, "total": cfg.images})
        _write(path, lambda buf: np.savez(buf, X=np.concatenate(X), Y=np.concatenate(Y)))
    return parts


def _load_parts(parts: list[Path], max_pixels: int | None = None, seed: int = 0
                ) -> tuple[np.ndarray, np.ndarray, int]:
    """(X, Y, pixels on disk): all parts in one array, filled part by part (concatenating a list
    of them would hold every pixel twice at the peak, about 12 GB more at 2 400 renders). With
    ``max_pixels``, each part keeps the same share of its pixels, drawn by ``seed``: more renders
    in the same memory. Neighbouring pixels of one render teach much the same thing: fitted
    twice as long on the same 2 400 renders, band pixels right rose 0.899 -> 0.906 but blade IoU
    on 200 development renders fell 0.8597 -> 0.8581."""
    def bad(p: Path, e: Exception) -> InputError:
        return InputError(f"{p}: unreadable training data ({e.__class__.__name__}); delete it "
                          "and run again with --resume to make it anew")

    sizes = []
    for p in parts:
        try:
            with np.load(p) as d:  # the labels only: one byte per pixel
                sizes.append(len(d["Y"]))
        except Exception as e:  # noqa: BLE001 - a damaged part: say which and how to redo it
            raise bad(p, e) from None
    made = sum(sizes)
    share = min(1.0, max_pixels / made) if max_pixels and made else 1.0
    keep = [round(n * share) for n in sizes]
    X = np.empty((sum(keep), R.N_FEATURES), np.float16)
    Y = np.empty(sum(keep), bool)
    at = 0
    for k, (p, n, nk) in enumerate(zip(parts, sizes, keep)):
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
    return X, Y, made


def fit(cfg: RefinerConfig, X: np.ndarray, Y: np.ndarray,
        progress: Callable[[dict[str, Any]], None] | None = None) -> tuple[R.Refiner, dict[str, Any]]:
    """Stage 2: the MLP trained on (X, Y); resumes from OUT/last.ckpt after a whole pass."""
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
    opt = torch.optim.AdamW(net.parameters(), cfg.lr, weight_decay=1e-4)
    steps_per = max(1, len(train) // cfg.batch_size)
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
        perm = train[np.random.default_rng([cfg.seed, epoch]).permutation(len(train))]
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
    if cfg.threads:
        torch.set_num_threads(int(cfg.threads))
    t0 = time.monotonic()
    parts = make_data(cfg, progress)
    t1 = time.monotonic()
    X, Y, made = _load_parts(parts, cfg.max_pixels, cfg.seed)
    net, stats = fit(cfg, X, Y, progress)
    t2 = time.monotonic()
    meta = {"images": cfg.images, "seed": cfg.seed, "epochs": cfg.epochs, "pixels": int(len(X)),
            "segmenter": str(cfg.model or "shipped"), **_segmenter_run(cfg.model),
            "val_accuracy": round(stats["val_accuracy"], 4)}
    R.save_refiner(net, out / "refiner.pt", meta)
    summary = {"arch": R.ARCH, "config": asdict(cfg), "data_seconds": t1 - t0, "fit_seconds": t2 - t1,
               "pixels": int(len(X)), "pixels_made": int(made), **stats,
               "evaluation": evaluate(cfg, net) if cfg.eval_count else {},
               "weights": str(out / "refiner.pt"), "checkpoint": str(out / "last.ckpt")}
    write_json(out / "metrics.json", document(REFINER_SCHEMA, 1, summary))
    return summary
