"""`wtinspect segment IMAGE|FOLDER`: blade, tower and nacelle masks with the shipped Mask R-CNN;
instances JSON, background-removed image and overlay per photo (docs/segment.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from wtcli.segment.defaults import DEFAULT_MAX_SIZE, DEFAULT_SCORE_THRESHOLD


def segment(
    path: Path = typer.Argument(..., metavar="IMAGE|FOLDER",
                                help="A photo (jpg/png/tif) or a folder of them."),
    out: Path = typer.Option(Path("segment-out"), "--out", "-o",
                             help="Output folder (created): instances.json, report.json, "
                                  "instances/, background_removed/, overlay/, classes/."),
    score_threshold: float = typer.Option(DEFAULT_SCORE_THRESHOLD, "--score-threshold", min=0.0,
                                          max=1.0, help="Keep instances scoring at least this."),
    max_size: int = typer.Option(DEFAULT_MAX_SIZE, "--max-size", min=64,
                                 help="Downscale larger photos to this long side for inference; "
                                      "masks are scaled back to the photo's size."),
    zoom: bool = typer.Option(True, "--zoom/--no-zoom",
                              help="Segment each small (distant) turbine again on a crop around "
                                   "it: its blades come out fuller and its angles truer."),
    wide: bool = typer.Option(True, "--wide/--no-wide",
                              help="Look at the photo again smaller, for a part too big for the "
                                   "first look (a blade filling a close-up's frame)."),
    flip: bool = typer.Option(True, "--flip/--no-flip",
                              help="Detect the photo and its mirror image together (fewer "
                                   "missed blades, truer thin ones; --no-flip: about 2x "
                                   "faster)."),
    refine: bool = typer.Option(True, "--refine/--no-refine",
                                help="Decide each mask's edge again, pixel by pixel, with the edge "
                                     "refiner (docs/segment.md)."),
    refiner: Optional[Path] = typer.Option(None, "--refiner",
                                           help="Edge refiner weights (default: "
                                                "models/wtseg-refine.pt)."),
    device: str = typer.Option("auto", "--device", help="auto (GPU if present) | cpu | cuda[:N]."),
    precision: str = typer.Option("auto", "--precision",
                                  help="auto | fp32 | bf16. auto: the backbone in bfloat16 on a "
                                       "CPU that does bf16 natively (faster, as accurate), else fp32."),
    model: Optional[Path] = typer.Option(None, "--model", "-m",
                                         help="Weights file (default: models/wtseg-r18s.pt)."),
    mirror_model: Optional[str] = typer.Option(
        None, "--mirror-model",
        help="Weights of another network to read the mirror image, e.g. a second training "
             "of the model's recipe (default: NAME.mirror.pt beside the model NAME.pt, where "
             "there is one; none ships; 'none': the model reads both)."),
    recursive: bool = typer.Option(False, "--recursive", "-r", help="Look in subfolders too."),
    resume: bool = typer.Option(False, "--resume",
                                help="Skip photos whose outputs already exist in --out."),
    json_out: bool = typer.Option(False, "--json", help="Print the batch report JSON on stdout."),
) -> None:
    """Segment photos into blade, tower and nacelle instances (paper step 1)."""
    from rich.table import Table

    from wtcli.console import count_bar, err_console
    from wtcli.errors import InputError, OutputError, PartialFailure
    from wtcli.jsonio import dumps
    from wtcli.segment.batch import (FOUND, batch_report, find_images, not_read_text,
                                     photos_not_read, segment_paths, write_batch_files)
    from wtcli.segment.infer import load_model, segment_image
    from wtcli.segment.model import resolve_weights
    from wtcli.segment.refine import load_refiner, resolve_refiner

    from wtcli.outputs import writable_folder
    from wtcli.segment.batch import SUBFOLDERS
    # A read-only or blocked --out (or a subfolder of it) fails now, not after the model ran.
    for folder in (out, *(out / sub for sub in SUBFOLDERS)):
        writable_folder(folder)
    _, files = find_images(path, recursive, out)  # errors (no such path, empty folder) before loading
    not_read = photos_not_read(path, recursive, out)
    if not_read:
        err_console.print(f"note: {sum(not_read.values())} photo(s) in {path} not read: "
                          f"{not_read_text(not_read)}", soft_wrap=True)
    weights = resolve_weights(model)
    net = load_model(weights, device, precision, mirror=mirror_model or "auto")
    if refine:
        load_refiner(refiner, net.precision)  # a missing refiner is refused before any photo

    def run(img):  # the segmenter alone: no low-score blades kept for pitch (candidate_floor)
        return segment_image(img, net, score_threshold, max_size, candidate_floor=None, zoom=zoom,
                             flip=flip, refine=refine, refiner=refiner, wide=wide)

    settings = {"score_threshold": score_threshold, "max_size": max_size, "zoom": zoom,
                "wide": wide, "flip": flip,
                "model": str(weights), "mirror_model": net.mirror_weights if flip else None,
                "refiner": str(resolve_refiner(refiner)) if refine else None,
                "device": str(next(net.parameters()).device), "precision": net.precision}
    with count_bar("segment", len(files)) as advance:
        batch = segment_paths(path, out, run, recursive=recursive, resume=resume,
                              on_progress=lambda res: advance(f"{res.rel} {res.status}"),
                              score_threshold=score_threshold, settings=settings)
    results = batch.results
    report = batch_report(out, results, settings, interrupted=batch.interrupted, not_read=not_read)
    unsaved: OutputError | None = None  # the summary could not be written (the disk filled)
    try:
        write_batch_files(out, results, report)
    except OutputError as e:  # said beside what stopped the batch, not instead of it
        unsaved = e
    if batch.interrupted:  # Ctrl-C or SIGTERM: the photos done are summed up, then exit 130/143
        err_console.print(f"{len(results)}/{len(files)} image(s) done before the interrupt"
                          + (f" (the summary could not be written: {unsaved})" if unsaved else "")
                          + "; rerun with --resume to go on", soft_wrap=True)
        raise KeyboardInterrupt

    found = report["n_found"]  # photos by what they hold: rotor, single blade, tower only, nothing
    table = Table(title=f"segment -> {out}/", title_justify="left", caption_justify="left",
                  caption="found: " + ", ".join(f"{found[k]} {k.replace('_', ' ')}" for k in FOUND))
    for col in ("file", "status", "found", "blades", "towers", "nacelles", "note"):
        table.add_column(col)
    # A large batch lists its failed photos only (40 at most); every photo is in report.json.
    shown = results if len(results) <= 40 else [r for r in results if r.status == "error"][:40]
    for r in shown:
        c = r.counts
        table.add_row(r.rel, r.status, (r.found or "").replace("_", " "),
                      str(c.get("blade", "")), str(c.get("tower", "")), str(c.get("nacelle", "")),
                      (r.error or "")[:80], style="red" if r.status == "error" else None)
    if len(shown) < len(results):
        table.caption += (f"\n{len(results)} photos: {'the failed shown, ' if shown else ''}"
                          f"every photo in {out / 'report.json'}")
    if shown:
        err_console.print(table)
    else:
        err_console.print(f"segment -> {out}/\n{table.caption}", soft_wrap=True)
    for r in results:  # whole, one line each: the table cuts them, and a log wraps its cells
        if r.status == "error":
            err_console.print(f"failed: {r.error}", soft_wrap=True)
    bad = report["n_failed"]
    err_console.print(f"{len(results) - bad}/{len(results)} image(s) segmented"
                      + (f" ({report['n_skipped']} already done)" if report["n_skipped"] else ""),
                      soft_wrap=True)
    if json_out and unsaved is None:
        typer.echo(dumps(report))
    if batch.stopped is not None:
        left = len(files) - len(results) + 1  # the photo it stopped at is not done either
        also = f", and the summary could not be written ({unsaved})" if unsaved else ""
        raise OutputError(f"{batch.stopped}; stopped with {left} photo(s) not done{also}; those "
                          "done are kept: fix it and rerun with --resume to go on")
    if unsaved is not None:
        raise OutputError(f"{unsaved}; the files of the {len(results) - bad} photo(s) segmented "
                          "are kept: fix it and rerun with --resume to write the summary")
    if bad:
        if len(results) == 1 and path.is_file():
            raise InputError(results[0].error)
        raise PartialFailure(f"{bad} of {len(results)} images failed (see {out}/report.json)")


def register(app: typer.Typer) -> None:
    app.command("segment")(segment)
