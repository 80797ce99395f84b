"""Edge refinement: each instance mask's boundary decided again, pixel by pixel, at the photo's
own resolution.

The network's masks are 28 x 28 per box, predicted from features of stride 4 and more: their
edges land a pixel or two off, which on blades a few pixels wide is most of the IoU lost
(measured on 60 development renders with an earlier network: blade IoU 0.777; the same masks
with every pixel within 1 px of their boundary set right 0.917, within 2 px 0.940). Here a
small MLP looks at each pixel within ``BAND`` px of an instance's boundary — the photo around
it (PATCH x PATCH), the mask around it, the instance's class, the mean colours inside and just
outside the instance, and the same two colours near the pixel (LOCAL_WIN) — and says whether
it belongs to the instance's class. Pixels farther from the boundary keep the network's answer.

Trained by ``wtinspect train-refiner`` (docs/train-refiner.md) on our own renders, with the
segmenter's own masks as input; weights in ``models/wtseg-refine.pt``.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from torch import nn

from wtcli.errors import ModelError
from wtcli.masks import LABELS, Instances
from wtcli.segment.defaults import DEFAULT_MAX_SIZE
from wtcli.segment.model import MODELS_DIR, resolve_precision

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
ARCH = "wtrefine-mlp-local"
DEFAULT_REFINER = "wtseg-refine.pt"
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


class Refiner(nn.Module):
    """MLP on ``features``, to which it adds each patch pixel's place between the outside and
    the inside colour (0 outside, 1 inside: the share of the part it shows, if the two are
    flat) and the contrast between them, for the instance-wide colours and the local ones:
    those hold across lighting, where raw colours do not.

    Widths 512-256 (390 657 parameters): trained on the same 600 renders (3 passes), 256-128 /
    512-256 / 1024-512 got band pixels right 0.883 / 0.894 / 0.905 and 100 development renders'
    blade IoU 0.813 / 0.816 / 0.819, but on the benchmark's 1024 x 683 speed render (14 118 band
    pixels, 2 cores) 1024-512's MLP takes 0.54 s against 512-256's 0.26 s (bf16: 0.25 / 0.14 s),
    past the speed goal."""

    def __init__(self, hidden: tuple[int, int] = (512, 256)) -> None:
        super().__init__()
        n = N_FEATURES + 2 * (PATCH * PATCH + 1)
        self.precision = "fp32"  # "bf16": ``probability`` runs the MLP under bfloat16 autocast
        self.net = nn.Sequential(nn.Linear(n, hidden[0]), nn.ReLU(), nn.Linear(*hidden),
                                 nn.ReLU(), nn.Linear(hidden[1], 1))

    @staticmethod
    def _between(pix: torch.Tensor, inside: torch.Tensor, outside: torch.Tensor) -> list[torch.Tensor]:
        d = inside - outside
        d2 = (d * d).sum(1, keepdim=True)
        alpha = (torch.einsum("nkc,nc->nk", pix, d) - (outside * d).sum(1, keepdim=True)) / (d2 + 0.01)
        return [alpha.clamp(-1, 2), d2.sqrt()]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        k = PATCH * PATCH
        pix = x[:, :3 * k].reshape(len(x), k, 3)
        extra = (self._between(pix, x[:, -6:-3], x[:, -3:])
                 + self._between(pix, x[:, LOCAL:LOCAL + 3], x[:, LOCAL + 4:LOCAL + 7]))
        return self.net(torch.cat([x, *extra], 1))[:, 0]


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


def probability(refiner: Refiner, f: np.ndarray) -> np.ndarray:
    """The refiner's probability for ``features`` ``f``: the mean of its logits on the pixels
    and on their mirror image, as the network looks at a photo and its mirror. A scene is
    left-right symmetric, not up-down (sky above, light from above): on 100 development
    renders blade / tower / nacelle IoU 0.818 / 0.876 / 0.813 alone, 0.821 / 0.879 / 0.816
    with the mirror, 0.817 / 0.878 / 0.812 with the up-down flips as well."""
    bf16 = getattr(refiner, "precision", "fp32") == "bf16"
    with torch.inference_mode(), torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
        lo = refiner(torch.from_numpy(np.concatenate([f, mirrored(f)]))).float()
    return torch.sigmoid(0.5 * (lo[:len(f)] + lo[len(f):])).numpy()


def refine_edges(refiner: Refiner, image_bgr: np.ndarray, inst: Instances, add_at: float = ADD_AT,
                 keep_at: dict[str, float] | float | None = None,
                 max_size: int | None = REFINE_MAX_SIZE) -> Instances:
    """The instances with each mask's boundary band decided by ``refiner`` (a pixel joins at
    ``add_at``, stays above ``keep_at``: one value, or one per class, default ``KEEP_AT``); a
    mask the refinement would empty keeps its own. A photo longer than ``max_size`` is refined
    at that size and the masks scaled back."""
    from wtcli.segment.bgr import as_bgr

    keep_at = KEEP_AT if keep_at is None else keep_at
    if not len(inst):
        return inst
    image_bgr = as_bgr(image_bgr)  # grey and BGRA photos too, as the network takes them
    H, W = inst.masks.shape[1:]
    if max_size and max(H, W) > max_size:
        f = max_size / max(H, W)
        w, h = max(1, round(W * f)), max(1, round(H * f))
        small = Instances(inst.labels, np.stack([_resize_mask(m, w, h) for m in inst.masks]),
                          inst.scores, inst.boxes * f)
        done = refine_edges(refiner, cv2.resize(image_bgr, (w, h), interpolation=cv2.INTER_AREA), small,
                            add_at, keep_at, None)
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
        p = probability(refiner, features(img, m, inst.labels[i], px[:, 0], px[:, 1]))
        new = m.copy()
        keep = keep_at[inst.labels[i]] if isinstance(keep_at, dict) else keep_at
        new[px[:, 0], px[:, 1]] = np.where(m[px[:, 0], px[:, 1]], p >= keep, p >= add_at)
        if new.any():
            masks[i, y0:y0 + m.shape[0], x0:x0 + m.shape[1]] = new
    return Instances(inst.labels, masks, inst.scores, inst.boxes)


def _resize_mask(mask: np.ndarray, w: int, h: int) -> np.ndarray:
    return cv2.resize(mask.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR) >= 0.5


def resolve_refiner(path: str | Path | None = None) -> Path:
    """``path`` as given, else models/DEFAULT_REFINER next to the package."""
    return Path(path) if path is not None else MODELS_DIR / DEFAULT_REFINER


_CACHE: dict[tuple, Refiner] = {}
_LOCK = threading.Lock()


def load_refiner(path: str | Path | None = None, precision: str | None = None) -> Refiner:
    """The refiner in ``path`` (default: the shipped one), on the CPU (it is small), cached.
    ``precision`` as the network's (``model.resolve_precision``: auto takes bf16 on a CPU that
    does bfloat16 natively). Raises ModelError naming the file when it is missing, unreadable
    or not a refiner."""
    prec = resolve_precision(precision, torch.device("cpu"))
    p = resolve_refiner(path)
    if not p.is_file():
        raise ModelError(f"{p}: refiner weights not found (train them with `wtinspect "
                         "train-refiner`, pass --refiner PATH, or segment with --no-refine)")
    key = (str(p.resolve()), p.stat().st_mtime_ns, prec)
    with _LOCK:
        if key in _CACHE:
            return _CACHE[key]
        try:
            blob = torch.load(p, map_location="cpu", weights_only=True)
        except Exception as e:  # noqa: BLE001 - any failure to unpickle means a bad file
            raise ModelError(f"{p}: not a readable refiner file ({e.__class__.__name__})") from None
        if not isinstance(blob, dict) or blob.get("arch") != ARCH:
            got = blob.get("arch") if isinstance(blob, dict) else type(blob).__name__
            hint = ("; an earlier wtinspect's refiner: train one anew with `wtinspect train-refiner`"
                    if isinstance(got, str) and got.startswith("wtrefine") else "")
            raise ModelError(f"{p}: not refiner weights of architecture {ARCH!r} (found {got!r}){hint}")
        hidden = blob.get("hidden", (256, 128))
        if not isinstance(hidden, (list, tuple)) or not 1 <= len(hidden) <= 8 or not all(
                isinstance(h, int) and 1 <= h <= 8192 for h in hidden):  # sized before allocating
            raise ModelError(f"{p}: refiner layer widths {str(hidden)[:80]} are not 1..8192")
        ref = Refiner(tuple(hidden))
        try:
            ref.load_state_dict({k: v.float() for k, v in blob["state_dict"].items()})
        except (RuntimeError, KeyError, AttributeError) as e:
            raise ModelError(f"{p}: refiner weights do not fit ({str(e).splitlines()[0][:160]})") from None
        if not all(torch.isfinite(v).all() for v in ref.state_dict().values() if v.is_floating_point()):
            raise ModelError(f"{p}: refiner weights are corrupt (NaN or infinite values)")
        ref.eval()
        ref.precision = prec
        ref.meta = blob.get("meta", {}) if isinstance(blob.get("meta"), dict) else {}
        _CACHE[key] = ref
        return ref


def save_refiner(refiner: Refiner, path: str | Path, meta: dict[str, Any] | None = None) -> Path:
    """{"arch", "hidden", "state_dict" (float32: the file is ~1.6 MB at 512-256), "meta"},
    atomically."""
    import io

    from wtcli.jsonio import atomic_write_bytes

    hidden = (refiner.net[0].out_features, refiner.net[2].out_features)
    buf = io.BytesIO()
    torch.save({"arch": ARCH, "hidden": list(hidden), "state_dict": refiner.state_dict(),
                "meta": dict(meta or {})}, buf)
    return atomic_write_bytes(path, buf.getvalue())
