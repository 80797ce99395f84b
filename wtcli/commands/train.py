"""`wtinspect train`: train (or fine-tune) the segmenter on synthetic renders or a COCO dataset,
labelled real photos mixed in (docs/train.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer


def train(
    out: Path = typer.Option(Path("runs/train"), "--out", "-o",
                             help="Run folder: last.ckpt (resumable), model.pt, metrics.json."),
    data: Optional[Path] = typer.Option(None, "--data",
                                        help="COCO instances JSON (or a folder with instances.json, "
                                             "e.g. from `synth`); default: renders made on the fly."),
    iterations: int = typer.Option(2000, "--iterations", "-n", help="Optimizer steps in all."),
    batch_size: int = typer.Option(2, "--batch-size", help="Images per step."),
    lr: float = typer.Option(1e-3, "--lr", help="Peak AdamW learning rate."),
    warmup: int = typer.Option(200, "--warmup", help="Linear warm-up steps."),
    max_minutes: Optional[float] = typer.Option(None, "--max-minutes",
                                                help="Stop after this long (the LR schedule "
                                                     "follows whichever ends first)."),
    width: int = typer.Option(640, "--width", help="Synthetic render width."),
    height: int = typer.Option(480, "--height", help="Synthetic render height."),
    seed: int = typer.Option(0, "--seed", help="Seed of initialisation, order and augmentation."),
    init: Optional[Path] = typer.Option(None, "--init",
                                        help="Start from these weights (fine-tuning), e.g. "
                                             "models/wtseg-r18s.pt; default: random."),
    checkpoint_every: int = typer.Option(100, "--checkpoint-every", help="Steps between checkpoints."),
    eval_count: int = typer.Option(16, "--eval-count",
                                   help="Held-out images evaluated at the end (0: none)."),
    val: Optional[Path] = typer.Option(None, "--val", help="COCO dataset to evaluate on."),
    device: str = typer.Option("auto", "--device", help="auto (GPU if present) | cpu | cuda[:N]."),
    workers: int = typer.Option(1, "--workers", help="Data-loading processes (0: in the main one)."),
    threads: Optional[int] = typer.Option(None, "--threads", min=1,
                                          help="CPU threads for torch (default 1: fastest on a "
                                               "shared CPU; raise it on an idle many-core one)."),
    sizes: Optional[str] = typer.Option(None, "--sizes",
                                        help="Shorter sides to train at, e.g. 384,416,448,480 "
                                             "(default 320,352,384,416; inference uses 576); "
                                             "on renders, at most --height/--width."),
    no_augment: bool = typer.Option(False, "--no-augment", help="Train on the images as they are."),
    stops: float = typer.Option(0.3, "--stops", min=0.0, max=1.0,
                                help="Share of synthetic renders whose rotor stands where crews "
                                     "stop it for inspection: a Y or an inverted Y (a blade in "
                                     "front of the tower)."),
    view_mix: Optional[str] = typer.Option(None, "--view-mix",
                                           help="Shares of the renders' views, as `synth "
                                                "--view-mix`, e.g. 'mixed=0.5,closeup=0.2,"
                                                "nadir=0.1,distant=0.2' (default: the usual mix)."),
    precision: str = typer.Option("auto", "--precision",
                                  help="auto | fp32 | bf16. auto: the backbone in bfloat16 on a "
                                       "CPU that does bf16 natively (faster steps), else fp32."),
    fine_lr_mult: float = typer.Option(1.0, "--fine-lr-mult",
                                       help="The mask head's stride-4 branch learns at this times "
                                            "--lr (the shipped model: 10)."),
    average_with: Optional[Path] = typer.Option(None, "--average-with",
                                                help="Also write OUT/model-average.pt: the run's "
                                                     "weights averaged with these (e.g. the --init "
                                                     "file)."),
    real: Optional[Path] = typer.Option(None, "--real",
                                        help="Labelled real photos mixed in: a folder with "
                                             "manifest.csv and semantic masks (0 background, 1 "
                                             "blade, 2 tower; split into instances), or a COCO "
                                             "instances JSON."),
    real_share: float = typer.Option(0.3, "--real-share",
                                     help="Share of each batch from --real, on average (0-1]."),
    real_holdout: Optional[list[str]] = typer.Option(None, "--real-holdout-sequence",
                                                     metavar="SEQ",
                                                     help="Leave this flight sequence of --real "
                                                          "out (repeatable), to measure on it."),
    ema: float = typer.Option(0.0, "--ema",
                              help="Ship an exponential moving average of the weights, this "
                                   "decay per step (e.g. 0.99: about the last 100 steps); 0: the "
                                   "last step's weights."),
    resume: bool = typer.Option(False, "--resume",
                                help="Continue from OUT/last.ckpt (a folder holding a run is "
                                     "otherwise refused)."),
    json_out: bool = typer.Option(False, "--json", help="Print the run summary JSON on stdout."),
) -> None:
    """Train the blade/tower/nacelle Mask R-CNN on renders, COCO data and labelled real photos;
    resumable; evaluates at the end."""
    from rich.table import Table

    from wtcli.console import err_console
    from wtcli.errors import ConfigError, InputError
    from wtcli.jsonio import document, dumps
    from wtcli.segment.model import TRAIN_MIN_SIZES
    from wtcli.segment.train import TRAIN_SCHEMA, TrainConfig
    from wtcli.segment.train import train as run_training

    train_sizes = TRAIN_MIN_SIZES
    if sizes is not None:
        try:
            train_sizes = tuple(int(v) for v in sizes.split(","))
        except ValueError:
            raise ConfigError(f"--sizes {sizes!r}: expected whole pixel sizes separated by commas, "
                             "e.g. 384,416,448,480") from None
        # Renders are never blown up (a run would silently train at fewer sizes than asked):
        # render larger instead.
        short = min(width, height)
        big = [v for v in train_sizes if v > short]
        if data is None and big:
            raise ConfigError(f"--sizes {sizes}: {','.join(map(str, big))} above the renders' shorter "
                             f"side ({width}x{height}); renders are not enlarged, so render larger "
                             f"(e.g. --width {round(max(big) * width / short)} --height "
                             f"{round(max(big) * height / short)}) or leave those sizes out")
    if real is not None and not real.exists():
        raise InputError(f"{real}: no such photo folder or COCO file (--real)")
    if data is not None and not data.exists():
        raise InputError(f"{data}: no such dataset (a COCO instances JSON or a folder with one)")
    from wtcli.outputs import writable_folder
    writable_folder(out)  # before hours of training, not after
    cfg = TrainConfig(out=str(out), data=str(data) if data else None, iterations=iterations,
                      batch_size=batch_size, lr=lr, warmup=warmup, max_minutes=max_minutes,
                      width=width, height=height, seed=seed, init=str(init) if init else None,
                      checkpoint_every=checkpoint_every, eval_count=eval_count,
                      val=str(val) if val else None, device=device, workers=workers, threads=threads,
                      augment=not no_augment, stops=stops, resume=resume, train_sizes=train_sizes,
                      precision=precision, fine_lr_mult=fine_lr_mult,
                      average_with=str(average_with) if average_with else None,
                      view_mix=view_mix, real=str(real) if real else None, real_share=real_share,
                      real_holdout=tuple(real_holdout or ()), ema=ema)
    report = _Report(iterations, max_minutes, checkpoint_every)
    try:
        summary = run_training(cfg, progress=report.step,
                               note=lambda line: err_console.print(f"train: {line}", soft_wrap=True))
    finally:
        report.close()
    ev = summary.get("evaluation") or {}
    if ev:
        table = Table(title=f"evaluation on {ev.get('images')} held-out image(s)", title_justify="left")
        for col in ("class", "mask IoU", "AP50"):
            table.add_column(col)
        for label in ("blade", "tower", "nacelle"):
            iou, ap = ev.get(f"{label}_mask_iou"), ev.get(f"{label}_ap50")
            table.add_row(label, "-" if iou is None else f"{iou:.3f}", "-" if ap is None else f"{ap:.3f}")
        err_console.print(table)
    err_console.print(f"{summary['iterations']} iterations in {summary['train_seconds']:.0f} s on "
                      f"{summary['device']} ({summary['precision']}); weights -> {summary['weights']}, "
                      f"resume from {summary['checkpoint']}", soft_wrap=True)
    if summary.get("average"):
        err_console.print(f"averaged with {average_with} -> {summary['average']}", soft_wrap=True)
    if json_out:
        typer.echo(dumps(document(TRAIN_SCHEMA, 1, summary)))


class _Report:
    """What a person sees while a run trains (hours on a CPU). On a terminal: a bar that fills
    as the run's end nears (the iterations or ``--max-minutes``, whichever comes first, as the
    learning-rate schedule) with the step and the losses. In a log (a batch server, ``nohup``):
    a plain line at the first step and then every ``--checkpoint-every`` steps, since a bar
    would print nothing there until the end."""

    def __init__(self, iterations: int, max_minutes: float | None, every: int) -> None:
        self.iterations, self.every = iterations, max(1, every)
        self.budget_s = 60.0 * max_minutes if max_minutes else None
        self.bar = self.task = None
        self.last: tuple[int, float] | None = None  # (iteration, elapsed s) of the last line

    def share(self, rec: dict) -> float:
        share = rec["iteration"] / self.iterations
        if self.budget_s:
            share = max(share, rec["elapsed_s"] / self.budget_s)
        return min(share, 1.0)

    @staticmethod
    def losses(rec: dict) -> str:
        return (f"loss {rec['loss']:.3f} (mask {rec.get('loss_mask', 0):.3f}, "
                f"cls {rec.get('loss_classifier', 0):.3f}) lr {rec['lr']:.1e}")

    def step(self, rec: dict) -> None:
        from wtcli.console import err_console

        if err_console.is_terminal:
            self._bar(rec)
            return
        it, el = rec["iteration"], rec["elapsed_s"]
        if self.last is not None and it - self.last[0] < self.every:
            return
        pace = f", {(el - self.last[1]) / (it - self.last[0]):.2f} s/step" if self.last else ""
        end = (f"{self.iterations} steps or {self.budget_s / 60:g} min" if self.budget_s
               else f"{self.iterations} steps")
        err_console.print(f"train: step {it}, {100 * self.share(rec):.0f} % of the run ({end}), "
                          f"{self.losses(rec)}{pace}, {el / 60:.1f} min trained", soft_wrap=True)
        self.last = (it, el)

    def _bar(self, rec: dict) -> None:
        from rich.progress import (BarColumn, Progress, TaskProgressColumn, TextColumn,
                                   TimeElapsedColumn, TimeRemainingColumn)

        from wtcli.console import err_console

        status = f"step {rec['iteration']} {self.losses(rec)}"
        if self.bar is None:  # started at the first step, so a resumed run's ETA is its own pace
            self.bar = Progress(TextColumn("[bold]train"), BarColumn(), TaskProgressColumn(),
                                TextColumn("{task.fields[status]}"), TimeElapsedColumn(),
                                TimeRemainingColumn(), console=err_console)
            self.bar.start()
            self.task = self.bar.add_task("train", total=1.0, completed=self.share(rec), status=status)
        else:
            self.bar.update(self.task, completed=self.share(rec), status=status)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()


def register(app: typer.Typer) -> None:
    app.command("train")(train)
