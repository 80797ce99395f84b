"""The edge refiner's pixels and features, and the masks' edges decided again from its
probabilities (``wtcli.segment.refine`` holds the network itself and runs it in torch;
``wtcli.segment.cvnet`` runs the same layers in numpy). numpy and cv2 only: importing this
module loads no torch.
"""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from wtcli.masks import LABELS, Instances
from wtcli.segment.bgr import as_bgr
from wtcli.segment.defaults import DEFAULT_MAX_SIZE

BAND = 2  # px each side of the boundary decided again
PATCH = 9  # the photo and mask seen around each pixel
RING = (3, 7)  # "just outside": between these distances (px) from the mask
# Near the pixel: the mean colour of the mask's core and of a ring LOCAL_RING px outside it,
# within LOCAL_WIN x LOCAL_WIN around the pixel. A blade's shading and the sky or ground behind
# it change along the blade; the instance-wide means above do not follow. On 100 development
# renders (refiner trained on 600 renders, 3 passes) blade / tower / nacelle IoU 0.805 / 0.872
# / 0.803 without -> 0.810 / 0.876 / 0.804 with; band pixels right 0.872 -> 0.878.
LOCAL_WIN = 11
LOCAL_RING = (2, 4)
# ``features`` layout: the photo patch (3 per pixel), the mask patch, the class, the local
# inside colour and the share of the window it was measured on, the same outside (8), the mean
# colour inside, the mean colour outside (3 each, last).
N_FEATURES = 4 * PATCH * PATCH + len(LABELS) + 8 + 6
MASK_CENTRE = 3 * PATCH * PATCH + PATCH * PATCH // 2  # the feature holding the mask at the pixel
LOCAL = 4 * PATCH * PATCH + len(LABELS)  # where the local colours start
# Photos larger than this (longer side) are refined at this size, as ``predict`` segments
# them: the refiner was trained on renders up to 1280 px, where an edge is a pixel or two wide.
REFINE_MAX_SIZE = DEFAULT_MAX_SIZE
# A pixel outside the mask joins it at refiner probability ADD_AT; one inside leaves it only
# below KEEP_AT of its class. Removing is where renders and real photos disagree: the photos'
# hand-drawn masks are more generous at the edges than our renders' labels. With the first
# refiner, leaving at 0.3 / 0.2 / 0.1 / never gave blade IoU on the 38 real photos (first pass,
# unrefined 0.756) 0.748 / 0.751 / 0.754 / -, while on 60 development renders (unrefined
# 0.777 / 0.818 / 0.771) 0.3 gave the best tower and nacelle IoU. So blade pixels leave the
# mask only when the refiner is sure: below 0.4, the best on development renders with the
# shipped pair (200 renders, blade IoU 0.8630 / 0.8641 at 0.3 / 0.4; the refiner before it
# 0.8554 / 0.8590 / 0.8597 / 0.8570 at 0.2 / 0.3 / 0.4 / 0.5), while the real photos stay above
# their 0.75 goal (0.761 / 0.759 at 0.3 / 0.4). The threshold rose with each better network
# (0.1, 0.2, 0.3, 0.4): after training the segmenter further, retrain the refiner and choose it
# again.
ADD_AT = 0.5
KEEP_AT = {"blade": 0.4, "tower": 0.3, "nacelle": 0.3}


def _disk(r: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def band(mask: np.ndarray, r: int = BAND) -> np.ndarray:
    """Pixels within ``r`` px (square) of the boundary of ``mask``, inside or out."""
    m = mask.astype(np.uint8)
    k = np.ones((2 * r + 1, 2 * r + 1), np.uint8)
    return (cv2.dilate(m, k) > 0) & ~(cv2.erode(m, k) > 0)


def _core(mask: np.ndarray) -> np.ndarray:
    """The mask less its outermost pixels (the part's own colour, not an edge's mix), or the
    whole mask when that leaves fewer than 4 pixels."""
    core = cv2.erode(mask.astype(np.uint8), _disk(1)) > 0
    return core if core.sum() >= 4 else mask.astype(bool)


def _ring(mask: np.ndarray, r: tuple[int, int]) -> np.ndarray:
    """Pixels between r[0] (exclusive) and r[1] px (disk) outside the mask."""
    m = mask.astype(np.uint8)
    return (cv2.dilate(m, _disk(r[1])) > 0) & ~(cv2.dilate(m, _disk(r[0])) > 0)


def _colour_means(img: np.ndarray, core: np.ndarray, ring: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean colour (0..1) of the mask's core and of the ring just outside it (the core's, if
    the ring is empty)."""
    inside = img[core]
    outside = img[ring] if ring.any() else inside
    return inside.mean(axis=0) / 255.0, outside.mean(axis=0) / 255.0


def _local_means(img: np.ndarray, core: np.ndarray, ring: np.ndarray, inside: np.ndarray,
                 outside: np.ndarray, ys: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """[N, 8]: at each pixel (ys, xs), the mean colour (-1..1) of the mask's ``core`` within
    LOCAL_WIN and the share of the window that core fills, then the same for ``ring``; a
    window without any falls back to ``inside`` / ``outside`` (0..1) with share 0."""
    f = img.astype(np.float32) / 255.0
    out = []
    for sel, fallback in ((core.astype(np.float32), inside), (ring.astype(np.float32), outside)):
        share = cv2.boxFilter(sel, -1, (LOCAL_WIN, LOCAL_WIN), borderType=cv2.BORDER_CONSTANT)[ys, xs]
        num = cv2.boxFilter(f * sel[..., None], -1, (LOCAL_WIN, LOCAL_WIN),
                            borderType=cv2.BORDER_CONSTANT)[ys, xs]
        mean = np.where(share[:, None] > 1e-6, num / np.maximum(share[:, None], 1e-6), fallback[None, :])
        out += [mean * 2 - 1, share[:, None]]
    return np.concatenate(out, axis=1).astype(np.float32)


def features(img: np.ndarray, mask: np.ndarray, label: str, ys: np.ndarray, xs: np.ndarray
             ) -> np.ndarray:
    """[N, N_FEATURES] float32 features of pixels (ys, xs) of one instance (``img`` BGR uint8
    cropped around it, ``mask`` its bool mask in the same crop)."""
    h = PATCH // 2
    ip = cv2.copyMakeBorder(img, h, h, h, h, cv2.BORDER_REFLECT)
    mp = np.pad(mask, h)
    d = np.arange(-h, h + 1)
    yy = (ys[:, None, None] + h + d[None, :, None])
    xx = (xs[:, None, None] + h + d[None, None, :])
    n = len(ys)
    pix = ip[yy, xx].reshape(n, -1).astype(np.float32) / 127.5 - 1.0
    msk = mp[yy, xx].reshape(n, -1).astype(np.float32) - 0.5
    core = _core(mask)
    inside, outside = _colour_means(img, core, _ring(mask, RING))
    cls = np.zeros(len(LABELS), np.float32)
    cls[LABELS.index(label)] = 1.0
    local = _local_means(img, core, _ring(mask, LOCAL_RING), inside, outside, ys, xs)
    means = np.concatenate([inside * 2 - 1, outside * 2 - 1]).astype(np.float32)
    return np.concatenate([pix, msk, np.broadcast_to(cls, (n, len(cls))), local,
                           np.broadcast_to(means, (n, 6))], axis=1)


def instance_pixels(img: np.ndarray, mask: np.ndarray, pad: int = PATCH + RING[1]
                    ) -> tuple[tuple[int, int], np.ndarray, np.ndarray, np.ndarray] | None:
    """(crop origin (y0, x0), crop of ``img``, crop of ``mask``, band pixels [N, 2] in the
    crop) of one instance, or None for an empty mask."""
    ys, xs = np.nonzero(mask)
    if not len(ys):
        return None
    H, W = mask.shape
    y0, y1 = max(ys.min() - pad, 0), min(ys.max() + pad + 1, H)
    x0, x1 = max(xs.min() - pad, 0), min(xs.max() + pad + 1, W)
    m = mask[y0:y1, x0:x1]
    by, bx = np.nonzero(band(m))
    return (y0, x0), img[y0:y1, x0:x1], m, np.stack([by, bx], 1)


_MIRROR = np.arange(PATCH * PATCH).reshape(PATCH, PATCH)[:, ::-1].ravel()


def mirrored(f: np.ndarray) -> np.ndarray:
    """``features`` of the same pixels in the photo mirrored left to right: the patches' columns
    reversed; the class and the colour means (over symmetric windows) stay."""
    k = PATCH * PATCH
    g = f.copy()
    g[:, :3 * k] = f[:, :3 * k].reshape(len(f), k, 3)[:, _MIRROR].reshape(len(f), -1)
    g[:, 3 * k:4 * k] = f[:, 3 * k:4 * k][:, _MIRROR]
    return g



def refine_edges(probability: Callable[[np.ndarray], np.ndarray], image_bgr: np.ndarray,
                 inst: Instances, add_at: float = ADD_AT,
                 keep_at: dict[str, float] | float | None = None,
                 max_size: int | None = REFINE_MAX_SIZE) -> Instances:
    """The instances with each mask's boundary band decided by the refiner's ``probability``
    of each band pixel's ``features`` (a pixel joins at
    ``add_at``, stays above ``keep_at``: one value, or one per class, default ``KEEP_AT``); a
    mask the refinement would empty keeps its own. A photo longer than ``max_size`` is refined
    at that size and the masks scaled back."""
    keep_at = KEEP_AT if keep_at is None else keep_at
    if not len(inst):
        return inst
    image_bgr = as_bgr(image_bgr)  # grey and BGRA photos too, as the network takes them
    H, W = inst.masks.shape[1:]
    if max_size and max(H, W) > max_size:
        small_img, small = at_refine_size(image_bgr, inst, max_size)
        done = refine_edges(probability, small_img, small, add_at, keep_at, None)
        # only what the refiner changed is scaled back: the rest keeps the photo's own masks
        masks = np.stack([(m | _resize_mask(d & ~s, W, H)) & ~_resize_mask(s & ~d, W, H)
                          for m, s, d in zip(inst.masks, small.masks, done.masks)])
        empty = ~masks.reshape(len(masks), -1).any(axis=1)
        masks[empty] = inst.masks[empty]
        return Instances(inst.labels, masks, inst.scores, inst.boxes)
    masks = inst.masks.copy()
    for i in range(len(inst)):
        got = instance_pixels(image_bgr, masks[i])
        if got is None:
            continue
        (y0, x0), img, m, px = got
        if not len(px):
            continue
        p = probability(features(img, m, inst.labels[i], px[:, 0], px[:, 1]))
        new = m.copy()
        keep = keep_at[inst.labels[i]] if isinstance(keep_at, dict) else keep_at
        new[px[:, 0], px[:, 1]] = np.where(m[px[:, 0], px[:, 1]], p >= keep, p >= add_at)
        if new.any():
            masks[i, y0:y0 + m.shape[0], x0:x0 + m.shape[1]] = new
    return Instances(inst.labels, masks, inst.scores, inst.boxes)


def at_refine_size(image_bgr: np.ndarray, inst: Instances, max_size: int | None = REFINE_MAX_SIZE
                   ) -> tuple[np.ndarray, Instances]:
    """The photo and the instances as ``refine_edges`` looks at them: scaled down to ``max_size``
    px on the longer side where larger (area-averaged photo, masks by coverage), else as they are.
    ``train-refiner`` cuts its photos' training pixels at the same size."""
    H, W = image_bgr.shape[:2]
    if not max_size or max(H, W) <= max_size:
        return image_bgr, inst
    f = max_size / max(H, W)
    w, h = max(1, round(W * f)), max(1, round(H * f))
    masks = (np.stack([_resize_mask(m, w, h) for m in inst.masks]) if len(inst)
             else np.zeros((0, h, w), bool))
    return (cv2.resize(image_bgr, (w, h), interpolation=cv2.INTER_AREA),
            Instances(inst.labels, masks, inst.scores, inst.boxes * f))


def _resize_mask(mask: np.ndarray, w: int, h: int) -> np.ndarray:
    return cv2.resize(mask.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR) >= 0.5

