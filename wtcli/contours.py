"""Step 1.3 of the paper: instance masks -> binarised masks (eq. 4) -> contours (eq. 5) ->
area filter (eq. 6). The result is a typed ``ContourSet`` per image; ``pitch`` reads it.

Conventions: contours are integer pixel coordinates (x right, y down), each an (K, 2) int32
array as ``cv2.findContours`` returns it (outer boundaries only, ``RETR_EXTERNAL``, straight
runs compressed with ``CHAIN_APPROX_SIMPLE``: filling the polygon gives back the region exactly).

The area A(c) of eq. 6 is the number of pixels in the region the contour encloses, not the
polygon area through the boundary pixel centres (``cv2.contourArea``), which is 0 for a blade one
pixel wide and about half the perimeter too small in general.

Inputs: a COCO instances JSON (``wtinspect.instances``, written by ``segment`` and ``synth``)
or mask PNGs (one single-channel binary PNG per instance, or one label PNG whose pixel value is
the instance id). Files: ``wtinspect.contours`` schema version 1 (docs/contours.md).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Sized

import cv2
import numpy as np

from wtcli.console import StageProgress, stage_ticker
from wtcli.errors import InputError, PerceptionError
from wtcli.jsonio import atomic_write_bytes, document, dumps_streamed, read_json, shown
from wtcli.masks import (LABELS, Instances, InstancesFile, check_declared_size, check_pixels,
                         check_size)

CONTOURS_SCHEMA = "wtinspect.contours"
CONTOURS_VERSION = 1
DEFAULT_AREA_THRESHOLD = 20.0  # px; eq. 6 A_threshold: specks only (select_rotor drops far turbines)
MASK_SUFFIXES = (".png", ".bmp", ".tif", ".tiff")


# ---- eq. 4-6 -------------------------------------------------------------------------------
def binarise(mask: np.ndarray) -> np.ndarray:
    """Eq. 4: M_b(x, y) = 1 where M(x, y) = 1 (any non-zero value), else 0; uint8 (H, W)."""
    m = np.asarray(mask)
    if m.ndim != 2:
        raise ValueError(f"expected a mask [H, W], got shape {m.shape}")
    return (m > 0).astype(np.uint8)


def region_area(contour: np.ndarray) -> int:
    """Pixels enclosed by one contour (its filled region, boundary included)."""
    c = np.asarray(contour, np.int32).reshape(-1, 2)
    x0, y0 = c.min(axis=0)
    x1, y1 = c.max(axis=0)
    roi = np.zeros((y1 - y0 + 1, x1 - x0 + 1), np.uint8)
    cv2.drawContours(roi, [(c - [x0, y0]).reshape(-1, 1, 2)], -1, 1, thickness=cv2.FILLED)
    return int(roi.sum())


def mask_contours(mask: np.ndarray) -> list[np.ndarray]:
    """Eq. 5: outer contours of a binarised mask, each (K, 2) int32."""
    found, _ = cv2.findContours(binarise(mask), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    return [c.reshape(-1, 2).astype(np.int32) for c in found]


# ---- typed result --------------------------------------------------------------------------
@dataclass(frozen=True)
class InstanceContours:
    """The contours of one instance that passed the area filter (eq. 6)."""

    label: str  # blade | tower | nacelle
    score: float  # detection score in [0, 1]; 1 for ground truth
    source_index: int  # index of the instance in its image (annotation order)
    contours: tuple[np.ndarray, ...]  # each (K, 2) int32, x right, y down
    areas: tuple[int, ...]  # A(c) of each contour, pixels

    def __post_init__(self) -> None:
        if self.label not in LABELS:
            raise ValueError(f"expected label in {LABELS}, got {self.label!r}")
        if not 0.0 <= float(self.score) <= 1.0:
            raise ValueError(f"expected score in [0, 1], got {self.score}")
        cs = tuple(np.asarray(c, np.int32).reshape(-1, 2) for c in self.contours)
        if not cs:
            raise ValueError("expected at least one contour")
        if any(len(c) == 0 for c in cs):
            raise ValueError("expected contours with at least one point")
        areas = tuple(int(a) for a in self.areas)
        if len(areas) != len(cs) or any(a <= 0 for a in areas):
            raise ValueError(f"expected {len(cs)} positive areas, got {list(self.areas)}")
        object.__setattr__(self, "contours", cs)
        object.__setattr__(self, "areas", areas)
        object.__setattr__(self, "score", float(self.score))
        object.__setattr__(self, "source_index", int(self.source_index))

    @property
    def area(self) -> int:
        return int(sum(self.areas))

    @property
    def points(self) -> np.ndarray:
        """All contour points together, (K, 2) int32."""
        return np.concatenate(self.contours)

    def fill(self, shape: tuple[int, int] | None = None) -> np.ndarray:
        """The region as a bool mask; with ``shape`` (H, W) in image coordinates, else in its
        bounding box (see ``bbox``)."""
        if shape is None:
            x0, y0, x1, y1 = self.bbox
            canvas = np.zeros((y1 - y0, x1 - x0), np.uint8)
            off = np.array([x0, y0], np.int32)
        else:
            canvas = np.zeros(shape, np.uint8)
            off = np.zeros(2, np.int32)
        cv2.drawContours(canvas, [(c - off).reshape(-1, 1, 2) for c in self.contours], -1, 1,
                         thickness=cv2.FILLED)
        return canvas.astype(bool)

    @property
    def bbox(self) -> tuple[int, int, int, int]:
        """xyxy, exclusive max."""
        p = self.points
        return (int(p[:, 0].min()), int(p[:, 1].min()), int(p[:, 0].max()) + 1,
                int(p[:, 1].max()) + 1)

    def to_dict(self) -> dict[str, Any]:
        return {"label": self.label, "score": self.score, "source_index": self.source_index,
                "area": self.area, "areas": list(self.areas),
                "contours": [c.tolist() for c in self.contours]}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> InstanceContours:
        return cls(d["label"], float(d.get("score", 1.0)), int(d["source_index"]),
                   tuple(np.asarray(c, np.int32).reshape(-1, 2) for c in d["contours"]),
                   tuple(d["areas"]))


@dataclass(frozen=True)
class ContourSet:
    """Filtered contours of the instances of one image (the paper's C_filtered, eq. 6).

    Filter like ``cs.of("blade")`` or ``cs[[0, 2]]``."""

    instances: tuple[InstanceContours, ...]
    image_size: tuple[int, int]  # (H, W)
    area_threshold: float  # px; contours with A(c) > this were kept
    image: dict = field(default_factory=dict)  # the COCO image record (id, file_name, ...)
    source: str = ""  # the file the masks came from
    dropped: int = 0  # contours removed by the area filter
    largest_dropped_area: int = 0  # px, to explain an empty result

    def __post_init__(self) -> None:
        h, w = (int(v) for v in self.image_size)
        if h <= 0 or w <= 0:
            raise ValueError(f"expected a positive image size (H, W), got {self.image_size}")
        if not np.isfinite(self.area_threshold) or self.area_threshold < 0:
            raise ValueError(f"expected area_threshold >= 0, got {self.area_threshold}")
        insts = tuple(self.instances)
        for inst in insts:
            if not isinstance(inst, InstanceContours):
                raise ValueError(f"expected InstanceContours, got {type(inst).__name__}")
            p = inst.points
            if (p < 0).any() or (p[:, 0] >= w).any() or (p[:, 1] >= h).any():
                raise ValueError(f"expected contour points inside the {w}x{h} image "
                                 f"({inst.label} {inst.source_index})")
        object.__setattr__(self, "instances", insts)
        object.__setattr__(self, "image_size", (h, w))
        object.__setattr__(self, "area_threshold", float(self.area_threshold))
        object.__setattr__(self, "image", dict(self.image or {}))

    def __len__(self) -> int:
        return len(self.instances)

    def __iter__(self) -> Iterator[InstanceContours]:
        return iter(self.instances)

    def __getitem__(self, idx: Any) -> ContourSet:
        sel = np.arange(len(self))[idx]
        keep = tuple(self.instances[int(i)] for i in np.atleast_1d(sel))
        return ContourSet(keep, self.image_size, self.area_threshold, self.image, self.source,
                          self.dropped, self.largest_dropped_area)

    @property
    def labels(self) -> np.ndarray:
        return np.array([i.label for i in self.instances], dtype=object)

    @property
    def scores(self) -> np.ndarray:
        return np.array([i.score for i in self.instances], float)

    @property
    def areas(self) -> np.ndarray:
        return np.array([i.area for i in self.instances], float)

    def of(self, label: str) -> ContourSet:
        return self[self.labels == label] if len(self) else self

    @property
    def name(self) -> str:
        """How to name this image in messages: its file name, else the source file."""
        fn = self.image.get("file_name")
        if fn:
            return str(fn)
        if "id" in self.image:
            return f"{self.source} image {self.image['id']}"
        return self.source or "the input"

    def to_dict(self) -> dict[str, Any]:
        return {"image": self.image, "image_size": list(self.image_size),
                "area_threshold": self.area_threshold, "dropped": self.dropped,
                "largest_dropped_area": self.largest_dropped_area,
                "instances": [i.to_dict() for i in self.instances]}

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = "") -> ContourSet:
        return cls(tuple(InstanceContours.from_dict(i) for i in d["instances"]),
                   tuple(d["image_size"]), float(d["area_threshold"]), d.get("image") or {},
                   source, int(d.get("dropped", 0)), int(d.get("largest_dropped_area", 0)))


def find_contours(instances: Instances, area_threshold: float = DEFAULT_AREA_THRESHOLD,
                  image: dict | None = None, source: str = "") -> ContourSet:
    """Eq. 4-6 for every instance of one image. Instances left without a contour are dropped
    (their annotation index stays in ``source_index`` of the others). May return an empty set."""
    if not np.isfinite(area_threshold) or area_threshold < 0:
        raise ValueError(f"expected area_threshold >= 0, got {area_threshold}")
    kept: list[InstanceContours] = []
    dropped, largest_dropped = 0, 0
    for i in range(len(instances)):
        cs, areas = [], []
        for c in mask_contours(instances.masks[i]):
            a = region_area(c)
            if a > area_threshold:  # eq. 6, strict
                cs.append(c)
                areas.append(a)
            else:
                dropped += 1
                largest_dropped = max(largest_dropped, a)
        if cs:
            kept.append(InstanceContours(str(instances.labels[i]), float(instances.scores[i]), i,
                                         tuple(cs), tuple(areas)))
    return ContourSet(tuple(kept), instances.image_size, area_threshold, image or {}, source,
                      dropped, largest_dropped)


def require_contours(cs: ContourSet) -> ContourSet:
    """Raise PerceptionError when nothing survived the area filter."""
    if len(cs) == 0:
        if cs.dropped:
            raise PerceptionError(
                f"no contour above the area threshold ({cs.area_threshold:g} px) in {cs.name}: "
                f"{cs.dropped} contour(s) dropped, the largest {cs.largest_dropped_area} px "
                "(lower --area-threshold?)")
        raise PerceptionError(f"no mask pixels in {cs.name} (no instance, or its masks are empty)")
    return cs


# ---- inputs ----------------------------------------------------------------------------------
_LABEL_FROM_NAME = re.compile(r"^(blade|tower|nacelle|hub)", re.I)


def read_mask_image(path: str | Path) -> np.ndarray:
    """A mask file as a 2-D integer array; InputError if unreadable or a colour photo."""
    path = Path(path)
    if not path.exists():
        from wtcli.jsonio import missing

        raise InputError(f"{path}: {missing(path)}")
    data = np.fromfile(str(path), np.uint8) if path.is_file() else np.zeros(0, np.uint8)
    check_declared_size(data, path)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if img is None:
        raise InputError(f"{path}: cannot read the image (empty, truncated or not an image)")
    if img.ndim == 3:
        if img.shape[2] == 4:
            img = img[:, :, :3]
        if not (np.array_equal(img[:, :, 0], img[:, :, 1])
                and np.array_equal(img[:, :, 1], img[:, :, 2])):
            raise InputError(f"{path}: a colour image, not a mask; masks are single-channel PNGs "
                             "(run `wtinspect segment` on photos first)")
        img = img[:, :, 0]
    if img.size == 0:
        raise InputError(f"{path}: the image is empty (0 pixels)")
    return np.asarray(img)


def instances_from_mask_files(paths: list[Path]) -> tuple[dict, Instances]:
    """Mask PNG(s) of one image -> (image record, Instances).

    A PNG with one non-zero value is one instance (binary mask); a PNG with several non-zero
    values is a label image, one instance per value. The label comes from the file name
    (``blade*``, ``tower*``, ``nacelle*``/``hub*``), else ``blade``."""
    if not paths:
        raise InputError("no mask files given")
    labels, masks = [], []
    shape = None
    for p in paths:
        img = read_mask_image(p)
        if shape is None:
            shape = img.shape
        elif img.shape != shape:
            raise InputError(f"{p}: size {img.shape[1]}x{img.shape[0]} differs from "
                             f"{paths[0]} ({shape[1]}x{shape[0]}); masks of one image must match")
        m = _LABEL_FROM_NAME.match(p.name)
        label = "blade" if m is None else ("nacelle" if m.group(1).lower() == "hub"
                                           else m.group(1).lower())
        values = [v for v in np.unique(img) if v != 0]
        for v in values:
            labels.append(label)
            masks.append(img == v)
    h, w = shape
    name = paths[0].name if len(paths) == 1 else ", ".join(p.name for p in paths)
    record = {"file_name": name, "width": int(w), "height": int(h)}
    if not masks:
        return record, Instances.empty(h, w)
    return record, Instances(np.array(labels, dtype=object), np.stack(masks))


def is_mask_file(path: Path) -> bool:
    return path.suffix.lower() in MASK_SUFFIXES


def load_instances(paths: list[Path]) -> tuple[str, Sized]:
    """INPUT of ``contours``: one instances JSON (every image in it) or mask PNGs of one image.
    Returns (source, images): ``len(images)`` images, iterated as (image record, instances),
    an instances file's masks drawn one image at a time (``InstancesFile``)."""
    paths = [Path(p) for p in paths]
    if not paths:
        raise InputError("no input given")
    if len(paths) == 1 and paths[0].suffix.lower() == ".json":
        doc_images = InstancesFile(paths[0])
        if not len(doc_images):
            raise InputError(f"{paths[0]}: no images in the instances file")
        return str(paths[0]), doc_images
    if all(is_mask_file(p) for p in paths):
        return str(paths[0]), [instances_from_mask_files(paths)]
    bad = next(p for p in paths if not is_mask_file(p))
    raise InputError(f"{bad}: expected an instances JSON or mask PNG files "
                     f"(one JSON, or {', '.join(MASK_SUFFIXES)} masks)")


# ---- files -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class ContoursBatch:
    """Contours of every image of an input; failed images carry their error message."""

    sets: tuple[ContourSet | None, ...]
    errors: tuple[str | None, ...]
    images: tuple[dict, ...]
    source: str
    area_threshold: float

    @property
    def n_failed(self) -> int:
        return sum(e is not None for e in self.errors)

    def to_document(self) -> dict[str, Any]:
        return {**self._header(), "images": list(self._items())}

    def write(self, path: str | Path) -> Path:
        """``write_json(path, self.to_document())``, byte for byte, one image's contours turned
        into JSON at a time (a folder's contours file can be hundreds of MB)."""
        return atomic_write_bytes(path, dumps_streamed(self._header(), "images", self._items()))

    def _header(self) -> dict[str, Any]:
        return document(CONTOURS_SCHEMA, CONTOURS_VERSION,
                        {"source": self.source, "area_threshold": self.area_threshold, "images": []})

    def _items(self) -> Iterator[dict[str, Any]]:
        for cs, err, img in zip(self.sets, self.errors, self.images):
            yield {"image": img, "error": err} if cs is None else {**cs.to_dict(), "error": None}


def contours_batch(paths: list[Path], area_threshold: float = DEFAULT_AREA_THRESHOLD,
                   progress: StageProgress | None = None) -> ContoursBatch:
    """``find_contours`` on every image of the input; an image where nothing survives the
    filter is recorded as failed, the others go on. ``progress``: stage "images", per image."""
    source, loaded = load_instances(paths)
    sets, errors, images = [], [], []
    tick = stage_ticker(progress, "images", len(loaded))
    for img, inst in loaded:
        cs = find_contours(inst, area_threshold, image=img, source=source)
        try:
            sets.append(require_contours(cs))
            errors.append(None)
        except PerceptionError as e:
            sets.append(None)
            errors.append(str(e))
        images.append(img)
        tick()
    return ContoursBatch(tuple(sets), tuple(errors), tuple(images), source, area_threshold)


def _check_numbers(d: dict[str, Any]) -> None:
    """The numbers of one image of a contours file a reader would trust: the image size within
    MAX_IMAGE_PIXELS, every contour point an integer within the image extended by its size."""
    size = d["image_size"]
    if not isinstance(size, list) or len(size) != 2:
        raise ValueError(f"image_size: expected [H, W], got {shown(size)}")
    h, w = check_size(size[0], "image_size[0]"), check_size(size[1], "image_size[1]")
    check_pixels(h, w, "image_size")
    if not isinstance(d["instances"], list):
        raise ValueError(f"instances: expected a list, got {shown(d['instances'])}")
    for k, inst in enumerate(d["instances"]):
        if not isinstance(inst, dict) or not isinstance(inst.get("contours"), list):
            raise ValueError(f"instances[{k}]: expected an object with a 'contours' list")
        for j, c in enumerate(inst["contours"]):
            pts = np.asarray(c, dtype=object).reshape(-1) if isinstance(c, list) else None
            if pts is None or not all(isinstance(v, int) and not isinstance(v, bool)
                                      and -2 * max(h, w) <= v <= 3 * max(h, w) for v in pts):
                raise ValueError(f"instances[{k}].contours[{j}]: expected [x, y] integer pixel "
                                 f"points within the {w}x{h} image, got {shown(c)}")


def read_contours(path: str | Path) -> list[tuple[ContourSet | None, str | None, dict]]:
    """Read a ``wtinspect.contours`` file: (set or None, error or None, image record) per image."""
    path = Path(path)
    doc = read_json(path, CONTOURS_SCHEMA, CONTOURS_VERSION)
    items = doc.get("images")
    if not isinstance(items, list):
        raise InputError(f"{path}: expected an 'images' list")
    out = []
    for i, d in enumerate(items):
        if not isinstance(d, dict):
            raise InputError(f"{path}: images[{i}] is not an object")
        img = d.get("image") or {}
        if not isinstance(img, dict):
            raise InputError(f"{path}: images[{i}].image: expected an object, got {shown(img)}")
        if d.get("error"):
            out.append((None, str(d["error"]), img))
            continue
        try:
            _check_numbers(d)
            cs = ContourSet.from_dict(d, source=str(doc.get("source", path)))
        except KeyError as e:
            raise InputError(f"{path}: images[{i}]: missing key {shown(e.args[0])}") from None
        except (TypeError, ValueError, OverflowError) as e:
            raise InputError(f"{path}: images[{i}]: {str(e)[:200]}") from None
        out.append((cs, None, img))
    return out
