"""The perception chain for a photo, in one place: segment (``wtcli.segment``) -> contours
(``wtcli.contours``, eq. 4-6) -> pitch (``wtcli.pitch``, eq. 7). ``pitch`` on photos and
``plan`` from a photo both go through ``photo_to_pitch``; nothing below this module runs a stage
above its own (``tests/test_layout.py``).

The photo is segmented at the segmenter's score threshold (0.5), keeping the blades that score
at least ``candidate_floor`` as rotor-completion candidates; pitch counts what scores its
threshold (the same 0.5 unless told otherwise) and may admit a candidate to complete the rotor
(docs/pitch.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from wtcli.contours import find_contours, require_contours
from wtcli.errors import InputError, PerceptionError
from wtcli.masks import Instances
from wtcli.pitch.inputs import PitchBatch, PitchInput, area_threshold_px
from wtcli.pitch.measure import measure_pitch
from wtcli.pitch.result import PitchResult
from wtcli.segment.defaults import CANDIDATE_FLOOR, DEFAULT_SCORE_THRESHOLD


@dataclass(frozen=True)
class PhotoPitch:
    """One photo through the chain: what the segmenter found, the contours it gave (``input``,
    also the overlay's background) and the pitch measured on them, or the error that stopped
    the chain (no contours, wrong blade count)."""

    input: PitchInput
    instances: Instances
    result: PitchResult | None
    error: str | None

    def __post_init__(self) -> None:
        if (self.result is None) == (self.error is None):
            raise ValueError("expected a result or an error, not both or neither")


def photo_input(path: str | Path, area_threshold: float | None = None,
                candidate_floor: float | None = CANDIDATE_FLOOR, fast: bool = False
                ) -> tuple[PitchInput, Instances]:
    """Segment one photo file with the shipped model at its default score threshold, keeping the
    blades scoring at least ``candidate_floor`` (None: none) as rotor-completion candidates, and
    find its contours (``find_contours``, as for an instances JSON). Returns the pitch input (its
    contours or the error that stopped them; the photo as overlay background) and the instances.
    An unreadable file is an InputError. ``fast``: one pass of the network, without the mirror
    pass and the second look (``segment --no-flip --no-zoom``; ``plan --fast``). Never the wide
    look (``segment --no-wide``): it finds a blade filling a close-up's frame, and the photo a
    plan reads angles from shows a whole rotor."""
    from wtcli.segment import cvnet
    from wtcli.segment.batch import read_image

    if cvnet.chosen():  # the shipped network without importing torch (1-1.5 s of a plan)
        segment_image = cvnet.segment_image
    else:
        from wtcli.segment.infer import segment_image  # torch: loaded only when a photo is given

    path = Path(path)
    thr = area_threshold_px(area_threshold)
    try:
        img = read_image(path)
        inst = segment_image(img, score_threshold=DEFAULT_SCORE_THRESHOLD,
                             candidate_floor=candidate_floor, flip=not fast, zoom=not fast,
                             wide=False)
    except InputError as e:
        # The segmenter's own checks ("image is too small (1x1)") see pixels, not the file.
        raise e if str(path) in str(e) else type(e)(f"{path}: {e}") from None
    rec = {"id": 1, "file_name": path.name, "path": str(path), "width": int(img.shape[1]),
           "height": int(img.shape[0])}
    try:
        cs = require_contours(find_contours(inst, thr, image=rec, source=str(path)))
        return PitchInput(cs, None, rec, (path,), DEFAULT_SCORE_THRESHOLD), inst
    except PerceptionError as e:
        return PitchInput(None, str(e), rec, (path,), DEFAULT_SCORE_THRESHOLD), inst


def photo_to_pitch(path: str | Path, expected_blades: int | None = 3, *,
                   one_short_ok: bool = False, rotor_blades: int | None = None,
                   area_threshold: float | None = None, score_threshold: float | None = None,
                   candidate_floor: float | None = CANDIDATE_FLOOR, fast: bool = False) -> PhotoPitch:
    """Segment -> contours -> pitch for one photo file.

    ``expected_blades``: the blade count the result must have (None or 0: any count >= 1);
    with ``one_short_ok`` a rotor of 3 or more blades may also come out one blade short (the
    planner infers the missing one from the rotor's even spacing). ``rotor_blades``: the
    rotor's blade count, what a low-score blade may complete it to (default
    ``expected_blades``, else 3). ``score_threshold``: what pitch counts (None: the
    segmenter's 0.5). A wrong count or no contours is the result's ``error`` (a PerceptionError
    message), not raised. ``fast``: as ``photo_input``'s."""
    inp, inst = photo_input(path, area_threshold, candidate_floor, fast)
    if inp.contours is None:
        return PhotoPitch(inp, inst, None, inp.error)
    thr = inp.score_threshold if score_threshold is None else score_threshold
    try:
        if one_short_ok and expected_blades:
            # Any count first (trimmed to the rotor's where that is clear); one short is kept,
            # any other count is measured again against ``expected_blades`` to say what is wrong.
            n_rotor = rotor_blades or expected_blades
            res = measure_pitch(inp.contours, None, thr, candidate_floor, n_rotor)
            n = len(res.blades)
            if n != expected_blades and not (expected_blades >= 3 and n == expected_blades - 1):
                res = measure_pitch(inp.contours, expected_blades, thr, candidate_floor, n_rotor)
        else:
            res = measure_pitch(inp.contours, expected_blades or None, thr, candidate_floor,
                                rotor_blades)
    except PerceptionError as e:
        return PhotoPitch(inp, inst, None, str(e))
    return PhotoPitch(inp, inst, res, None)


def pitch_photos(paths: list[Path], expected_blades: int | None = 3, source: str = "",
                 on_done: Callable[[int, str | None], None] | None = None,
                 area_threshold: float | None = None, score_threshold: float | None = None,
                 candidate_floor: float | None = CANDIDATE_FLOOR) -> PitchBatch:
    """``photo_to_pitch`` on every photo, as ``pitch_batch`` does on files: per-photo errors are
    recorded, not raised; ``on_done(index, error)`` after each photo (for a progress bar)."""
    area_threshold_px(area_threshold)  # a bad threshold is refused before any photo is segmented
    results, errors, inputs = [], [], []
    for k, path in enumerate(paths):
        try:
            pp = photo_to_pitch(path, expected_blades, area_threshold=area_threshold,
                                score_threshold=score_threshold, candidate_floor=candidate_floor)
            result, error, inp = pp.result, pp.error, pp.input
        except InputError as e:  # an unreadable photo is one failed item, the batch goes on
            if len(paths) == 1:
                raise
            rec = {"id": 1, "file_name": Path(path).name, "path": str(path), "width": 0, "height": 0}
            result, error, inp = None, str(e), PitchInput(None, str(e), rec, ())
        results.append(result)
        errors.append(error)
        inputs.append(inp)
        if on_done is not None:
            on_done(k, error)
    return PitchBatch(tuple(results), tuple(errors), tuple(inputs), source, expected_blades,
                      score_threshold, candidate_floor)
