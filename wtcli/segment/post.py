"""What both ways of running the segmenter share (torch: ``wtcli.segment.infer``; OpenCV's DNN
module: ``wtcli.segment.cvnet``): the photo's checks and working size, each box's mask pasted
into the photo, duplicate blades dropped, and the second look at small turbines. numpy and cv2
only: importing this module loads no torch.
"""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from wtcli.errors import InputError
from wtcli.masks import LABELS, Instances
from wtcli.segment.bgr import as_bgr
from wtcli.segment.defaults import DEFAULT_MAX_SIZE

MASK_OFFSET_PX = 0.5  # see paste_mask; weights trained with area-resized masks
MIRROR_BOX_SHIFT_PX = 0.5  # see unmirror_boxes
# Where each class's soft mask is cut. Blades at 0.45: on 200 development renders (seeds
# 7 000 000 +, an earlier model) blade IoU 0.742 against 0.735 at 0.5 (0.737 at 0.4, 0.715 at 0.55): the
# soft edge of a blade a few pixels wide comes out a little below 0.5. Tower and nacelle peak
# at 0.5.
MASK_THRESHOLD = {"blade": 0.45, "tower": 0.5, "nacelle": 0.5}
DUPLICATE_INSIDE = 0.3  # a blade this much inside a better-scored blade is the same blade
SAME_REGION_IOU = 0.7  # two classes' masks this alike are one part read twice (``drop_duplicates``)
# ``absorb_blade_ends``: a lone blade's end read as a nacelle or tower lies on the blade's axis
# (its middle within this share of the blade's width there) and is at most this much wider.
NACELLE_IN_LINE = 0.5
NACELLE_AS_WIDE = 1.3
NACELLE_GAP = 1.0  # ... or lies beyond a blade that stops short of it by at most its width there
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
# Wide look (``wide_look``): the photo again at the smallest size the network trained at (its
# shorter side WIDE_SIZE[0], longer at most WIDE_SIZE[1]; ``model.TRAIN_MIN_SIZES[0]``,
# ``TRAIN_MAX_SIZE``). Its detections whose box spans WIDE_BIG of the photo's width or height
# or more are ones the first look, at 576 px, sees larger than its largest anchors
# (``model.build_model``: 320 px, 554 px at 1:3) and can miss: a blade filling the frame.
WIDE_SIZE = (320, 555)
MAX_ASPECT = 100  # longer side / shorter side a photo may have: 5 px high at WIDE_SIZE's 555
WIDE_BIG = 0.6
WIDE_SAME = 0.5  # a first-look instance of the class with this mask IoU already is the big one
WIDE_INSIDE = 0.5  # a first-look detection this much inside the big one is a piece of it
WIDE_COVERED = 0.8  # the first look has the big one when its sure detections of the class cover this much


def working_image(image_bgr: np.ndarray, score_threshold: float, max_size: int | None
                  ) -> tuple[np.ndarray, int, int]:
    """The photo as the network takes it (BGR, longer side at most ``max_size``) and the
    photo's own height and width; a bad threshold, a photo under 8 px or one longer than
    MAX_ASPECT times its width (a strip the network's smallest look would read 0 px high)
    is an InputError."""
    img = as_bgr(image_bgr)
    if not 0.0 <= score_threshold <= 1.0:
        raise InputError(f"expected a score threshold in [0, 1], got {score_threshold}")
    H, W = img.shape[:2]
    if H < 8 or W < 8:
        raise InputError(f"image is too small ({W}x{H})")
    if max(H, W) > MAX_ASPECT * min(H, W):
        raise InputError(f"image is too narrow ({W}x{H}): at most {MAX_ASPECT}:1 (a drone "
                         "panorama is under 10:1)")
    if max_size and max(H, W) > max_size:
        scale = max_size / max(H, W)
        img = cv2.resize(img, (max(1, round(W * scale)), max(1, round(H * scale))),
                         interpolation=cv2.INTER_AREA)
    return img, H, W


def instances(scores: np.ndarray, labels: np.ndarray, soft: np.ndarray, work_boxes: np.ndarray,
              work_hw: tuple[int, int], H: int, W: int, score_threshold: float, offset: float
              ) -> Instances:
    """The network's detections (class ids, M x M soft masks and boxes in the working size
    ``work_hw``) as instances of the H x W photo: those scoring ``score_threshold`` or more,
    each mask pasted (``paste_mask``) and cut at its class's ``MASK_THRESHOLD``, duplicate
    blades dropped."""
    keep = scores >= score_threshold
    if not keep.any():
        return Instances.empty(H, W)
    labels, soft, work_boxes = labels[keep], soft[keep], work_boxes[keep]
    sx, sy = W / work_hw[1], H / work_hw[0]  # working size -> original image
    boxes = work_boxes * np.array([sx, sy, sx, sy])
    masks = np.zeros((len(soft), H, W), bool)
    names = np.array([LABELS[int(c) - 1] for c in labels], dtype=object)
    for i, m in enumerate(soft):
        paste_mask(masks[i], m, work_boxes[i], sx, sy, offset, MASK_THRESHOLD[names[i]])
    boxes[:, [0, 2]] = boxes[:, [0, 2]].clip(0, W)
    boxes[:, [1, 3]] = boxes[:, [1, 3]].clip(0, H)
    return drop_duplicates(Instances(names, masks, scores[keep].clip(0, 1), boxes))


def _axis(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A pixel set's centre and unit main axis (its principal direction)."""
    c = pts.mean(axis=0)
    w, v = np.linalg.eigh(np.cov((pts - c).T))
    return c, v[:, int(np.argmax(w))]


def _blade_end(blade: np.ndarray, piece: np.ndarray, tower: bool, touching: bool) -> np.ndarray | None:
    """Where ``piece`` is the end of ``blade`` (``absorb_blade_ends``), the pixels joining
    them (the piece, and the hull of the blade's last stretch and the piece when a gap lies
    between them); None where it is not."""
    bp = np.argwhere(blade)[:, ::-1].astype(float)  # (x, y)
    pp = np.argwhere(piece)[:, ::-1].astype(float)
    if len(bp) < 16:
        return None
    c, u = _axis(bp)
    n = np.array([-u[1], u[0]])
    sb, tb = (bp - c) @ u, (bp - c) @ n
    sn, tn = (pp - c) @ u, (pp - c) @ n
    if np.median(sn) < 0:  # look along the blade towards the piece
        sb, sn = -sb, -sn
    lo, hi = np.percentile(sb, [1, 99])
    length = hi - lo
    end = sb > hi - 0.15 * length  # the blade's last stretch towards the piece
    if end.sum() < 8 or length <= 0:
        return None
    t_lo, t_hi = np.percentile(tb[end], [1, 99])
    width, mid = t_hi - t_lo, 0.5 * (t_lo + t_hi)
    s_lo, s_hi = np.percentile(sn, [1, 99])
    n_width = np.subtract(*np.percentile(tn, [99, 1]))
    gap = s_lo - hi
    if tower and s_hi - s_lo > n_width:
        return None  # a tower running on along the blade's axis is a tower
    if not touching:
        if not 0 <= gap <= NACELLE_GAP * width:
            return None
        start = sb < lo + 0.15 * length
        if start.sum() < 8 or width > np.subtract(*np.percentile(tb[start], [99, 1])):
            return None  # a blade narrows to its tip: the end it widens to is at the hub
    if not (np.mean(sn > hi - 0.15 * length) >= 0.9 and abs(np.median(tn) - mid) <= NACELLE_IN_LINE * width
            and n_width <= NACELLE_AS_WIDE * width):
        return None
    if touching:
        return piece
    hull = cv2.convexHull(np.vstack([bp[end], pp]).astype(np.int32))
    fill = np.zeros(blade.shape, np.uint8)
    cv2.fillConvexPoly(fill, hull, 1)
    return fill.astype(bool) | piece


def absorb_blade_ends(inst: Instances, score_threshold: float) -> Instances:
    """A "nacelle" or "tower" that is the end of a lone blade becomes part of that blade; only
    detections scoring ``score_threshold`` or more (what ``segment`` reports) are weighed, so a
    doubtful detection never grows a blade's mask. Run on the whole photo, after the second look.

    A nacelle carries the hub, where every blade's root meets, and sits on the tower. In a
    tip close-up the network can take the blade's rounded end for a nacelle (real photos: the
    last chord of a blade tip against the ground), or the end's bright rim, a short bar across
    the blade, for a tower. Such a detection lies inside the frame (clear of its edges by the
    few pixels a mask's edge may be off), touches one blade and no other tower, lies on that
    blade's axis beyond its end, and is no wider than the blade there (NACELLE_IN_LINE,
    NACELLE_AS_WIDE): a true nacelle seen with one blade is beside the blade's root, or wider
    than it, or on a tower, or (seen along the blade, at its root) cut by the frame. A "tower"
    must also be no longer along the blade than it is across it: a true tower in line with a
    blade (a blade pointing up from the hub above it) runs on along the axis far beyond its own
    width, and one that touches the nacelle is no blade's end. Where the network's blade stops
    short of the piece, a piece that touches no blade joins the one blade whose end it lies
    beyond by at most NACELLE_GAP of the blade's width, and the gap between them with it."""
    sure = inst.scores >= score_threshold
    ends = np.nonzero(sure & np.isin(inst.labels, ("nacelle", "tower")))[0]
    blades = np.nonzero(sure & (inst.labels == "blade"))[0]
    if not len(ends) or not len(blades):
        return inst
    H, W = inst.image_size
    r = max(2, int(round(0.005 * max(H, W))))
    grow = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    masks, boxes = inst.masks.copy(), inst.boxes.copy()
    drop = []
    for i in ends:
        m = inst.masks[i]
        if m.sum() < 16 or m[:r].any() or m[-r:].any() or m[:, :r].any() or m[:, -r:].any():
            continue  # a tip close-up shows the tip's end in the frame; a cut part is no tip
        near = cv2.dilate(m.view(np.uint8), grow).astype(bool)
        holds = ("tower",) if inst.labels[i] == "nacelle" else ("tower", "nacelle")
        if any((near & inst.masks[k]).any() for k in ends if k != i and inst.labels[k] in holds):
            continue
        touching = [j for j in blades if (near & inst.masks[j]).any()]
        if len(touching) > 1:
            continue  # where two blades meet is the hub
        tower = inst.labels[i] == "tower"
        found = [(j, f) for j in (touching or blades)
                 if (f := _blade_end(inst.masks[j], m, tower, bool(touching))) is not None]
        if len(found) != 1:
            continue
        j, fill = found[0]
        masks[j] |= fill
        ys, xs = np.nonzero(fill)
        boxes[j, :2] = np.minimum(boxes[j, :2], [xs.min(), ys.min()])
        boxes[j, 2:] = np.maximum(boxes[j, 2:], [xs.max() + 1, ys.max() + 1])
        drop.append(i)
    if not drop:
        return inst
    keep = np.setdiff1d(np.arange(len(inst)), drop)
    return Instances(inst.labels[keep], masks[keep], inst.scores[keep], boxes[keep])


def _shared_pixels(inst: Instances, i: int, j: int) -> int:
    """Pixels in both instance i's and j's masks, counted where their boxes meet (a detection's
    mask lies inside its box)."""
    u0, v0 = int(max(inst.boxes[i][0], inst.boxes[j][0])), int(max(inst.boxes[i][1], inst.boxes[j][1]))
    u1 = int(np.ceil(min(inst.boxes[i][2], inst.boxes[j][2])))
    v1 = int(np.ceil(min(inst.boxes[i][3], inst.boxes[j][3])))
    if u1 <= u0 or v1 <= v0:
        return 0
    return int(np.count_nonzero(inst.masks[i, v0:v1, u0:u1] & inst.masks[j, v0:v1, u0:u1]))


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
        dup = area[a] == 0
        for b in kept:
            if dup:
                break
            dup = _shared_pixels(inst, i, idx[b]) >= inside * area[a]
        if dup:
            drop.append(i)
        else:
            kept.append(a)
    if not drop:
        return inst
    return inst[np.setdiff1d(np.arange(len(inst)), drop)]


def drop_duplicates(inst: Instances, inside: float = DUPLICATE_INSIDE,
                    same: float | None = None) -> Instances:
    """``drop_duplicate_blades``, after dropping each detection whose mask has an IoU of
    ``same`` or more with a better-scored one's of another class: box NMS is per class, so one
    part can come out twice (a blade close-up also as a "tower", a tower behind a blade also
    as a blade), and a pixel shows one part. Parts of different classes meet or overlap at an
    edge (a blade over the tower, a nacelle at the blade roots) but are not the same region.
    Greedy by score, so the result at any score threshold is this one, thresholded.
    ``same``: default SAME_REGION_IOU."""
    same = SAME_REGION_IOU if same is None else same
    n = len(inst)
    if n >= 2 and len(set(inst.labels)) > 1:
        order = np.argsort(-inst.scores, kind="stable")
        area = inst.masks.reshape(n, -1).sum(axis=1)
        kept: list[int] = []
        drop = []
        for i in order:
            dup = False
            for j in kept:
                if inst.labels[j] == inst.labels[i]:
                    continue
                both = _shared_pixels(inst, i, j)
                union = int(area[i] + area[j]) - both
                if union and both >= same * union:
                    dup = True
                    break
            if dup:
                drop.append(i)
            else:
                kept.append(i)
        if drop:
            inst = inst[np.setdiff1d(np.arange(n), drop)]
    return drop_duplicate_blades(inst, inside)


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



def second_look(look: Callable[..., Instances], image_bgr: np.ndarray, inst: Instances,
                score_threshold: float, max_size: int | None = DEFAULT_MAX_SIZE,
                flip: bool = True) -> Instances:
    """``look(crop, score_threshold, max_size, flip)``: the network's instances on a crop.

    Segment each small turbine again on a crop around it, and use those instances instead.

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
        sub = look(img[Y0:Y1, X0:X1], score_threshold, max_size, flip)
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
    return drop_duplicates(Instances(np.concatenate(labels)[order], np.concatenate(masks)[order],
                                     scores_a[order], np.concatenate(boxes)[order]))



def _mask_iou_inside(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(IoU of masks a and b, share of b's pixels inside a)."""
    both = int(np.count_nonzero(a & b))
    nb = int(np.count_nonzero(b))
    union = int(np.count_nonzero(a)) + nb - both
    return (both / union if union else 0.0), (both / nb if nb else 0.0)


def wide_look(look: Callable[..., Instances], image_bgr: np.ndarray, inst: Instances,
              score_threshold: float, max_size: int | None = DEFAULT_MAX_SIZE,
              flip: bool = True, sure: float | None = None) -> Instances:
    """``look(photo, score_threshold, max_size, flip)``: the network's instances with the photo
    at WIDE_SIZE. Adds what only that look finds: a part too big for the first look.

    The network's largest anchors are 320 px (554 x 185 px at 1:3) at its 576 px working size,
    so a blade filling the frame of a close-up (the photos an inspection takes) gets no
    proposal that fits it, and the first look finds nothing, or its end as a "nacelle", or an
    edge as a "tower". Seen at the size the network first trained at, the same blade fits.
    A wide-look detection whose box spans WIDE_BIG of the photo's width or height and that
    scores ``sure`` (``segment``'s reporting threshold; default ``score_threshold``) or more
    joins the first look's, best score first, and the first
    look's detections that are it (its class, a mask IoU of WIDE_SAME) or pieces of it (any
    class, WIDE_INSIDE or more of their mask within it) and score lower go; unless the first
    look, finer, has it already: one of its class scoring higher is it or a piece of it, or
    its detections of the class scoring ``sure`` cover WIDE_COVERED of it (two blades
    meeting at a hub, told apart)."""
    img = np.asarray(image_bgr)
    H, W = img.shape[:2]
    wide = look(img, score_threshold, max_size, flip)
    if not len(wide):
        return inst
    b = wide.boxes
    sure = score_threshold if sure is None else sure
    big = np.nonzero((((b[:, 2] - b[:, 0]) >= WIDE_BIG * W) | ((b[:, 3] - b[:, 1]) >= WIDE_BIG * H))
                     & (wide.scores >= sure))[0]
    if not len(big):
        return inst
    keep = np.ones(len(inst), bool)
    added = []
    for i in big[np.argsort(-wide.scores[big], kind="stable")]:
        m, label = wide.masks[i], wide.labels[i]
        if not m.any():
            continue
        theirs = np.nonzero(keep & (inst.labels == label) & (inst.scores >= sure))[0]
        if len(theirs) and np.count_nonzero(m & inst.masks[theirs].any(axis=0)) >= \
                WIDE_COVERED * np.count_nonzero(m):
            continue
        pieces, surer = [], False
        for j in np.nonzero(keep)[0]:
            iou, inside = _mask_iou_inside(m, inst.masks[j])
            mine = inst.labels[j] == label
            if inside >= WIDE_INSIDE or (mine and iou >= WIDE_SAME):
                pieces.append(j)
                surer |= bool(mine and inst.scores[j] > wide.scores[i])
        if surer:
            continue
        keep[[j for j in pieces if inst.scores[j] <= wide.scores[i]]] = False
        added.append(i)
    if not added:
        return inst
    scores = np.concatenate([inst.scores[keep], wide.scores[added]])
    order = np.argsort(-scores, kind="stable")  # as predict's: best first
    return drop_duplicates(Instances(
        np.concatenate([inst.labels[keep], wide.labels[added]])[order],
        np.concatenate([inst.masks[keep], wide.masks[added]])[order], scores[order],
        np.concatenate([inst.boxes[keep], wide.boxes[added]])[order]))
