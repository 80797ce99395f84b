"""Labelled real photos as training and test data: semantic masks turned into instances.

A folder of real photos (e.g. ``../shared/real-photos``: ``manifest.csv`` with columns
``image``, ``mask``, ``site``, ``view``; masks 0 background, 1 blade, 2 tower with nacelle and
hub) labels classes, not objects, while the segmenter trains on instances. ``split_semantic``
makes them:

* **towers**: the connected parts of class 2, the parts of one tower that a blade passing in
  front cuts apart joined again (they overlap in columns and the gap between them is blade);
* **hub**: per tower, the tower pixel next to the blades from which the blade pixels around it
  (an annulus) fall into the most separate directions; none where no blade touches the tower;
* **blades**: the blade pixels near a hub, a disk around the hub removed (its radius the
  smallest that separates the most pieces), split into connected pieces, each a blade (pieces
  within 8 degrees of one direction from the hub are one blade the tower hides a part of); the
  disk's blade pixels go to the piece nearest in angle. The hub is then moved to where the
  pieces' long axes meet, when that is near, and the split made again. Blade parts touching no hub (close-ups,
  other turbines) are a blade each;
* **nacelle**, where it can be told apart: on a tower at least four times as tall as its
  shaft is wide, the rows near its top (from within its top 15 %, down to at most 40 %) at least
  twice the shaft's width (nacelle and hub, as the renders label them); a class-2 part no
  taller than 1.5 times its width (a nacelle seen close, no shaft below it) is a nacelle whole.
  Otherwise the class-2 part stays tower, and where a hub was found its rows down to two shaft
  widths under the hub (or to its lowest wide row near the top) are boxed as ``unknown``: the
  nacelle is in there somewhere, so training takes them out of the tower and teaches neither
  tower nor background there.

Flight sequences: frames of one flight are near-duplicates, so a photo's figures count only
from a model that trained on none of its sequence. A ``sequence`` column in the manifest says
it; without one, ``sequences`` groups rows named ``SITE_NN`` that follow each other in the
manifest with frame numbers rising by at most 2, same site, into a sequence when at least 8
long (``envA_01-28``); every other row belongs to one sequence ``other``. For the WTA photos
that is envA_01-28, envB_01-21, envB_34-41, envC_01-20 and the original 38 as ``other``, the
split their README names.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from wtcli.errors import InputError
from wtcli.masks import Instances, image_size_as_read, read_labelled_image

BLADE, TOWER = 1, 2  # classes of the semantic masks
VIEW_TYPES = ("close-up", "nadir", "side", "front", "front-oblique", "rear", "rear-oblique",
              "oblique", "distant", "other")
SEQUENCE_MIN_FRAMES = 8
SEQUENCE_MAX_STEP = 2
OTHER_SEQUENCE = "other"
SAME_BLADE_DEG = 8.0  # pieces this close in direction from the hub are one blade
MAX_SIDE = 1024  # photos are read at most this long (the segmenter works at 1024 x 576)


# ---- the folder ----------------------------------------------------------------------------
@dataclass(frozen=True)
class RealPhoto:
    image: Path
    mask: Path
    name: str  # the image's stem, e.g. envA_03
    sequence: str
    view: str  # one of VIEW_TYPES
    note: str  # the manifest's view text as written


def view_type(text: str) -> str:
    """The manifest's free-text view description -> one of ``VIEW_TYPES`` (first rule that
    matches; ``other`` when none does, rather than a guess)."""
    t = text.lower()
    rules = (
        ("nadir", r"nadir|steep(ly)? down|straight down|top-down"),
        ("close-up", r"single blade|^one blade|blade tip|blade close-up"),
        ("distant", r"distant"),
        ("rear-oblique", r"rear three-quarter|rear-oblique|behind-side|above/behind"),
        ("rear", r"\brear\b"),
        ("front-oblique", r"front-oblique|front-ish"),
        ("front", r"\bfront\b"),
        ("oblique", r"oblique"),
        ("side", r"side|edge-on"),
    )
    for name, pat in rules:
        if re.search(pat, t):
            return name
    return "other"


_FRAME = re.compile(r"^(?P<site>.+)_(?P<num>\d+)$")


def sequences(names: list[str]) -> list[str]:
    """A flight-sequence id per photo name, in order (the rule in the module docstring)."""
    parsed = [_FRAME.match(n) for n in names]
    out = [OTHER_SEQUENCE] * len(names)
    i = 0
    while i < len(names):
        j = i
        while (parsed[i] and j + 1 < len(names) and parsed[j + 1]
               and parsed[j + 1]["site"] == parsed[j]["site"]
               and 0 < int(parsed[j + 1]["num"]) - int(parsed[j]["num"]) <= SEQUENCE_MAX_STEP):
            j += 1
        if parsed[i] and j - i + 1 >= SEQUENCE_MIN_FRAMES:
            seq = f"{parsed[i]['site']}_{parsed[i]['num']}-{parsed[j]['num']}"
            out[i:j + 1] = [seq] * (j - i + 1)
        i = j + 1
    return out


def is_photo_folder(path: str | Path) -> bool:
    p = Path(path)
    return p.is_dir() and (p / "manifest.csv").is_file()


MANIFEST_COLUMNS = ("image", "mask")  # required; view, view_type and sequence are optional


def read_manifest(man: Path) -> list[dict[str, str]]:
    """The rows of ``manifest.csv`` as {column: text}, column names as written but trimmed and
    in lower case (``Image`` is ``image``); a UTF-8 byte-order mark (Excel's "CSV UTF-8")
    is skipped."""
    try:
        with man.open(encoding="utf-8-sig", newline="") as f:
            table = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise InputError(f"{man}: unreadable ({e.__class__.__name__})") from None
    if not table:
        raise InputError(f"{man}: empty; expected a header line with columns image, mask")
    header = [c.strip().lower() for c in table[0]]
    twice = sorted({c for c in header if c and header.count(c) > 1})
    if twice:
        raise InputError(f"{man}: column {twice[0]!r} given twice in the header line "
                         f"({', '.join(table[0])})")
    missing = [c for c in MANIFEST_COLUMNS if c not in header]
    if missing:
        got = ", ".join(repr(c) for c in table[0][:8]) or "nothing"
        raise InputError(f"{man}: expected columns image and mask in the header line, missing "
                         f"{' and '.join(missing)} (it has {got})")
    width = len(header)  # a short row's missing cells read as empty
    rows = [dict(zip(header, [v.strip() for v in r] + [""] * (width - len(r))))
            for r in table[1:] if any(v.strip() for v in r)]
    if not rows:
        raise InputError(f"{man}: no photos listed")
    return rows


def read_folder(root: str | Path) -> list[RealPhoto]:
    """The photos of a folder with ``manifest.csv`` (columns image, mask; view and sequence
    optional; ``read_manifest``), each file checked to exist."""
    root = Path(root)
    man = root / "manifest.csv"
    if not man.is_file():
        raise InputError(f"{root}: no manifest.csv (columns image, mask[, view, sequence])")
    rows = read_manifest(man)
    names = [Path(r.get("image") or "").stem for r in rows]
    seqs = ([r.get("sequence") or OTHER_SEQUENCE for r in rows] if "sequence" in rows[0]
            else sequences(names))
    photos = []
    for k, (r, name, seq) in enumerate(zip(rows, names, seqs), start=2):
        paths = []
        for col in MANIFEST_COLUMNS:
            if not r.get(col):
                raise InputError(f"{man}, line {k}: no {col} given")
            paths.append(root / r[col])
            if not paths[-1].is_file():
                raise InputError(f"{man}, line {k}: {paths[-1]} not found")
        note = r.get("view") or ""
        photos.append(RealPhoto(paths[0], paths[1], name, seq, r.get("view_type") or view_type(note), note))
    return photos


def read_mask(path: Path) -> np.ndarray:
    """A semantic mask, uint8 [H, W] of classes 0, 1 (blade), 2 (tower): refused from its header
    when over the pixel limit, and when colour-coded or holding other values."""
    sem = read_labelled_image(path, flags=cv2.IMREAD_UNCHANGED)
    if sem is None:
        raise InputError(f"{path}: not a readable mask")
    if sem.ndim == 3:
        # A palette or colour-coded PNG comes out of OpenCV as colours, not class numbers:
        # grey stored as RGB is fine, anything else would be read as other classes.
        if sem.shape[2] == 4:
            sem = sem[:, :, :3]
        if not (sem == sem[:, :, :1]).all():
            raise InputError(f"{path}: a colour mask (a palette or colour-coded PNG); "
                             "expected one channel of class numbers 0, 1 (blade), 2 (tower)")
        sem = sem[:, :, 0]
    bad = set(np.unique(sem).tolist()) - {0, BLADE, TOWER}
    if bad:
        raise InputError(f"{path}: expected classes 0, 1 (blade), 2 (tower), found {sorted(bad)}")
    return sem.astype(np.uint8)


def check_photo(photo: RealPhoto) -> None:
    """What ``read_pair`` would refuse, found before training starts: the mask decoded (its
    values), the photo's size from its header where that tells it (``image_size_as_read``)."""
    h, w = read_mask(photo.mask).shape
    got = image_size_as_read(photo.image, (h, w))
    if got is None:
        raise InputError(f"{photo.image}: not a readable image")
    if got != (h, w):
        raise InputError(f"{photo.mask}: mask is {w}x{h} but its photo {photo.image} is "
                         f"{got[1]}x{got[0]}")


def read_pair(photo: RealPhoto, max_side: int | None = MAX_SIDE) -> tuple[np.ndarray, np.ndarray]:
    """(BGR image, semantic mask uint8), scaled together so the longer side is at most
    ``max_side`` (area-averaged image, nearest-neighbour mask)."""
    sem = read_mask(photo.mask)
    h, w = sem.shape
    img = read_labelled_image(photo.image, (h, w))
    if img is None:
        raise InputError(f"{photo.image}: not a readable image")
    if img.shape[:2] != (h, w):
        raise InputError(f"{photo.mask}: mask is {w}x{h} but its photo {photo.image} is "
                         f"{img.shape[1]}x{img.shape[0]}")
    f = min(1.0, max_side / max(h, w)) if max_side else 1.0
    if f < 1.0:
        size = (max(1, round(w * f)), max(1, round(h * f)))
        img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
        sem = cv2.resize(sem, size, interpolation=cv2.INTER_NEAREST)
    return img, sem


# ---- semantic -> instances -----------------------------------------------------------------
@dataclass(frozen=True)
class Split:
    instances: Instances
    hubs: tuple[tuple[float, float], ...]  # (x, y) of every hub found
    blade_hub: tuple[int | None, ...]  # per blade instance (in order): its hub's index, or None
    # Where the mask cannot say the class: the top of a tower whose nacelle is not told apart
    # (``nacelle_unknown``). Training leaves it out of the tower and teaches nothing there.
    unknown: np.ndarray | None = None  # (H, W) bool


def _components(mask: np.ndarray, min_pixels: int) -> list[np.ndarray]:
    n, lab, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    return [lab == k for k in range(1, n) if stats[k, cv2.CC_STAT_AREA] >= min_pixels]


def _join_towers(towers: list[np.ndarray], blade: np.ndarray) -> list[np.ndarray]:
    """Tower parts cut apart by a blade in front: overlapping columns with blade between them
    (a lower blade across the tower), or close with blade between (a nacelle cut by blades)."""
    n = len(towers)
    parent = list(range(n))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    boxes = []
    for m in towers:
        ys, xs = np.nonzero(m)
        boxes.append((xs.min(), xs.max(), ys.min(), ys.max()))
    dist = [cv2.distanceTransform((~m).astype(np.uint8), cv2.DIST_L2, 3) for m in towers] if n > 1 else []
    for i in range(n):
        for j in range(i + 1, n):
            # Close parts with blade between them: pieces of one nacelle or tower a blade cuts.
            d = float(dist[i][towers[j]].min())
            if d <= max(4.0, 1.5 * math.sqrt(min(towers[i].sum(), towers[j].sum()))):
                bridge = (dist[i] <= d + 1) & (dist[j] <= d + 1) & ~towers[i] & ~towers[j]
                if bridge.any() and blade[bridge].mean() >= 0.6:
                    parent[find(i)] = find(j)
                    continue
            a, b = boxes[i], boxes[j]
            x0, x1 = max(a[0], b[0]), min(a[1], b[1])
            if x1 < x0 or (x1 - x0 + 1) < 0.5 * min(a[1] - a[0] + 1, b[1] - b[0] + 1):
                continue
            up, down = (a, b) if a[2] <= b[2] else (b, a)
            y0, y1 = up[3] + 1, down[2] - 1
            if y1 < y0:  # touching or overlapping rows but not connected: leave apart
                continue
            gap = blade[y0:y1 + 1, x0:x1 + 1]
            if gap.mean() >= 0.5:
                parent[find(i)] = find(j)
    groups: dict[int, np.ndarray] = {}
    for i, m in enumerate(towers):
        r = find(i)
        groups[r] = groups[r] | m if r in groups else m.copy()
    return list(groups.values())


def _angles(ys: np.ndarray, xs: np.ndarray, hub: tuple[float, float]) -> np.ndarray:
    """Degrees in [0, 360), counter-clockwise from the image's +x with y up."""
    return np.degrees(np.arctan2(-(ys - hub[1]), xs - hub[0])) % 360.0


def _runs(hist: np.ndarray, min_share: float = 0.05, gap: int = 3) -> int:
    """Directions in an angle histogram on a circle: runs of occupied bins, gaps of up to
    ``gap`` bins closed, each holding at least ``min_share`` of the pixels."""
    total = hist.sum()
    occ = hist > 0
    if not occ.any():
        return 0
    n = len(hist)
    for i in np.nonzero(occ)[0]:  # close short gaps (circularly)
        for g in range(2, gap + 2):
            if occ[(i + g) % n]:
                occ[[(i + k) % n for k in range(1, g)]] = True
                break
    if occ.all():
        return 1
    start = int(np.argmin(occ))  # a free bin: runs do not wrap from here
    runs, mass = 0, 0.0
    for k in range(1, n + 1):
        i = (start + k) % n
        if occ[i]:
            mass += hist[i]
        elif mass:
            runs += mass >= min_share * total
            mass = 0.0
    return int(runs + (mass >= min_share * total if mass else 0))


def _radius(blade: np.ndarray) -> float:
    """The annulus around a hub candidate, from the blade area: blades' roots lie within it."""
    return max(12.0, 0.35 * math.sqrt(max(int(blade.sum()), 1)))


def _find_hub(tower: np.ndarray, blade: np.ndarray) -> tuple[float, float] | None:
    """The tower pixel next to the blades with blade pixels in the most directions around it."""
    near = cv2.dilate(blade.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool) & tower
    cy, cx = np.nonzero(near)
    if not len(cy):
        return None
    by, bx = np.nonzero(blade)
    if len(by) > 40_000:  # a subsample keeps this fast on large masks; directions do not change
        k = np.linspace(0, len(by) - 1, 40_000).astype(int)
        by, bx = by[k], bx[k]
    step = max(1, len(cy) // 200)
    r_out = _radius(blade)
    r_in = 0.3 * r_out
    best, best_key = None, (-1, -1.0)
    for y, x in zip(cy[::step], cx[::step]):
        d = np.hypot(by - y, bx - x)
        sel = (d >= r_in) & (d <= r_out)
        if not sel.any():
            continue
        a = _angles(by[sel], bx[sel], (x, y))
        hist, _ = np.histogram(a, bins=72, range=(0, 360))
        hist[hist < max(2, 0.005 * sel.sum())] = 0  # a few stray pixels are no direction
        key = (_runs(hist), float(sel.sum()))
        if key > best_key:
            best_key, best = key, (float(x), float(y))
    return best


def _split_at_hub(blade_near: np.ndarray, hub: tuple[float, float], min_pixels: int) -> list[np.ndarray]:
    """Blade pixels around one hub -> one mask per blade (a disk around the hub removed)."""
    ys, xs = np.nonzero(blade_near)
    if not len(ys):
        return []
    d = np.hypot(ys - hub[1], xs - hub[0])
    keep_min = max(min_pixels, int(0.02 * len(ys)))
    best_r, best_n = 0.0, 0
    for r in np.geomspace(2.0, max(3.0, np.percentile(d, 60)), 14):
        rest = blade_near.copy()
        rest[ys[d < r], xs[d < r]] = False
        n = len(_components(rest, keep_min))
        if n > best_n:
            best_r, best_n = float(r), n
    rest = blade_near.copy()
    inner = d < best_r
    rest[ys[inner], xs[inner]] = False
    pieces = _components(rest, keep_min)
    if not pieces:
        return [blade_near]
    # Everything outside the pieces (the disk, small scraps) goes to the piece nearest in angle.
    mean_a = []
    for p in pieces:
        py, px = np.nonzero(p)
        a = np.radians(_angles(py, px, hub))
        mean_a.append(math.degrees(math.atan2(np.sin(a).mean(), np.cos(a).mean())) % 360.0)
    # Pieces in one direction from the hub are one blade the tower (or a gap) cuts in two.
    merged: list[tuple[np.ndarray, float]] = []
    for p, a in sorted(zip(pieces, mean_a), key=lambda t: t[1]):
        if merged and abs((a - merged[-1][1] + 180.0) % 360.0 - 180.0) <= SAME_BLADE_DEG:
            merged[-1] = (merged[-1][0] | p, merged[-1][1])
        else:
            merged.append((p, a))
    if len(merged) > 1 and abs((merged[0][1] - merged[-1][1] + 180.0) % 360.0 - 180.0) <= SAME_BLADE_DEG:
        merged[0] = (merged[0][0] | merged.pop()[0], merged[0][1])
    pieces, mean_a = [m for m, _ in merged], [a for _, a in merged]
    left = blade_near & ~np.any(pieces, axis=0)
    ly, lx = np.nonzero(left)
    if len(ly):
        la = _angles(ly, lx, hub)
        diff = np.abs((la[:, None] - np.array(mean_a)[None, :] + 180.0) % 360.0 - 180.0)
        owner = np.argmin(diff, axis=1)
        for k, p in enumerate(pieces):
            p[ly[owner == k], lx[owner == k]] = True
    return pieces


def _axes_meet(pieces: list[np.ndarray]) -> tuple[float, float] | None:
    """Least-squares meeting point of the long axes of the elongated pieces (>= 2 of them, not
    all parallel): the hub the blades point to, where the tower pixels only hint at it."""
    rows, rhs = [], []
    for p in pieces:
        ys, xs = np.nonzero(p)
        if len(ys) < 10:
            continue
        c = np.array([xs.mean(), ys.mean()])
        cov = np.cov(np.stack([xs - c[0], ys - c[1]]))
        ev, evec = np.linalg.eigh(cov)
        if ev[1] < 4.0 * max(ev[0], 1e-9):  # not elongated: no axis to trust
            continue
        n = evec[:, 0]  # the axis's normal
        rows.append(n)
        rhs.append(float(n @ c))
    if len(rows) < 2:
        return None
    a, b = np.array(rows), np.array(rhs)
    if np.linalg.cond(a.T @ a) > 1e6:
        return None
    x = np.linalg.lstsq(a, b, rcond=None)[0]
    return float(x[0]), float(x[1])


def _shaft_width(rows: np.ndarray, ys: np.ndarray) -> float:
    """A tower's shaft width: the median width of the rows in the lower half of its height."""
    lower = rows[ys[0] + (ys[-1] - ys[0] + 1) // 2: ys[-1] + 1]
    lower = lower[lower > 0]
    return float(np.median(lower)) if len(lower) else 0.0


def _nacelle_part(tower: np.ndarray) -> np.ndarray | None:
    """The nacelle (with hub) at a tower's top where it can be told apart, else None; the whole
    part when it is a nacelle seen close (no taller than 1.5 times its width)."""
    rows = tower.sum(axis=1)
    ys = np.nonzero(rows)[0]
    height = ys[-1] - ys[0] + 1
    xs = np.nonzero(tower.any(axis=0))[0]
    width = xs[-1] - xs[0] + 1
    shaft = _shaft_width(rows, ys)
    if shaft > 0 and height >= 4 * shaft:
        wide = rows[ys[0]: ys[-1] + 1] >= 2 * shaft
        top = int(np.argmax(wide))  # first wide row from the top (a nacelle's top is rounded)
        if wide.any() and top <= 0.15 * height:
            end = top
            while end + 1 < len(wide) and (wide[end + 1] or (end + 2 < len(wide) and wide[end + 2])):
                end += 1
            if (end + 1) <= 0.4 * height:
                nac = np.zeros_like(tower)
                nac[ys[0]: ys[0] + end + 1] = tower[ys[0]: ys[0] + end + 1]
                return nac
    if height <= 1.5 * width and not (shaft > 0 and height >= 4 * shaft):
        return tower.copy()
    return None


NACELLE_BELOW_HUB = 2.0  # shaft widths: how far below the hub a nacelle not told apart may reach


def nacelle_unknown(tower: np.ndarray, hub: tuple[float, float]) -> np.ndarray | None:
    """The box round a tower's pixels where its nacelle may be, when ``_nacelle_part`` cannot
    tell it apart: every row above ``NACELLE_BELOW_HUB`` shaft widths under the hub, or above
    the lowest row in the tower's top 40 % at least 1.5 shaft widths wide if lower (the renders
    label nacelle and hub apart from the tower; a photo's class 2 does not). None without a
    shaft to measure."""
    rows = tower.sum(axis=1)
    ys = np.nonzero(rows)[0]
    if not len(ys):
        return None
    shaft = _shaft_width(rows, ys)
    if shaft <= 0:
        return None
    end = hub[1] + NACELLE_BELOW_HUB * shaft
    top = rows[ys[0]: ys[0] + int(0.4 * (ys[-1] - ys[0] + 1)) + 1]
    wide = np.nonzero(top >= 1.5 * shaft)[0]  # a nacelle lower than the hub hint (oblique views)
    if len(wide):
        end = max(end, ys[0] + wide[-1] + 0.5 * shaft)
    region = tower.copy()
    region[int(math.ceil(end)):] = False
    if not region.any():
        return None
    ry, rx = np.nonzero(region)
    box = np.zeros_like(tower)  # the box round them: blades crossing it do not cut it apart
    box[ry.min(): ry.max() + 1, rx.min(): rx.max() + 1] = True
    return box


def split_semantic(sem: np.ndarray, min_pixels: int = 24) -> Split:
    """A semantic mask (0 background, 1 blade, 2 tower incl. nacelle and hub) -> instances:
    a blade each, a tower per turbine, its nacelle where it can be told apart (module docstring)."""
    sem = np.asarray(sem)
    h, w = sem.shape
    blade, tower_px = sem == BLADE, sem == TOWER
    towers = _join_towers(_components(tower_px, min_pixels), blade) if tower_px.any() else []
    towers.sort(key=lambda m: -int(m.sum()))
    blade_parts = _components(blade, min_pixels)
    taken = np.zeros(len(blade_parts), bool)
    out_labels, out_masks, blade_hub, hubs = [], [], [], []
    unknown = np.zeros((h, w), bool)
    for t in towers:
        free = [k for k in range(len(blade_parts)) if not taken[k]]
        if not free:
            hub = None
        else:
            hub = _find_hub(t, np.any([blade_parts[k] for k in free], axis=0))
        if hub is not None:
            grown = cv2.dilate(t.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
            touching = [k for k in free if (blade_parts[k] & grown).any()]
            near = np.any([blade_parts[k] for k in touching], axis=0) if touching else None
            if near is not None:
                pieces = _split_at_hub(near, hub, min_pixels)
                meet = _axes_meet(pieces) if len(pieces) >= 2 else None
                if meet is not None and math.dist(meet, hub) <= 0.5 * _radius(near):
                    hub = meet  # the axes' meeting point, when it is near the tower's hint
                    pieces = _split_at_hub(near, hub, min_pixels)
                hubs.append(hub)
                for p in pieces:
                    out_labels.append("blade")
                    out_masks.append(p)
                    blade_hub.append(len(hubs) - 1)
                taken[touching] = True
        nac = _nacelle_part(t)
        if nac is not None and nac.sum() >= min_pixels:
            rest = t & ~nac
            if rest.sum() >= min_pixels:
                out_labels.append("tower")
                out_masks.append(rest)
            out_labels.append("nacelle")
            out_masks.append(nac)
        else:
            out_labels.append("tower")
            out_masks.append(t)
            top = nacelle_unknown(t, hub) if hub is not None else None
            if top is not None:
                unknown |= top
    for k in np.nonzero(~taken)[0]:
        out_labels.append("blade")
        out_masks.append(blade_parts[k])
        blade_hub.append(None)
    # Blades first (as the renders list them), then towers and nacelles.
    order = ([i for i, l in enumerate(out_labels) if l == "blade"]
             + [i for i, l in enumerate(out_labels) if l != "blade"])
    unk = unknown if unknown.any() else None
    if not order:
        return Split(Instances.empty(h, w), tuple(hubs), (), unk)
    inst = Instances(np.array([out_labels[i] for i in order], dtype=object),
                     np.stack([out_masks[i] for i in order]))
    return Split(inst, tuple(hubs), tuple(blade_hub), unk)


def blade_angles(split: Split) -> list[tuple[int | None, float]]:
    """(hub index, direction hub -> blade in degrees, counter-clockwise from +x, y up) per blade
    split at a hub, in the instances' order; blades without a hub are left out."""
    out = []
    blades = split.instances.masks[split.instances.labels == "blade"]
    for m, hi in zip(blades, split.blade_hub):
        if hi is None:
            continue
        ys, xs = np.nonzero(m)
        a = np.radians(_angles(ys, xs, split.hubs[hi]))
        out.append((hi, math.degrees(math.atan2(np.sin(a).mean(), np.cos(a).mean())) % 360.0))
    return out
