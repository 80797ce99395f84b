"""`wtinspect pitch`: blade contours -> θ (eq. 7), class, direction φ, overlay. docs/pitch.md"""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import cv2
import typer

from wtcli.console import err_console, stage_bars, stage_ticker
from wtcli.errors import InputError, PartialFailure, PerceptionError
from wtcli.jsonio import atomic_write_bytes, dumps, write_json
from wtcli.pitch.inputs import is_photo, load_pitch_input, pitch_batch
from wtcli.pitch.overlay import HUB_NOTE, draw_pitch_overlay, overlay_background, overlay_names
from wtcli.segment.batch import read_image
from wtcli.segment.defaults import CANDIDATE_FLOOR


def register(app: typer.Typer) -> None:
    @app.command("pitch")
    def pitch(
        inputs: List[Path] = typer.Argument(
            ..., metavar="INPUT...",
            help="A contours JSON (from `contours`), an instances JSON (COCO, every image in it), "
                 "mask PNGs of one image (one binary PNG per instance, or a label PNG), or "
                 "photos (segmented first with the shipped model)."),
        area_threshold: Optional[float] = typer.Option(
            None, "--area-threshold", min=0, metavar="PX",
            help="Eq. 6 threshold in pixels (default 20; a contours JSON keeps its own)."),
        blades: int = typer.Option(3, "--blades", min=0,
                                   help="Expected blades per image; 0 accepts any count."),
        score_threshold: Optional[float] = typer.Option(
            None, "--score-threshold", min=0.0, max=1.0,
            help="Count only instances scoring at least this; lower-scoring blades may complete "
                 "a rotor that is short of blades. Default: 0.5 for a photo, none for a file "
                 "(every instance in it counts)."),
        candidate_floor: float = typer.Option(
            CANDIDATE_FLOOR, "--candidate-floor", min=0.0, max=1.0,
            help="Lowest score at which a blade may be admitted to complete the rotor; at or "
                 "above --score-threshold none is."),
        out: Optional[Path] = typer.Option(None, "--out", "-o", help="Write the pitch JSON here."),
        overlay_dir: Optional[Path] = typer.Option(
            None, "--overlay-dir", help="Write one PNG per image with each blade's axis, θ, "
                                        "class and φ drawn on it."),
        image: Optional[Path] = typer.Option(
            None, "--image", help="Background photo for the overlay (one image only); default: "
                                  "the image's file_name next to the instances JSON, or the "
                                  "photo segment read, else the masks."),
        json_out: bool = typer.Option(False, "--json", help="Print the pitch JSON on stdout."),
    ) -> None:
        """Measure each blade's angle θ, its class and its direction φ hub -> tip (eq. 7)."""
        paths = [Path(p) for p in inputs]
        from wtcli.outputs import check_not_inputs, check_outputs
        given = [("an input file", p) for p in paths] + [("the --image photo", image)]
        check_not_inputs([("--out", out)], given)
        check_outputs(files=[out], folders=[overlay_dir])  # before the work, not after
        photos = bool(paths) and all(is_photo(p) for p in paths)
        if photos:  # segment -> contours -> pitch, photo by photo (wtcli.chain)
            from wtcli.chain import pitch_photos

            def run(on_done=None):
                return pitch_photos(paths, blades or None, source=str(inputs[0]), on_done=on_done,
                                    area_threshold=area_threshold, score_threshold=score_threshold,
                                    candidate_floor=candidate_floor)
            n_images = len(paths)
        else:
            loaded = load_pitch_input(paths, area_threshold)

            def run(on_done=None):
                return pitch_batch(loaded, blades or None, source=str(inputs[0]), on_done=on_done,
                                   score_threshold=score_threshold, candidate_floor=candidate_floor)
            n_images = len(loaded)
        if image is not None and n_images != 1:
            raise InputError(f"--image needs an input with one image, got {n_images}")
        if overlay_dir is not None:  # an overlay over an input photo or mask would replace it
            records = [{"file_name": p.name} for p in paths] if photos else \
                [inp.image for inp in loaded]
            check_not_inputs([("--overlay-dir file", overlay_dir / n)
                              for n in overlay_names(records)], given)
        texts = {"images": "pitch", "overlays": "overlays"}
        if n_images > 1:  # a bar on a terminal, lines in a log once it has run a while
            with stage_bars(texts, "pitch") as progress:
                tick = stage_ticker(progress, "images", n_images)
                batch = run(lambda k, err: tick())
        else:
            batch = run()
        for res, inp in zip(batch.results, batch.inputs):
            if res is not None and res.admitted:
                name = inp.image.get("file_name") or inp.image.get("id", "?")
                which = ", ".join(f"blade {res.blades.index(b) + 1} (score {b.score:.2f})"
                                  for b in res.admitted)
                err_console.print(f"note: {name}: {which} admitted below the score threshold "
                                  f"{res.score_threshold:g} to complete the {len(res.blades)}-blade "
                                  "rotor", soft_wrap=True)
        overlays: list[Optional[str]] | None = None
        if overlay_dir is not None:
            overlays = []
            # From every record, failed ones too: a name must not change with what else failed.
            names = overlay_names([inp.image for inp in batch.inputs])
            with stage_bars(texts, "pitch") as progress:  # drawn on the photos: seconds each
                tick = stage_ticker(progress if n_images > 1 else None, "overlays", n_images)
                for k, (res, inp) in enumerate(zip(batch.results, batch.inputs)):
                    if res is None:
                        overlays.append(None)
                        tick()
                        continue
                    bg, note = overlay_background(inp, image, read_image)  # as segment read it
                    if note:
                        err_console.print(f"note: {note}", soft_wrap=True)
                    ok, png = cv2.imencode(".png", draw_pitch_overlay(bg, res))
                    path = overlay_dir / names[k]
                    atomic_write_bytes(path, png.tobytes())
                    overlays.append(str(path))
                    tick()
        doc = batch.to_document(overlays)
        if out is not None:
            write_json(out, doc)
        if json_out:
            typer.echo(dumps(doc))
        elif out is None:
            for res, err, inp in zip(batch.results, batch.errors, batch.inputs):
                name = inp.image.get("file_name") or inp.image.get("id", "?")
                if res is None:
                    typer.echo(f"{name}: error: {err}")
                    continue
                for k, b in enumerate(res.blades):
                    typer.echo(f"{name}: blade {k + 1}: theta {b.theta_deg:7.2f}  "
                               f"{b.theta_class:<10}  phi {b.phi_deg:7.2f}  "
                               f"(eq. 7 minAreaRect {b.theta_eq7_deg:.2f})"
                               + ("  admitted at low score" if b.admitted_low_score else "")
                               + ("" if b.direction_known else "  direction unknown"))
                if not res.hub_in_frame:
                    typer.echo(f"{name}: {HUB_NOTE[res.hub_source]}")
        n, bad = len(batch.results), batch.n_failed
        if out is not None or overlay_dir is not None:
            where = ", ".join(str(p) for p in (out, overlay_dir) if p is not None)
            unknown = sum(r is not None and not r.direction_known for r in batch.results)
            err_console.print(f"pitch of {n - bad}/{n} image(s) -> {where}"
                              + (f" ({unknown} with the hub out of frame: blade direction "
                                 "unknown)" if unknown else ""), soft_wrap=True)
        if bad:
            if n == 1:
                raise PerceptionError(batch.errors[0])
            raise PartialFailure(f"{bad} of {n} images failed (see the 'error' entries"
                                 + (f" in {out})" if out else ")"))
