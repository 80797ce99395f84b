"""The shipped segmenter run by OpenCV's DNN module, without torch: the same network, weights and
detection steps as ``wtcli.segment.infer`` (which runs it in torch), for the photo -> plan path.

``import torch`` alone takes 1.1-1.6 s of a 2-core CPU, more than the network's pass; this
module imports numpy and cv2 only. ``models/wtseg-r18s.cv2.npz`` (made by
``python -m wtcli.segment.export_cv2`` from the shipped ``.pt`` files) holds the network's
dense part (trunk, FPN, RPN head), its box head and its mask head as three ONNX graphs with
float16 weights (exactly the ``.pt``'s), the edge refiner's weights, and the SHA-256 of the
``.pt`` files it was made from: when those differ from the files in ``models/`` (a retrained
model), ``available()`` is false and the torch path runs instead.

The rest is torchvision's Mask R-CNN inference written in numpy: the transform (normalise,
resize, pad to 32), anchors, the RPN's proposal filter, RoIAlign (aligned=False, sampling
ratio 2) with the level mapper, the box decoding and selection, and ``infer._detect_both``'s
mirror pass. On the 40 held-out front renders of ``benchmarks/plan_latency.py --accuracy``
it gives the torch path's blade counts and angles (figures in docs/segment.md).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import threading
from pathlib import Path

import cv2
import numpy as np

from wtcli.errors import ModelError
from wtcli.masks import LABELS, Instances
from wtcli.segment import post
from wtcli.segment.defaults import CANDIDATE_FLOOR, DEFAULT_MAX_SIZE, DEFAULT_SCORE_THRESHOLD
from wtcli.segment.post import MIRROR_BOX_SHIFT_PX

MODELS_DIR = Path(__file__).resolve().parents[2] / "models"
CONVERTED = MODELS_DIR / "wtseg-r18s.cv2.npz"
SOURCES = ("wtseg-r18s.pt", "wtseg-refine.pt")  # what the converted file is made from
MIRROR = "wtseg-r18s.mirror.pt"  # a mirror network put beside them: torch reads the pair, this file cannot
FORMAT = 1
BOX_CLIP = math.log(1000.0 / 16)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def available(path: Path = CONVERTED) -> bool:
    """Whether the converted file is there and was made from the ``.pt`` files now beside it
    (each compared by SHA-256, about 30 ms for both), and no mirror network lies beside them
    (``infer.load_model`` would read the mirror pass with it; this file holds one network)."""
    if not path.is_file():
        return False
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(bytes(z["meta"]).decode())
    except (OSError, ValueError, KeyError):
        return False
    if meta.get("format") != FORMAT or (path.parent / MIRROR).is_file():
        return False
    for name in SOURCES:
        src = path.parent / name
        if not src.is_file() or meta.get("sha256", {}).get(name) != _sha256(src):
            return False
    return True


class CvModel:
    """The converted network: ``dense`` (image -> FPN levels and RPN outputs), ``box`` and
    ``mask`` heads as cv2.dnn nets, the refiner's layers as arrays, and ``meta`` (the
    torchvision settings it was exported with)."""

    def __init__(self, path: Path = CONVERTED):
        try:
            with np.load(path, allow_pickle=False) as z:
                self.meta = json.loads(bytes(z["meta"]).decode())
                nets = {k: cv2.dnn.readNetFromONNX(np.ascontiguousarray(z[k]))
                        for k in ("dense", "box", "mask")}
                self.refiner_layers = [(z[f"refiner_w{i}"].astype(np.float32),
                                        z[f"refiner_b{i}"].astype(np.float32))
                                       for i in range(self.meta["refiner_layers"])]
        except (OSError, ValueError, KeyError, cv2.error) as e:
            raise ModelError(f"{path}: not a readable converted model ({e.__class__.__name__})") from None
        self.dense, self.box, self.mask = nets["dense"], nets["box"], nets["mask"]
        self.mask_offset_px = float(self.meta["mask_offset_px"])
        self.precision = "fp32"
        self._lock = threading.Lock()  # a cv2.dnn net holds one input at a time

    # -- the network's parts ------------------------------------------------------------------
    def dense_pass(self, x: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
        """x [1, 3, H, W] (normalised, padded) -> (the FPN levels "0", "1", "2" and the fine
        "p2"), RPN objectness per level [1, A, h, w], RPN deltas per level [1, 4A, h, w]."""
        with self._lock:
            self.dense.setInput(np.ascontiguousarray(x))
            out = self.dense.forward(self.meta["dense_outputs"])
        n = self.meta["rpn_levels"]
        return list(out[:4]), list(out[4:4 + n]), list(out[4 + n:4 + 2 * n])

    def box_head(self, pooled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        with self._lock:
            self.box.setInput(np.ascontiguousarray(pooled))
            logits, deltas = self.box.forward(["logits", "deltas"])
        return logits, deltas

    def mask_head(self, pooled: np.ndarray) -> np.ndarray:
        with self._lock:
            self.mask.setInput(np.ascontiguousarray(pooled))
            return self.mask.forward()

    def refiner_logits(self, f: np.ndarray) -> np.ndarray:
        """The edge refiner's MLP (``refine.Refiner.forward``) on features ``f`` [N, F]."""
        from wtcli.segment.edges import LOCAL, PATCH

        k = PATCH * PATCH
        pix = f[:, :3 * k].reshape(len(f), k, 3)

        def between(inside, outside):
            d = inside - outside
            d2 = (d * d).sum(1, keepdims=True)
            alpha = (np.einsum("nkc,nc->nk", pix, d) - (outside * d).sum(1, keepdims=True)) / (d2 + 0.01)
            return [np.clip(alpha, -1, 2), np.sqrt(d2)]

        h = np.concatenate([f, *between(f[:, -6:-3], f[:, -3:]),
                            *between(f[:, LOCAL:LOCAL + 3], f[:, LOCAL + 4:LOCAL + 7])], 1)
        for i, (w, b) in enumerate(self.refiner_layers):
            h = h @ w.T + b
            if i < len(self.refiner_layers) - 1:
                np.maximum(h, 0, out=h)
        return h[:, 0]

    def refiner_probability(self, f: np.ndarray) -> np.ndarray:
        """As ``refine.probability``: the mean of the logits on the pixels and their mirror."""
        from wtcli.segment.edges import mirrored

        lo = self.refiner_logits(np.concatenate([f, mirrored(f)]).astype(np.float32))
        return 1.0 / (1.0 + np.exp(-0.5 * (lo[:len(f)] + lo[len(f):])))

    # -- torchvision's steps in numpy ---------------------------------------------------------
    def transform(self, image_bgr: np.ndarray, size: tuple[int, int] | None = None
                  ) -> tuple[np.ndarray, tuple[int, int]]:
        """GeneralizedRCNNTransform: RGB in [0, 1], normalised, resized so the shorter side is
        ``min_size`` (the longer at most ``max_size``; bilinear, as torch's interpolate; or
        ``size`` = (shorter, longer at most)), padded with zeros to a multiple of 32. Returns
        the tensor and the resized (h, w)."""
        m = self.meta
        rgb = image_bgr[:, :, ::-1].astype(np.float32) / 255.0
        rgb = (rgb - np.float32(m["image_mean"])) / np.float32(m["image_std"])
        h, w = rgb.shape[:2]
        lo, hi = (m["min_size"], m["max_size"]) if size is None else size
        scale = min(lo / min(h, w), hi / max(h, w))
        nh, nw = math.floor(h * scale), math.floor(w * scale)
        rgb = cv2.resize(rgb, (nw, nh), interpolation=cv2.INTER_LINEAR)
        d = m["size_divisible"]
        ph, pw = int(math.ceil(nh / d) * d), int(math.ceil(nw / d) * d)
        x = np.zeros((1, 3, ph, pw), np.float32)
        x[0, :, :nh, :nw] = rgb.transpose(2, 0, 1)
        return x, (nh, nw)

    def anchors(self, tensor_hw: tuple[int, int], grids: list[tuple[int, int]]) -> list[np.ndarray]:
        """torchvision's AnchorGenerator: per level [h * w * A, 4], location-major."""
        out = []
        for (gh, gw), sizes, ratios in zip(grids, self.meta["anchor_sizes"], self.meta["aspect_ratios"]):
            scales, ar = np.asarray(sizes, np.float32), np.asarray(ratios, np.float32)
            hr = np.sqrt(ar)
            wr = 1 / hr
            ws = (wr[:, None] * scales[None, :]).reshape(-1)
            hs = (hr[:, None] * scales[None, :]).reshape(-1)
            base = np.round(np.stack([-ws, -hs, ws, hs], 1) / 2)
            sy, sx = tensor_hw[0] // gh, tensor_hw[1] // gw
            yy, xx = np.meshgrid(np.arange(gh, dtype=np.float32) * sy,
                                 np.arange(gw, dtype=np.float32) * sx, indexing="ij")
            shifts = np.stack([xx.ravel(), yy.ravel(), xx.ravel(), yy.ravel()], 1)
            out.append((shifts[:, None, :] + base[None]).reshape(-1, 4).astype(np.float32))
        return out

    def rpn(self, tensor_hw, image_hw, objectness: list[np.ndarray], deltas: list[np.ndarray]
            ) -> np.ndarray:
        """The RPN's proposals (xyxy) for one image: top ``pre_nms_top_n`` per level, decoded,
        clipped, small ones dropped, NMS per level, the best ``post_nms_top_n``."""
        m = self.meta
        grids = [o.shape[-2:] for o in objectness]
        anchors = self.anchors(tensor_hw, grids)
        boxes, scores, levels = [], [], []
        for lvl, (o, d, a) in enumerate(zip(objectness, deltas, anchors)):
            A = o.shape[1]
            ob = o[0].transpose(1, 2, 0).reshape(-1)  # (h, w, A)
            de = d[0].reshape(A, 4, *o.shape[-2:]).transpose(2, 3, 0, 1).reshape(-1, 4)
            top = np.argsort(-ob, kind="stable")[:min(m["rpn_pre_nms_top_n"], len(ob))]
            boxes.append(decode(de[top], a[top], (1.0, 1.0, 1.0, 1.0)))
            scores.append(ob[top])
            levels.append(np.full(len(top), lvl))
        boxes = clip_boxes(np.concatenate(boxes), image_hw)
        scores = 1.0 / (1.0 + np.exp(-np.concatenate(scores)))
        levels = np.concatenate(levels)
        keep = small_kept(boxes, m["rpn_min_size"]) & (scores >= m["rpn_score_thresh"])
        boxes, scores, levels = boxes[keep], scores[keep], levels[keep]
        keep = batched_nms(boxes, scores, levels, m["rpn_nms_thresh"])[:m["rpn_post_nms_top_n"]]
        return boxes[keep]

    def pool(self, levels: list[np.ndarray], boxes: np.ndarray, size: int, fine: bool) -> np.ndarray:
        """torchvision's MultiScaleRoIAlign on levels "0", "1", "2" (strides 8, 16, 32), each box
        on the level its size maps to; ``fine``: boxes of the stride-8 level pool the stride-4
        level instead (``model._FineMaskPool``)."""
        m = self.meta
        k_min, k_max = 3, 5
        s = np.sqrt((boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1]))
        lvl = np.floor(m["canonical_level"] + np.log2(s / m["canonical_scale"] + 1e-6))
        lvl = (np.clip(lvl, k_min, k_max) - k_min).astype(int)
        C = levels[0].shape[1]
        out = np.zeros((len(boxes), C, size, size), np.float32)
        for i, b in enumerate(boxes):
            li = int(lvl[i])
            feat, scale = (levels[3], 0.25) if fine and li == 0 else (levels[li], 2.0 ** -(3 + li))
            out[i] = roi_align_one(feat[0], b, scale, size, m["sampling_ratio"])
        return out

    def heads(self, levels, proposals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, C) class probabilities and (N, C, 4) boxes of the proposals (``infer._box_head``)."""
        if not len(proposals):  # cv2.dnn takes no empty batch
            C = len(LABELS) + 1
            return np.zeros((0, C), np.float32), np.zeros((0, C, 4), np.float32)
        logits, deltas = self.box_head(self.pool(levels, proposals, 7, False))
        e = np.exp(logits - logits.max(1, keepdims=True))
        prob = e / e.sum(1, keepdims=True)
        C = prob.shape[1]
        boxes = decode(deltas.reshape(-1, 4), np.repeat(proposals, C, 0),
                       tuple(self.meta["box_weights"])).reshape(-1, C, 4)
        return prob, boxes

    def mask_probs(self, levels, boxes: np.ndarray, labels: np.ndarray) -> np.ndarray:
        """(N, M, M) mask probabilities of each box for its label (``infer._mask_probs``)."""
        M = 2 * 14
        if not len(boxes):
            return np.zeros((0, M, M), np.float32)
        logits = self.mask_head(self.pool(levels, boxes, 14, True))
        return 1.0 / (1.0 + np.exp(-logits[np.arange(len(labels)), labels]))

    def select(self, prob: np.ndarray, boxes: np.ndarray, image_hw) -> tuple[np.ndarray, ...]:
        """RoIHeads.postprocess_detections: background dropped, score floor, small boxes
        dropped, NMS per class, the best ``detections_per_img``."""
        m = self.meta
        C = prob.shape[1]
        boxes = clip_boxes(boxes.reshape(-1, 4), image_hw).reshape(-1, C, 4)
        labels = np.broadcast_to(np.arange(C), prob.shape)
        b, s, lab = boxes[:, 1:].reshape(-1, 4), prob[:, 1:].reshape(-1), labels[:, 1:].reshape(-1)
        keep = s > m["box_score_thresh"]
        b, s, lab = b[keep], s[keep], lab[keep]
        keep = small_kept(b, 1e-2)
        b, s, lab = b[keep], s[keep], lab[keep]
        keep = batched_nms(b, s, lab, m["box_nms_thresh"])[:m["detections_per_img"]]
        return b[keep], s[keep], lab[keep]

    def detect(self, image_bgr: np.ndarray, flip: bool, size: tuple[int, int] | None = None
               ) -> tuple[dict, tuple[int, int]]:
        """As ``infer._detect``: boxes, labels, scores and M x M masks in the working size."""
        x, hw = self.transform(image_bgr, size)
        levels, obj, dl = self.dense_pass(x)
        tensor_hw = x.shape[-2:]
        proposals = self.rpn(tensor_hw, hw, obj, dl)
        if not flip:
            prob, boxes = self.heads(levels, proposals)
            b, s, lab = self.select(prob, boxes, hw)
            masks = self.mask_probs(levels, b, lab)
            return {"boxes": b, "labels": lab, "scores": s, "masks": masks}, hw
        # infer._detect_both, step by step
        h, w = hw
        T = np.ascontiguousarray(x[..., ::-1])
        W = T.shape[-1]
        levels_m, obj_m, dl_m = self.dense_pass(T)
        p_mirror = self.rpn(tensor_hw, (h, W), obj_m, dl_m)
        p_mirror = np.stack([W - p_mirror[:, 2], p_mirror[:, 1], W - p_mirror[:, 0], p_mirror[:, 3]], 1)
        proposals = clip_boxes(np.concatenate([proposals, p_mirror[p_mirror[:, 0] < w - 1]]), hw)
        prob, boxes = self.heads(levels, proposals)
        prob_m, boxes_m = self.heads(levels_m, mirror_boxes(proposals, W))
        prob = 0.5 * (prob + prob_m)
        boxes = 0.5 * (boxes + unmirror_boxes(boxes_m, W))
        b, s, lab = self.select(prob, boxes, hw)
        masks = 0.5 * (self.mask_probs(levels, b, lab)
                       + self.mask_probs(levels_m, mirror_boxes(b, W), lab)[..., ::-1])
        return {"boxes": b, "labels": lab, "scores": s, "masks": masks}, hw


def decode(deltas: np.ndarray, ref: np.ndarray, weights) -> np.ndarray:
    """torchvision's BoxCoder.decode_single for one delta per reference box."""
    widths = ref[:, 2] - ref[:, 0]
    heights = ref[:, 3] - ref[:, 1]
    cx = ref[:, 0] + 0.5 * widths
    cy = ref[:, 1] + 0.5 * heights
    wx, wy, ww, wh = (np.float32(v) for v in weights)
    dx, dy = deltas[:, 0] / wx, deltas[:, 1] / wy
    dw = np.minimum(deltas[:, 2] / ww, np.float32(BOX_CLIP))
    dh = np.minimum(deltas[:, 3] / wh, np.float32(BOX_CLIP))
    pcx, pcy = dx * widths + cx, dy * heights + cy
    pw, ph = np.exp(dw) * widths, np.exp(dh) * heights
    return np.stack([pcx - 0.5 * pw, pcy - 0.5 * ph, pcx + 0.5 * pw, pcy + 0.5 * ph], 1).astype(np.float32)


def clip_boxes(boxes: np.ndarray, hw) -> np.ndarray:
    out = boxes.copy()
    out[:, 0::2] = out[:, 0::2].clip(0, hw[1])
    out[:, 1::2] = out[:, 1::2].clip(0, hw[0])
    return out


def small_kept(boxes: np.ndarray, min_size: float) -> np.ndarray:
    return ((boxes[:, 2] - boxes[:, 0]) >= min_size) & ((boxes[:, 3] - boxes[:, 1]) >= min_size)


def nms(boxes: np.ndarray, scores: np.ndarray, thresh: float) -> np.ndarray:
    """Greedy NMS as torchvision's: best score first, a box overlapping a kept one by IoU above
    ``thresh`` dropped; indices of the kept boxes by decreasing score."""
    order = np.argsort(-scores, kind="stable")
    b = boxes[order].astype(np.float32)
    area = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    alive = np.ones(len(b), bool)
    keep = []
    for i in range(len(b)):
        if not alive[i]:
            continue
        keep.append(i)
        r = slice(i + 1, None)
        iw = np.maximum(np.minimum(b[i, 2], b[r, 2]) - np.maximum(b[i, 0], b[r, 0]), 0)
        ih = np.maximum(np.minimum(b[i, 3], b[r, 3]) - np.maximum(b[i, 1], b[r, 1]), 0)
        inter = iw * ih
        alive[i + 1:] &= inter / (area[i] + area[r] - inter) <= thresh
    return order[np.asarray(keep, int)]


def batched_nms(boxes: np.ndarray, scores: np.ndarray, groups: np.ndarray, thresh: float) -> np.ndarray:
    """NMS within each group; the kept indices by decreasing score."""
    keep = [np.nonzero(groups == g)[0][nms(boxes[groups == g], scores[groups == g], thresh)]
            for g in np.unique(groups)]
    if not keep:
        return np.zeros(0, int)
    keep = np.concatenate(keep)
    return keep[np.argsort(-scores[keep], kind="stable")]


def _interp_matrix(start: float, extent: float, n_bins: int, grid: int, size: int
                   ) -> tuple[np.ndarray, int]:
    """RoIAlign's sampling along one axis as a [n_bins, span] matrix of bilinear weights (the
    mean over the bin's ``grid`` samples), and the first feature cell it spans."""
    binsz = max(extent, 1.0) / n_bins
    t = start + (np.arange(n_bins)[:, None] + (np.arange(grid)[None, :] + 0.5) / grid) * binsz
    t = t.ravel()
    valid = (t >= -1.0) & (t <= size)
    t = np.maximum(t, 0.0)
    lo = np.floor(t).astype(int)
    top = lo >= size - 1
    lo = np.where(top, size - 1, lo)
    hi = np.where(top, size - 1, lo + 1)
    t = np.where(top, lo, t)
    frac = t - lo
    first, last = int(lo[valid].min()) if valid.any() else 0, int(hi[valid].max()) if valid.any() else 0
    span = last - first + 1
    Wm = np.zeros((n_bins * grid, span), np.float64)
    rows = np.arange(len(t))
    np.add.at(Wm, (rows[valid], lo[valid] - first), (1 - frac)[valid])
    np.add.at(Wm, (rows[valid], hi[valid] - first), frac[valid])
    return Wm.reshape(n_bins, grid, span).mean(axis=1).astype(np.float32), first


def roi_align_one(feat: np.ndarray, box: np.ndarray, scale: float, size: int, grid: int) -> np.ndarray:
    """torchvision's roi_align (aligned=False) of one box on feature map ``feat`` [C, H, W]:
    [C, size, size]. Bilinear sampling is separable, so the pool is Wy @ feat @ Wx^T on the
    box's rows and columns."""
    C, H, W = feat.shape
    x1, y1, x2, y2 = (float(v) * scale for v in box)
    wy, y0 = _interp_matrix(y1, y2 - y1, size, grid, H)
    wx, x0 = _interp_matrix(x1, x2 - x1, size, grid, W)
    crop = feat[:, y0:y0 + wy.shape[1], x0:x0 + wx.shape[1]]
    return np.matmul(np.matmul(wy, crop), wx.T)


def mirror_boxes(boxes: np.ndarray, width: int) -> np.ndarray:
    """As ``infer.mirror_boxes``."""
    out = boxes.copy()
    out[:, 0] = width - boxes[:, 2] - 1
    out[:, 2] = width - boxes[:, 0] - 1
    return out


def unmirror_boxes(boxes: np.ndarray, width: int, shift: float = MIRROR_BOX_SHIFT_PX) -> np.ndarray:
    """As ``infer.unmirror_boxes``."""
    out = boxes.copy()
    out[..., 0] = width - shift - boxes[..., 2]
    out[..., 2] = width - shift - boxes[..., 0]
    return out


_CACHE: dict[tuple, CvModel] = {}
_LOCK = threading.Lock()


def load(path: Path = CONVERTED) -> CvModel:
    """The converted model, cached per file."""
    key = (str(path), path.stat().st_mtime_ns if path.is_file() else None)
    with _LOCK:
        if key not in _CACHE:
            if not path.is_file():
                raise ModelError(f"{path}: converted model not found (make it with "
                                 "`python -m wtcli.segment.export_cv2`)")
            _CACHE[key] = CvModel(path)
        return _CACHE[key]


ENGINES = ("auto", "torch", "cv2")


def chosen() -> bool:
    """Whether photos are segmented here rather than in torch (``$WTINSPECT_SEGMENTER``: auto,
    the default | torch | cv2). auto takes this path when the converted file matches the
    shipped ``.pt`` files (``available``), unless ``$WTINSPECT_MODEL`` names other weights or
    torch's segmenter (``wtcli.segment.infer``) is already loaded in this process (a library
    user or a test that set it up: it keeps the network it has). cv2 insists (a ModelError if
    the converted file is missing or stale); torch never takes this path."""
    asked = os.environ.get("WTINSPECT_SEGMENTER", "auto").strip().lower() or "auto"
    if asked not in ENGINES:
        raise ModelError(f"WTINSPECT_SEGMENTER={asked!r}: expected one of {', '.join(ENGINES)}")
    if asked == "torch":
        return False
    if asked == "cv2":
        if not available():
            raise ModelError(f"{CONVERTED}: missing, or made from other weights than models/ holds "
                             "(make it with `python -m wtcli.segment.export_cv2`)")
        return True
    if os.environ.get("WTINSPECT_MODEL") or "wtcli.segment.infer" in sys.modules:
        return False
    return available()


def predict(model: CvModel, image_bgr: np.ndarray, score_threshold: float = DEFAULT_SCORE_THRESHOLD,
            max_size: int | None = DEFAULT_MAX_SIZE, flip: bool = True,
            size: tuple[int, int] | None = None) -> Instances:
    """As ``infer.predict``, with the converted network."""
    img, H, W = post.working_image(image_bgr, score_threshold, max_size)
    det, hw = model.detect(img, flip, size)
    return post.instances(det["scores"], det["labels"], det["masks"], det["boxes"], hw, H, W,
                          score_threshold, model.mask_offset_px)


def segment_image(image_bgr: np.ndarray, score_threshold: float = DEFAULT_SCORE_THRESHOLD,
                  max_size: int | None = DEFAULT_MAX_SIZE,
                  candidate_floor: float | None = CANDIDATE_FLOOR, zoom: bool = True,
                  flip: bool = True, refine: bool = True, wide: bool = True) -> Instances:
    """As ``infer.segment_image`` with the shipped model and refiner, converted: the
    instances scoring ``score_threshold`` and the blades scoring ``candidate_floor``; ``wide``
    (the wide look), ``zoom`` (the second look), ``flip`` (the mirror pass) and ``refine``
    (the edge refiner) as there."""
    from wtcli.segment.edges import refine_edges

    model = load()
    floor = score_threshold if candidate_floor is None else min(candidate_floor, score_threshold)
    inst = predict(model, image_bgr, floor, max_size, flip)
    if wide:
        inst = post.wide_look(lambda img, thr, ms, fl: predict(model, img, thr, ms, fl,
                                                               size=post.WIDE_SIZE),
                              image_bgr, inst, floor, max_size, flip, sure=score_threshold)
    if zoom:
        inst = post.second_look(lambda img, thr, ms, fl: predict(model, img, thr, ms, fl),
                                image_bgr, inst, floor, max_size, flip)
    inst = post.absorb_blade_ends(inst, score_threshold)
    if refine:
        inst = refine_edges(model.refiner_probability, image_bgr, inst)
    if not len(inst) or floor >= score_threshold:
        return inst
    return inst[(inst.scores >= score_threshold) | (inst.labels == "blade")]
