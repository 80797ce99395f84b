"""Run the segmenter on one image: BGR uint8 [H, W, 3] in, ``wtcli.masks.Instances`` out.

Large photos (a 5472x3648 drone frame) are first downscaled so their longer side is at most
``max_size`` (the network itself works at 576 px high, see ``wtcli.segment.model``); each
predicted M x M box mask is then pasted straight into the ORIGINAL image size (``paste_mask``)
and thresholded, so masks, boxes and the background-removed image line up with the
photo. Masks are pasted one instance at a time, into their box only, and cut at
``MASK_THRESHOLD`` of their class. With ``flip`` (the default) the photo and its mirror image
are detected together: proposals, class scores, boxes and masks of both passes averaged
(``_detect_both``), the mirror read by a second network where the weights have one beside them
(``NAME.mirror.pt``) or one is named.
"""

from __future__ import annotations

import copy
import threading
from pathlib import Path

import cv2
import numpy as np
import torch

# model first: it imports torchvision the quick way (model._import_torchvision)
from wtcli.segment.model import (backbone_in_bf16, build_model, load_weights, mirror_weights,
                                 pick_device, resolve_precision, resolve_weights, set_infer_size)
from torchvision.models.detection.image_list import ImageList  # noqa: I001
from torchvision.ops import boxes as box_ops

from wtcli.errors import ModelError
from wtcli.masks import Instances
from wtcli.segment import post
from wtcli.segment.data import image_tensor
from wtcli.segment.defaults import CANDIDATE_FLOOR, DEFAULT_MAX_SIZE, DEFAULT_SCORE_THRESHOLD
# shared with the torch-free path (wtcli.segment.cvnet); the names stay importable from here
from wtcli.segment.post import (DUPLICATE_INSIDE, MASK_OFFSET_PX, MASK_THRESHOLD,  # noqa: F401
                                MIRROR_BOX_SHIFT_PX, SMALL_TURBINE, WIDE_SIZE, ZOOM_MAX, ZOOM_MIN_CROP,
                                ZOOM_PAD,
                                _turbine_groups, drop_duplicate_blades, instances, paste_mask,
                                working_image)


_CACHE: dict[tuple, torch.nn.Module] = {}
_LOCK = threading.RLock()  # re-entered: a network loads its mirror partner


def load_model(weights: str | Path | None = None, device: str | torch.device | None = None,
               precision: str | None = None, mirror: str | Path | None = "auto"):
    """Build the network and load weights (default: the shipped ``models/`` file); cached per
    (path, device, precision, mirror), so a batch or a chained command loads it once.
    ``precision``: auto (None) | fp32 | bf16 (``model.resolve_precision``); the model's
    ``precision`` says which it runs in. ``mirror``: the network that reads the mirror pass
    (``_detect_both``): "auto", the weights' ``NAME.mirror.pt`` when there is one
    (``model.mirror_weights``); None or "none", the same network; or a weights file. The
    model's ``mirror_partner`` is that network (None: itself), ``mirror_weights`` its file."""
    dev = device if isinstance(device, torch.device) else pick_device(device)
    prec = resolve_precision(precision, dev)
    path = resolve_weights(weights)
    if isinstance(mirror, str) and mirror in ("auto", "none"):
        partner = mirror_weights(path) if mirror == "auto" else None
    else:
        partner = None if mirror is None else Path(mirror)
    key = (_file_key(path), str(dev), prec, None if partner is None else _file_key(partner))
    with _LOCK:
        if key not in _CACHE:
            model = build_model()
            meta = load_weights(model, path)
            # Where mask cells sit in their box depends on how the weights were trained
            # (see paste_mask); files from before that was recorded are offset 0.
            model.mask_offset_px = float(meta.get("mask_offset_px", 0.0))
            model.meta = meta  # how the file was trained (e.g. which real photos it learned)
            set_infer_size(model)
            model.eval().to(dev)
            backbone_in_bf16(model, prec == "bf16")
            model.precision = prec
            model.mirror_partner, model.mirror_weights = None, None
            if partner is not None:
                other = load_model(partner, dev, prec, mirror=None)
                if other.mask_offset_px != model.mask_offset_px:  # the two passes' masks are averaged
                    raise ModelError(f"{partner}: its masks sit {other.mask_offset_px} px in their "
                                     f"box, {path}'s {model.mask_offset_px} px: not a mirror partner "
                                     "for it")
                model.mirror_partner, model.mirror_weights = other, str(partner)
            _CACHE[key] = model
        return _CACHE[key]


def _file_key(path: Path) -> tuple:
    return (str(path.resolve()) if path.exists() else str(path),
            path.stat().st_mtime_ns if path.is_file() else None)


def _device_of(model: torch.nn.Module) -> torch.device:
    return next(model.parameters()).device


def predict(model: torch.nn.Module, image_bgr: np.ndarray, score_threshold: float = DEFAULT_SCORE_THRESHOLD,
            max_size: int | None = DEFAULT_MAX_SIZE, device=None, flip: bool = True,
            size: tuple[int, int] | None = None) -> Instances:
    """Instances (labels, masks at the image's size, scores, boxes xyxy) with score >= threshold.

    ``flip``: detect the photo and its mirror image together (``_detect_both``); about 2 x
    the time. On 300 development renders (an earlier model, second look) blade / tower /
    nacelle IoU 0.757 / 0.855 / 0.768 without -> 0.774 / 0.867 / 0.778 with. ``size``: the
    network's working size (shorter side, longer side at most) instead of its own."""
    img, H, W = working_image(image_bgr, score_threshold, max_size)
    dev = _device_of(model) if device is None else torch.device(device)
    model.eval()
    with torch.inference_mode():
        det, hw = _detect(model, image_tensor(img).to(dev), flip, size)
    return instances(det["scores"].float().cpu().numpy(), det["labels"].cpu().numpy(),
                     det["masks"][:, 0].float().cpu().numpy(), det["boxes"].float().cpu().numpy(),
                     hw, H, W, score_threshold, float(getattr(model, "mask_offset_px", MASK_OFFSET_PX)))


def _detect(model, x: torch.Tensor, flip: bool = False, size: tuple[int, int] | None = None
            ) -> tuple[dict, tuple[int, int]]:
    """The network's detections for one image tensor, in the network's working size
    (image resized by its transform, or to ``size``), with the masks still M x M per box:
    torchvision's own postprocess pastes them half a pixel to a pixel off (see
    ``paste_mask``). ``flip``: the photo and its mirror image detected together
    (``_detect_both``)."""
    transform = model.transform
    if size is not None:  # a copy: the cached model is shared between threads
        transform = copy.copy(transform)
        transform.min_size, transform.max_size = (int(size[0]),), int(size[1])
    images, _ = transform([x])
    feats = model.backbone(images.tensors)
    if flip:
        return _detect_both(model, images, feats), tuple(images.image_sizes[0])
    proposals, _ = model.rpn(images, feats)
    det, _ = model.roi_heads(feats, proposals, images.image_sizes)
    return det[0], tuple(images.image_sizes[0])


def mirror_boxes(boxes: torch.Tensor, width: int) -> torch.Tensor:
    """Boxes (xyxy, pixel edges at integers) of a ``width``-wide tensor as the heads must pool
    them in the mirrored tensor: mirrored, then moved one pixel left. RoIAlign (aligned=False,
    as both heads pool) samples a box half a pixel right of its frame; in the mirror image
    that is half a pixel left of the plain pass's, so without the move the mirrored masks land
    a pixel off (on 60 development renders blade IoU 0.750 instead of 0.767)."""
    out = boxes.clone()
    out[:, 0] = width - boxes[:, 2] - 1
    out[:, 2] = width - boxes[:, 0] - 1
    return out


def unmirror_boxes(boxes: torch.Tensor, width: int) -> torch.Tensor:
    """Boxes (..., 4) the box head found in the mirrored ``width``-wide tensor, in the photo's
    frame: mirrored back and moved half a pixel left. Measured: the box head regressing from
    the true boxes of 40 development renders (an earlier model) reads them 0.46 px right of the truth
    (median) in the mirrored pass with the plain mirror, 0.0 in the plain pass."""
    out = boxes.clone()
    out[..., 0] = width - MIRROR_BOX_SHIFT_PX - boxes[..., 2]
    out[..., 2] = width - MIRROR_BOX_SHIFT_PX - boxes[..., 0]
    return out


def _detect_both(model, images, feats: dict) -> dict:
    """Detections of the photo and its mirror image together: the region proposals of both
    passes (those of the mirror mirrored back), each scored and regressed by the box head in
    both passes and the two averaged (class probabilities; boxes, the mirror's mirrored back),
    then torchvision's selection (score floor, per-class NMS, the best
    ``detections_per_img``); each kept box's mask is the mean of both passes' masks. The
    mirror is read by the model's ``mirror_partner`` where it has one (``load_model``).

    A detection one pass scores low is kept when the other scores it well, and the two passes'
    pixel jitter on thin blades partly cancels. On 300 development renders
    (an earlier model, second look) blade / tower / nacelle IoU 0.767 / 0.862 / 0.779 with the masks
    alone averaged -> 0.774 / 0.867 / 0.778; on the real photos blade 0.707 -> 0.719."""
    rh = model.roi_heads
    T = images.tensors.flip(-1)
    W = T.shape[-1]
    h, w = images.image_sizes[0]
    other = getattr(model, "mirror_partner", None) or model  # the network reading the mirror
    feats_m = other.backbone(T)
    # The padded tensor's photo sits at its right in the mirror: the mirror's "image" is the
    # whole width, and proposals starting in the padding are dropped once mirrored back.
    mirror_size = [(h, W)]
    p_plain = model.rpn(images, feats)[0][0]
    p_mirror = other.rpn(ImageList(T, mirror_size), feats_m)[0][0]
    # Proposals are mirrored back exactly: they only need to be near, the box head refines them.
    p_mirror = torch.stack([W - p_mirror[:, 2], p_mirror[:, 1], W - p_mirror[:, 0], p_mirror[:, 3]], 1)
    proposals = box_ops.clip_boxes_to_image(
        torch.cat([p_plain, p_mirror[p_mirror[:, 0] < w - 1]]), (h, w))
    prob, boxes = _box_head(model, feats, proposals, images.image_sizes)
    prob_m, boxes_m = _box_head(other, feats_m, mirror_boxes(proposals, W), mirror_size)
    prob = 0.5 * (prob + prob_m)
    boxes = 0.5 * (boxes + unmirror_boxes(boxes_m, W))
    # torchvision's RoIHeads.postprocess_detections from here on, on the averaged values
    C = prob.shape[-1]
    boxes = box_ops.clip_boxes_to_image(boxes.reshape(-1, 4), (h, w)).reshape(-1, C, 4)
    labels = torch.arange(C, device=prob.device).view(1, -1).expand_as(prob)
    boxes, scores, labels = boxes[:, 1:].reshape(-1, 4), prob[:, 1:].reshape(-1), labels[:, 1:].reshape(-1)
    keep = torch.where(scores > rh.score_thresh)[0]
    boxes, scores, labels = boxes[keep], scores[keep], labels[keep]
    keep = box_ops.remove_small_boxes(boxes, min_size=1e-2)
    boxes, scores, labels = boxes[keep], scores[keep], labels[keep]
    keep = box_ops.batched_nms(boxes, scores, labels, rh.nms_thresh)[: rh.detections_per_img]
    boxes, scores, labels = boxes[keep], scores[keep], labels[keep]
    masks = 0.5 * (_mask_probs(model, feats, boxes, labels, images.image_sizes)
                   + _mask_probs(other, feats_m, mirror_boxes(boxes, W), labels, mirror_size).flip(-1))
    return {"boxes": boxes, "labels": labels, "scores": scores, "masks": masks[:, None]}


def _box_head(model, feats: dict, proposals: torch.Tensor, sizes) -> tuple[torch.Tensor, torch.Tensor]:
    """(N, C) class probabilities and (N, C, 4) decoded boxes of the proposals."""
    rh = model.roi_heads
    logits, deltas = rh.box_predictor(rh.box_head(rh.box_roi_pool(feats, [proposals], sizes)))
    return torch.softmax(logits.float(), -1), rh.box_coder.decode(deltas.float(), [proposals])


def _mask_probs(model, feats: dict, boxes: torch.Tensor, labels: torch.Tensor, sizes) -> torch.Tensor:
    """(N, M, M) mask probabilities of each box for its label."""
    if not len(boxes):
        M = 2 * model.roi_heads.mask_roi_pool.output_size[0]
        return torch.zeros((0, M, M), device=boxes.device)
    rh = model.roi_heads
    logits = rh.mask_predictor(rh.mask_head(rh.mask_roi_pool(feats, [boxes], sizes)))
    return logits[torch.arange(len(labels), device=labels.device), labels].float().sigmoid()




def second_look(model: torch.nn.Module, image_bgr: np.ndarray, inst: Instances,
                score_threshold: float, max_size: int | None = DEFAULT_MAX_SIZE,
                flip: bool = True) -> Instances:
    """``post.second_look`` with this network's ``predict``: each small turbine segmented
    again on a crop around it (figures: docs/segment.md)."""
    return post.second_look(lambda img, thr, ms, fl: predict(model, img, thr, ms, flip=fl),
                            image_bgr, inst, score_threshold, max_size, flip)

def segment_image(image_bgr: np.ndarray, model: torch.nn.Module | None = None,
                  score_threshold: float = DEFAULT_SCORE_THRESHOLD, max_size: int | None = DEFAULT_MAX_SIZE,
                  device: str | None = None, weights: str | Path | None = None,
                  candidate_floor: float | None = CANDIDATE_FLOOR, zoom: bool = True,
                  flip: bool = True, refine: bool = True, refiner: str | Path | None = None,
                  wide: bool = True) -> Instances:
    """The one call other stages use: segment a BGR photo with the shipped model (loaded lazily
    and cached) or the ``model`` given.

    Returns the instances scoring at least ``score_threshold`` AND the blades scoring at least
    ``candidate_floor`` (default 0.2; None: none): those are rotor-completion candidates for
    ``wtcli.pitch.measure_pitch`` (``wtcli.chain.photo_to_pitch``), which counts only what
    scores ``score_threshold`` (give it the same one). ``inst[inst.scores >= score_threshold]`` is the segmentation alone;
    without ``zoom`` it is the same as predicting at that threshold (duplicates are dropped
    greedily by score). ``zoom``: small turbines get a ``second_look`` (at the lower threshold,
    as ``segment --score-threshold 0.2`` does, so files chain to the same result). ``flip``: as
    ``predict``'s. ``wide``: the photo looked at again smaller, for a part too big for the
    first look (``post.wide_look``). ``refine``: the masks' edges decided again by the edge
    refiner (``wtcli.segment.refine``; ``refiner``: its weights, default the shipped ones)."""
    if model is None:
        model = load_model(weights, device)
    floor = score_threshold if candidate_floor is None else min(candidate_floor, score_threshold)
    inst = predict(model, image_bgr, floor, max_size, flip=flip)
    if wide:
        inst = wide_look(model, image_bgr, inst, floor, max_size, flip, sure=score_threshold)
    if zoom:
        inst = second_look(model, image_bgr, inst, floor, max_size, flip)
    inst = post.absorb_blade_ends(inst, score_threshold)
    if refine:
        from wtcli.segment.refine import load_refiner, refine_edges

        edges = load_refiner(refiner, getattr(model, "precision", None))  # as the network runs
        inst = refine_edges(edges, image_bgr, inst)
    if not len(inst) or floor >= score_threshold:
        return inst
    return inst[(inst.scores >= score_threshold) | (inst.labels == "blade")]


def remove_background(image_bgr: np.ndarray, inst: Instances) -> np.ndarray:
    """I_t of the paper (step 1.2): the image where any instance is, black elsewhere."""
    union = inst.union().astype(np.uint8) * 255
    return cv2.bitwise_and(image_bgr, image_bgr, mask=union)


COLORS = {"blade": (40, 200, 255), "tower": (255, 140, 40), "nacelle": (80, 220, 80)}  # BGR


def overlay(image_bgr: np.ndarray, inst: Instances, alpha: float = 0.45) -> np.ndarray:
    """The photo with each instance tinted by class, outlined, and labelled with its score."""
    out = image_bgr.copy()
    for i in np.argsort(-inst.masks.reshape(len(inst), -1).sum(axis=1)) if len(inst) else []:
        m, label = inst.masks[i], inst.labels[i]
        col = np.array(COLORS[label], np.float32)
        out[m] = (out[m] * (1 - alpha) + col * alpha).astype(np.uint8)
        cs, _ = cv2.findContours(m.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        thick = max(1, round(max(out.shape[:2]) / 500))
        cv2.drawContours(out, cs, -1, COLORS[label], thick, cv2.LINE_AA)
        x0, y0 = (int(v) for v in inst.boxes[i][:2])
        cv2.putText(out, f"{label} {inst.scores[i]:.2f}", (x0 + 2, max(12, y0 + 12)),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.4 * thick, COLORS[label], thick, cv2.LINE_AA)
    return out


def wide_look(model: torch.nn.Module, image_bgr: np.ndarray, inst: Instances,
              score_threshold: float, max_size: int | None = DEFAULT_MAX_SIZE,
              flip: bool = True, sure: float | None = None) -> Instances:
    """``post.wide_look`` with this network's ``predict`` at ``WIDE_SIZE``: a part too big
    for the first look (a blade filling the frame) found on the photo seen smaller."""
    return post.wide_look(lambda img, thr, ms, fl: predict(model, img, thr, ms, flip=fl, size=WIDE_SIZE),
                          image_bgr, inst, score_threshold, max_size, flip, sure)
