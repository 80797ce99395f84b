"""INPUT of ``pitch`` read from files (a contours JSON, an instances JSON, mask PNGs of one image),
measured image by image (``pitch_batch``) into a ``PitchBatch``, which writes the pitch JSON.
Photos are segmented first by ``wtcli.chain``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import cv2
import numpy as np

from wtcli.contours import (CONTOURS_SCHEMA, DEFAULT_AREA_THRESHOLD, MASK_SUFFIXES, ContourSet,
                            InstanceContours, find_contours, instances_from_mask_files,
                            read_contours, require_contours)
from wtcli.errors import ConfigError, InputError, PerceptionError
from wtcli.jsonio import document, read_json
from wtcli.masks import InstancesFile
from wtcli.pitch.angles import CLASS_INTERVALS
from wtcli.pitch.measure import measure_pitch
from wtcli.pitch.result import PITCH_SCHEMA, PITCH_VERSION, THETA_SOURCE, PitchResult
from wtcli.segment.defaults import CANDIDATE_FLOOR

PHOTO_SUFFIXES = (".jpg", ".jpeg", ".webp")


@dataclass(frozen=True)
class PitchInput:
    """One image to measure: its contours (or the error that stopped them) and where its photo
    may be found for the overlay background."""

    contours: ContourSet | None
    error: str | None
    image: dict
    background_candidates: tuple[Path, ...] = ()
    score_threshold: float | None = None  # a segmented photo: 0.5; a file: none (all count)


def _image_candidates(img: dict, *dirs: Path) -> tuple[Path, ...]:
    """Where the image's photo may be: its ``file_name`` in each of ``dirs``, then the ``path``
    that ``segment`` records (as given to it)."""
    file_name, recorded = img.get("file_name"), img.get("path")
    out = [d / file_name for d in dirs] if file_name else []
    if recorded:
        out.append(Path(str(recorded)))
    return tuple(dict.fromkeys(out))


def area_threshold_px(area_threshold: float | None) -> float:
    """The eq. 6 area threshold to use: the one given (checked), else the default."""
    thr = DEFAULT_AREA_THRESHOLD if area_threshold is None else float(area_threshold)
    if thr < 0 or not math.isfinite(thr):
        raise ConfigError(f"--area-threshold must be >= 0, got {area_threshold}")
    return thr


def load_pitch_input(paths: list[Path], area_threshold: float | None = None) -> list[PitchInput]:
    """INPUT of ``pitch`` read from files, dispatched on its type: a contours JSON, an instances
    JSON (contours found here) or mask PNG(s) of one image. Photos are refused here:
    ``wtcli.chain`` segments them first (``pitch_photos``)."""
    paths = [Path(p) for p in paths]
    if not paths:
        raise InputError("no input given")
    thr = area_threshold_px(area_threshold)
    first = paths[0]
    if len(paths) == 1 and first.suffix.lower() == ".json":
        doc = read_json(first)
        if isinstance(doc, dict) and doc.get("schema") == CONTOURS_SCHEMA:
            return _from_contours_file(first, area_threshold)
        out = []
        for img, inst in InstancesFile(first):  # one image's masks at a time
            cands = _image_candidates(img, first.parent)
            try:
                cs = require_contours(find_contours(inst, thr, image=img, source=str(first)))
                out.append(PitchInput(cs, None, img, cands))
            except PerceptionError as e:
                out.append(PitchInput(None, str(e), img, cands))
        if not out:
            raise InputError(f"{first}: no images in the instances file")
        return out
    photos = [p for p in paths if is_photo(p)]
    if photos:
        if len(photos) != len(paths):
            raise InputError(f"{photos[0]}: a photo among mask files; give photos or masks, "
                             "not both")
        raise InputError(f"{photos[0]}: a photo; segment it first (wtcli.chain.pitch_photos)")
    if all(p.suffix.lower() in MASK_SUFFIXES for p in paths):
        rec, inst = instances_from_mask_files(paths)
        try:
            cs = require_contours(find_contours(inst, thr, image=rec, source=str(first)))
            return [PitchInput(cs, None, rec)]
        except PerceptionError as e:
            return [PitchInput(None, str(e), rec)]
    bad = next(p for p in paths if p.suffix.lower() not in MASK_SUFFIXES)
    raise InputError(f"{bad}: expected a contours or instances JSON, or mask PNG files")


def is_photo(path: Path) -> bool:
    """A photo rather than a mask: a .jpg/.jpeg/.webp, or an image file with colour in it."""
    if path.suffix.lower() in PHOTO_SUFFIXES:
        return True
    if path.suffix.lower() in MASK_SUFFIXES and path.is_file():
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is not None and img.ndim == 3:
            c = img[:, :, :3]
            return not (np.array_equal(c[:, :, 0], c[:, :, 1])
                        and np.array_equal(c[:, :, 1], c[:, :, 2]))
    return False


def _from_contours_file(path: Path, area_threshold: float | None) -> list[PitchInput]:
    out = []
    doc_source = str(read_json(path).get("source") or "")  # a hand-edited file may hold anything
    src_dir = Path(doc_source).parent if doc_source else Path(".")
    for cs, err, img in read_contours(path):
        cands = _image_candidates(img, src_dir, path.parent / src_dir, path.parent)
        if cs is not None and area_threshold is not None:
            if area_threshold < cs.area_threshold:
                raise ConfigError(f"{path} was filtered at {cs.area_threshold:g} px; a lower "
                                  f"--area-threshold ({area_threshold:g}) needs `wtinspect "
                                  "contours` again")
            cs = _refilter(cs, area_threshold)
            try:
                require_contours(cs)
            except PerceptionError as e:
                cs, err = None, str(e)
        out.append(PitchInput(cs, err, img, cands))
    if not out:
        raise InputError(f"{path}: no images in the contours file")
    return out


def _refilter(cs: ContourSet, threshold: float) -> ContourSet:
    kept, dropped, largest = [], cs.dropped, cs.largest_dropped_area
    for inst in cs:
        keep = [(c, a) for c, a in zip(inst.contours, inst.areas) if a > threshold]
        for a in inst.areas:
            if a <= threshold:
                dropped += 1
                largest = max(largest, a)
        if keep:
            kept.append(InstanceContours(inst.label, inst.score, inst.source_index,
                                         tuple(c for c, _ in keep), tuple(a for _, a in keep)))
    return ContourSet(tuple(kept), cs.image_size, threshold, cs.image, cs.source, dropped, largest)


@dataclass(frozen=True)
class PitchBatch:
    results: tuple[PitchResult | None, ...]
    errors: tuple[str | None, ...]
    inputs: tuple[PitchInput, ...]
    source: str
    expected_blades: int | None
    score_threshold: float | None = None  # as given; each image records the one it used
    candidate_floor: float | None = CANDIDATE_FLOOR

    @property
    def n_failed(self) -> int:
        return sum(e is not None for e in self.errors)

    def to_document(self, overlays: list[str | None] | None = None) -> dict[str, Any]:
        items = []
        for k, (res, err, inp) in enumerate(zip(self.results, self.errors, self.inputs)):
            item = ({"image": inp.image, "error": err} if res is None
                    else {**res.to_dict(), "error": None})
            if overlays is not None:
                item["overlay"] = overlays[k]
            items.append(item)
        return document(PITCH_SCHEMA, PITCH_VERSION, {
            "source": self.source, "expected_blades": self.expected_blades or 0,
            "score_threshold": self.score_threshold, "candidate_floor": self.candidate_floor,
            "theta_source": THETA_SOURCE, "angle_convention":
                "degrees, counter-clockwise, image y up, 0 = right; theta in [0, 180), "
                "phi hub->tip in [0, 360)",
            "classes": CLASS_INTERVALS, "images": items})


def pitch_batch(inputs: list[PitchInput], expected_blades: int | None = 3,
                source: str = "", on_done: Callable[[int, str | None], None] | None = None,
                score_threshold: float | None = None,
                candidate_floor: float | None = CANDIDATE_FLOOR) -> PitchBatch:
    """``measure_pitch`` on every input image; per-image errors are recorded, not raised.
    ``on_done(index, error)`` is called after each image (for a progress bar).
    ``score_threshold``: None uses each input's own (0.5 for a photo, none for a file)."""
    results, errors = [], []
    for k, inp in enumerate(inputs):
        if inp.contours is None:
            results.append(None)
            errors.append(inp.error or "no contours")
        else:
            try:
                thr = inp.score_threshold if score_threshold is None else score_threshold
                results.append(measure_pitch(inp.contours, expected_blades, thr, candidate_floor))
                errors.append(None)
            except PerceptionError as e:
                results.append(None)
                errors.append(str(e))
        if on_done is not None:
            on_done(k, errors[-1])
    return PitchBatch(tuple(results), tuple(errors), tuple(inputs), source, expected_blades,
                      score_threshold, candidate_floor)
