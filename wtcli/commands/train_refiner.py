"""`wtinspect train-refiner`: train the edge refiner that `segment` runs on the segmenter's
masks (docs/train-refiner.md)."""

from __future__ import annotations

from contextlib import ExitStack
from pathlib import Path
from typing import Optional

import typer


def train_refiner(
    out: Path = typer.Option(Path("runs/refiner"), "--out", "-o",
                             help="Run folder: data/ (resumable), last.ckpt, refiner.pt, metrics.json."),
    images: int = typer.Option(2400, "--images", "-n",
                               help="Renders segmented for training pixels (about 2 s each on "
                                    "2 cores; ~5 GB of memory per 1000 in the fit, or "
                                    "--max-pixels)."),
    model: Optional[Path] = typer.Option(None, "--model", "-m",
                                         help="Segmenter whose masks it learns to correct "
                                              "(default: models/wtseg-r18s.pt)."),
    seed: int = typer.Option(0, "--seed", help="Scenes, sampling and initialisation (0-4)."),
    epochs: int = typer.Option(5, "--epochs", help="Passes over the training pixels."),
    max_pixels: Optional[int] = typer.Option(None, "--max-pixels",
                                             help="Fit at most this many pixels, the same share "
                                                  "of every render's (memory; default all)."),
    lr: float = typer.Option(2e-3, "--lr", help="Peak AdamW learning rate (one-cycle)."),
    hidden: str = typer.Option("512,256", "--hidden", metavar="A,B",
                               help="Widths of the MLP's two hidden layers (stored in the file)."),
    eval_count: int = typer.Option(16, "--eval-count",
                                   help="Held-out renders evaluated at the end (0: none)."),
    init: Optional[Path] = typer.Option(None, "--init",
                                        help="Refiner weights to start from (e.g. "
                                             "models/wtseg-refine.pt): fine-tune instead of "
                                             "training anew."),
    real: Optional[Path] = typer.Option(None, "--real",
                                        help="Labelled photos too, as `train --real` takes them "
                                             "(a folder with manifest.csv and semantic masks, or "
                                             "a COCO file): their blade and tower edges."),
    real_share: float = typer.Option(0.25, "--real-share",
                                     help="The photos' share of the fitted pixels (0-1; renders "
                                          "make the rest)."),
    real_holdout: Optional[list[str]] = typer.Option(None, "--real-holdout-sequence",
                                                     metavar="SEQ",
                                                     help="Leave this flight sequence of --real "
                                                          "out (repeatable), to measure on it."),
    threads: Optional[int] = typer.Option(None, "--threads", min=1, help="CPU threads for torch."),
    resume: bool = typer.Option(False, "--resume",
                                help="Continue OUT: keep its data parts and last finished pass."),
    json_out: bool = typer.Option(False, "--json", help="Print the run summary JSON on stdout."),
) -> None:
    """Train the edge refiner on renders (and labelled photos) segmented by the segmenter;
    resumable."""
    from rich.table import Table

    from wtcli.console import count_bar, err_console
    from wtcli.errors import ConfigError, InputError
    from wtcli.jsonio import document, dumps
    from wtcli.segment.train_refine import REFINER_SCHEMA, RefinerConfig
    from wtcli.segment.train_refine import train_refiner as run

    try:
        widths = tuple(int(v) for v in hidden.split(","))
    except ValueError:
        raise ConfigError(f"--hidden {hidden}: two layer widths, e.g. 512,256") from None
    from wtcli.outputs import writable_folder
    if real is not None and not real.exists():
        raise InputError(f"{real}: no such photo folder or COCO file (--real)")
    if init is not None and not init.is_file():
        raise InputError(f"{init}: no such refiner weights file (--init)")
    cfg = RefinerConfig(out=str(out), images=images, model=str(model) if model else None, seed=seed,
                        epochs=epochs, max_pixels=max_pixels, lr=lr, eval_count=eval_count,
                        threads=threads, resume=resume, hidden=widths,
                        init=str(init) if init else None, real=str(real) if real else None,
                        real_share=real_share, real_holdout=tuple(real_holdout or ()))
    cfg.check()  # a wrong option is said before the folder is made
    writable_folder(out)  # before the training, not after
    with ExitStack() as stack:
        bars: dict[str, object] = {}

        def progress(rec: dict) -> None:
            stage = rec["stage"]
            if stage not in bars:
                stack.close()  # the previous stage's bar ends where the next begins
                name = {"data": "render + segment", "photos": "photos: segment"}.get(stage, "fit")
                bars[stage] = stack.enter_context(count_bar(f"train-refiner {name}", rec["total"]))
            note = "on disk" if rec.get("skipped") else (
                f"pass {rec['epoch']}/{rec['epochs']} loss {rec['loss']:.3f}" if stage == "fit" else "")
            bars[stage](note)

        summary = run(cfg, progress=progress)
    ev = summary.get("evaluation") or {}
    if ev:
        table = Table(title=f"mask IoU on {ev['refined']['images']} held-out renders",
                      title_justify="left")
        for col in ("class", "segment alone", "refined"):
            table.add_column(col)
        for label in ("blade", "tower", "nacelle"):
            a, b = ev["unrefined"].get(f"{label}_mask_iou"), ev["refined"].get(f"{label}_mask_iou")
            table.add_row(label, "-" if a is None else f"{a:.3f}", "-" if b is None else f"{b:.3f}")
        err_console.print(table)
    kept = (f" (of {summary['pixels_made']})" if summary["pixels_made"] > summary["pixels"] else "")
    photos = f" and labelled photos ({summary['photo_pixels']})" if summary["photo_pixels"] else ""
    err_console.print(f"{summary['pixels']} band pixels{kept} from {images} renders{photos} "
                      f"({summary['data_seconds']:.0f} s), fitted in {summary['fit_seconds']:.0f} s: "
                      f"pixel accuracy {summary['val_accuracy_unrefined']:.3f} -> "
                      f"{summary['val_accuracy']:.3f}; weights -> {summary['weights']}", soft_wrap=True)
    if json_out:
        typer.echo(dumps(document(REFINER_SCHEMA, 1, summary)))


def register(app: typer.Typer) -> None:
    app.command("train-refiner")(train_refiner)
