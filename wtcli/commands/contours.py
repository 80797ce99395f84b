"""`wtinspect contours`: instance masks -> filtered contours (paper eq. 4-6). docs/contours.md"""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from wtcli.console import err_console, stage_bars
from wtcli.contours import DEFAULT_AREA_THRESHOLD, contours_batch
from wtcli.errors import PartialFailure, PerceptionError
from wtcli.jsonio import dumps
from wtcli.outputs import check_not_inputs, check_outputs


def register(app: typer.Typer) -> None:
    @app.command("contours")
    def contours(
        inputs: List[Path] = typer.Argument(
            ..., metavar="INPUT...",
            help="An instances JSON (COCO, from segment/synth; every image in it), or mask PNGs "
                 "of one image (one binary PNG per instance, or a label PNG: value = instance)."),
        area_threshold: float = typer.Option(
            DEFAULT_AREA_THRESHOLD, "--area-threshold", min=0, metavar="PX",
            help="Eq. 6: keep contours enclosing more than PX pixels."),
        out: Optional[Path] = typer.Option(None, "--out", "-o", help="Write the contours JSON here."),
        json_out: bool = typer.Option(False, "--json", help="Print the contours JSON on stdout."),
    ) -> None:
        """Binarise instance masks, find their contours and drop small ones (eq. 4-6)."""
        check_not_inputs([("--out", out)], [("an input file", p) for p in inputs])
        check_outputs(files=[out])
        with stage_bars({"images": "contours"}, "contours") as progress:
            batch = contours_batch(inputs, area_threshold, progress)
        if out is not None:
            batch.write(out)  # one image at a time
        if json_out:
            typer.echo(dumps(batch.to_document()))
        elif out is None:
            for cs, err, img in zip(batch.sets, batch.errors, batch.images):
                name = img.get("file_name") or img.get("id", "?")
                if cs is None:
                    typer.echo(f"{name}: error: {err}")
                    continue
                counts = {lab: int((cs.labels == lab).sum()) for lab in ("blade", "tower", "nacelle")}
                typer.echo(f"{name}: " + ", ".join(f"{n} {lab}" for lab, n in counts.items())
                           + f" (dropped {cs.dropped} contour(s) <= {cs.area_threshold:g} px)")
        n, bad = len(batch.sets), batch.n_failed
        if out is not None:
            err_console.print(f"contours of {n - bad}/{n} image(s) -> {out}", soft_wrap=True)
        if bad:
            if n == 1:
                raise PerceptionError(batch.errors[0])
            raise PartialFailure(f"{bad} of {n} images failed (see the 'error' entries"
                                 + (f" in {out})" if out else ")"))
