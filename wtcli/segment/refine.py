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

import numpy as np
import torch
from torch import nn

from wtcli.errors import ModelError
from wtcli.masks import LABELS, Instances  # noqa: F401 - LABELS as before
from wtcli.segment import edges
from wtcli.segment.model import MODELS_DIR, resolve_precision

# the features and thresholds, shared with the torch-free path (wtcli.segment.cvnet)
from wtcli.segment.edges import (ADD_AT, BAND, KEEP_AT, LOCAL, LOCAL_RING, LOCAL_WIN,  # noqa: F401
                                 MASK_CENTRE, N_FEATURES, PATCH, REFINE_MAX_SIZE, RING, _colour_means,
                                 _core, _disk, _local_means, _resize_mask, _ring, band, features,
                                 instance_pixels, mirrored)

ARCH = "wtrefine-mlp-local"
DEFAULT_REFINER = "wtseg-refine.pt"


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
    """``edges.refine_edges`` with this refiner's ``probability``: each mask's boundary band
    decided again (a pixel joins at ``add_at``, stays above ``keep_at``)."""
    return edges.refine_edges(lambda f: probability(refiner, f), image_bgr, inst, add_at, keep_at,
                              max_size)

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
