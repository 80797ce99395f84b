"""Train the segmenter: on synthetic renders made on the fly (default) or a COCO dataset,
with labelled real photos mixed in (``real``, ``real_share`` of each batch on average).

``train(TrainConfig(...), progress=callback)`` runs the loop; it never prints. Everything a run
needs to continue lives in ``OUT/last.ckpt`` (model, optimizer, iteration, config), written
atomically every ``checkpoint_every`` iterations and at the end, so ``resume=True`` picks up
where a stopped run left off. The final weights go to ``OUT/model.pt`` in the shipped format
(float16 state dict, see ``wtcli.segment.model.save_weights``) and the end-of-run evaluation to
``OUT/metrics.json``. A run folder that holds a run already is refused unless resumed.

Learning rate: linear warm-up, then cosine decay to 2 % of the peak over the run. The schedule
follows the run's progress, the larger of iterations done / ``iterations`` and time spent /
``max_minutes``, so a run given a time budget still ends on a small learning rate.
"""

from __future__ import annotations

import io
import math
import random
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from wtcli.errors import ConfigError, InputError, ModelError, WtError
from wtcli.jsonio import atomic_write_bytes, document, write_json
from wtcli.outputs import remove_temp_files
from wtcli.segment import data as D
from wtcli.segment.infer import MASK_OFFSET_PX
from wtcli.segment.model import (ARCH, PRECISIONS, TRAIN_MIN_SIZES, average_weights,
                                 backbone_in_bf16, build_model, load_weights, pick_device,
                                 resolve_precision, save_weights, set_infer_size, set_train_sizes)

TRAIN_SCHEMA = "wtinspect.train_metrics"
CKPT_NAME = "last.ckpt"
AVERAGE_NAME = "model-average.pt"  # --average-with: the run's weights averaged with another file's
RUN_FILES = r"last\.ckpt|model\.pt|metrics\.json|model-average\.pt"  # what a run writes in OUT


@dataclass
class TrainConfig:
    out: str = "runs/train"
    data: str | None = None  # COCO instances JSON (or folder holding instances.json); None: synthetic
    iterations: int = 2000
    batch_size: int = 2
    lr: float = 1e-3
    weight_decay: float = 1e-4
    warmup: int = 200
    max_minutes: float | None = None  # stop (and finish the schedule) after this long
    width: int = 640  # synthetic render size
    height: int = 480
    # Distinct synthetic scenes (seeds TRAIN_SEED_BASE + i): 50 seeds' stretches, all below the
    # development (7 000 000) and held-out (9 000 000) seeds.
    synth_count: int = 5_000_000
    seed: int = 0
    init: str | None = None  # weights to start from (fine-tuning); None: random
    checkpoint_every: int = 100
    eval_count: int = 16  # held-out synthetic scenes (or val images) evaluated at the end
    val: str | None = None  # COCO dataset to evaluate on instead of held-out renders
    device: str | None = None
    workers: int = 1
    threads: int | None = None  # torch CPU threads; None: 1 on a CPU (see train())
    augment: bool = True
    stops: float = 0.3  # share of synthetic scenes whose rotor stands in a Y / inverted Y
    view_mix: str | None = None  # render_sample's shares of views (e.g. the wider ones); None: default
    resume: bool = False
    train_sizes: tuple[int, ...] = field(default_factory=lambda: TRAIN_MIN_SIZES)
    precision: str = "auto"  # auto | fp32 | bf16: see model.resolve_precision
    # The mask head's stride-4 branch (backbone.fine, 45 248 parameters) learns at this times
    # ``lr``: at the rate of the trained rest it grows slowly (its last conv's mean |w| was 0.004
    # after 3 461 steps at 1x, 0.011 at 10x).
    fine_lr_mult: float = 1.0
    average_with: str | None = None  # also write OUT/model-average.pt: the mean with these weights
    # Labelled real photos mixed in (a photo folder with manifest.csv and semantic masks, or a
    # COCO file): ``real_share`` of every batch on average, these flight sequences left out.
    real: str | None = None
    real_share: float = 0.3
    real_holdout: tuple[str, ...] = ()
    # Keep an exponential moving average of the weights (decay per step; 0: off) and ship it as
    # model.pt: one run's last steps, averaged, depend less on the last few batches it drew.
    ema: float = 0.0

    def check(self) -> None:
        def need(ok: bool, what: str) -> None:
            if not ok:
                raise ConfigError(what)

        need(self.iterations >= 1, f"expected --iterations >= 1, got {self.iterations}")
        need(self.batch_size >= 1, f"expected --batch-size >= 1, got {self.batch_size}")
        need(self.lr > 0, f"expected --lr > 0, got {self.lr}")
        need(self.fine_lr_mult > 0, f"expected --fine-lr-mult > 0, got {self.fine_lr_mult}")
        need(32 <= self.width <= 8192 and 32 <= self.height <= 8192,
             f"expected --width/--height in 32..8192, got {self.width}x{self.height}")
        need(self.checkpoint_every >= 1, "expected --checkpoint-every >= 1")
        need(self.eval_count >= 0, "expected --eval-count >= 0")
        need(self.max_minutes is None or self.max_minutes > 0, "expected --max-minutes > 0")
        need(0.0 <= self.stops <= 1.0, f"expected --stops in [0, 1], got {self.stops}")
        need(0.0 < self.real_share <= 1.0, f"expected --real-share in (0, 1], got {self.real_share}")
        need(0.0 <= self.ema < 1.0, f"expected --ema in [0, 1), got {self.ema}")
        if self.view_mix is not None:
            from wtcli.synth.render import parse_view_mix

            try:
                parse_view_mix(self.view_mix)
            except ValueError as e:
                raise ConfigError(f"--view-mix: {e}") from None
        need(self.real is not None or not self.real_holdout,
             "--real-holdout-sequence needs --real (the photos it leaves out)")
        need(self.precision in PRECISIONS,
             f"expected --precision one of {', '.join(PRECISIONS)}, got {self.precision!r}")
        need(len(self.train_sizes) > 0 and all(64 <= v <= 2048 for v in self.train_sizes),
             f"expected --sizes in 64..2048 px, got {','.join(map(str, self.train_sizes)) or 'none'}")


SYNTH_STRETCH = 100_000  # synthetic scenes reserved per seed (runs so far saw < 20 000)
# Until 2026-12-02 the set held 1 000 000 scenes, so seeds 10-15 re-used seeds 0-5's stretches.


def lr_factor(progress: float, it: int, warmup: int) -> float:
    warm = min(1.0, (it + 1) / max(1, warmup))
    cos = 0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * min(1.0, progress)))
    return warm * cos


def _seed_all(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % (2 ** 32))
    torch.manual_seed(seed)


def _worker_init(_: int) -> None:
    torch.set_num_threads(1)


def make_dataset(cfg: TrainConfig):
    if cfg.data:
        base = D.CocoDataset(cfg.data, augment=cfg.augment, aug_seed=cfg.seed)
    else:
        base = D.SynthDataset(cfg.synth_count, cfg.width, cfg.height, augment=cfg.augment,
                              aug_seed=cfg.seed, stops=cfg.stops, view_mix=cfg.view_mix)
    if not cfg.real:
        return base
    real = D.RealDataset(cfg.real, holdout=tuple(cfg.real_holdout), augment=cfg.augment,
                         aug_seed=cfg.seed)
    return D.MixedDataset(base, real, seed=cfg.seed, synth_start=cfg.seed * SYNTH_STRETCH)


def real_in_batch(cfg: TrainConfig, b: int) -> int:
    """How many real photos batch ``b`` holds: ``real_share`` of the batch, the fraction made
    up by a draw keyed on (seed, b), so the share holds on average and resuming repeats it."""
    want = cfg.real_share * cfg.batch_size
    k = int(math.floor(want + 1e-9))
    if k < cfg.batch_size and np.random.default_rng((cfg.seed, 6, b)).random() < want - k:
        k += 1
    return k


def _mixed_batches(ds, cfg: TrainConfig, start_it: int):
    """Endless batches of ("base", pos) and ("real", pos) items (``MixedDataset``); batch ``b``
    is a function of (seed, b), so a resumed run continues the same stream."""
    base_pos = real_pos = 0
    for b in range(start_it):  # where the stream stood: cheap, one draw a batch
        k = real_in_batch(cfg, b)
        real_pos, base_pos = real_pos + k, base_pos + cfg.batch_size - k

    def plan():
        nonlocal base_pos, real_pos
        b = start_it
        while True:
            k = real_in_batch(cfg, b)
            yield ([("real", real_pos + j) for j in range(k)]
                   + [("base", base_pos + j) for j in range(cfg.batch_size - k)])
            real_pos, base_pos, b = real_pos + k, base_pos + cfg.batch_size - k, b + 1

    yield from torch.utils.data.DataLoader(
        ds, batch_sampler=plan(), num_workers=cfg.workers, collate_fn=D.collate,
        worker_init_fn=_worker_init if cfg.workers else None,
        prefetch_factor=2 if cfg.workers else None)


def _param_groups(model, params: list, fine_lr_mult: float) -> list[dict]:
    """One optimizer group, or two when the fine branch learns at its own rate (``lr_mult``,
    applied with the schedule in ``train``)."""
    if fine_lr_mult == 1.0:
        return [{"params": params}]
    fine = {id(p) for p in model.backbone.fine.parameters()}
    return [{"params": [p for p in params if id(p) not in fine], "lr_mult": 1.0},
            {"params": [p for p in params if id(p) in fine], "lr_mult": fine_lr_mult}]


def _batches(ds, cfg: TrainConfig, start_it: int):
    """Endless batches; the order is a function of (seed, epoch), so resuming is repeatable."""
    n = len(ds)
    epoch_len = max(1, n // cfg.batch_size) if n >= cfg.batch_size else 1
    epoch, skip = divmod(start_it, epoch_len)
    while True:
        g = torch.Generator().manual_seed(cfg.seed * 1_000_003 + epoch)
        if n > 100_000:  # synthetic: a fresh stretch of seeds per epoch; no permutation needed
            # Each seed starts its own stretch, so a run continued with a new seed sees new scenes.
            start = cfg.seed * SYNTH_STRETCH + epoch * epoch_len * cfg.batch_size
            order = (torch.arange(epoch_len * cfg.batch_size) + start) % n
        else:
            order = torch.randperm(n, generator=g)
            if n < cfg.batch_size:
                order = order.repeat(math.ceil(cfg.batch_size / n))
        order = order[skip * cfg.batch_size: epoch_len * cfg.batch_size]
        if hasattr(ds, "epoch"):
            ds.epoch = epoch
        sampler = _Chunks(order, cfg.batch_size)
        loader = torch.utils.data.DataLoader(
            ds, batch_sampler=sampler, num_workers=cfg.workers, collate_fn=D.collate,
            worker_init_fn=_worker_init if cfg.workers else None,
            persistent_workers=False, prefetch_factor=2 if cfg.workers else None)
        yield from loader
        epoch, skip = epoch + 1, 0


class _Chunks:
    """Batches of indices, made lazily (a synthetic epoch is a million seeds long)."""

    def __init__(self, order, size: int):
        self.order, self.size = order, size

    def __len__(self) -> int:
        return len(self.order) // self.size

    def __iter__(self):
        for i in range(len(self)):
            yield [int(j) for j in self.order[i * self.size:(i + 1) * self.size]]


class WeightAverage:
    """An exponential moving average of a model's floating-point state (weights and buffers):
    after each step ``avg = decay * avg + (1 - decay) * now``. Integer buffers follow as they are."""

    def __init__(self, model, decay: float, state: dict[str, torch.Tensor] | None = None) -> None:
        self.decay = decay
        now = model.state_dict()
        self.state = {k: (state[k] if state is not None and k in state else v).detach().clone().float()
                      if v.is_floating_point() else v.detach().clone() for k, v in now.items()}

    @torch.no_grad()
    def update(self, model) -> None:
        for k, v in model.state_dict().items():
            avg = self.state[k]
            if v.is_floating_point():
                avg.mul_(self.decay).add_(v.detach().float(), alpha=1.0 - self.decay)
            else:
                avg.copy_(v)

    def copy_to(self, model) -> None:
        now = model.state_dict()
        model.load_state_dict({k: v.to(now[k].dtype) for k, v in self.state.items()})


def _save_ckpt(path: Path, model, opt, it: int, cfg: TrainConfig, elapsed: float,
               history: list[dict], ema: WeightAverage | None = None) -> None:
    buf = io.BytesIO()
    torch.save({"arch": ARCH, "state_dict": model.state_dict(), "optimizer": opt.state_dict(),
                "iteration": it, "elapsed_s": elapsed, "config": _cfg_dict(cfg),
                "history": history[-2000:],
                **({"ema_state_dict": ema.state} if ema is not None else {})}, buf)
    atomic_write_bytes(path, buf.getvalue())


def _cfg_dict(cfg: TrainConfig) -> dict[str, Any]:
    d = asdict(cfg)
    d["train_sizes"] = list(cfg.train_sizes)
    d["real_holdout"] = list(cfg.real_holdout)
    return d


# What a resumed run must keep: its data, its order and its recipe ("continues exactly there").
# A run may be resumed longer (--iterations, --max-minutes) or elsewhere (device, threads).
RESUME_SAME = ("data", "real", "real_share", "real_holdout", "seed", "batch_size", "lr", "warmup",
               "weight_decay", "width", "height", "train_sizes", "stops", "view_mix", "augment",
               "synth_count", "init", "ema")


def _same_run(path: Path, was: dict[str, Any], cfg: TrainConfig) -> None:
    """ConfigError (exit 4) when a resume asks for another run than the checkpoint's, e.g. other
    data, or another held-out sequence (which would leak it into a cross-validated fold)."""
    now = _cfg_dict(cfg)
    for k in RESUME_SAME:
        if k in was and was[k] != now.get(k):
            raise ConfigError(f"{path}: the run was started with {k} {was[k]!r}; resume it with "
                              f"that (asked {now.get(k)!r}), or start a new run in another --out")


def _from_worker(e: Exception) -> Exception:
    """A data-loading worker's error as the user should read it: torch re-raises it as "Caught
    InputError in DataLoader worker process 0. Original Traceback ..." ending in the message."""
    text = str(e)
    if not text.startswith("Caught "):
        return e
    head = f"{type(e).__module__}.{type(e).__qualname__}: "
    last = [ln for ln in text.splitlines() if ln.startswith(head)]
    return type(e)(last[-1][len(head):]) if last else e


def _load_ckpt(path: Path) -> dict[str, Any]:
    try:
        ck = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001
        raise ModelError(f"{path}: cannot resume from this checkpoint ({e.__class__.__name__})") from None
    missing = [k for k in ("state_dict", "optimizer", "iteration") if not isinstance(ck, dict) or k not in ck]
    if missing:  # an edited or foreign file: say so rather than fail on the first lookup
        raise ModelError(f"{path}: cannot resume from this checkpoint (no {', '.join(missing)} in it)")
    return ck


def train(cfg: TrainConfig, progress: Callable[[dict[str, Any]], None] | None = None,
          note: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run (or resume) a training run; returns the summary written to OUT/metrics.json.
    ``note``: told once, before the first step, what the data held beyond its instances (COCO
    annotations ignored or skipped, images trained as negatives), a line per file."""
    cfg.check()
    if cfg.average_with:  # a bad file fails now, not after hours of training
        load_weights(build_model(), cfg.average_with)
    out = Path(cfg.out)
    ckpt_path = out / CKPT_NAME
    if not cfg.resume:
        held = [n for n in (CKPT_NAME, "model.pt", "metrics.json") if (out / n).is_file()]
        if held:  # as train-refiner: a finished or stopped run is never overwritten silently
            raise InputError(f"{out}: holds a run already ({', '.join(held)}); --resume to "
                             "continue it, or pick another --out")
    out.mkdir(parents=True, exist_ok=True)
    remove_temp_files(out, RUN_FILES)  # what a kill mid-write left (.last.ckpt.k2x9q0ab)
    device = pick_device(cfg.device)
    if cfg.threads or device.type == "cpu":
        # One thread unless asked: on a shared or busy CPU, torch's thread pool spends more
        # time synchronising than computing (measured 3x slower steps with 2 threads under load).
        torch.set_num_threads(int(cfg.threads or 1))
    _seed_all(cfg.seed)
    model = build_model()
    start_it, elapsed0, history = 0, 0.0, []
    state = None
    if cfg.resume:
        if not ckpt_path.is_file():
            raise InputError(f"{ckpt_path}: no checkpoint to resume from (run without --resume first)")
        state = _load_ckpt(ckpt_path)
        if state.get("arch") != ARCH:
            raise ModelError(f"{ckpt_path}: a checkpoint of architecture {state.get('arch')!r}, this "
                             f"wtinspect trains {ARCH!r}; start a new run with --init {out / 'model.pt'}")
        _same_run(ckpt_path, state.get("config") or {}, cfg)
        model.load_state_dict(state["state_dict"])
        start_it, elapsed0 = int(state["iteration"]), float(state.get("elapsed_s", 0.0))
        history = list(state.get("history", []))
    elif cfg.init:
        load_weights(model, cfg.init)
    ds = make_dataset(cfg)
    # --val is read at the end: a bad file must stop the run now, not after it has trained.
    val = D.CocoDataset(cfg.val, augment=False) if cfg.val and cfg.eval_count else None
    notes = [f"{opt} {n}" for opt, d in (("--data", getattr(ds, "base", ds)),
                                         ("--real", getattr(ds, "real", None)), ("--val", val))
             if hasattr(d, "notes") for n in d.notes()]
    for n in notes if note else ():
        note(n)
    model.to(device)
    sizes = tuple(cfg.train_sizes)
    if not cfg.data:  # never blow small renders up (mixed with photos too): at most their own size
        sizes = tuple(s for s in sizes if s <= min(cfg.width, cfg.height)) or (min(cfg.width, cfg.height),)
    longest = max(max(sizes) * 4 // 3, max(cfg.width, cfg.height))
    if cfg.real:  # photos are mostly 16:9: let their longer side follow the drawn size
        longest = max(longest, max(sizes) * 16 // 9)
    set_train_sizes(model, sizes, longest)
    precision = resolve_precision(cfg.precision, device)
    params = [p for p in model.parameters() if p.requires_grad]
    opt = torch.optim.AdamW(_param_groups(model, params, cfg.fine_lr_mult), lr=cfg.lr,
                            weight_decay=cfg.weight_decay, foreach=True)
    if state is not None and "optimizer" in state:
        saved = len(state["optimizer"].get("param_groups", []))
        if saved != len(opt.param_groups):
            was = (state.get("config") or {}).get("fine_lr_mult", 1.0)
            raise ConfigError(f"{ckpt_path}: the run was started with --fine-lr-mult {was:g}; "
                              f"resume it with that (asked {cfg.fine_lr_mult:g})")
        opt.load_state_dict(state["optimizer"])
    ema = None
    if cfg.ema:
        saved_ema = state.get("ema_state_dict") if state is not None else None
        if state is not None and saved_ema is None:
            raise ConfigError(f"{ckpt_path}: the run was started without --ema; resume it without")
        ema = WeightAverage(model, cfg.ema, saved_ema)
    t0 = time.monotonic()
    it = start_it
    last_ckpt_it = it
    budget_s = cfg.max_minutes * 60.0 if cfg.max_minutes else None
    model.train()
    stopped = "iterations"
    if precision == "bf16":
        backbone_in_bf16(model)
    try:
        if it < cfg.iterations:
            stream = _mixed_batches if cfg.real else _batches
            for images, targets in stream(ds, cfg, start_it):
                elapsed = elapsed0 + time.monotonic() - t0
                prog = it / cfg.iterations
                if budget_s:
                    prog = max(prog, elapsed / budget_s)
                f = lr_factor(prog, it, cfg.warmup)
                for g in opt.param_groups:
                    g["lr"] = cfg.lr * f * g.get("lr_mult", 1.0)
                images = [im.to(device) for im in images]
                targets = [{k: v.to(device) for k, v in t.items()} for t in targets]
                losses = model(images, targets)
                loss = sum(losses.values())
                if not torch.isfinite(loss):
                    raise ModelError(f"training diverged at iteration {it} (loss {float(loss)}); "
                                     f"lower --lr (now {cfg.lr})")
                opt.zero_grad(set_to_none=True)
                loss.backward()
                torch.nn.utils.clip_grad_norm_(params, 10.0)
                opt.step()
                if ema is not None:
                    ema.update(model)
                it += 1
                rec = {"iteration": it, "loss": loss.item(), "lr": cfg.lr * f,
                       **{k: v.item() for k, v in losses.items()}}
                history.append(rec)
                if progress:
                    progress({**rec, "total": cfg.iterations, "elapsed_s": elapsed0 + time.monotonic() - t0})
                if it - last_ckpt_it >= cfg.checkpoint_every:
                    _save_ckpt(ckpt_path, model, opt, it, cfg, elapsed0 + time.monotonic() - t0, history, ema)
                    last_ckpt_it = it
                if it >= cfg.iterations:
                    break
                if budget_s and elapsed0 + time.monotonic() - t0 >= budget_s:
                    stopped = "max_minutes"
                    break
    except KeyboardInterrupt:  # Ctrl-C: the steps since the last checkpoint are kept
        if it > last_ckpt_it:
            _save_ckpt(ckpt_path, model, opt, it, cfg, elapsed0 + time.monotonic() - t0, history, ema)
        raise
    except WtError as e:
        raise _from_worker(e) from None

    elapsed = elapsed0 + time.monotonic() - t0
    backbone_in_bf16(model, False)  # the plain float32 backbone for the end-of-run check
    _save_ckpt(ckpt_path, model, opt, it, cfg, elapsed, history, ema)
    if ema is not None:  # the averaged weights are the run's result (the checkpoint keeps both)
        ema.copy_to(model)
    model.eval()
    set_infer_size(model)
    save_weights(model, out / "model.pt", meta={"iterations": it, "train_seconds": round(elapsed, 1),
                                                "data": cfg.data or "synthetic", "seed": cfg.seed,
                                                **({"real": cfg.real, "real_share": cfg.real_share,
                                                    "real_holdout": list(cfg.real_holdout)}
                                                   if cfg.real else {}),
                                                "precision": precision,
                                                **({"ema": cfg.ema} if cfg.ema else {}),
                                                "mask_offset_px": MASK_OFFSET_PX})
    if cfg.average_with:
        average_weights([out / "model.pt", cfg.average_with], out / AVERAGE_NAME)
    metrics = evaluate_run(model, cfg, device, val) if cfg.eval_count else {}
    recent = history[-50:]
    summary = {
        "arch": ARCH, "iterations": it, "stopped_by": stopped, "train_seconds": elapsed,
        "device": str(device), "precision": precision,
        "final_loss": float(np.mean([h["loss"] for h in recent])) if recent else None,
        "config": _cfg_dict(cfg), "train_sizes_used": list(sizes), "evaluation": metrics,
        "data_notes": notes,
        "weights": str(out / "model.pt"), "checkpoint": str(ckpt_path),
        "average": str(out / AVERAGE_NAME) if cfg.average_with else None,
    }
    write_json(out / "metrics.json", document(TRAIN_SCHEMA, 1, summary))
    return summary


def evaluate_run(model, cfg: TrainConfig, device, val: D.CocoDataset | None = None) -> dict[str, Any]:
    """Quick end-of-run check: mask IoU per class, AP50 and blade-count accuracy. On ``--val``
    (``val``, read before training), a detection at least half inside a crowd or box-only
    region is left out, as COCO's evaluation does: that region is no instance to miss or hit."""
    from wtcli.segment.evaluate import Evaluator
    from wtcli.segment.infer import predict

    ev = Evaluator()
    if cfg.val:
        vs = val if val is not None else D.CocoDataset(cfg.val, augment=False)
        samples = (vs.load(i) for i in range(min(len(vs), cfg.eval_count)))
    else:
        samples = (D.render(D.HELDOUT_SEED_BASE + 500_000 + i, cfg.width, cfg.height)
                   for i in range(cfg.eval_count))
    for s in samples:
        pred = predict(model, s.image, score_threshold=0.0, device=device)
        ignore = getattr(s, "ignore", None)
        if ignore is not None and len(pred):
            area = pred.masks.reshape(len(pred), -1).sum(axis=1)
            inside = (pred.masks & ignore).reshape(len(pred), -1).sum(axis=1)
            pred = pred[inside < 0.5 * np.maximum(area, 1)]
        ev.add(pred, s.instances)
    return ev.summary()


def export_checkpoint(ckpt: str | Path, weights: str | Path) -> Path:
    """A training checkpoint (OUT/last.ckpt) -> the shipped float16 weights file."""
    state = _load_ckpt(Path(ckpt))
    model = build_model()
    # A run with --ema ships its averaged weights; its checkpoint holds both.
    model.load_state_dict(state.get("ema_state_dict") or state["state_dict"])
    meta = {"iterations": int(state.get("iteration", 0)),
            "train_seconds": round(float(state.get("elapsed_s", 0.0)), 1),
            "data": (state.get("config") or {}).get("data") or "synthetic",
            "seed": (state.get("config") or {}).get("seed", 0), "mask_offset_px": MASK_OFFSET_PX}
    return save_weights(model, weights, meta=meta)
