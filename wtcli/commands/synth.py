"""`wtinspect synth OUT`: render synthetic turbine photos with COCO instance masks and ground
truth (docs/synth.md)."""

from __future__ import annotations

from pathlib import Path

import typer

from wtcli.errors import ConfigError

VIEW_CHOICES = ("front", "oblique", "side", "rear", "mixed", "closeup", "nadir", "hub", "cut",
                "broadside", "overtower", "distant")


def synth(
    out: Path = typer.Argument(..., help="Output folder (created): images/, instances.json, "
                                         "ground_truth.json."),
    count: int = typer.Option(8, "--count", "-n", help="Number of images to render."),
    seed: int = typer.Option(0, "--seed", "-s", help="Dataset seed (>= 0); same seed, same bytes."),
    width: int = typer.Option(640, "--width", help="Image width in pixels (32..8192)."),
    height: int = typer.Option(480, "--height", help="Image height in pixels (32..8192)."),
    view: str = typer.Option("mixed", "--view",
                             help="front | oblique | side | rear | mixed (draw one per image), or a "
                                  "wider view: closeup | nadir | hub | cut | broadside | overtower | "
                                  "distant (docs/synth.md)."),
    view_mix: str | None = typer.Option(None, "--view-mix",
                                 help="Draw each image's view from these shares instead, e.g. "
                                      "'mixed=0.5,closeup=0.2,nadir=0.1,distant=0.2' or "
                                      "'closeup,nadir' (equal shares)."),
    labels: str = typer.Option("outline", "--labels",
                               help="Label convention: outline (every pixel a part visibly tints, "
                                    "as photos are annotated) | half (a part covering half of the "
                                    "pixel, before blur: the labels of versions before 2026-12)."),
    json_out: bool = typer.Option(False, "--json", help="Print a JSON summary on stdout."),
) -> None:
    """Render turbines through the camera model: images + COCO masks + ground truth."""
    from wtcli.jsonio import document, dumps
    from wtcli.synth.render import LABELS, render_dataset

    if count < 1:
        raise ConfigError(f"--count: expected an integer >= 1, got {count}")
    if seed < 0:
        raise ConfigError(f"--seed: expected an integer >= 0, got {seed}")
    for name, v in (("--width", width), ("--height", height)):
        if not 32 <= v <= 8192:
            raise ConfigError(f"{name}: expected an integer in 32..8192, got {v}")
    if view not in VIEW_CHOICES:
        raise ConfigError(f"--view: expected one of {', '.join(VIEW_CHOICES)}, got {view!r}")
    if labels not in LABELS:
        raise ConfigError(f"--labels: expected one of {', '.join(LABELS)}, got {labels!r}")
    if view_mix is not None:
        from wtcli.synth.render import parse_view_mix

        if view != "mixed":
            raise ConfigError(f"--view-mix: expected no --view with it, got --view {view}")
        try:
            view_mix = parse_view_mix(view_mix)
        except ValueError as e:
            raise ConfigError(f"--view-mix: {e}") from None
    from wtcli.outputs import writable_folder

    writable_folder(out, "output folder")
    summary = render_dataset(out, count, seed, width, height,
                             view=None if view == "mixed" else view, progress=not json_out,
                             labels=labels, view_mix=view_mix)
    if json_out:
        typer.echo(dumps(document("wtinspect.synth_summary", 1, summary)))
    else:
        from wtcli.console import err_console

        err_console.print(f"wrote {summary['images']} images, {summary['instances']} instances "
                          f"to {out}/ (instances.json, ground_truth.json)", soft_wrap=True)


def register(app: typer.Typer) -> None:
    app.command("synth")(synth)
