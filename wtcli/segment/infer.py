"""Run the segmenter on one image: BGR uint8 [H, W, 3] in, ``wtcli.masks.Instances`` out.

Large photos (a 5472x3648 drone frame) are first downscaled so their longer side is at most
``max_size`` (the network itself works at 576 px high, see ``wtcli.segment.model``); each
predicted M x M box mask is then pasted straight into the ORIGINAL image size (``paste_mask``)
and thresholded, so masks, boxes and the background-removed image line up with the
photo. Masks are pasted one instance at a time, into their box only, and cut at
``MASK_THRESHOLD`` of their class. With ``flip`` (the default) the photo and its mirror image
are detected together: proposals, class scores, boxes and masks of both passes averaged
(``_detect_both``).
"""

from __future__ import annotations

import threading
from pathlib import Path

import cv2
import numpy as np
import torch

# model first: it imports torchvision the quick way (model._import_torchvision)
from wtcli.segment.model import (backbone_in_bf16, build_model, load_weights, pick_device,
                                 resolve_precision, resolve_weights, set_infer_size)
from torchvision.models.detection.image_list import ImageList  # noqa: I001
from torchvision.ops import boxes as box_ops

from wtcli.errors import InputError
from wtcli.masks import LABELS, Instances
from wtcli.segment.bgr import as_bgr
from wtcli.segment.data import image_tensor
from wtcli.segment.defaults import CANDIDATE_FLOOR, DEFAULT_MAX_SIZE, DEFAULT_SCORE_THRESHOLD

MASK_OFFSET_PX = 0.5  # see paste_mask; weights trained with area-resized masks
MIRROR_BOX_SHIFT_PX = 0.5  # see unmirror_boxes
# Where each class's soft mask is cut. Blades at 0.45: on 200 development renders (seeds
# 7 000 000 +, an earlier model) blade IoU 0.742 against 0.735 at 0.5 (0.737 at 0.4, 0.715 at 0.55): the
# soft edge of a blade a few pixels wide comes out a little below 0.5. Tower and nacelle peak
# at 0.5.
MASK_THRESHOLD = {"blade": 0.45, "tower": 0.5, "nacelle": 0.5}
DUPLICATE_INSIDE = 0.3  # a blade this much inside a better-scored blade is the same blade
# Second look (``second_look``): a turbine whose detections span less than this share of the
# frame is segmented again on a crop around it, padded by ZOOM_PAD of its size on each side.
SMALL_TURBINE = 0.5
ZOOM_PAD = 0.6
# ... but the crop is at least ZOOM_MIN_CROP of the frame's height: a turbine a few dozen pixels
# tall, magnified 5-10x to the network's size, is blurrier than anything it was trained on, and
# its faint blades were missed. On 100 development renders (an earlier model, refined) blade IoU /
# AP50 with no floor, 0.3, 0.45, 0.6, 0.7, 0.76 of the frame: 0.836 / 0.762, 0.837 / 0.776,
# 0.840 / 0.780, 0.844 / 0.798, 0.845 / 0.789, 0.846 / 0.789 (a floor of 0.85 with crops allowed
# up to 0.9: 0.847 / 0.768, nacelle IoU 0.826 -> 0.819); the 38 real photos' blade IoU 0.753 ->
# 0.754 (0.7), tower 0.802 -> 0.804. Each look costs one pass whatever the crop's size.
ZOOM_MIN_CROP = 0.75
ZOOM_MAX = 3  # the largest this many small turbines (each look costs a pass of the network)

_CACHE: dict[tuple, torch.nn.Module] = {}
_LOCK = threading.Lock()


def load_model(weights: str | Path | None = None, device: str | torch.device | None = None,
               precision: str | None = None):
    """Build the network and load weights (default: the shipped ``models/`` file); cached per
    (path, device, precision), so a batch or a chained command loads it once. ``precision``:
    auto (None) | fp32 | bf16 (``model.resolve_precision``); the model's ``precision`` says
    which it runs in."""
    dev = device if isinstance(device, torch.device) else pick_device(device)
    prec = resolve_precision(precision, dev)
    path = resolve_weights(weights)
    stamp = path.stat().st_mtime_ns if path.is_file() else None
    key = (str(path.resolve()) if path.exists() else str(path), str(dev), stamp, prec)
    with _LOCK:
        if key not in _CACHE:
            model = build_model()
            meta = load_weights(model, path)
            # Where mask cells sit in their box depends on how the weights were trained
            # (see paste_mask); files from before that was recorded are offset 0.
            model.mask_offset_px = float(meta.get("mask_offset_px", 0.0))
            set_infer_size(model)
            model.eval().to(dev)
            backbone_in_bf16(model, prec == "bf16")
            model.precision = prec
            _CACHE[key] = model
        return _CACHE[key]


def _device_of(model: torch.nn.Module) -> torch.device:
    return next(model.parameters()).device


def predict(model: torch.nn.Module, image_bgr: np.ndarray, score_threshold: float = DEFAULT_SCORE_THRESHOLD,
            max_size: int | None = DEFAULT_MAX_SIZE, device=None, flip: bool = True) -> Instances:
    """Instances (labels, masks at the image's size, scores, boxes xyxy) with score >= threshold.

    ``flip``: detect the photo and its mirror image together (``_detect_both``); about 2 x
    the time. On 300 development renders (an earlier model, second look) blade / tower /
    nacelle IoU 0.757 / 0.855 / 0.768 without -> 0.774 / 0.867 / 0.778 with."""
    img = as_bgr(image_bgr)
    if not 0.0 <= score_threshold <= 1.0:
        raise InputError(f"expected a score threshold in [0, 1], got {score_threshold}")
    H, W = img.shape[:2]
    if H < 8 or W < 8:
        raise InputError(f"image is too small ({W}x{H})")
    scale = 1.0
    if max_size and max(H, W) > max_size:
        scale = max_size / max(H, W)
        img = cv2.resize(img, (max(1, round(W * scale)), max(1, round(H * scale))),
                         interpolation=cv2.INTER_AREA)
    dev = _device_of(model) if device is None else torch.device(device)
    model.eval()
    with torch.inference_mode():
        det, (hw, ww) = _detect(model, image_tensor(img).to(dev), flip)
    scores = det["scores"].float().cpu().numpy()
    keep = scores >= score_threshold
    if not keep.any():
        return Instances.empty(H, W)
    labels = det["labels"].cpu().numpy()[keep]
    soft = det["masks"][keep, 0].float().cpu().numpy()  # [N, M, M] in each box
    work_boxes = det["boxes"].float().cpu().numpy()[keep]
    sx, sy = W / ww, H / hw  # working size -> original image
    boxes = work_boxes * np.array([sx, sy, sx, sy])
    masks = np.zeros((len(soft), H, W), bool)
    offset = float(getattr(model, "mask_offset_px", MASK_OFFSET_PX))
    names = np.array([LABELS[int(c) - 1] for c in labels], dtype=object)
    for i, m in enumerate(soft):
        paste_mask(masks[i], m, work_boxes[i], sx, sy, offset, MASK_THRESHOLD[names[i]])
    boxes[:, [0, 2]] = boxes[:, [0, 2]].clip(0, W)
    boxes[:, [1, 3]] = boxes[:, [1, 3]].clip(0, H)
    return drop_duplicate_blades(Instances(names, masks, scores[keep].clip(0, 1), boxes))


def drop_duplicate_blades(inst: Instances, inside: float = DUPLICATE_INSIDE) -> Instances:
    """Drop a blade detection whose mask lies ``inside`` (share of its pixels) or more within a
    better-scored blade's: the network sometimes proposes a blade twice (whole and a part, two
    overlapping boxes) that box NMS keeps, and each copy would count as a blade. Distinct blades
    share only a few pixels at the hub (seen from the side, the hidden one's mask is its visible
    part). Greedy by score, so the result at any score threshold is this one, thresholded."""
    idx = np.nonzero(inst.labels == "blade")[0]
    if len(idx) < 2:
        return inst
    idx = idx[np.argsort(-inst.scores[idx], kind="stable")]
    area = inst.masks[idx].reshape(len(idx), -1).sum(axis=1)
    kept: list[int] = []
    drop = []
    for a, i in enumerate(idx):
        x0, y0, x1, y1 = inst.boxes[i]
        dup = area[a] == 0
        for b in kept:
            if dup:
                break
            j = idx[b]  # the masks can overlap only where the boxes do
            u0, v0 = int(max(x0, inst.boxes[j][0])), int(max(y0, inst.boxes[j][1]))
            u1, v1 = int(np.ceil(min(x1, inst.boxes[j][2]))), int(np.ceil(min(y1, inst.boxes[j][3])))
            if u1 > u0 and v1 > v0:
                both = inst.masks[i, v0:v1, u0:u1] & inst.masks[j, v0:v1, u0:u1]
                dup = int(both.sum()) >= inside * area[a]
        if dup:
            drop.append(i)
        else:
            kept.append(a)
    if not drop:
        return inst
    return inst[np.setdiff1d(np.arange(len(inst)), drop)]


def _detect(model, x: torch.Tensor, flip: bool = False) -> tuple[dict, tuple[int, int]]:
    """The network's detections for one image tensor, in the network's working size
    (image resized by its transform), with the masks still M x M per box: torchvision's own
    postprocess pastes them half a pixel to a pixel off (see ``paste_mask``). ``flip``: the
    photo and its mirror image detected together (``_detect_both``)."""
    images, _ = model.transform([x])
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
    ``detections_per_img``); each kept box's mask is the mean of both passes' masks.

    A detection one pass scores low is kept when the other scores it well, and the two passes'
    pixel jitter on thin blades partly cancels. On 300 development renders
    (an earlier model, second look) blade / tower / nacelle IoU 0.767 / 0.862 / 0.779 with the masks
    alone averaged -> 0.774 / 0.867 / 0.778; on the real photos blade 0.707 -> 0.719."""
    rh = model.roi_heads
    T = images.tensors.flip(-1)
    W = T.shape[-1]
    h, w = images.image_sizes[0]
    feats_m = model.backbone(T)
    # The padded tensor's photo sits at its right in the mirror: the mirror's "image" is the
    # whole width, and proposals starting in the padding are dropped once mirrored back.
    mirror_size = [(h, W)]
    p_plain = model.rpn(images, feats)[0][0]
    p_mirror = model.rpn(ImageList(T, mirror_size), feats_m)[0][0]
    # Proposals are mirrored back exactly: they only need to be near, the box head refines them.
    p_mirror = torch.stack([W - p_mirror[:, 2], p_mirror[:, 1], W - p_mirror[:, 0], p_mirror[:, 3]], 1)
    proposals = box_ops.clip_boxes_to_image(
        torch.cat([p_plain, p_mirror[p_mirror[:, 0] < w - 1]]), (h, w))
    prob, boxes = _box_head(model, feats, proposals, images.image_sizes)
    prob_m, boxes_m = _box_head(model, feats_m, mirror_boxes(proposals, W), mirror_size)
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
                   + _mask_probs(model, feats_m, mirror_boxes(boxes, W), labels, mirror_size).flip(-1))
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


def paste_mask(out: np.ndarray, soft: np.ndarray, box, sx: float, sy: float,
               offset: float = MASK_OFFSET_PX, threshold: float = 0.5) -> None:
    """Threshold the M x M mask ``soft`` of ``box`` (working-size pixels) at ``threshold``
    into ``out`` (bool, original image size; ``sx, sy`` = original / working size).

    Cell i of a box [x1, x2) is centred at x1 + offset + (i + 0.5) (x2 - x1) / M (pixel edges
    at integers). Training targets come from torchvision's ``project_masks_on_boxes``
    (RoIAlign, aligned=False), whose cells sit half a pixel right of the box's own frame:
    offset 0.5, when the masks were resized by area (``model._Transform``). torchvision's
    ``paste_masks_in_image`` ignores that and widens the box by a pixel: on TRUE masks at
    640x480 its round trip keeps blade IoU 0.77, this one 0.93 (thin blades are a few pixels
    wide)."""
    M = soft.shape[-1]
    H, W = out.shape
    x1, y1, x2, y2 = (float(v) for v in box)
    X0, Y0 = max(int(np.floor(x1 * sx)), 0), max(int(np.floor(y1 * sy)), 0)
    X1, Y1 = min(int(np.ceil(x2 * sx)), W), min(int(np.ceil(y2 * sy)), H)
    if X1 <= X0 or Y1 <= Y0:
        return
    # cell i's centre in original pixel-index units (pixel centres at integers)
    ax, ay = (x2 - x1) / M * sx, (y2 - y1) / M * sy
    bx = (x1 + offset + 0.5 * (x2 - x1) / M) * sx - 0.5 - X0
    by = (y1 + offset + 0.5 * (y2 - y1) / M) * sy - 0.5 - Y0
    A = np.array([[ax, 0, bx], [0, ay, by]], np.float64)
    region = cv2.warpAffine(soft.astype(np.float32), A, (X1 - X0, Y1 - Y0), flags=cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_REPLICATE)
    out[Y0:Y1, X0:X1] |= region >= threshold


def _turbine_groups(boxes: np.ndarray, grow: float = 0.25) -> list[np.ndarray]:
    """Indices of the detections of each turbine: boxes that overlap once each is grown by
    ``grow`` of its size per side (blades meet at the hub, the tower under the nacelle)."""
    w = (boxes[:, 2] - boxes[:, 0]) * grow
    h = (boxes[:, 3] - boxes[:, 1]) * grow
    lo, hi = boxes[:, :2] - np.c_[w, h], boxes[:, 2:] + np.c_[w, h]
    touch = ((lo[:, None] <= hi[None]) & (lo[None] <= hi[:, None])).all(axis=2)
    group = np.arange(len(boxes))
    for _ in range(len(boxes)):  # label propagation: each takes the least label it touches
        new = np.where(touch, group[None, :], len(boxes)).min(axis=1)
        if (new == group).all():
            break
        group = new
    return [np.nonzero(group == g)[0] for g in np.unique(group)]


def second_look(model: torch.nn.Module, image_bgr: np.ndarray, inst: Instances,
                score_threshold: float, max_size: int | None = DEFAULT_MAX_SIZE,
                flip: bool = True) -> Instances:
    """Segment each small turbine again on a crop around it, and use those instances instead.

    The network works at 576 px high: a distant turbine's blades are then 1-3 px wide and come
    out too thin, or not at all. Cropped with its surroundings (ZOOM_PAD of its size each side,
    at least ZOOM_MIN_CROP of the frame's height, the frame's aspect), it is seen larger, though
    not blurrier than in training (figures: docs/segment.md).
    The crop's detections that meet the turbine's box replace the first pass's of it, except
    those cut by the crop's edge (not the photo's); if none is left, the first pass's stand.
    The ZOOM_MAX largest small turbines are looked at again."""
    if not len(inst):
        return inst
    img = np.asarray(image_bgr)
    H, W = img.shape[:2]
    keep = np.ones(len(inst), bool)
    small = []
    for g in _turbine_groups(inst.boxes):
        x0, y0 = inst.boxes[g, :2].min(axis=0)
        x1, y1 = inst.boxes[g, 2:].max(axis=0)
        if max((y1 - y0) / H, (x1 - x0) / W) < SMALL_TURBINE:
            small.append((-(y1 - y0) * (x1 - x0), g, x0, y0, x1, y1))
    small.sort(key=lambda c: c[0])
    labels, masks, scores, boxes = [], [], [], []
    for _, g, x0, y0, x1, y1 in small[:ZOOM_MAX]:
        ch = max(max(y1 - y0, (x1 - x0) * H / W) * (1 + 2 * ZOOM_PAD), ZOOM_MIN_CROP * H)
        if ch >= 0.8 * H or ch < 16:  # hardly a closer look, or a photo too small to crop
            continue
        cw = ch * W / H
        X0 = int(round(np.clip((x0 + x1 - cw) / 2, 0, W - cw)))
        Y0 = int(round(np.clip((y0 + y1 - ch) / 2, 0, H - ch)))
        X1, Y1 = min(W, X0 + int(round(cw))), min(H, Y0 + int(round(ch)))
        sub = predict(model, img[Y0:Y1, X0:X1], score_threshold, max_size, flip=flip)
        b = sub.boxes
        cut = (((b[:, 0] <= 1) & (X0 > 0)) | ((b[:, 1] <= 1) & (Y0 > 0))
               | ((b[:, 2] >= X1 - X0 - 1) & (X1 < W)) | ((b[:, 3] >= Y1 - Y0 - 1) & (Y1 < H)))
        # Only this turbine's: a detection meeting its box (a blade missed before starts at
        # its hub); a neighbour in the crop keeps its own detections.
        b = b + (X0, Y0, X0, Y0)
        mine = ~cut & (b[:, 0] <= x1) & (b[:, 2] >= x0) & (b[:, 1] <= y1) & (b[:, 3] >= y0)
        if not mine.any():  # the closer look found nothing of it: the first look stands
            continue
        keep[g] = False
        m = np.zeros((int(mine.sum()), H, W), bool)
        m[:, Y0:Y1, X0:X1] = sub.masks[mine]
        labels.append(sub.labels[mine])
        masks.append(m)
        scores.append(sub.scores[mine])
        boxes.append(b[mine])
    if not labels:
        return inst
    labels, masks = [inst.labels[keep]] + labels, [inst.masks[keep]] + masks
    scores, boxes = [inst.scores[keep]] + scores, [inst.boxes[keep]] + boxes
    scores_a = np.concatenate(scores)
    order = np.argsort(-scores_a, kind="stable")  # as predict's: best first
    return drop_duplicate_blades(Instances(np.concatenate(labels)[order], np.concatenate(masks)[order],
                                           scores_a[order], np.concatenate(boxes)[order]))


def segment_image(image_bgr: np.ndarray, model: torch.nn.Module | None = None,
                  score_threshold: float = DEFAULT_SCORE_THRESHOLD, max_size: int | None = DEFAULT_MAX_SIZE,
                  device: str | None = None, weights: str | Path | None = None,
                  candidate_floor: float | None = CANDIDATE_FLOOR, zoom: bool = True,
                  flip: bool = True, refine: bool = True, refiner: str | Path | None = None
                  ) -> Instances:
    """The one call other stages use: segment a BGR photo with the shipped model (loaded lazily
    and cached) or the ``model`` given.

    Returns the instances scoring at least ``score_threshold`` AND the blades scoring at least
    ``candidate_floor`` (default 0.2; None: none): those are rotor-completion candidates for
    ``wtcli.pitch.measure_pitch`` (``wtcli.chain.photo_to_pitch``), which counts only what
    scores ``score_threshold`` (give it the same one). ``inst[inst.scores >= score_threshold]`` is the segmentation alone;
    without ``zoom`` it is the same as predicting at that threshold (duplicates are dropped
    greedily by score). ``zoom``: small turbines get a ``second_look`` (at the lower threshold,
    as ``segment --score-threshold 0.2`` does, so files chain to the same result). ``flip``: as
    ``predict``'s. ``refine``: the masks' edges decided again by the edge refiner
    (``wtcli.segment.refine``; ``refiner``: its weights, default the shipped ones)."""
    if model is None:
        model = load_model(weights, device)
    floor = score_threshold if candidate_floor is None else min(candidate_floor, score_threshold)
    inst = predict(model, image_bgr, floor, max_size, flip=flip)
    if zoom:
        inst = second_look(model, image_bgr, inst, floor, max_size, flip)
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
