"""The pitch overlay: each blade's contour, eq. 7 rectangle, axis (arrow hub -> tip), θ, class
and φ drawn on the photo or on the masks.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from wtcli.errors import InputError
from wtcli.pitch.angles import ACUTE, CLASS_INTERVALS, CLASSES, HORIZONTAL, VERTICAL
from wtcli.pitch.inputs import PitchInput
from wtcli.pitch.result import PitchResult


CLASS_COLORS_BGR = {HORIZONTAL: (80, 200, 40), ACUTE: (0, 165, 255), VERTICAL: (230, 60, 230)}
_PART_GREY = {"blade": 90, "tower": 55, "nacelle": 120}
# What the overlay and the summary say when the hub is not in the frame, by hub source.
HUB_NOTE = {"none": "hub out of frame: direction unknown (axis only)",
            "frame_edge": "hub out of frame, beyond the cut end",
            "nacelle": "hub out of frame", "blade_axes": "hub out of frame (where the axes meet)",
            "common_end": "hub out of frame", "blade_taper": "hub out of frame"}


def mask_canvas(result: PitchResult) -> np.ndarray:
    """A black BGR canvas with every instance's region in grey (when there is no photo)."""
    h, w = result.image_size
    canvas = np.zeros((h, w, 3), np.uint8)
    if result.contours is not None:
        for inst in result.contours:
            g = _PART_GREY.get(inst.label, 80)
            cv2.drawContours(canvas, [c.reshape(-1, 1, 2) for c in inst.contours], -1,
                             (g, g, g), thickness=cv2.FILLED)
    return canvas


def _text(img: np.ndarray, s: str, org: tuple[int, int], scale: float, color, thick: int) -> None:
    for dx, dy in ((-1, -1), (-1, 1), (1, -1), (1, 1)):  # a dark outline, same glyph widths
        cv2.putText(img, s, (org[0] + dx, org[1] + dy), cv2.FONT_HERSHEY_SIMPLEX, scale,
                    (0, 0, 0), thick, cv2.LINE_AA)
    cv2.putText(img, s, org, cv2.FONT_HERSHEY_SIMPLEX, scale, color, thick, cv2.LINE_AA)


def draw_pitch_overlay(image_bgr: np.ndarray | None, result: PitchResult) -> np.ndarray:
    """Each blade's contour, eq. 7 rectangle, axis (arrow hub -> tip), θ, class and φ on a copy
    of the image (BGR, same size as the masks), or on ``mask_canvas`` when ``image_bgr`` is None."""
    h, w = result.image_size
    if image_bgr is None:
        img = mask_canvas(result)
    else:
        img = np.ascontiguousarray(image_bgr[:, :, :3] if image_bgr.ndim == 3
                                   else cv2.cvtColor(image_bgr, cv2.COLOR_GRAY2BGR)).copy()
        if img.shape[:2] != (h, w):
            raise ValueError(f"expected an image of {w}x{h}, got {img.shape[1]}x{img.shape[0]}")
    s = max(h, w) / 1000.0
    thick = max(1, round(2 * s))
    scale = max(0.45, 0.6 * s)
    blades_contours = {}
    if result.contours is not None:
        blades_contours = {i.source_index: i for i in result.contours.of("blade")}
    for k, b in enumerate(result.blades):
        color = CLASS_COLORS_BGR[b.theta_class]
        inst = blades_contours.get(b.source_index)
        if inst is not None:
            cv2.drawContours(img, [c.reshape(-1, 1, 2) for c in inst.contours], -1, color,
                             max(1, thick // 2), cv2.LINE_AA)
        if b.rect.corners is not None:
            cv2.polylines(img, [np.round(b.rect.corners).astype(np.int32).reshape(-1, 1, 2)],
                          True, (200, 200, 200), 1, cv2.LINE_AA)
        root = tuple(int(round(v)) for v in b.root_px)
        tip = tuple(int(round(v)) for v in b.tip_px)
        length = max(1.0, math.dist(root, tip))
        if b.direction_known:
            cv2.arrowedLine(img, root, tip, color, thick + 1, cv2.LINE_AA,
                            tipLength=min(0.2, 30 * s / length))
        else:  # the axis only: no arrowhead where the sense is unknown
            cv2.line(img, root, tip, color, thick + 1, cv2.LINE_AA)
        # "#k" just beyond the tip; the numbers go in the table at the top left.
        tag = f"#{k + 1}"
        (tw, th), _ = cv2.getTextSize(tag, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)
        along = (np.asarray(b.tip_px) - np.asarray(b.root_px)) / length
        anchor = np.asarray(b.tip_px) + along * (8 + tw) * max(s, 0.7)
        x = int(np.clip(anchor[0] - tw / 2, 2, max(2, w - tw - 2)))
        y = int(np.clip(anchor[1] + th / 2, th + 2, h - 4))
        _text(img, tag, (x, y), scale, color, thick)
    if result.hub_px is not None:
        hub = tuple(int(round(v)) for v in result.hub_px)
        cv2.circle(img, hub, max(3, round(6 * s)), (40, 40, 255), -1, cv2.LINE_AA)
        cv2.circle(img, hub, max(3, round(6 * s)), (255, 255, 255), 1, cv2.LINE_AA)
    step = int(24 * max(s, 0.7))
    for k, b in enumerate(result.blades):
        phi = f"phi {b.phi_deg:5.1f}" if b.direction_known else "phi unknown"
        _text(img, f"#{k + 1}  theta {b.theta_deg:5.1f}  {b.theta_class:<10}  {phi}"
                   f"  (eq. 7: {b.theta_eq7_deg:5.1f})"
                   + (f"  admitted, score {b.score:.2f}" if b.admitted_low_score else ""),
              (8, step * (k + 1)), scale,
              CLASS_COLORS_BGR[b.theta_class], thick)
    if not result.hub_in_frame:
        _text(img, HUB_NOTE[result.hub_source], (8, step * (len(result.blades) + 1)), scale,
              (255, 255, 255), thick)
    # Legend: the classes and the angle convention.
    step = int(24 * max(s, 0.7))
    y = h - 4 * step + step // 2
    for name in CLASSES:
        _text(img, f"{name} {CLASS_INTERVALS[name]}", (8, y), scale, CLASS_COLORS_BGR[name], thick)
        y += step
    _text(img, "angles CCW from right, y up", (8, y), scale, (255, 255, 255), thick)
    return img


def overlay_background(inp: PitchInput, explicit: Path | None,
                       read: Callable[[Path], np.ndarray]) -> tuple[np.ndarray | None, str]:
    """The photo to draw on: ``explicit`` (must load and match the masks' size) or the first
    candidate that exists and matches; else None (black canvas). Returns (image, note).

    ``read``: path -> BGR uint8 [H, W, 3], InputError if it cannot. Give the reader segment
    used (``wtcli.segment.batch.read_image``: EXIF orientation, 16-bit, grey, alpha), so the
    masks lie on the pixels they were found on; it is passed in because pitch never imports
    the segmenter's package (tests/test_layout.py)."""
    h, w = inp.contours.image_size if inp.contours is not None else (0, 0)
    if explicit is not None:
        try:
            img = read(explicit)
        except InputError as e:
            raise InputError(f"{e} (--image, the overlay's background)") from None
        if img.shape[:2] != (h, w):
            raise InputError(f"{explicit}: {img.shape[1]}x{img.shape[0]} does not match the "
                             f"masks ({w}x{h})")
        return img, ""
    for p in inp.background_candidates:
        if p.is_file():
            try:
                img = read(p)
            except InputError:
                img = None
            if img is not None and img.shape[:2] == (h, w):
                return img, ""
            return None, f"{p}: unreadable or not {w}x{h}; overlay drawn on the masks"
    return None, ""


OVERLAY_SUFFIX = "_pitch.png"


def _relative_parts(file_name: str) -> list[str]:
    """An image's ``file_name`` as folders and name under --overlay-dir: both slashes split
    (COCO files from Windows use backslashes), and nothing may climb out of the folder (``..``)
    or start at its root: an absolute name keeps its name only."""
    text = str(file_name)
    parts = [p for p in re.split(r"[\\/]", text) if p not in ("", ".", "..")]
    if text.startswith(("/", "\\")) or re.match(r"[A-Za-z]:", text):
        parts = parts[-1:]
    return parts


def overlay_names(images: list[dict]) -> list[str]:
    """The overlay file of each image record, relative to ``--overlay-dir``, one file per record.

    The record's ``file_name`` keeps its folders (``site1/IMG_0001.JPG`` ->
    ``site1/IMG_0001_pitch.png``), so photos of several folders (``segment -r``) stay apart.
    Records whose names still meet keep their extension (``dup.jpg`` and ``dup.png`` ->
    ``dup.jpg_pitch.png``, ``dup.png_pitch.png``); names still alike (``a.jpg`` and ``A.jpg``)
    get ``~2``, ``~3`` after all but the first in sorted order (``A.jpg_pitch.png``,
    ``a.jpg~2_pitch.png``), as ``segment`` names its outputs. Names are compared without case,
    as on macOS and Windows disks, and the names follow from the whole set, not its order
    (but for a name given twice, numbered in input order)."""
    from wtcli.outputs import distinct_names

    parts = [_relative_parts(img.get("file_name") or "") or [f"image{img.get('id', k)}"]
             for k, img in enumerate(images)]
    return distinct_names(["/".join(p) for p in parts], OVERLAY_SUFFIX)
