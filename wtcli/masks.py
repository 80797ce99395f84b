"""Instance masks in memory (``Instances``) and on disk (COCO-compatible instances JSON).

Used by ``synth`` (ground truth), ``segment`` (predictions) and ``contours`` (input).
Masks are bool arrays [N, H, W]; boxes are xyxy pixels in memory and xywh in COCO files.
Segmentation on disk is uncompressed RLE ``{"counts": [...], "size": [H, W]}`` (column-major,
starting with a background run) or polygons ``[[x1, y1, x2, y2, ...], ...]`` (formats.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import cv2
import numpy as np

from wtcli.errors import InputError
from wtcli.jsonio import (atomic_write_bytes, document, dumps_streamed, number, read_json,
                          shown, write_json)

LABELS = ("blade", "tower", "nacelle")
CATEGORIES = [{"id": i + 1, "name": n, "supercategory": "wind_turbine"} for i, n in enumerate(LABELS)]
# A pixel shows one part. A segmenter's blade mask runs on under what covers the blade's root or
# middle (hub and nacelle; the tower in front of the lower blade seen from behind): on 100
# development renders such overlaps were truly tower 2:1 and nacelle 2.6:1 (docs/segment.md).
# Painted in this order: nacelle over tower over blade.
CLASS_MAP_ORDER = ("blade", "tower", "nacelle")
INSTANCES_SCHEMA = "wtinspect.instances"
INSTANCES_VERSION = 1
# The largest image (width x height) an instances file may declare: 200 megapixels, above the
# 100-150 MP of inspection cameras. Checked before any mask is allocated, so a file declaring
# 200000 x 200000 is refused at once instead of trying to allocate 37 GiB per mask.
MAX_IMAGE_PIXELS = 200_000_000


def rle_encode(mask: np.ndarray) -> dict[str, Any]:
    """Uncompressed COCO RLE of a bool mask [H, W]."""
    return {"counts": _runs(mask).tolist(), "size": [int(mask.shape[0]), int(mask.shape[1])]}


def _runs(mask: np.ndarray) -> np.ndarray:
    """A bool mask's uncompressed RLE run lengths (column-major, background first), int64."""
    flat = np.asarray(mask, dtype=bool).flatten(order="F")
    if flat.size == 0:
        return np.zeros(0, np.int64)
    change = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    counts = np.diff(np.concatenate([[0], change, [flat.size]]))
    return np.concatenate([[0], counts]) if flat[0] else counts


def _rle_counts(rle: dict[str, Any]) -> tuple[int, int, np.ndarray]:
    """(H, W, run lengths) of an uncompressed RLE, checked without expanding it."""
    size = rle["size"]
    if not isinstance(size, list) or len(size) != 2:
        raise ValueError(f"RLE size: expected [H, W], got {shown(size)}")
    h, w = (check_size(v, f"RLE size[{i}]") for i, v in enumerate(size))
    check_pixels(h, w, "RLE size")
    counts = rle["counts"]
    if isinstance(counts, str):
        raise ValueError("compressed RLE strings are not supported; write uncompressed RLE "
                         "(counts as a list of integers) or polygons")
    if not isinstance(counts, list):
        raise ValueError(f"RLE counts: expected a list of integers, got {shown(counts)}")
    for i, c in enumerate(counts):
        if isinstance(c, bool) or not isinstance(c, int) or not 0 <= c <= h * w:
            raise ValueError(f"RLE counts[{i}]: expected an integer in [0, {h * w}], got {shown(c)}")
    runs = np.asarray(counts, dtype=np.int64)
    if runs.sum() != h * w:
        raise ValueError(f"RLE counts sum to {int(runs.sum())}, expected {h * w} (= H*W)")
    return h, w, runs.astype(np.int32)  # each <= MAX_IMAGE_PIXELS: half the memory of int64


def _draw_rle(runs: np.ndarray, h: int, w: int) -> np.ndarray:
    values = np.arange(len(runs)) % 2 == 1
    return np.repeat(values, runs).reshape((h, w), order="F")


def rle_decode(rle: dict[str, Any]) -> np.ndarray:
    h, w, runs = _rle_counts(rle)
    return _draw_rle(runs, h, w)


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


def _polygon_points(polys: list[list[float]], h: int, w: int) -> tuple[np.ndarray, ...]:
    """Polygons checked against an image of h x w: int32 (n, 2) points in 1/16 px, as
    ``cv2.fillPoly(..., shift=4)`` draws them."""
    out = []
    for k, p in enumerate(polys):
        if not isinstance(p, list) or len(p) < 6 or len(p) % 2:
            raise ValueError(f"polygon {k}: needs >= 3 (x, y) points, got {shown(p)}")
        for i, v in enumerate(p):
            # Within the image extended by its own size on each side: any real polygon, and
            # far from the int32 overflow of the fixed-point fill (1e12 would wrap silently).
            lim = w if i % 2 == 0 else h
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or not -lim <= v <= 2 * lim:
                raise ValueError(f"polygon {k}[{i}]: expected a coordinate in [{-lim}, {2 * lim}] "
                                 f"(the image is {w}x{h}), got {shown(v)}")
        out.append(np.round(np.asarray(p, float).reshape(-1, 2) * 16).astype(np.int32))
    return tuple(out)


def _draw_polygons(points: tuple[np.ndarray, ...], h: int, w: int) -> np.ndarray:
    canvas = np.zeros((h, w), np.uint8)
    for pts in points:
        cv2.fillPoly(canvas, [pts], 1, shift=4)
    return canvas.astype(bool)


def polygons_decode(polys: list[list[float]], h: int, w: int) -> np.ndarray:
    return _draw_polygons(_polygon_points(polys, h, w), h, w)


@dataclass(frozen=True, eq=False)
class Shape:
    """One annotation's segmentation, checked against its image but not drawn: an RLE's run
    lengths or polygons' points, a few kB where the drawn mask [H, W] is H*W bytes. ``mask()``
    draws it."""

    height: int
    width: int
    runs: np.ndarray | None = None  # uncompressed RLE run lengths, int32, background first
    polygons: tuple[np.ndarray, ...] = ()  # int32 (n, 2) points in 1/16 px

    @classmethod
    def of_mask(cls, mask: np.ndarray) -> Shape:
        """A drawn mask [H, W] kept as its run lengths (a blade in a 12 MP photo: ~30 kB
        against 12 MB drawn, 1.5 MB as packed bits)."""
        h, w = mask.shape
        return cls(int(h), int(w), runs=_runs(mask).astype(np.int32))

    def mask(self) -> np.ndarray:
        """bool [H, W]."""
        if self.runs is not None:
            return _draw_rle(self.runs, self.height, self.width)
        return _draw_polygons(self.polygons, self.height, self.width)


def check_segmentation(seg: Any, h: int, w: int) -> Shape:
    """A COCO segmentation (uncompressed RLE or polygons) checked for an image of h x w,
    without drawing it; ValueError (or KeyError for a missing RLE key) says what is wrong."""
    if isinstance(seg, dict):
        rh, rw, runs = _rle_counts(seg)
        if (rh, rw) != (h, w):
            raise ValueError(f"RLE size {[rh, rw]} does not match the image {h}x{w}")
        return Shape(h, w, runs=runs)
    if isinstance(seg, list):
        return Shape(h, w, polygons=_polygon_points(seg, h, w))
    raise ValueError(f"segmentation must be RLE (dict) or polygons (list), got {type(seg).__name__}")


def decode_segmentation(seg: Any, h: int, w: int) -> np.ndarray:
    return check_segmentation(seg, h, w).mask()


def check_bbox(box: Any, h: int, w: int) -> list[float]:
    """A COCO bbox [x, y, width, height] checked for an image of h x w -> xyxy (ValueError or
    InputError naming ``bbox``)."""
    if not isinstance(box, list) or len(box) != 4:
        raise ValueError(f"bbox: expected [x, y, width, height], got {shown(box)}")
    x, y = (number(v, "bbox", -w, 2 * w if i == 0 else 2 * h) for i, v in enumerate(box[:2]))
    bw, bh = (number(v, "bbox width/height", 0, 3 * max(h, w)) for v in box[2:])
    return [x, y, x + bw, y + bh]


def check_size(value: Any, where: str) -> int:
    """An image side read from a file: an integer >= 1 (ValueError naming ``where``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or value != int(value) or value < 1:
        raise ValueError(f"{where}: expected an integer >= 1, got {shown(value)}")
    return int(value)


def check_pixels(h: int, w: int, where: str) -> None:
    """Refuse an image larger than MAX_IMAGE_PIXELS before anything is allocated for it."""
    if h * w > MAX_IMAGE_PIXELS:
        raise ValueError(f"{where}: {w}x{h} is {h * w:,} pixels, over the limit of "
                         f"{MAX_IMAGE_PIXELS:,} (docs/exit-codes.md)")


def declared_size(data: np.ndarray) -> tuple[int, int] | None:
    """(width, height) a PNG, JPEG, TIFF, BMP or WebP file declares in its header, read without
    decoding it (so a small file declaring a huge image is refused before anything is
    allocated); None for other formats or a header too damaged to tell (the decoder then
    decides). The format is told from the bytes, not the file name: OpenCV decodes by content."""
    b = data[:1 << 20].tobytes()
    if b[:8] == b"\x89PNG\r\n\x1a\n" and len(b) >= 24 and b[12:16] == b"IHDR":
        return int.from_bytes(b[16:20], "big"), int.from_bytes(b[20:24], "big")
    if b[:4] in (b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"):
        return _tiff_size(data)
    if b[:2] == b"BM" and len(b) >= 26:
        if int.from_bytes(b[14:18], "little") == 12:  # OS/2 BITMAPCOREHEADER: 16-bit sides
            return int.from_bytes(b[18:20], "little"), int.from_bytes(b[20:22], "little")
        w = int.from_bytes(b[18:22], "little", signed=True)
        h = int.from_bytes(b[22:26], "little", signed=True)  # negative: stored top-down
        return abs(w), abs(h)
    if b[:4] == b"RIFF" and b[8:12] == b"WEBP" and len(b) >= 30:
        chunk = b[12:16]
        if chunk == b"VP8X":  # extended: canvas width-1 and height-1, 24 bits each
            return int.from_bytes(b[24:27], "little") + 1, int.from_bytes(b[27:30], "little") + 1
        if chunk == b"VP8L":  # lossless: 14 bits width-1, 14 bits height-1
            bits = int.from_bytes(b[21:25], "little")
            return (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1
        if chunk == b"VP8 ":  # lossy key frame: 14-bit sides after the start code
            return (int.from_bytes(b[26:28], "little") & 0x3FFF,
                    int.from_bytes(b[28:30], "little") & 0x3FFF)
        return None
    if b[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 9 <= len(b):  # JPEG segments: FF marker, 2-byte length; SOFn holds H and W
        if b[i] != 0xFF:
            return None
        marker = b[i + 1]
        if marker == 0xFF:
            i += 1
            continue
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            return int.from_bytes(b[i + 7:i + 9], "big"), int.from_bytes(b[i + 5:i + 7], "big")
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
            i += 2
            continue
        i += 2 + int.from_bytes(b[i + 2:i + 4], "big")
    return None


def _tiff_size(data: np.ndarray) -> tuple[int, int] | None:
    """ImageWidth (tag 256) and ImageLength (257) of a TIFF's first IFD (the page OpenCV
    decodes), classic or BigTIFF, either byte order, SHORT/LONG/LONG8 values; None if the IFD
    lies outside the file or lacks either tag."""
    order = "little" if data[0] == ord("I") else "big"
    big = int(data[2]) == 43 or int(data[3]) == 43

    def num(at: int, n: int) -> int | None:
        return int.from_bytes(data[at:at + n].tobytes(), order) if 0 <= at and at + n <= len(data) \
            else None

    ifd = num(8, 8) if big else num(4, 4)
    head, entry, count_n, value_at = (8, 20, 8, 12) if big else (2, 12, 4, 8)
    entries = num(ifd, head) if ifd is not None else None
    if entries is None:
        return None
    sizes = {3: 2, 4: 4, 16: 8}  # SHORT, LONG, LONG8
    found: dict[int, int] = {}
    for k in range(min(entries, 4096)):
        at = ifd + head + k * entry
        tag, kind = num(at, 2), num(at + 2, 2)
        if tag is None or kind is None:
            return None
        if tag in (256, 257) and kind in sizes:
            value = num(at + value_at, sizes[kind])
            if value is None:
                return None
            found[tag] = value
    if 256 in found and 257 in found:
        return found[256], found[257]
    return None


def check_declared_size(data: np.ndarray, path: str | Path) -> None:
    """InputError naming ``path`` if its header (``declared_size``) declares more than
    MAX_IMAGE_PIXELS."""
    size = declared_size(data)
    if size is not None and size[0] * size[1] > MAX_IMAGE_PIXELS:
        raise InputError(f"{path}: image too large to decode ({size[0]}x{size[1]} is "
                         f"{size[0] * size[1]:,} pixels, over the limit of {MAX_IMAGE_PIXELS:,}, "
                         "docs/exit-codes.md); downscale it first")


HEADER_BYTES = 1 << 20  # what ``declared_size`` looks at: far past any header's size fields


def file_declared_size(path: str | Path) -> tuple[int, int] | None:
    """(width, height) the image file at ``path`` declares in its header (``declared_size``),
    read without decoding it: its first MiB, or a TIFF's whole file when the tags of its first
    page lie further on. InputError naming ``path`` when it cannot be read or declares more than
    MAX_IMAGE_PIXELS; None when the header does not tell (the decoder then decides)."""
    path = Path(path)
    try:
        with path.open("rb") as f:
            head = np.frombuffer(f.read(HEADER_BYTES), np.uint8)
            size = declared_size(head)
            if size is None and head[:4].tobytes() in (b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"):
                f.seek(0)
                head = np.frombuffer(f.read(), np.uint8)
                size = declared_size(head)
    except OSError as e:
        raise InputError(f"{path}: unreadable ({e.strerror or e.__class__.__name__})") from None
    check_declared_size(head, path)
    return size


def read_labelled_image(path: str | Path, size: tuple[int, int] | None = None,
               flags: int = cv2.IMREAD_COLOR) -> np.ndarray | None:
    """The image at ``path`` decoded (``cv2.imread``; None if it cannot be), refused from its
    header first when over MAX_IMAGE_PIXELS. OpenCV turns a JPEG by its EXIF orientation; with
    ``size`` (H, W) the size its labels were drawn at, a photo turned a quarter away from that
    size is read as stored instead: the labels were drawn on the stored pixels."""
    file_declared_size(path)
    img = cv2.imread(str(path), flags)
    if img is not None and size is not None and img.shape[:2] != tuple(size) \
            and img.shape[:2] == tuple(size)[::-1]:
        stored = cv2.imread(str(path), flags | cv2.IMREAD_IGNORE_ORIENTATION)
        if stored is not None and stored.shape[:2] == tuple(size):
            return stored
    return img


def image_size_as_read(path: str | Path, size: tuple[int, int]) -> tuple[int, int] | None:
    """(H, W) ``read_labelled_image(path, size)`` will give, from the header where that tells it (the
    stored size is ``size``, or differs from it other than by a quarter turn), otherwise by
    decoding it once; None if it cannot be decoded. InputError as ``file_declared_size``."""
    declared = file_declared_size(path)
    if declared is not None:
        stored = (declared[1], declared[0])
        if stored == tuple(size) or stored[::-1] != tuple(size):
            return stored
    img = read_labelled_image(path, size)  # no header read, or turned: only the decoder knows
    return None if img is None else (int(img.shape[0]), int(img.shape[1]))


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

    def class_map(self) -> np.ndarray:
        """uint8 [H, W]: each pixel's category id (1 blade, 2 tower, 3 nacelle; 0 background).
        Where masks of different classes overlap, the later class of ``CLASS_MAP_ORDER`` shows."""
        out = np.zeros(self.image_size, np.uint8)
        for label in CLASS_MAP_ORDER:
            out[self.of(label).union()] = LABELS.index(label) + 1
        return out

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
                if not isinstance(a, dict):
                    raise ValueError(f"expected an object, got {shown(a)}")
                cid = number(a["category_id"], "category_id", 1, len(LABELS), integer=True)
                score = number(a.get("score", 1.0), "score", 0.0, 1.0)
                box = a.get("bbox")
                if box is not None:
                    box = check_bbox(box, h, w)
                m = decode_segmentation(a["segmentation"], h, w)
            except KeyError as e:
                raise InputError(f"{at}: missing key {e.args[0]!r}") from None
            except (TypeError, ValueError) as e:
                raise InputError(f"{at}: {e}") from None
            except InputError as e:
                raise InputError(f"{at}.{e}") from None
            labels.append(LABELS[cid - 1])
            masks.append(m)
            scores.append(score)
            boxes.append(box if box is not None else mask_box(m).tolist())
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


def write_instances_streamed(path: str | Path, images: list[dict],
                             annotations: Iterable[list[dict]], extra: dict | None = None) -> Path:
    """``write_instances``, byte for byte, from each image's annotations as they come (e.g. read
    back from a file per image), renumbered: one image's masks in memory at a time, where
    ``instances_document`` holds every image's (a thousand 20 MP photos: tens of GB).
    ``annotations``: per image of ``images``, in order, its COCO annotations (their ``id`` and
    ``image_id`` are replaced)."""
    body = {"info": {"description": "wtinspect instances"}, "licenses": [], "images": images,
            "annotations": [], "categories": CATEGORIES, **(extra or {})}

    def renumbered():
        n = 0
        for img, anns in zip(images, annotations, strict=True):
            for a in anns:
                n += 1
                yield {**a, "id": n, "image_id": int(img["id"])}

    return atomic_write_bytes(path, dumps_streamed(
        document(INSTANCES_SCHEMA, INSTANCES_VERSION, body), "annotations", renumbered()))


def read_coco_document(path: str | Path) -> dict:
    """A COCO instances file's document (ours, or any COCO-compatible one), its top-level
    lists checked; ``categories`` defaults to ours."""
    path = Path(path)
    doc = read_json(path, INSTANCES_SCHEMA, INSTANCES_VERSION, header_required=False)
    if not isinstance(doc, dict) or not isinstance(doc.get("images"), list) \
            or not isinstance(doc.get("annotations"), list):
        raise InputError(f"{path}: expected a COCO instances JSON with 'images' and 'annotations' lists")
    categories = doc.setdefault("categories", CATEGORIES)
    if not isinstance(categories, list) or not all(isinstance(c, dict) for c in categories):
        raise InputError(f"{path}: categories: expected a list of objects, got {shown(categories)}")
    return doc


def coco_images(path: str | Path, doc: dict) -> list[tuple[dict, int, int, list[dict]]]:
    """(image entry, H, W, its annotations) per image of a ``read_coco_document``, sizes and
    ids checked, the annotations not yet."""
    by_image: dict[int, list[dict]] = {}
    for a in doc["annotations"]:
        if not isinstance(a, dict) or isinstance(a.get("image_id"), bool) \
                or not isinstance(a.get("image_id"), (int, str)):
            raise InputError(f"{path}: every annotation needs an integer 'image_id', got "
                             f"{shown(a.get('image_id') if isinstance(a, dict) else a)}")
        by_image.setdefault(a["image_id"], []).append(a)
    known = {img.get("id") for img in doc["images"]
             if isinstance(img, dict) and isinstance(img.get("id"), (int, str))}
    lost = [k for k in by_image if k not in known]
    if lost:  # an export whose ids do not meet (text "1" against 1) would train on nothing
        n = sum(len(by_image[k]) for k in lost)
        raise InputError(f"{path}: {n} annotation(s) name an image_id no image has (e.g. "
                         f"{shown(lost[0])}; image ids are e.g. {shown(next(iter(known), None))})")
    out = []
    for i, img in enumerate(doc["images"]):
        if not isinstance(img, dict) or not all(k in img for k in ("id", "width", "height")):
            raise InputError(f"{path}: images[{i}] needs integer 'id', 'width' and 'height'")
        try:
            h, w = check_size(img["height"], "height"), check_size(img["width"], "width")
            check_pixels(h, w, "width x height")
            iid = img["id"]
            if isinstance(iid, bool) or not isinstance(iid, (int, str)):
                raise ValueError(f"id: expected an integer, got {shown(iid)}")
            for key in ("file_name", "path"):  # later joined to folders, shown, written
                v = img.get(key)
                if v is not None and (not isinstance(v, str) or len(v) > 1024 or "\0" in v):
                    raise ValueError(f"{key}: expected a file name (text, at most 1024 "
                                     f"characters), got {shown(v)}")
        except (TypeError, ValueError) as e:
            raise InputError(f"{path}: images[{i}].{e}") from None
        out.append((img, h, w, by_image.get(iid, [])))
    return out


def read_instances(path: str | Path) -> list[tuple[dict, Instances]]:
    """Read a COCO instances file (ours, or any COCO-compatible one with our category names
    and ids), every mask drawn."""
    return list(InstancesFile(path))


class InstancesFile:
    """A COCO instances file read and checked up front (sizes, ids, categories), each image's
    masks drawn only as it is reached, one image at a time: a file of a thousand 20 MP photos
    holds their runs (about 1 GB as Python numbers), never all their full-size masks (tens of
    GB). ``len()`` counts the images; iterating gives (image record, Instances); a bad
    annotation is InputError naming the image when its image is reached."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        doc = read_coco_document(self.path)
        cats = {c.get("id"): c.get("name") for c in doc["categories"]}
        if any(cats.get(i + 1) != n for i, n in enumerate(LABELS)):
            raise InputError(f"{self.path}: categories must be {[c['name'] for c in CATEGORIES]} "
                             f"with ids 1..3, got {shown(list(cats.items()))}")
        self.items = coco_images(self.path, doc)

    def __len__(self) -> int:
        return len(self.items)

    def __iter__(self):
        for img, h, w, anns in self.items:
            yield img, Instances.from_annotations(anns, h, w, where=f"{self.path}: image {shown(img['id'])} ")
