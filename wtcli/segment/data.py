"""Training data for the segmenter: synthetic renders made on the fly, a COCO instances
dataset on disk (ours from `synth`, or the user's own annotated photos), or labelled real
photos (``RealDataset``: a folder of photos with semantic masks, split into instances by
``wtcli.segment.real``, or a COCO file), plus augmentation.

Images are BGR uint8 [H, W, 3] (OpenCV) until ``to_target`` turns them into the RGB float
tensors [3, H, W] in [0, 1] and target dicts (boxes xyxy float, labels 1..3, masks uint8)
torchvision's Mask R-CNN trains on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

from wtcli.errors import InputError
from wtcli.jsonio import number, shown
from wtcli.masks import (LABELS, Instances, Shape, check_bbox, check_segmentation, coco_images,
                         image_size_as_read, mask_box, read_coco_document, read_labelled_image)

TRAIN_SEED_BASE = 1_000_000  # synthetic training scenes use seeds TRAIN_SEED_BASE + i
DEV_SEED_BASE = 7_000_000  # development probes (choosing thresholds); never trained on
HELDOUT_SEED_BASE = 9_000_000  # benchmarks only; never trained on
MIN_INSTANCE_PIXELS = 24


@dataclass(frozen=True)
class Sample:
    image: np.ndarray  # BGR uint8 [H, W, 3]
    instances: Instances
    # [H, W] bool where the labels cannot say the class (a real photo's nacelle, whose masks
    # have no such class: ``training_instances``): proposals and anchors there teach nothing.
    ignore: np.ndarray | None = None


# ---- sources -------------------------------------------------------------------------------
def _fallback_render(seed: int, width: int, height: int, view: str | None = None) -> Sample:
    """Masks from the one geometry on a plain gradient sky: used only when the synthetic
    renderer (wtcli.synth.render) is not importable, e.g. while developing the trainer."""
    from wtcli.geometry.projection import instance_masks
    from wtcli.synth.scene import sample_scene

    rng = np.random.default_rng(seed)
    scene = sample_scene(rng, width, height, view)
    top, bottom = rng.uniform(120, 255, 3), rng.uniform(60, 230, 3)
    t = np.linspace(0, 1, height)[:, None, None]
    img = (top * (1 - t) + bottom * t) * np.ones((1, width, 1))
    inst = instance_masks(scene.turbine, scene.camera, min_pixels=MIN_INSTANCE_PIXELS)
    grey = rng.uniform(170, 250)
    for label, _, m in inst:
        img[m] = grey * {"blade": 1.0, "tower": 0.93, "nacelle": 0.85}[label] + rng.normal(0, 4, 3)
    img = np.clip(img + rng.normal(0, 3, img.shape), 0, 255).astype(np.uint8)
    if not inst:
        return Sample(img, Instances.empty(height, width))
    return Sample(img, Instances(np.array([i[0] for i in inst], dtype=object),
                                 np.stack([i[2] for i in inst])))


def render(seed: int, width: int, height: int, view: str | None = None, stops: float = 0.0,
           view_mix: str | None = None) -> Sample:
    """One synthetic scene: wtcli.synth.render.render_sample when available (``view_mix``: its
    shares of views, e.g. the wider ones, docs/synth.md; None: the default mix)."""
    try:
        from wtcli.synth.render import render_sample
    except ImportError:
        return _fallback_render(seed, width, height, view)
    if view_mix is None:  # as before view mixes existed: the same scenes, seed for seed
        s = render_sample(seed, width=width, height=height, view=view, stops=stops)
    else:
        s = render_sample(seed, width=width, height=height, view=view, stops=stops, view_mix=view_mix)
    return Sample(s.image, s.instances)


class SynthDataset(torch.utils.data.Dataset):
    """Scene ``i`` is the render of seed ``seed_base + i`` (deterministic, nothing stored)."""

    def __init__(self, length: int, width: int = 640, height: int = 480,
                 seed_base: int = TRAIN_SEED_BASE, augment: bool = True, aug_seed: int = 0,
                 stops: float = 0.0, view_mix: str | None = None):
        self.length, self.width, self.height = int(length), int(width), int(height)
        self.view_mix = view_mix
        self.seed_base, self.augment, self.aug_seed = int(seed_base), augment, int(aug_seed)
        self.stops = float(stops)  # render_sample's: rotors stopped in a Y / inverted Y

    def __len__(self) -> int:
        return self.length

    def __getitem__(self, i: int):
        s = render(self.seed_base + int(i), self.width, self.height, stops=self.stops,
                   view_mix=self.view_mix)
        if self.augment:
            s = augment(s, np.random.default_rng((self.aug_seed, self.seed_base + int(i))))
        return to_target(s)


@dataclass(frozen=True)
class CocoImage:
    """One image of a COCO file as training reads it: its annotations checked, not drawn
    (``CocoDataset.load`` draws them when the image is drawn), so memory holds the annotations
    and nothing the size of the image."""

    height: int
    width: int
    labels: tuple[str, ...]
    shapes: tuple[Shape, ...]  # the instances' segmentations, one per label
    # Crowd regions and annotations with a box but no mask: their box (xyxy), or a crowd
    # region's shape where it has no bbox. Trained as neither instance nor background.
    ignore: tuple[list[float] | Shape, ...] = ()


@dataclass
class CocoCounts:
    """What reading a COCO file for training left out of the instances (``notes``)."""

    crowd: int = 0  # iscrowd 1: ignore regions
    box_only: int = 0  # a bbox, no segmentation: ignore regions
    empty: int = 0  # neither a segmentation nor a bbox: nothing to use
    other: dict[str, int] = field(default_factory=dict)  # category name -> annotations skipped
    negatives: int = 0  # images with no instance: trained as background
    instances: int = 0


def read_training_coco(path: str | Path) -> tuple[list[tuple[dict, CocoImage]], CocoCounts]:
    """A COCO instances file as training data (docs/train.md, "Your own COCO data"): categories
    matched by name (blade, tower, nacelle in any case, whatever their ids); annotations of
    other categories skipped (background, as anything else in the photo); ``iscrowd`` 1 regions
    and box-only annotations kept as ignore regions. InputError when nothing is left to train
    on as an instance."""
    path = Path(path)
    doc = read_coco_document(path)
    names: dict[Any, str] = {}
    for k, c in enumerate(doc["categories"]):
        cid, name = c.get("id"), c.get("name")
        if isinstance(cid, bool) or not isinstance(cid, (int, str)) or not isinstance(name, str):
            raise InputError(f"{path}: categories[{k}]: expected an integer 'id' and a text "
                             f"'name', got {shown(c)}")
        if names.get(cid, name) != name:
            raise InputError(f"{path}: categories[{k}]: id {shown(cid)} is also "
                             f"{shown(names[cid])}")
        names[cid] = name
    trained = {cid: n.strip().lower() for cid, n in names.items() if n.strip().lower() in LABELS}
    if not trained:
        raise InputError(f"{path}: no category is blade, tower or nacelle (its categories: "
                         f"{shown(', '.join(names.values()))})")
    counts = CocoCounts()
    items = []
    for img, h, w, anns in coco_images(path, doc):
        labels, shapes, ignore = [], [], []
        for j, a in enumerate(anns):
            at = f"{path}: image {shown(img['id'])} annotations[{j}]"
            try:
                cid = a["category_id"]
                if isinstance(cid, bool) or not isinstance(cid, (int, str)) or cid not in names:
                    raise ValueError(f"category_id: expected one of the categories' ids "
                                     f"{shown(sorted(names, key=str))}, got {shown(cid)}")
                if cid not in trained:
                    counts.other[names[cid]] = counts.other.get(names[cid], 0) + 1
                    continue
                crowd = number(a.get("iscrowd", 0), "iscrowd", 0, 1, integer=True)
                box = check_bbox(a["bbox"], h, w) if a.get("bbox") is not None else None
                seg = a.get("segmentation")
                if crowd:  # only its extent is used: a compressed RLE with a bbox is fine
                    ignore.append(box if box is not None else check_segmentation(seg, h, w))
                    counts.crowd += 1
                elif seg is None or seg == []:
                    if box is None:
                        counts.empty += 1
                    else:
                        ignore.append(box)
                        counts.box_only += 1
                else:
                    number(a.get("score", 1.0), "score", 0.0, 1.0)
                    shapes.append(check_segmentation(seg, h, w))
                    labels.append(trained[cid])
            except KeyError as e:
                raise InputError(f"{at}: missing key {e.args[0]!r}") from None
            except (TypeError, ValueError) as e:
                raise InputError(f"{at}: {e}") from None
            except InputError as e:
                raise InputError(f"{at}.{e}") from None
        counts.instances += len(labels)
        counts.negatives += not labels
        items.append((img, CocoImage(h, w, tuple(labels), tuple(shapes), tuple(ignore))))
    if not items:
        raise InputError(f"{path}: the dataset has no images")
    if not counts.instances:
        raise InputError(f"{path}: no annotation to train on: none of its {len(doc['annotations'])} "
                         f"is a blade, tower or nacelle mask ({_left_out(counts) or 'no annotations'})")
    return items, counts


def _left_out(c: CocoCounts) -> str:
    parts = []
    if c.other:
        cats = ", ".join(f"{n} {k}" for n, k in sorted(c.other.items(), key=lambda t: (-t[1], t[0])))
        parts.append(f"{sum(c.other.values())} of categories not trained ({cats})")
    if c.crowd:
        parts.append(f"{c.crowd} crowd region(s) (iscrowd 1)")
    if c.box_only:
        parts.append(f"{c.box_only} box(es) without a mask")
    if c.empty:
        parts.append(f"{c.empty} with neither a mask nor a box")
    return "; ".join(parts)


class CocoDataset(torch.utils.data.Dataset):
    """A COCO instances JSON (``read_training_coco``); image files next to it, in ``images/``,
    or at their ``file_name`` path. Every image is found and its size checked against the file
    when the dataset is made (from its header where that tells it), so a run stops before it
    trains rather than when it first draws a bad one; masks are drawn per draw."""

    def __init__(self, path: str | Path, augment: bool = True, aug_seed: int = 0):
        path = Path(path)
        if path.is_dir():
            path = path / "instances.json"
        self.path, self.root = path, path.parent
        self.items, self.counts = read_training_coco(path)
        for info, im in self.items:
            p = self.image_path(info)
            got = image_size_as_read(p, (im.height, im.width))
            if got is None:
                raise InputError(f"{p}: not a readable image")
            if got != (im.height, im.width):
                raise InputError(f"{p}: image is {got[1]}x{got[0]} but {self.path} says "
                                 f"{im.width}x{im.height} (image {info.get('id')!r})")
        self.augment, self.aug_seed, self.epoch = augment, int(aug_seed), 0

    def __len__(self) -> int:
        return len(self.items)

    def notes(self) -> list[str]:
        """What the file holds beyond its instances, in a line, when anything (for the user)."""
        c = self.counts
        parts = [f"{c.instances} instance(s) in {len(self.items)} image(s)"]
        if c.negatives:
            parts.append(f"{c.negatives} image(s) with no instance (negatives: all background)")
        left = _left_out(c)
        if left:
            parts.append(f"ignored {left}")
        return [f"{self.path}: " + "; ".join(parts)] if c.negatives or left else []

    def image_path(self, info: dict) -> Path:
        name = str(info.get("file_name", ""))
        for cand in (self.root / name, self.root / "images" / name, Path(name)):
            if name and cand.is_file():
                return cand
        raise InputError(f"{self.path}: image {name!r} not found next to it or in images/")

    def load(self, i: int) -> Sample:
        info, im = self.items[i]
        p = self.image_path(info)
        img = read_labelled_image(p, (im.height, im.width))
        if img is None:
            raise InputError(f"{p}: not a readable image")
        if img.shape[:2] != (im.height, im.width):
            raise InputError(f"{p}: image is {img.shape[1]}x{img.shape[0]} but its annotations "
                             f"say {im.width}x{im.height}")
        ignore = None
        if im.ignore:
            ignore = np.zeros((im.height, im.width), bool)
            for region in im.ignore:
                x0, y0, x1, y1 = mask_box(region.mask()) if isinstance(region, Shape) else region
                ignore[max(0, math.floor(y0)): max(0, math.ceil(y1)),
                       max(0, math.floor(x0)): max(0, math.ceil(x1))] = True
            ignore = ignore if ignore.any() else None
        if not im.labels:
            return Sample(img, Instances.empty(im.height, im.width), ignore)
        masks = np.stack([s.mask() for s in im.shapes])
        return Sample(img, Instances(np.array(im.labels, dtype=object), masks), ignore)

    def __getitem__(self, i: int):
        s = self.load(i)
        if self.augment:
            s = augment(s, np.random.default_rng((self.aug_seed, self.epoch, int(i))))
        return to_target(s)


class RealDataset(torch.utils.data.Dataset):
    """Labelled real photos, flight sequences in ``holdout`` left out: a folder with
    ``manifest.csv`` and semantic masks (``wtcli.segment.real``; photos read at most
    ``real.MAX_SIDE`` px long, each split once and kept packed in memory), or a COCO instances
    file or folder (an image's ``sequence`` field names its sequence; without one, the
    sequences ``real.sequences`` derives from the file names)."""

    def __init__(self, path: str | Path, holdout: tuple[str, ...] = (), augment: bool = True,
                 aug_seed: int = 0):
        from wtcli.errors import ConfigError
        from wtcli.segment import real as R

        self.path = Path(path)
        self.coco: CocoDataset | None = None
        if R.is_photo_folder(self.path):
            self.photos = R.read_folder(self.path)
            for photo in self.photos:  # now, not when first drawn: minutes into a run
                R.check_photo(photo)
            seqs = [p.sequence for p in self.photos]
        else:
            if not self.path.exists():
                raise InputError(f"{self.path}: no such folder or file (a photo folder with "
                                 "manifest.csv, or a COCO instances JSON)")
            self.coco = CocoDataset(self.path, augment=False)
            self.photos = []
            infos = [info for info, _ in self.coco.items]
            derived = R.sequences([Path(str(i.get("file_name", ""))).stem for i in infos])
            seqs = [str(i.get("sequence") or d) for i, d in zip(infos, derived)]
        known = sorted(set(seqs))
        unknown = [q for q in holdout if q not in known]
        if unknown:
            raise ConfigError(f"--real-holdout-sequence {unknown[0]}: not a sequence of {self.path} "
                              f"(it has: {', '.join(known)})")
        self.sequences = seqs
        self.keep = [i for i, q in enumerate(seqs) if q not in set(holdout)]
        if not self.keep:
            raise ConfigError(f"{self.path}: every photo is held out (--real-holdout-sequence); "
                              "nothing left to train on")
        self.augment, self.aug_seed, self.epoch = augment, int(aug_seed), 0
        self._cache: dict[int, tuple[np.ndarray, np.ndarray, tuple[int, int]]] = {}

    def __len__(self) -> int:
        return len(self.keep)

    def notes(self) -> list[str]:
        return self.coco.notes() if self.coco is not None else []

    def load(self, i: int) -> Sample:
        k = self.keep[i]
        if self.coco is not None:
            return self.coco.load(k)
        from wtcli.segment import real as R

        img, sem = R.read_pair(self.photos[k])
        if k not in self._cache:  # the split is the slow part (~0.3 s a photo): once per process
            # Kept as run lengths: packed bits of every photo's masks took 8.7 MB a 9 MP photo
            # (the real photos' masks at 4000 x 2250), 24 kB as runs; each data worker has a copy.
            labels, masks, ignore = training_instances(R.split_semantic(sem, MIN_INSTANCE_PIXELS))
            self._cache[k] = (labels, tuple(Shape.of_mask(m) for m in masks), sem.shape,
                              None if ignore is None else Shape.of_mask(ignore))
        labels, shapes, (h, w), unk = self._cache[k]
        ignore = None if unk is None else unk.mask()
        if not len(labels):
            return Sample(img, Instances.empty(h, w), ignore)
        return Sample(img, Instances(labels, np.stack([m.mask() for m in shapes])), ignore)

    def __getitem__(self, i: int):
        s = self.load(i)
        if self.augment:
            s = augment(s, np.random.default_rng((self.aug_seed, 2, self.epoch, int(i))))
        return to_target(s)


def training_instances(split) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """A photo's split as training targets: (labels, masks, ignore). The photos' masks have no
    nacelle class, so the nacelle is left to the renders: a nacelle the split tells apart is a
    guess at its extent (rows of the tower's top), one it does not is somewhere in the tower's
    top (``split.unknown``). Both become ignore boxes, and the second is taken out of the tower."""
    inst = split.instances
    h, w = inst.image_size
    if not len(inst):
        return inst.labels, inst.masks.reshape(0, h, w), split.unknown
    ignore = np.zeros((h, w), bool) if split.unknown is None else split.unknown.copy()
    for m in inst.masks[inst.labels == "nacelle"]:
        ys, xs = np.nonzero(m)
        ignore[ys.min(): ys.max() + 1, xs.min(): xs.max() + 1] = True
    masks = inst.masks.copy()
    tower = inst.labels == "tower"
    masks[tower] &= ~ignore
    keep = (inst.labels != "nacelle") & (~tower | (masks.reshape(len(masks), -1).sum(axis=1)
                                                  >= MIN_INSTANCE_PIXELS))
    return inst.labels[keep], masks[keep], ignore if ignore.any() else None


class MixedDataset(torch.utils.data.Dataset):
    """Renders (or a ``--data`` COCO set) and real photos in one stream. Item ``("base", pos)``
    is the ``pos``-th base image drawn: for renders the scene ``pos`` on from the seed's own
    stretch (``synth_start``), for a dataset on disk each pass in its own order; ``("real",
    pos)`` likewise for the photos. Augmentation is keyed by the draw, so resuming repeats the
    stream exactly."""

    def __init__(self, base, real: RealDataset, seed: int = 0, synth_start: int = 0):
        self.base, self.real, self.seed = base, real, int(seed)
        self.synth_start = int(synth_start)

    def __len__(self) -> int:
        return len(self.base)

    @staticmethod
    def _index(n: int, seed: int, stream: int, pos: int) -> int:
        order = np.random.default_rng((seed, stream, pos // n)).permutation(n)
        return int(order[pos % n])

    def __getitem__(self, key):
        which, pos = key[0], int(key[1])
        if which == "base" and isinstance(self.base, SynthDataset):
            return self.base[(self.synth_start + pos) % len(self.base)]
        ds, stream = (self.base, 5) if which == "base" else (self.real, 3)
        s = ds.load(self._index(len(ds), self.seed, stream, pos))
        if ds.augment:
            s = augment(s, np.random.default_rng((ds.aug_seed, stream + 1, pos)))
        return to_target(s)


# ---- augmentation --------------------------------------------------------------------------
def augment(s: Sample, rng: np.random.Generator) -> Sample:
    """Photometric and geometric jitter on top of the renderer's own randomisation:
    horizontal flip, crop-and-rescale, brightness/contrast/saturation, blur, noise, JPEG."""
    img, inst = s.image, s.instances
    ignore = getattr(s, "ignore", None)  # renders (synth.SynthSample) label everything
    masks, labels = inst.masks, inst.labels
    h, w = img.shape[:2]
    if rng.random() < 0.5:
        img, masks = img[:, ::-1], masks[:, :, ::-1]
        ignore = None if ignore is None else ignore[:, ::-1]
    if rng.random() < 0.3:  # crop a part and scale it back to full size (closer views)
        f = rng.uniform(0.6, 0.95)
        ch, cw = int(h * f), int(w * f)
        y0, x0 = int(rng.integers(0, h - ch + 1)), int(rng.integers(0, w - cw + 1))
        img = cv2.resize(np.ascontiguousarray(img[y0:y0 + ch, x0:x0 + cw]), (w, h),
                         interpolation=cv2.INTER_LINEAR)
        # Masks scaled like the image (bilinear, then >= 0.5): nearest would shift them.
        masks = np.stack([cv2.resize(np.ascontiguousarray(m[y0:y0 + ch, x0:x0 + cw]).astype(np.float32),
                                     (w, h), interpolation=cv2.INTER_LINEAR) >= 0.5
                          for m in masks]) if len(masks) else np.zeros((0, h, w), bool)
        if ignore is not None:
            ignore = cv2.resize(np.ascontiguousarray(ignore[y0:y0 + ch, x0:x0 + cw]).astype(np.float32),
                                (w, h), interpolation=cv2.INTER_LINEAR) >= 0.5
    img = np.ascontiguousarray(img).astype(np.float32)
    if rng.random() < 0.8:
        img = img * rng.uniform(0.7, 1.3) + rng.uniform(-25, 25)
        mean = img.mean(axis=(0, 1), keepdims=True)
        img = (img - mean) * rng.uniform(0.75, 1.25) + mean
    if rng.random() < 0.4:
        grey = img.mean(axis=2, keepdims=True)
        img = grey + (img - grey) * rng.uniform(0.4, 1.4)
    if rng.random() < 0.25:
        k = int(rng.choice([3, 5]))
        img = cv2.GaussianBlur(img, (k, k), 0)
    if rng.random() < 0.4:
        img = img + rng.normal(0, rng.uniform(2, 9), img.shape).astype(np.float32)
    img = np.clip(img, 0, 255).astype(np.uint8)
    if rng.random() < 0.3:
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(35, 90))])
        if ok:
            img = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    keep = masks.reshape(len(masks), -1).sum(axis=1) >= MIN_INSTANCE_PIXELS if len(masks) else []
    if len(masks) and not np.all(keep):
        masks, labels = masks[keep], labels[keep]
    if ignore is not None:
        ignore = np.ascontiguousarray(ignore) if ignore.any() else None
    if not len(masks):
        return Sample(img, Instances.empty(h, w), ignore)
    return Sample(img, Instances(labels, np.ascontiguousarray(masks)), ignore)


# ---- tensors -------------------------------------------------------------------------------
def image_tensor(image_bgr: np.ndarray) -> torch.Tensor:
    """BGR uint8 [H, W, 3] -> RGB float [3, H, W] in [0, 1]."""
    rgb = np.ascontiguousarray(image_bgr[:, :, ::-1])
    return torch.from_numpy(rgb).permute(2, 0, 1).float().div_(255.0)


def to_target(s: Sample) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    inst = s.instances
    h, w = s.image.shape[:2]
    if len(inst):
        big = inst.masks.reshape(len(inst), -1).sum(axis=1) >= MIN_INSTANCE_PIXELS
        inst = inst[big] if not big.all() else inst
    n = len(inst)
    if n:
        boxes = np.array([_box(m) for m in inst.masks], np.float32)
        labels = np.array([LABELS.index(l) + 1 for l in inst.labels], np.int64)
        masks = torch.from_numpy(inst.masks.astype(np.uint8))
    else:
        boxes, labels = np.zeros((0, 4), np.float32), np.zeros(0, np.int64)
        masks = torch.zeros((0, h, w), dtype=torch.uint8)
    return image_tensor(s.image), {"boxes": torch.from_numpy(boxes), "labels": torch.from_numpy(labels),
                                   "masks": masks,
                                   "ignore_boxes": torch.from_numpy(ignore_boxes(getattr(s, "ignore", None)))}


def ignore_boxes(ignore: np.ndarray | None) -> np.ndarray:
    """(K, 4) float32 xyxy: a box round each connected part of the ignore mask."""
    if ignore is None or not ignore.any():
        return np.zeros((0, 4), np.float32)
    n, _, stats, _ = cv2.connectedComponentsWithStats(ignore.astype(np.uint8), connectivity=8)
    x, y, bw, bh = (stats[1:, i].astype(np.float32) for i in range(4))
    return np.stack([x, y, x + bw, y + bh], axis=1)


def _box(m: np.ndarray) -> list[float]:
    ys, xs = np.nonzero(m)
    return [float(xs.min()), float(ys.min()), float(xs.max() + 1), float(ys.max() + 1)]


def collate(batch):
    return tuple(zip(*batch))
