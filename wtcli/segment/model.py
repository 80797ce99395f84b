"""The segmentation model: a slim torchvision Mask R-CNN for blade, tower and nacelle.

Two steps, never one (STYLE.md 5): ``build_model()`` makes the network with no weights at all
(``weights=None``, nothing is downloaded), ``load_weights()`` fills it from a file in
``models/`` with ``torch.load(..., weights_only=True)``. Tests build the model without weights
and check the output contract.

Architecture (chosen by measuring on 2 CPU cores, see models/README.md): a ResNet-18 trunk
whose last stage is slimmed to 256 channels, a 128-channel FPN on strides 8/16/32 (+ pooled 64),
a box head of two 256-unit layers, and a mask head of two 128-channel convs that pools the
boxes of the stride-8 level from a fine stride-4 level instead (``_Backbone``). Plain
BatchNorm in the trunk (trained from scratch, two images a batch). About 8 M parameters; the
shipped file stores them as float16 (cast back to float32 on load).
"""

from __future__ import annotations

import sys
import types
from pathlib import Path
from typing import Any

import torch
from torch import nn


def _import_torchvision() -> None:
    """Import torchvision without importing ``torch._dynamo`` (the compiler), about 1 s of the
    1.2 s torchvision takes on the 2-core CPU, more than the network's forward pass.

    Only ``torchvision.ops.roi_align`` asks for it at import time, for one function
    (``is_compile_supported``) it calls only on a path this model never takes. While
    torchvision is imported, that module is a stand-in whose function imports the real one on
    its first call; then the stand-in is removed, so ``torch._dynamo`` imports as usual later.
    If torchvision asks for anything else of it, it is imported the ordinary way."""
    if "torchvision" in sys.modules or "torch._dynamo" in sys.modules:
        return

    def is_compile_supported(device_type):
        from torch._dynamo.utils import is_compile_supported as real

        return real(device_type)

    pkg, utils = types.ModuleType("torch._dynamo"), types.ModuleType("torch._dynamo.utils")
    utils.is_compile_supported = is_compile_supported
    pkg.__path__ = []  # a package, so the import system looks no further
    pkg.utils = utils
    sys.modules.update({"torch._dynamo": pkg, "torch._dynamo.utils": utils})
    try:
        import torchvision.models.detection  # noqa: F401 - the modules this file uses
        import torchvision.ops  # noqa: F401
    except (ImportError, AttributeError):  # a torchvision that needs more: the ordinary way
        for name in [n for n in sys.modules if n == "torchvision" or n.startswith("torchvision.")]:
            del sys.modules[name]
    finally:
        for name, stand_in in (("torch._dynamo.utils", utils), ("torch._dynamo", pkg)):
            if sys.modules.get(name) is stand_in:
                del sys.modules[name]
        if torch.__dict__.get("_dynamo") is pkg:  # set by the import system on the parent
            del torch._dynamo


_import_torchvision()

from torchvision.models import resnet18  # noqa: E402 - after _import_torchvision
from torchvision.models._utils import IntermediateLayerGetter  # noqa: E402
from torchvision.models.detection import MaskRCNN  # noqa: E402
from torchvision.models.detection.anchor_utils import AnchorGenerator  # noqa: E402
from torchvision.models.detection.faster_rcnn import FastRCNNPredictor, TwoMLPHead  # noqa: E402
from torchvision.models.detection.mask_rcnn import MaskRCNNHeads, MaskRCNNPredictor  # noqa: E402
from torchvision.models.detection.roi_heads import RoIHeads  # noqa: E402
from torchvision.models.detection.rpn import RegionProposalNetwork, RPNHead  # noqa: E402
from torchvision.models.detection.transform import GeneralizedRCNNTransform, resize_boxes  # noqa: E402
from torchvision.models.resnet import BasicBlock  # noqa: E402
from torchvision.ops import MultiScaleRoIAlign  # noqa: E402
from torchvision.ops.feature_pyramid_network import FeaturePyramidNetwork, LastLevelMaxPool  # noqa: E402
from torchvision.ops.poolers import _multiscale_roi_align, _setup_scales  # noqa: E402

from wtcli.errors import ModelError  # noqa: E402
from wtcli.masks import LABELS  # noqa: E402

ARCH = "wtseg-r18s-fpn128-p2"
# Files of the architecture before the fine level: they load with that level's branch at zero,
# which is exactly the network they were trained as (see _Backbone).
ARCH_BEFORE_P2 = "wtseg-r18s-fpn128"
NUM_CLASSES = len(LABELS) + 1  # + background; class ids 1..3 follow wtcli.masks.LABELS
MODELS_DIR = Path(__file__).resolve().parents[2] / "models"
DEFAULT_WEIGHTS = "wtseg-r18s.pt"

# Image size the network works at (GeneralizedRCNNTransform resizes inside the model):
# shorter side INFER_MIN_SIZE, longer side at most INFER_MAX_SIZE (16:9 frames keep the scale:
# 1024 x 576, not 768 x 432). 576 is above the training sizes on purpose: a 640 x 480 render is
# upscaled 1.2x, so thin blades span more feature cells. On 400 development renders (seeds
# 7 000 000 +, the network of 2026-12-01) against 480: blade / tower / nacelle IoU 0.686 / 0.815 /
# 0.687 -> 0.696 / 0.833 / 0.708, right blade count 94.2 -> 95.3 %, theta error 1.48 -> 1.39 deg;
# 528 and 624 were no better than 480 on count and theta (docs/segment.md). Cost: 1.34x the time.
INFER_MIN_SIZE = 576
INFER_MAX_SIZE = 1024
TRAIN_MIN_SIZES = (320, 352, 384, 416)
TRAIN_MAX_SIZE = 555
FPN_CHANNELS = 128
FINE = "p2"  # the stride-4 level's name among the backbone's features (mask head only)


def _trunk() -> nn.Module:
    r = resnet18(weights=None)  # plain BatchNorm2d, random init: nothing downloaded
    r.inplanes = 256
    r.layer4 = r._make_layer(BasicBlock, 256, 2, stride=2)  # slim last stage (8.4 M -> 2.4 M)
    r.fc = nn.Identity()
    return r


def _upsample2(x: torch.Tensor) -> torch.Tensor:
    """x at twice the resolution, cell j of the result at cell j / 2 of ``x`` (linear between,
    the last row and column repeated). That is RoIAlign's own convention (aligned=False: cell i
    at i x stride), so RoIAlign on the result at scale 2s samples exactly what it samples on
    ``x`` at scale s — unlike ``interpolate(..., align_corners=False)``, a quarter-cell shift."""
    h, w = x.shape[-2:]
    y = torch.nn.functional.interpolate(x, size=(2 * h - 1, 2 * w - 1), mode="bilinear",
                                        align_corners=True)
    return torch.nn.functional.pad(y, (0, 1, 0, 1), mode="replicate")


class _Backbone(nn.Module):
    """Trunk + FPN on strides 8/16/32 (+ pooled 64), as torchvision's BackboneWithFPN (same
    parameter names), plus a fine level "p2" at stride 4 for the mask head only: the stride-8
    level upsampled, plus the trunk's stride-4 features through a small branch whose last conv
    starts at zero. Blades are mostly 2-5 px wide at 640 x 480 (instance IoU 0.42 below 3 px,
    0.85 above 12 px, measured before this level existed): at stride 8 a blade's edges fall
    inside one feature cell."""

    def __init__(self, trunk: nn.Module):
        super().__init__()
        self.body = IntermediateLayerGetter(trunk, {"layer1": "c2", "layer2": "0", "layer3": "1",
                                                    "layer4": "2"})
        self.fpn = FeaturePyramidNetwork([128, 256, 256], FPN_CHANNELS, extra_blocks=LastLevelMaxPool())
        self.fine = nn.Sequential(nn.Conv2d(64, 64, 3, padding=1), nn.ReLU(inplace=True),
                                  nn.Conv2d(64, FPN_CHANNELS, 1))
        nn.init.zeros_(self.fine[2].weight)
        nn.init.zeros_(self.fine[2].bias)
        self.out_channels = FPN_CHANNELS

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        c = self.body(x)
        c2 = c.pop("c2")
        feats = self.fpn(c)
        feats[FINE] = _upsample2(feats["0"]) + self.fine(c2)
        return feats


IGNORE_OVERLAP = 0.5  # a box this much (of its own area) inside a target's ignore box teaches nothing


def _in_ignored(boxes: torch.Tensor, ignore: torch.Tensor | None) -> torch.Tensor:
    """(N,) bool: boxes with at least IGNORE_OVERLAP of their area inside one ignore box."""
    if ignore is None or not len(ignore) or not len(boxes):
        return torch.zeros(len(boxes), dtype=torch.bool, device=boxes.device)
    ignore = ignore.to(boxes)
    lt = torch.maximum(boxes[:, None, :2], ignore[None, :, :2])
    rb = torch.minimum(boxes[:, None, 2:], ignore[None, :, 2:])
    inter = (rb - lt).clamp(min=0).prod(dim=2)
    area = (boxes[:, 2:] - boxes[:, :2]).clamp(min=1e-6).prod(dim=1)
    return (inter / area[:, None] >= IGNORE_OVERLAP).any(dim=1)


class _CoarseRPN(RegionProposalNetwork):
    """The RPN of torchvision, on the FPN's levels without the fine one (which only the mask
    head pools from: proposals and anchors stay as trained). In training, anchors that would be
    background inside a target's ``ignore_boxes`` (``data.Sample.ignore``) are left out."""

    def forward(self, images, features, targets=None):
        return super().forward(images, {k: v for k, v in features.items() if k != FINE}, targets)

    def assign_targets_to_anchors(self, anchors, targets):
        labels, matched = super().assign_targets_to_anchors(anchors, targets)
        for a, lab, t in zip(anchors, labels, targets):
            lab[(lab == 0) & _in_ignored(a, t.get("ignore_boxes"))] = -1.0
        return labels, matched


class _IgnoringRoIHeads(RoIHeads):
    """torchvision's RoI heads, except that in training a proposal that would be background
    inside a target's ``ignore_boxes`` is never sampled (label -1, as between the thresholds)."""

    def select_training_samples(self, proposals, targets):
        self._ignore = [t.get("ignore_boxes") for t in targets] if targets is not None else None
        try:
            return super().select_training_samples(proposals, targets)
        finally:
            self._ignore = None

    def assign_targets_to_proposals(self, proposals, gt_boxes, gt_labels):
        matched, labels = super().assign_targets_to_proposals(proposals, gt_boxes, gt_labels)
        ignore = getattr(self, "_ignore", None)
        if ignore is not None:
            for p, lab, ig in zip(proposals, labels, ignore):
                lab[(lab == 0) & _in_ignored(p, ig)] = -1
        return matched, labels


class _FineMaskPool(MultiScaleRoIAlign):
    """torchvision's multi-scale RoIAlign with its level choice unchanged (by box size, over
    strides 8/16/32), except that boxes of the stride-8 level pool from the stride-4 one."""

    def forward(self, x, boxes, image_shapes):
        feats = [x[n] for n in self.featmap_names]
        if self.scales is None or self.map_levels is None:
            self.scales, self.map_levels = _setup_scales(feats, image_shapes, self.canonical_scale,
                                                         self.canonical_level)
        feats[0] = x[FINE]
        scales = [self.scales[0] * 2] + list(self.scales[1:])
        return _multiscale_roi_align(feats, boxes, self.output_size, self.sampling_ratio, scales,
                                     self.map_levels)


class _Transform(GeneralizedRCNNTransform):
    """torchvision's resize and normalisation, except that training masks are resized by
    area (antialiased bilinear, then >= 0.5), not nearest neighbour. Nearest shifts a
    downscaled mask by up to half a pixel against its image — on a blade a few pixels wide
    that is a fifth of it, and the mask head then learns blurred edges."""

    def resize(self, image, target=None):
        masks = target.pop("masks") if target is not None and "masks" in target else None
        h, w = image.shape[-2:]
        image, target = super().resize(image, target)
        if target is not None and "ignore_boxes" in target:
            target["ignore_boxes"] = resize_boxes(target["ignore_boxes"], (h, w), image.shape[-2:])
        if masks is not None:
            size = image.shape[-2:]
            if masks.shape[-2:] != size:
                masks = torch.nn.functional.interpolate(
                    masks[:, None].float(), size=tuple(size), mode="bilinear", align_corners=False,
                    antialias=True)[:, 0].ge(0.5).byte() if len(masks) else \
                    masks.new_zeros((0, *size))
            target["masks"] = masks
        return image, target


def build_model(detections_per_img: int = 20) -> MaskRCNN:
    """The network with random weights (no download). Call ``load_weights`` to make it useful."""
    backbone = _Backbone(_trunk())
    # Blades are long and thin: tall and wide anchors beside square ones; 9 per location.
    anchors = AnchorGenerator(sizes=((16, 24, 32), (32, 48, 64), (64, 96, 128), (128, 192, 320)),
                              aspect_ratios=((0.33, 1.0, 3.0),) * 4)
    names = ["0", "1", "2"]  # RoIAlign on strides 8/16/32 (the pooled level feeds the RPN only)
    model = MaskRCNN(
        backbone, num_classes=None,
        min_size=INFER_MIN_SIZE, max_size=INFER_MAX_SIZE,
        rpn_anchor_generator=anchors,
        rpn_head=RPNHead(FPN_CHANNELS, anchors.num_anchors_per_location()[0]),
        rpn_pre_nms_top_n_train=600, rpn_post_nms_top_n_train=300,
        rpn_pre_nms_top_n_test=300, rpn_post_nms_top_n_test=100,
        rpn_batch_size_per_image=128,
        box_roi_pool=MultiScaleRoIAlign(names, 7, 2),
        box_head=TwoMLPHead(FPN_CHANNELS * 7 * 7, 256),
        box_predictor=FastRCNNPredictor(256, NUM_CLASSES),
        box_batch_size_per_image=128, box_detections_per_img=detections_per_img,
        box_score_thresh=0.05,
        mask_roi_pool=_FineMaskPool(names, 14, 2),
        mask_head=MaskRCNNHeads(FPN_CHANNELS, [128, 128], 1),
        mask_predictor=MaskRCNNPredictor(128, 128, NUM_CLASSES),
    )
    model.rpn.__class__ = _CoarseRPN  # same RPN, same parameters; only the levels it sees
    model.roi_heads.__class__ = _IgnoringRoIHeads  # same heads; only what training samples
    t = model.transform
    model.transform = _Transform(t.min_size, t.max_size, t.image_mean, t.image_std)
    return model


def set_train_sizes(model: MaskRCNN, min_sizes=TRAIN_MIN_SIZES, max_size: int = TRAIN_MAX_SIZE) -> None:
    """Multi-scale training: GeneralizedRCNNTransform picks one of ``min_sizes`` per batch."""
    model.transform.min_size = tuple(int(s) for s in min_sizes)
    model.transform.max_size = int(max_size)


def set_infer_size(model: MaskRCNN, min_size: int = INFER_MIN_SIZE, max_size: int = INFER_MAX_SIZE) -> None:
    model.transform.min_size = (int(min_size),)
    model.transform.max_size = int(max_size)


def state_dict_fp16(model: nn.Module) -> dict[str, torch.Tensor]:
    """Float tensors cast to float16 (half the file); BN counters stay integer."""
    return {k: (v.detach().to(torch.float16) if v.is_floating_point() else v.detach()).cpu()
            for k, v in model.state_dict().items()}


def save_weights(model: nn.Module, path: str | Path, meta: dict[str, Any] | None = None) -> Path:
    """Write the shipped-weights format: {"arch", "state_dict" (fp16), "meta"}."""
    from wtcli.jsonio import atomic_write_bytes
    import io

    buf = io.BytesIO()
    torch.save({"arch": ARCH, "state_dict": state_dict_fp16(model), "meta": dict(meta or {})}, buf)
    return atomic_write_bytes(path, buf.getvalue())


def average_weights(paths: list[str | Path], out: str | Path) -> Path:
    """The element-wise mean of weights files of this architecture (float tensors averaged in
    float32, saved as float16; integer ones, BatchNorm's counters, from the first file), with
    the first file's meta plus ``weight_average``: the files it is the mean of.

    Two runs of one lineage averaged can beat both: two of the shipped model's ancestors were
    such means, each keeping most of the newer run's gain on the renders and better than either
    run on the real photos (docs/train.md)."""
    if len(paths) < 2:
        raise ModelError("expected at least two weights files to average")
    models, metas = [], []
    for path in paths:
        models.append(build_model())
        metas.append(load_weights(models[-1], path))  # checks each file as segment would
    mean = models[0]
    with torch.no_grad():  # state_dict() tensors share the parameters' storage
        for k, v in mean.state_dict().items():
            if v.is_floating_point():
                v.copy_(torch.stack([m.state_dict()[k] for m in models]).mean(0))
    meta = dict(metas[0])
    meta["weight_average"] = [str(p) for p in paths]
    return save_weights(mean, out, meta)


def resolve_weights(path: str | Path | None = None) -> Path:
    """``path`` as given, else $WTINSPECT_MODEL, else models/DEFAULT_WEIGHTS next to the package."""
    import os

    if path is not None:
        return Path(path)
    env = os.environ.get("WTINSPECT_MODEL")
    if env:
        return Path(env)
    return MODELS_DIR / DEFAULT_WEIGHTS


MIRROR_SUFFIX = ".mirror.pt"


def mirror_weights(path: str | Path) -> Path | None:
    """The network that reads the mirror pass of the weights file ``path``: ``NAME.mirror.pt``
    beside ``NAME.pt`` when there is one (e.g. a second training of the same recipe, another
    seed: the two passes then average two networks, not one network twice; docs/segment.md,
    "A second network on the mirror pass"), else None. A ``.mirror.pt`` file itself has none."""
    p = Path(path)
    if p.suffix != ".pt" or p.name.endswith(MIRROR_SUFFIX):
        return None
    m = p.with_name(p.name[: -len(".pt")] + MIRROR_SUFFIX)
    return m if m.is_file() else None


def load_weights(model: nn.Module, path: str | Path | None = None) -> dict[str, Any]:
    """Fill ``model`` from a weights file (ours, or a training checkpoint); return its meta.

    Raises ModelError naming the file when it is missing, unreadable, not ours or mismatched."""
    p = resolve_weights(path)
    if not p.is_file():
        raise ModelError(f"{p}: model weights not found (train one with `wtinspect train`, or "
                         "pass --model PATH / set WTINSPECT_MODEL)")
    try:
        blob = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001 - any failure to unpickle means a bad file
        raise ModelError(f"{p}: {_load_failure(e)}") from None
    if not isinstance(blob, dict):
        raise ModelError(f"{p}: expected a dict with 'state_dict', got {type(blob).__name__}")
    state = blob.get("state_dict", blob.get("model"))
    arch = blob.get("arch", ARCH)
    if arch not in (ARCH, ARCH_BEFORE_P2):
        raise ModelError(f"{p}: weights are for architecture {arch!r}, this wtinspect builds {ARCH!r}")
    if not isinstance(state, dict):
        raise ModelError(f"{p}: no 'state_dict' in the file")
    for k, v in state.items():
        if not isinstance(v, torch.Tensor):
            raise ModelError(f"{p}: state_dict entry {str(k)[:80]!r} is not a tensor")
        # NaN or infinite weights load and run, but every score is NaN: no instance survives and
        # every photo would come out "ok" with nothing found.
        if v.is_floating_point() and not torch.isfinite(v).all():
            raise ModelError(f"{p}: weights are corrupt: {str(k)[:80]!r} holds NaN or infinite values")
    ref = model.state_dict()
    state = {k: (v.to(ref[k].dtype) if k in ref and v.is_floating_point() else v)
             for k, v in state.items()}
    try:
        if arch == ARCH_BEFORE_P2:  # the fine branch set to zero: the network as trained
            missing, unexpected = model.load_state_dict(state, strict=False)
            if unexpected or any(not k.startswith("backbone.fine.") for k in missing):
                model.load_state_dict(state, strict=True)  # raises, naming the keys
            last = model.backbone.fine[-1]
            nn.init.zeros_(last.weight)
            nn.init.zeros_(last.bias)
        else:
            model.load_state_dict(state, strict=True)
    except RuntimeError as e:
        first = str(e).splitlines()[0:2]
        raise ModelError(f"{p}: weights do not fit the model ({' '.join(first)[:200]})") from None
    meta = blob.get("meta", {})
    return meta if isinstance(meta, dict) else {}


def _load_failure(e: Exception) -> str:
    """Why ``torch.load`` refused a file, in one whole sentence. torch's refusal of a pickle
    holding code goes on to explain how to turn that safety off; the cut first line of it read
    like advice to do so, so that case gets our own words."""
    text = " ".join(str(e).split())
    if "Weights only load failed" in text or "weights_only" in text:
        return ("refused: the file holds Python objects besides tensors, which could run code "
                "when loaded; only weights files saved by wtinspect are loaded")
    first = text.split(". ")[0].rstrip(".")
    if len(first) > 160:
        first = first[:157] + "..."
    return f"not a readable weights file ({e.__class__.__name__}: {first or 'corrupt'})"


PRECISIONS = ("auto", "fp32", "bf16")


def resolve_precision(asked: str | None, device: torch.device) -> str:
    """The precision the network computes in: "bf16" (``backbone_in_bf16``) or "fp32".
    "auto"/None takes bf16 on a CPU that does bfloat16 natively (AVX-512 BF16 or AMX: a training
    step 1.5x faster on this project's 2-core AMD EPYC, inference as accurate) and fp32
    elsewhere (emulated bf16 is slower; GPUs keep the precision the shipped runs were checked
    with)."""
    if asked not in (None, "auto"):
        if asked not in PRECISIONS:
            raise ModelError(f"unknown precision {asked!r}; expected one of {', '.join(PRECISIONS)}")
        return asked
    if device.type == "cpu" and torch.backends.mkldnn.is_available():
        try:
            return "bf16" if torch.ops.mkldnn._is_mkldnn_bf16_supported() else "fp32"
        except (AttributeError, RuntimeError):
            return "fp32"
    return "fp32"


def backbone_in_bf16(model: MaskRCNN, on: bool = True) -> None:
    """Run the trunk and FPN (most of the arithmetic) under bfloat16 autocast and hand float32
    features to the heads (``on=False``: plain float32 again). Only the backbone: with the whole
    network under autocast, box coordinates were bfloat16 too (8-bit mantissa, a few pixels at
    500 px), which made degenerate proposals and a NaN box loss on the first training step."""
    model.backbone.__dict__.pop("forward", None)
    if not on:
        return
    plain = model.backbone.forward

    def forward(x):
        with torch.autocast(x.device.type, dtype=torch.bfloat16):
            feats = plain(x)
        return type(feats)((k, v.float()) for k, v in feats.items())

    model.backbone.forward = forward


def pick_device(device: str | None = None) -> torch.device:
    """'auto'/None: CUDA when available, else CPU. Anything else goes to torch.device."""
    if device in (None, "", "auto"):
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        dev = torch.device(device)
    except RuntimeError as e:
        raise ModelError(f"unknown device {device!r} ({e})") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ModelError(f"device {device!r} asked for but no CUDA GPU is available")
    return dev
