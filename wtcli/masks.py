"""Instance masks in memory (``Instances``) and on disk (COCO-compatible instances JSON).

Used by ``synth`` (ground truth), ``segment`` (predictions) and ``contours`` (input).
Masks are bool arrays [N, H, W]; boxes are xyxy pixels in memory and xywh in COCO files.
Segmentation on disk is uncompressed RLE ``{"counts": [...], "size": [H, W]}`` (column-major,
starting with a background run) or polygons ``[[x1, y1, x2, y2, ...], ...]`` (formats.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from wtcli.errors import InputError
from wtcli.jsonio import document, read_json, write_json

LABELS = ("blade", "tower", "nacelle")
CATEGORIES = [{"id": i + 1, "name": n, "supercategory": "wind_turbine"} for i, n in enumerate(LABELS)]
INSTANCES_SCHEMA = "wtinspect.instances"
INSTANCES_VERSION = 1


def rle_encode(mask: np.ndarray) -> dict[str, Any]:
    """Uncompressed COCO RLE of a bool mask [H, W]."""
    flat = np.asarray(mask, dtype=bool).flatten(order="F")
    if flat.size == 0:
        return {"counts": [], "size": list(mask.shape)}
    change = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    bounds = np.concatenate([[0], change, [flat.size]])
    counts = np.diff(bounds).tolist()
    if flat[0]:
        counts = [0] + counts
    return {"counts": counts, "size": [int(mask.shape[0]), int(mask.shape[1])]}


def rle_decode(rle: dict[str, Any]) -> np.ndarray:
    h, w = (int(x) for x in rle["size"])
    counts = rle["counts"]
    if isinstance(counts, str):
        raise ValueError("compressed RLE strings are not supported; write uncompressed RLE "
                         "(counts as a list of integers) or polygons")
    counts = np.asarray(counts, dtype=np.int64)
    if (counts < 0).any() or counts.sum() != h * w:
        raise ValueError(f"RLE counts sum to {int(counts.sum())}, expected {h * w} (= H*W)")
    values = np.arange(len(counts)) % 2 == 1
    flat = np.repeat(values, counts)
    return flat.reshape((h, w), order="F")


def polygons_encode(mask: np.ndarray, epsilon: float = 0.0) -> list[list[float]]:
    contours, _ = cv2.findContours(np.asarray(mask, np.uint8), cv2.RETR_EXTERNAL,
                                   cv2.CHAIN_APPROX_SIMPLE)
    polys = []
    for c in contours:
        if epsilon > 0:
            c = cv2.approxPolyDP(c, epsilon, True)
        if len(c) >= 3:
            polys.append(c.reshape(-1).astype(float).tolist())
    return polys


def polygons_decode(polys: list[list[float]], h: int, w: int) -> np.ndarray:
    canvas = np.zeros((h, w), np.uint8)
    for p in polys:
        if len(p) < 6 or len(p) % 2:
            raise ValueError(f"a polygon needs >= 3 (x, y) points, got {len(p)} numbers")
        pts = np.round(np.asarray(p, float).reshape(-1, 2) * 16).astype(np.int32)
        cv2.fillPoly(canvas, [pts], 1, shift=4)
    return canvas.astype(bool)


def decode_segmentation(seg: Any, h: int, w: int) -> np.ndarray:
    if isinstance(seg, dict):
        m = rle_decode(seg)
        if m.shape != (h, w):
            raise ValueError(f"RLE size {list(m.shape)} does not match the image {h}x{w}")
        return m
    if isinstance(seg, list):
        return polygons_decode(seg, h, w)
    raise ValueError(f"segmentation must be RLE (dict) or polygons (list), got {type(seg).__name__}")


def mask_box(mask: np.ndarray) -> np.ndarray:
    ys, xs = np.nonzero(mask)
    if len(xs) == 0:
        return np.zeros(4)
    return np.array([xs.min(), ys.min(), xs.max() + 1, ys.max() + 1], float)


@dataclass(frozen=True)
class Instances:
    """Instances in one image. Filter like ``inst[inst.scores > 0.5]`` or ``inst.of("blade")``."""

    labels: np.ndarray  # (N,) str, each in LABELS
    masks: np.ndarray  # (N, H, W) bool
    scores: np.ndarray = field(default=None)  # (N,) float in [0, 1]; 1 for ground truth
    boxes: np.ndarray = field(default=None)  # (N, 4) xyxy pixels

    def __post_init__(self) -> None:
        labels = np.asarray(self.labels, dtype=object)
        masks = np.asarray(self.masks, dtype=bool)
        if masks.ndim != 3:
            raise ValueError(f"expected masks [N, H, W], got shape {masks.shape}")
        n = len(masks)
        if labels.shape != (n,):
            raise ValueError(f"expected {n} labels, got {labels.shape}")
        bad = [l for l in labels if l not in LABELS]
        if bad:
            raise ValueError(f"expected labels in {LABELS}, got {bad[0]!r}")
        scores = np.ones(n) if self.scores is None else np.asarray(self.scores, float)
        if scores.shape != (n,) or ((scores < 0) | (scores > 1)).any():
            raise ValueError(f"expected {n} scores in [0, 1], got {scores}")
        boxes = (np.array([mask_box(m) for m in masks]).reshape(n, 4) if self.boxes is None
                 else np.asarray(self.boxes, float).reshape(n, 4))
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "masks", masks)
        object.__setattr__(self, "scores", scores)
        object.__setattr__(self, "boxes", boxes)

    @classmethod
    def empty(cls, h: int, w: int) -> Instances:
        return cls(np.array([], dtype=object), np.zeros((0, h, w), bool), np.zeros(0), np.zeros((0, 4)))

    @property
    def image_size(self) -> tuple[int, int]:
        """(H, W)."""
        return int(self.masks.shape[1]), int(self.masks.shape[2])

    def __len__(self) -> int:
        return len(self.labels)

    def __getitem__(self, idx: Any) -> Instances:
        idx = np.arange(len(self))[idx]
        idx = np.atleast_1d(idx)
        return Instances(self.labels[idx], self.masks[idx], self.scores[idx], self.boxes[idx])

    def of(self, label: str) -> Instances:
        return self[self.labels == label]

    def union(self) -> np.ndarray:
        return self.masks.any(axis=0) if len(self) else np.zeros(self.image_size, bool)

    # ---- COCO-compatible file ---------------------------------------------------------------
    def annotations(self, image_id: int, first_id: int = 1, encoding: str = "rle") -> list[dict]:
        out = []
        for i in range(len(self)):
            m = self.masks[i]
            x0, y0, x1, y1 = self.boxes[i]
            seg = rle_encode(m) if encoding == "rle" else polygons_encode(m)
            out.append({
                "id": first_id + i, "image_id": image_id,
                "category_id": LABELS.index(self.labels[i]) + 1,
                "segmentation": seg, "area": int(m.sum()),
                "bbox": [x0, y0, x1 - x0, y1 - y0], "iscrowd": 0,
                "score": float(self.scores[i]),
            })
        return out

    @classmethod
    def from_annotations(cls, anns: list[dict], h: int, w: int, where: str = "") -> Instances:
        labels, masks, scores, boxes = [], [], [], []
        for j, a in enumerate(anns):
            at = f"{where}annotations[{j}]"
            try:
                cid = int(a["category_id"])
                if not 1 <= cid <= len(LABELS):
                    raise ValueError(f"category_id {cid} not in 1..{len(LABELS)}")
                m = decode_segmentation(a["segmentation"], h, w)
                score = float(a.get("score", 1.0))
            except KeyError as e:
                raise InputError(f"{at}: missing key {e.args[0]!r}") from None
            except (TypeError, ValueError) as e:
                raise InputError(f"{at}: {e}") from None
            labels.append(LABELS[cid - 1])
            masks.append(m)
            scores.append(score)
            if "bbox" in a and len(a["bbox"]) == 4:
                x, y, bw, bh = (float(v) for v in a["bbox"])
                boxes.append([x, y, x + bw, y + bh])
            else:
                boxes.append(mask_box(m).tolist())
        if not labels:
            return cls.empty(h, w)
        return cls(np.array(labels, dtype=object), np.stack(masks), np.array(scores), np.array(boxes))


def instances_document(images: list[dict], per_image: list[Instances], encoding: str = "rle",
                       extra: dict | None = None) -> dict:
    """A COCO dataset dict (images, annotations, categories) with the wtinspect header.

    ``images``: dicts with at least id, file_name, width, height."""
    anns: list[dict] = []
    for img, inst in zip(images, per_image):
        anns += inst.annotations(int(img["id"]), first_id=len(anns) + 1, encoding=encoding)
    body = {"info": {"description": "wtinspect instances"}, "licenses": [], "images": images,
            "annotations": anns, "categories": CATEGORIES, **(extra or {})}
    return document(INSTANCES_SCHEMA, INSTANCES_VERSION, body)


def write_instances(path: str | Path, images: list[dict], per_image: list[Instances],
                    encoding: str = "rle", extra: dict | None = None) -> Path:
    return write_json(path, instances_document(images, per_image, encoding, extra))


def read_instances(path: str | Path) -> list[tuple[dict, Instances]]:
    """Read a COCO instances file (ours, or any COCO-compatible one with our category names)."""
    path = Path(path)
    doc = read_json(path)
    if not isinstance(doc, dict) or not isinstance(doc.get("images"), list) \
            or not isinstance(doc.get("annotations"), list):
        raise InputError(f"{path}: expected a COCO instances JSON with 'images' and 'annotations' lists")
    if doc.get("schema", INSTANCES_SCHEMA) != INSTANCES_SCHEMA:
        raise InputError(f"{path}: expected schema '{INSTANCES_SCHEMA}', got {doc.get('schema')!r}")
    cats = {c.get("id"): c.get("name") for c in doc.get("categories", CATEGORIES)}
    if any(cats.get(i + 1) != n for i, n in enumerate(LABELS)):
        raise InputError(f"{path}: categories must be {[c['name'] for c in CATEGORIES]} with ids 1..3, "
                         f"got {sorted(cats.items())}")
    by_image: dict[int, list[dict]] = {}
    for a in doc["annotations"]:
        if not isinstance(a, dict) or "image_id" not in a:
            raise InputError(f"{path}: every annotation needs an 'image_id'")
        by_image.setdefault(a["image_id"], []).append(a)
    out = []
    for i, img in enumerate(doc["images"]):
        try:
            h, w, iid = int(img["height"]), int(img["width"]), img["id"]
        except (KeyError, TypeError, ValueError):
            raise InputError(f"{path}: images[{i}] needs integer 'id', 'width' and 'height'") from None
        out.append((img, Instances.from_annotations(by_image.get(iid, []), h, w,
                                                    where=f"{path}: image {iid} ")))
    return out
