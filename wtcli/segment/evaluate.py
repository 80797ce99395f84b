"""Segmentation metrics against ground-truth instances: per-class mask IoU (of the class's
union mask, per image, averaged over images where the class is present in either; and the same
on the class maps, one class a pixel, ``Instances.class_map``), AP50 per
class (greedy matching by score at mask IoU >= 0.5, VOC-style all-point interpolation) and
blade-count accuracy."""

from __future__ import annotations

from typing import Any

import numpy as np

from wtcli.masks import LABELS, Instances
from wtcli.segment.defaults import DEFAULT_SCORE_THRESHOLD


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    u = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / u) if u else 1.0


def _pairwise_iou(pm: np.ndarray, gm: np.ndarray) -> np.ndarray:
    if not len(pm) or not len(gm):
        return np.zeros((len(pm), len(gm)))
    p = pm.reshape(len(pm), -1).astype(np.float32)
    g = gm.reshape(len(gm), -1).astype(np.float32)
    inter = p @ g.T
    union = p.sum(1)[:, None] + g.sum(1)[None, :] - inter
    return inter / np.maximum(union, 1)


def average_precision(scores: list[float], hits: list[bool], n_gt: int) -> float | None:
    if n_gt == 0:
        return None
    if not scores:
        return 0.0
    order = np.argsort(-np.asarray(scores))
    tp = np.asarray(hits, float)[order]
    ctp, cfp = np.cumsum(tp), np.cumsum(1 - tp)
    rec = ctp / n_gt
    prec = ctp / np.maximum(ctp + cfp, 1e-9)
    mrec = np.concatenate([[0], rec, [1]])
    mpre = np.concatenate([[0], prec, [0]])
    for i in range(len(mpre) - 2, -1, -1):
        mpre[i] = max(mpre[i], mpre[i + 1])
    idx = np.nonzero(mrec[1:] != mrec[:-1])[0]
    return float(np.sum((mrec[idx + 1] - mrec[idx]) * mpre[idx + 1]))


class Evaluator:
    """``add(pred, truth)`` per image, then ``summary()``. ``pred`` should keep low-score
    detections (score_threshold ~0) for AP; IoU and counts use ``score_threshold``."""

    def __init__(self, score_threshold: float = DEFAULT_SCORE_THRESHOLD):
        self.t = score_threshold
        self.ious: dict[str, list[float]] = {l: [] for l in LABELS}
        self.map_ious: dict[str, list[float]] = {l: [] for l in LABELS}
        self.det: dict[str, list[tuple[float, bool]]] = {l: [] for l in LABELS}
        self.n_gt = {l: 0 for l in LABELS}
        self.n = 0

    def add(self, pred: Instances, truth: Instances) -> dict[str, float]:
        self.n += 1
        confident = pred[pred.scores >= self.t] if len(pred) else pred
        per = {}
        pmap, gmap = confident.class_map(), truth.class_map()
        for k, l in enumerate(LABELS, 1):
            g, p = truth.of(l), confident.of(l)
            if len(g) or len(p):
                iou = mask_iou(p.union(), g.union())
                self.ious[l].append(iou)
                per[l] = iou
            pk, gk = pmap == k, gmap == k
            if pk.any() or gk.any():
                self.map_ious[l].append(mask_iou(pk, gk))
            pl, gl = pred.of(l), truth.of(l)
            self.n_gt[l] += len(gl)
            ious = _pairwise_iou(pl.masks, gl.masks)
            taken = np.zeros(len(gl), bool)
            for i in np.argsort(-pl.scores):
                hit = False
                if len(gl):
                    cand = np.where(taken, -1, ious[i])
                    j = int(np.argmax(cand))
                    if cand[j] >= 0.5:
                        taken[j], hit = True, True
                self.det[l].append((float(pl.scores[i]), hit))
        return per

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {"images": self.n, "score_threshold": self.t}
        for l in LABELS:
            v = self.ious[l]
            out[f"{l}_mask_iou"] = float(np.mean(v)) if v else None
            m = self.map_ious[l]
            out[f"{l}_class_map_iou"] = float(np.mean(m)) if m else None
            ap = average_precision([s for s, _ in self.det[l]], [h for _, h in self.det[l]], self.n_gt[l])
            out[f"{l}_ap50"] = ap
        return out
