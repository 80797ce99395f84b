"""Step 1.4 of the paper: each blade's angle θ (eq. 7), its class, and its direction φ hub -> tip.

Angles (DESIGN.md): pixels are x right, y down, but every reported angle is counter-clockwise
positive with image y pointing UP, 0° = pointing right. θ ∈ [0, 180) is the blade's axis (no
direction); φ ∈ [0, 360) is the direction from the hub-side end to the tip.

Two θ per blade:

* ``theta_eq7_deg`` — the paper's eq. 7 on ``cv2.minAreaRect``: the line through the "top" and
  "bottom" points of the rectangle, i.e. the midpoints of its two short sides. We normalise the
  rectangle ourselves from ``cv2.boxPoints`` (long side, atan2 with y up); the angle
  ``minAreaRect`` returns is never used (its range changed across OpenCV releases).
* ``theta_deg`` — the blade's principal axis (second moments of its filled region). A blade is
  wide at the root and narrow at the tip, so the minimum-area rectangle often lies along one
  edge of the taper and eq. 7 tilts by 1-2°; the principal axis of the (symmetric) silhouette
  does not. ``theta_deg`` is the one classified and the one φ follows (benchmarks/pitch_accuracy.py).

Classes (DESIGN.md, the paper's Fig. 4): horizontal [0, 30] ∪ [150, 180), acute (30, 60] ∪
[120, 150), vertical (60, 120). θ is rounded to 6 decimals (as written to the file) before it is
classified, so the class in a file always agrees with the θ next to it.

The hub: the nacelle/hub instance's pixels near the blades' convergence point if there is a
nacelle, else the convergence point (least-squares intersection of the blade axes), else the
blades' common end, else (one blade alone) the blade's wider end (blades taper to the tip).

Rotor completion: with a ``score_threshold``, blades scoring below it are not counted; when the
confident blades of the main rotor are fewer than the rotor's blade count, a low-score blade
detection (score >= ``candidate_floor``) that fits the rotor — its axis through the hub, its root
at the hub, its direction in the free slot of the evenly spaced rotor, not inside another
blade — is admitted and flagged ``admitted_low_score`` (``admit_low_score_blades``).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import cv2
import numpy as np

from wtcli.contours import (CONTOURS_SCHEMA, DEFAULT_AREA_THRESHOLD, MASK_SUFFIXES, ContourSet,
                            InstanceContours, find_contours, instances_from_mask_files,
                            read_contours, require_contours)
from wtcli.errors import ConfigError, InputError, PerceptionError
from wtcli.jsonio import document, read_json
from wtcli.masks import Instances, read_instances

PITCH_SCHEMA = "wtinspect.pitch"
PITCH_VERSION = 2  # 2: admitted_low_score per blade, score_threshold and candidate_floor
HORIZONTAL, ACUTE, VERTICAL = "horizontal", "acute", "vertical"
CLASSES = (HORIZONTAL, ACUTE, VERTICAL)
CLASS_INTERVALS = {HORIZONTAL: "[0, 30] U [150, 180)", ACUTE: "(30, 60] U [120, 150)",
                   VERTICAL: "(60, 120)"}
ANGLE_DIGITS = 6
THETA_SOURCE = "principal_axis"
STUB_ELONGATION = 3.0  # below this a blade region has no reliable axis of its own
PHOTO_SUFFIXES = (".jpg", ".jpeg", ".webp")
# Rotor completion (docs/pitch.md). The threshold is segment's default (wtcli.segment.infer).
DEFAULT_SCORE_THRESHOLD = 0.5
CANDIDATE_FLOOR = 0.2  # lowest score a blade may be admitted at (seeds 9 500 000+, see docs)
SLOT_TOLERANCE_DEG = 25.0  # as plan's MAX_SPACING_ERROR_DEG: the rotor's gaps within this of even
CANDIDATE_INSIDE = 0.3  # a candidate this much inside a counted blade is that blade again
DEFAULT_ROTOR_BLADES = 3
CLOSE_UP_LENGTH = 3.0  # a blade this much longer than a rotor's is of a far nearer turbine


# ---- angles and classes ------------------------------------------------------------------------
def normalize_angle(deg: float, period: float) -> float:
    """``deg`` in [0, period), rounded to the file's 6 decimals (so 179.9999999 -> 0)."""
    a = round(float(deg) % period, ANGLE_DIGITS)
    return 0.0 if a >= period or a == 0 else a


def normalize_theta(deg: float) -> float:
    return normalize_angle(deg, 180.0)


def normalize_phi(deg: float) -> float:
    return normalize_angle(deg, 360.0)


def classify_theta(theta_deg: float) -> str:
    """The paper's class of an axis angle: horizontal [0,30] ∪ [150,180), acute (30,60] ∪
    [120,150), vertical (60,120). Angles outside [0, 180) are wrapped first."""
    if not math.isfinite(theta_deg):
        raise ValueError(f"expected a finite angle, got {theta_deg}")
    t = normalize_theta(theta_deg)
    if t <= 30.0 or t >= 150.0:
        return HORIZONTAL
    if t <= 60.0 or t >= 120.0:
        return ACUTE
    return VERTICAL


def image_angle(dx: float, dy_image: float) -> float:
    """Direction of the image vector (dx, dy) (pixels, y down) in degrees, y up, CCW, [0, 360)."""
    return math.degrees(math.atan2(-dy_image, dx)) % 360.0


# ---- eq. 7 on minAreaRect ----------------------------------------------------------------------
@dataclass(frozen=True)
class BladeRect:
    """``cv2.minAreaRect`` normalised by us: length >= width, angle = eq. 7's θ in [0, 180)."""

    center: tuple[float, float]  # px
    length: float  # px, the long side
    width: float  # px, the short side
    angle_deg: float  # eq. 7
    top: tuple[float, float]  # midpoint of the short side with the smaller image y
    bottom: tuple[float, float]
    corners: np.ndarray = field(repr=False, compare=False, default=None)  # (4, 2) boxPoints


def rect_eq7(points: np.ndarray) -> BladeRect:
    """Minimum-area rectangle of the points and the paper's eq. 7:

        θ = arctan((y_bottom − y_top) / (x_bottom − x_top))

    with y measured upwards (atan2, so a vertical blade needs no division by zero), where top
    and bottom are the midpoints of the rectangle's short sides (the blade's two ends)."""
    pts = np.asarray(points, np.float32).reshape(-1, 2)
    rect = cv2.minAreaRect(pts)
    box = cv2.boxPoints(rect).astype(float)  # 4 corners in order around the rectangle
    e01 = np.linalg.norm(box[1] - box[0])
    e12 = np.linalg.norm(box[2] - box[1])
    if e01 >= e12:  # sides 0-1 and 2-3 are long: the ends are the short sides 1-2 and 3-0
        ends = [(box[1] + box[2]) / 2, (box[3] + box[0]) / 2]
        length, width = e01, e12
    else:
        ends = [(box[0] + box[1]) / 2, (box[2] + box[3]) / 2]
        length, width = e12, e01
    top, bottom = sorted(ends, key=lambda p: (p[1], p[0]))  # image y down: top has smaller y
    x_top, y_top = top[0], -top[1]  # y up
    x_bottom, y_bottom = bottom[0], -bottom[1]
    theta = math.degrees(math.atan2(y_bottom - y_top, x_bottom - x_top))  # eq. 7
    center = (float(box[:, 0].mean()), float(box[:, 1].mean()))
    return BladeRect(center, float(length), float(width), normalize_theta(theta),
                     (float(top[0]), float(top[1])), (float(bottom[0]), float(bottom[1])), box)


# ---- principal axis -----------------------------------------------------------------------------
@dataclass(frozen=True)
class Axis:
    centroid: tuple[float, float]  # px
    theta_deg: float  # [0, 180), y up
    elongation: float  # sqrt(major / minor second moment); 1 for a disc
    t_min: float  # extent of the region along the axis from the centroid, px (image direction)
    t_max: float

    @property
    def direction(self) -> np.ndarray:
        """Unit vector of θ in image coordinates (x right, y down)."""
        r = math.radians(self.theta_deg)
        return np.array([math.cos(r), -math.sin(r)])

    def point(self, t: float) -> np.ndarray:
        return np.asarray(self.centroid) + t * self.direction


def principal_axis(inst: InstanceContours) -> Axis:
    """Centroid and major axis of the filled region (pixel second moments)."""
    region = inst.fill().astype(np.uint8)
    x0, y0, _, _ = inst.bbox
    m = cv2.moments(region, binaryImage=True)
    if m["m00"] <= 0:
        raise PerceptionError(f"{inst.label} {inst.source_index} has an empty region")
    cx, cy = m["m10"] / m["m00"] + x0, m["m01"] / m["m00"] + y0
    mu20, mu02, mu11 = m["mu20"], m["mu02"], m["mu11"]
    theta = normalize_theta(math.degrees(0.5 * math.atan2(-2.0 * mu11, mu20 - mu02)))
    common = math.sqrt(4 * mu11 * mu11 + (mu20 - mu02) ** 2)
    lam1, lam2 = (mu20 + mu02 + common) / 2, (mu20 + mu02 - common) / 2
    elong = math.sqrt(lam1 / lam2) if lam2 > 1e-9 else float("inf")
    r = math.radians(theta)
    u = np.array([math.cos(r), -math.sin(r)])
    ys, xs = np.nonzero(region)
    # Pixel corners, not centres: the region reaches half a pixel beyond its centres.
    t = (xs + x0 - cx) * u[0] + (ys + y0 - cy) * u[1]
    half = 0.5 * (abs(u[0]) + abs(u[1]))
    return Axis((float(cx), float(cy)), theta, float(min(elong, 1e6)),
                float(t.min() - half), float(t.max() + half))


# ---- the hub -------------------------------------------------------------------------------------
def axes_convergence(axes: list[Axis], lengths: list[float]) -> np.ndarray | None:
    """Least-squares intersection of the blade axes (weighted by length); None if the axes are
    (nearly) parallel or the point is far from the blades' ends."""
    if len(axes) < 2:
        return None
    A = np.zeros((2, 2))
    b = np.zeros(2)
    for ax, w in zip(axes, lengths):
        u = ax.direction
        P = np.eye(2) - np.outer(u, u)
        A += w * P
        b += w * P @ np.asarray(ax.centroid)
    ev = np.linalg.eigvalsh(A)
    if ev[0] <= 0.01 * ev[1]:
        return None
    hub = np.linalg.solve(A, b)
    # It must be near one end of most blades (not far beyond them): ratio to blade length.
    near = [min(abs(ax.t_min - (hub - ax.centroid) @ ax.direction),
                abs(ax.t_max - (hub - ax.centroid) @ ax.direction)) / max(L, 1e-9)
            for ax, L in zip(axes, lengths)]
    if float(np.median(near)) > 0.5:
        return None
    return hub


def common_end(axes: list[Axis]) -> np.ndarray:
    """The blades' common end: for each blade the end closest to any other blade's ends."""
    ends = [(ax.point(ax.t_min), ax.point(ax.t_max)) for ax in axes]
    chosen = []
    for i, (a, b) in enumerate(ends):
        others = [p for j, e in enumerate(ends) if j != i for p in e]
        da = min(np.linalg.norm(a - p) for p in others)
        db = min(np.linalg.norm(b - p) for p in others)
        chosen.append(a if da <= db else b)
    return np.mean(chosen, axis=0)


def wider_end(inst: InstanceContours, ax: Axis, decisive: bool = False) -> np.ndarray | None:
    """One blade alone: the end whose last quarter holds more pixels (root wider than tip).
    With ``decisive``, None unless one quarter holds at least 15 % more than the other and is
    at least a pixel wider on average (a thin blade's ends differ by pixel noise alone)."""
    region = inst.fill()
    x0, y0, _, _ = inst.bbox
    ys, xs = np.nonzero(region)
    u = ax.direction
    t = (xs + x0 - ax.centroid[0]) * u[0] + (ys + y0 - ax.centroid[1]) * u[1]
    q = 0.25 * (ax.t_max - ax.t_min)
    n_low = int((t < ax.t_min + q).sum())
    n_high = int((t > ax.t_max - q).sum())
    if decisive and (max(n_low, n_high) < 1.15 * min(n_low, n_high)
                     or abs(n_high - n_low) < max(q, 1.0)):
        return None
    return ax.point(ax.t_min if n_low >= n_high else ax.t_max)


def nacelle_hub(nacelles: ContourSet, near: np.ndarray | None, scale: float) -> np.ndarray | None:
    """Centroid of the nacelle/hub pixels near ``near`` (where the blade axes meet): those
    within the region's equivalent radius of it. None without ``near``, or when no nacelle
    comes within ``0.25 * scale`` (the blades' median length) of it — a far turbine's
    nacelle must not turn this rotor's blades around."""
    if len(nacelles) == 0 or near is None:
        return None
    best, best_d = None, math.inf
    for inst in nacelles:
        region = inst.fill()
        x0, y0, _, _ = inst.bbox
        ys, xs = np.nonzero(region)
        pts = np.stack([xs + x0, ys + y0], 1).astype(float)
        dist = np.linalg.norm(pts - near, axis=1)
        d = float(dist.min())
        rho = math.sqrt(len(pts) / math.pi)  # the region's equivalent radius
        if d < best_d:
            best, best_d = pts[dist <= max(rho, d + 1.0)].mean(axis=0), d
    if best is None or np.linalg.norm(best - near) > 0.25 * scale + 3.0:
        return None
    return best


# ---- which blades form the rotor ---------------------------------------------------------------
def _region_centroid(inst: InstanceContours) -> np.ndarray:
    m = cv2.moments(inst.fill().astype(np.uint8), binaryImage=True)
    x0, y0, _, _ = inst.bbox
    if m["m00"] <= 0:
        return np.asarray(inst.points.mean(axis=0), float)
    return np.array([m["m10"] / m["m00"] + x0, m["m01"] / m["m00"] + y0])


def _supports(ax: Axis, length: float, width: float, c: np.ndarray) -> bool:
    """Could ``c`` be this blade's hub: on its axis line, at (or a little beyond) one end?
    ``width`` (mean width, px) widens the tolerances for stubs cut short by the frame."""
    d = np.asarray(c, float) - np.asarray(ax.centroid)
    u = ax.direction
    t = float(d @ u)
    perp = abs(float(d[0] * u[1] - d[1] * u[0]))
    if perp > 0.1 * length + 0.5 * width + 3.0:
        return False
    slack = 0.25 * length + width
    near_low = ax.t_min - 0.5 * length - width <= t <= ax.t_min + slack
    near_high = ax.t_max - slack <= t <= ax.t_max + 0.5 * length + width
    return near_low or near_high


def _touches_border(inst: InstanceContours, image_size: tuple[int, int], margin: int = 2) -> bool:
    """Cut by the frame: a mask seldom reaches the very edge pixel of what the frame cut."""
    x0, y0, x1, y1 = inst.bbox
    return (x0 <= margin or y0 <= margin or x1 >= image_size[1] - margin
            or y1 >= image_size[0] - margin)


def _wide_end_away(inst: InstanceContours, ax: Axis, hub: np.ndarray, decisive: bool = False) -> bool:
    """The region's wider end (``wider_end``) is its axis end farther from ``hub``: not how a
    blade of that hub looks (its root is the wide end)."""
    root = wider_end(inst, ax, decisive)
    ends = (ax.point(ax.t_min), ax.point(ax.t_max))
    far = max(ends, key=lambda e: float(np.linalg.norm(e - hub)))
    return root is not None and bool(np.allclose(root, far))


def _root_at_border(inst: InstanceContours, ax: Axis, width: float,
                    image_size: tuple[int, int]) -> bool:
    """The blade's wider (root) end lies at the frame's edge: its hub is out of frame."""
    x, y = wider_end(inst, ax)
    h, w = image_size
    return min(x, y, w - x, h - y) <= 2.0 + width


def select_rotor(blades: ContourSet, axes: list[Axis],
                 nacelle_points: list[np.ndarray]) -> tuple[list[int], np.ndarray | None]:
    """The blades of the main rotor when a photo shows several turbines.

    Candidate hubs are the nacelle centroids and the crossing points of pairs of blade axes
    that lie near an end of both blades; each candidate is supported by the blades whose axis
    passes through it near one of their ends. The candidate whose supporting blades cover the
    most pixels wins (the inspected turbine is the nearest, largest one). A small supporter
    (< 30 % of the largest one's pixels, not cut by the frame) whose wider end is away from the
    hub is a far turbine's blade pointing at it, and is left out. Without any candidate (one
    blade; two in line and no nacelle) every blade is kept. In a close-up with the hub out of
    frame, the blades cut at their root by the frame win over a far rotor (see the code), and
    the hub returned is None."""
    n = len(axes)
    areas = [float(b.area) for b in blades]
    lengths = [max(ax.t_max - ax.t_min, 1.0) for ax in axes]
    widths = [a / L for a, L in zip(areas, lengths)]
    cands = [np.asarray(p, float) for p in nacelle_points]
    for i in range(n):
        for j in range(i + 1, n):
            ui, uj = axes[i].direction, axes[j].direction
            cross = ui[0] * uj[1] - ui[1] * uj[0]
            if abs(cross) < math.sin(math.radians(10)):
                continue
            d = np.asarray(axes[j].centroid) - np.asarray(axes[i].centroid)
            ti = (d[0] * uj[1] - d[1] * uj[0]) / cross
            x = np.asarray(axes[i].centroid) + ti * ui
            if (_supports(axes[i], lengths[i], widths[i], x)
                    and _supports(axes[j], lengths[j], widths[j], x)):
                cands.append(x)
    best, best_key, best_c = list(range(n)), None, None
    for c in cands:
        sup = [k for k in range(n) if _supports(axes[k], lengths[k], widths[k], c)]
        if not sup:
            continue
        key = (sum(areas[k] for k in sup), len(sup))
        if best_key is None or key > best_key:
            best, best_key, best_c = sup, key, c
    if best_c is not None:
        # A close-up may leave the inspected turbine's hub out of frame: blades cut by the frame
        # at their root end, not meeting the rotor found, are that turbine's when they outweigh
        # the rotor and one is far longer than its blades (much nearer: the rotor is a far one;
        # a shadow or the tower's edge read as a blade is seldom that long).
        cut = [k for k in range(n) if k not in best
               and _root_at_border(blades.instances[k], axes[k], widths[k], blades.image_size)]
        if (cut and sum(areas[k] for k in cut) > sum(areas[k] for k in best)
                and max(lengths[k] for k in cut) >= CLOSE_UP_LENGTH * max(lengths[k] for k in best)):
            return cut, None
    if best_c is not None and len(best) > 1:
        big = max(areas[k] for k in best)
        keep = []
        for k in best:
            inst = blades.instances[k]
            if areas[k] < 0.3 * big and not _touches_border(inst, blades.image_size):
                if _wide_end_away(inst, axes[k], best_c):
                    continue
            keep.append(k)
        best = keep
    return best, best_c


def _without_doubles(out: list[BladePitch], n: int,
                   slot_tolerance: float = SLOT_TOLERANCE_DEG) -> list[BladePitch]:
    """More blades on the hub than the rotor has, where the extra ones double a blade (the
    tower's edge beside the blade pointing down, a far rotor's blade behind one): keep the
    ``n`` spaced like an ``n``-blade rotor's (every gap in φ within ``slot_tolerance`` of
    360/n), the highest-scoring such choice, when every blade left out points within
    ``slot_tolerance`` of a kept one. Else keep all: a blade between the slots stays a count
    error (a wrong angle would misplace the flight around the rotor)."""
    if n < 2 or not n < len(out) <= 8:
        return out
    best, best_key = out, None
    for sub in itertools.combinations(range(len(out)), n):
        p = sorted(out[k].phi_deg for k in sub)
        gaps = np.diff(p + [p[0] + 360.0])
        if np.abs(gaps - 360.0 / n).max() > slot_tolerance:
            continue
        if any(min(abs(_angle_diff(out[d].phi_deg, out[k].phi_deg)) for k in sub) > slot_tolerance
               for d in range(len(out)) if d not in sub):
            continue
        key = (sum(out[k].score for k in sub), sum(out[k].area for k in sub))
        if best_key is None or key > best_key:
            best, best_key = [out[k] for k in sub], key
    return best


def _without_wide_tips(keep: list[int], blades: ContourSet, axes: list[Axis],
                       hub: np.ndarray) -> list[int]:
    """Too many blades on one hub: one clearly wider at its end away from the hub is not a
    blade (blades taper to the tip) but the tower under a close-up's hub, read as a blade."""
    return [k for k in keep if not _wide_end_away(blades.instances[k], axes[k], hub, decisive=True)]


def _longest_if_clearly(keep: list[int], axes: list[Axis], n: int) -> list[int]:
    """Too many blades on one hub: a far turbine right behind it shows shorter blades. Keep the
    ``n`` longest when each is at least 1.25x as long as every other; else keep all (and the
    count check reports them)."""
    by_length = sorted(keep, key=lambda k: axes[k].t_max - axes[k].t_min, reverse=True)
    length = [axes[k].t_max - axes[k].t_min for k in by_length]
    if length[n - 1] >= 1.25 * length[n]:
        return sorted(by_length[:n])
    return keep


# ---- typed result --------------------------------------------------------------------------------
@dataclass(frozen=True)
class BladePitch:
    source_index: int  # the blade's index in its image's instances
    score: float
    area: int  # px
    theta_deg: float  # principal axis, [0, 180): the θ that is classified
    theta_class: str
    theta_eq7_deg: float  # eq. 7 on minAreaRect, [0, 180)
    phi_deg: float  # hub -> tip, [0, 360)
    rect: BladeRect
    root_px: tuple[float, float]  # hub-side end of the blade's axis
    tip_px: tuple[float, float]  # far end
    centroid_px: tuple[float, float]
    elongation: float
    theta_method: str = "principal_axis"  # or hub_to_centroid for a stub (elongation < 3)
    admitted_low_score: bool = False  # scored below the threshold, admitted to complete the rotor

    def __post_init__(self) -> None:
        if self.theta_method not in ("principal_axis", "hub_to_centroid"):
            raise ValueError(f"unknown theta_method {self.theta_method!r}")
        for name, period in (("theta_deg", 180.0), ("theta_eq7_deg", 180.0), ("phi_deg", 360.0)):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0.0 <= v < period):
                raise ValueError(f"expected {name} in [0, {period:g}), got {v}")
        if self.theta_class != classify_theta(self.theta_deg):
            raise ValueError(f"expected class {classify_theta(self.theta_deg)!r} for θ "
                             f"{self.theta_deg}, got {self.theta_class!r}")
        d = (self.phi_deg - self.theta_deg) % 180.0
        if min(d, 180.0 - d) > 1e-4:
            raise ValueError(f"expected φ ({self.phi_deg}) = θ ({self.theta_deg}) or θ + 180")

    def to_dict(self) -> dict[str, Any]:
        r = self.rect
        return {"source_index": self.source_index, "score": self.score, "area": self.area,
                "theta_deg": self.theta_deg, "theta_class": self.theta_class,
                "theta_eq7_deg": self.theta_eq7_deg, "phi_deg": self.phi_deg,
                "rect": {"center": list(r.center), "size": [r.length, r.width],
                         "angle_deg": r.angle_deg, "top": list(r.top), "bottom": list(r.bottom)},
                "root_px": list(self.root_px), "tip_px": list(self.tip_px),
                "centroid_px": list(self.centroid_px), "elongation": self.elongation,
                "theta_method": self.theta_method, "admitted_low_score": self.admitted_low_score}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> BladePitch:
        r = d["rect"]
        rect = BladeRect(tuple(r["center"]), float(r["size"][0]), float(r["size"][1]),
                         float(r["angle_deg"]), tuple(r["top"]), tuple(r["bottom"]))
        return cls(int(d["source_index"]), float(d["score"]), int(d["area"]),
                   float(d["theta_deg"]), str(d["theta_class"]), float(d["theta_eq7_deg"]),
                   float(d["phi_deg"]), rect, tuple(d["root_px"]), tuple(d["tip_px"]),
                   tuple(d["centroid_px"]), float(d["elongation"]),
                   str(d.get("theta_method", "principal_axis")),
                   bool(d.get("admitted_low_score", False)))  # absent in version 1


@dataclass(frozen=True)
class PitchResult:
    blades: tuple[BladePitch, ...]
    hub_px: tuple[float, float]
    hub_source: str  # nacelle | blade_axes | common_end | blade_taper
    image_size: tuple[int, int]  # (H, W)
    image: dict = field(default_factory=dict)
    source: str = ""
    area_threshold: float = DEFAULT_AREA_THRESHOLD
    axes_convergence_px: tuple[float, float] | None = None
    other_rotor_blades: tuple[int, ...] = ()  # source indices of blades of other turbines
    contours: ContourSet | None = field(default=None, repr=False, compare=False)
    score_threshold: float | None = None  # blades below it were not counted (None: all were)
    candidate_floor: float | None = None  # ... unless admitted from at least this score

    def __post_init__(self) -> None:
        if not self.blades:
            raise ValueError("expected at least one blade")
        if self.hub_source not in ("nacelle", "blade_axes", "common_end", "blade_taper"):
            raise ValueError(f"unknown hub_source {self.hub_source!r}")
        object.__setattr__(self, "blades", tuple(self.blades))
        object.__setattr__(self, "image_size", tuple(int(v) for v in self.image_size))

    def __len__(self) -> int:
        return len(self.blades)

    @property
    def thetas(self) -> np.ndarray:
        return np.array([b.theta_deg for b in self.blades])

    @property
    def phis(self) -> np.ndarray:
        return np.array([b.phi_deg for b in self.blades])

    @property
    def classes(self) -> list[str]:
        return [b.theta_class for b in self.blades]

    @property
    def admitted(self) -> tuple[BladePitch, ...]:
        """The blades admitted below the score threshold to complete the rotor."""
        return tuple(b for b in self.blades if b.admitted_low_score)

    def to_dict(self) -> dict[str, Any]:
        return {"image": self.image, "image_size": list(self.image_size),
                "area_threshold": self.area_threshold, "n_blades": len(self.blades),
                "hub_px": list(self.hub_px), "hub_source": self.hub_source,
                "axes_convergence_px": (None if self.axes_convergence_px is None
                                        else list(self.axes_convergence_px)),
                "other_rotor_blades": list(self.other_rotor_blades),
                "score_threshold": self.score_threshold, "candidate_floor": self.candidate_floor,
                "blades": [b.to_dict() for b in self.blades]}

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = "") -> PitchResult:
        conv = d.get("axes_convergence_px")
        return cls(tuple(BladePitch.from_dict(b) for b in d["blades"]), tuple(d["hub_px"]),
                   d["hub_source"], tuple(d["image_size"]), d.get("image") or {}, source,
                   float(d.get("area_threshold", DEFAULT_AREA_THRESHOLD)),
                   None if conv is None else tuple(conv),
                   tuple(int(i) for i in d.get("other_rotor_blades", ())), None,
                   _opt_float(d.get("score_threshold")), _opt_float(d.get("candidate_floor")))


def _opt_float(v: Any) -> float | None:
    return None if v is None else float(v)


# ---- measuring -----------------------------------------------------------------------------------
def check_blade_count(n: int, expected: int | None, where: str, dropped: int = 0) -> None:
    if n == 0:
        extra = f" ({dropped} contour(s) below the area threshold)" if dropped else ""
        raise PerceptionError(f"no blade found in {where}{extra}")
    if expected and n != expected:
        raise PerceptionError(f"found {n} blade{'s' if n != 1 else ''} in {where}, expected "
                              f"{expected} (--blades 0 accepts any count)")


def measure_pitch(contours: ContourSet, expected_blades: int | None = 3,
                  score_threshold: float | None = None, candidate_floor: float | None = CANDIDATE_FLOOR,
                  rotor_blades: int | None = None) -> PitchResult:
    """θ (eq. 7 and principal axis), class and φ of every blade in one image's contours.

    ``expected_blades``: raise PerceptionError unless exactly this many blades are found
    (None or 0: any count >= 1).

    ``score_threshold``: instances scoring below it are not counted (None: every instance is).
    Blades among them scoring at least ``candidate_floor`` (None: none) are candidates: when
    the main rotor's counted blades are fewer than its blade count (``rotor_blades``, else
    ``expected_blades``, else 3), ``admit_low_score_blades`` may admit them; they are flagged
    ``admitted_low_score``."""
    if expected_blades is not None and expected_blades < 0:
        raise ValueError(f"expected_blades must be >= 0, got {expected_blades}")
    candidates: list[InstanceContours] = []
    full = contours
    if score_threshold is not None:
        if candidate_floor is not None:
            candidates = [i for i in contours if i.label == "blade"
                          and candidate_floor <= i.score < score_threshold]
        contours = contours[contours.scores >= score_threshold] if len(contours) else contours
    all_blades = contours.of("blade")
    check_blade_count(len(all_blades), None, contours.name, contours.dropped)
    all_axes = [principal_axis(b) for b in all_blades]
    nacelles = contours.of("nacelle")
    keep, candidate = select_rotor(all_blades, all_axes, [_region_centroid(n) for n in nacelles])
    n_rotor = rotor_blades or expected_blades or DEFAULT_ROTOR_BLADES
    trim_to = expected_blades or n_rotor  # also when any count is accepted: a rotor has n_rotor
    if len(keep) > trim_to:
        keep = _longest_if_clearly(keep, all_axes, trim_to)
    if len(keep) > trim_to and candidate is not None:
        fewer = _without_wide_tips(keep, all_blades, all_axes, candidate)
        # Only when that leaves the rotor's count: the tower read as a blade. Blades that hardly
        # taper (or thin ones, a few pixels wide) can look wider at the tip by pixel noise alone,
        # and dropping them would lose real blades (all of them, even).
        if len(fewer) == trim_to:
            keep = fewer
    blades = all_blades[keep]
    others = tuple(all_blades.instances[i].source_index for i in range(len(all_blades))
                   if i not in keep)
    axes = [all_axes[i] for i in keep]
    lengths = [ax.t_max - ax.t_min for ax in axes]

    conv = axes_convergence(axes, lengths)
    hub = nacelle_hub(nacelles, conv if conv is not None else candidate,
                      float(np.median(lengths)))
    if hub is not None and len(axes) == 1:
        # One blade cannot check a nacelle against other blades; its taper can.
        root = wider_end(blades.instances[0], axes[0], decisive=True)
        ends = (axes[0].point(axes[0].t_min), axes[0].point(axes[0].t_max))
        near_end = min(ends, key=lambda e: float(np.linalg.norm(e - hub)))
        if root is not None and not np.allclose(root, near_end):
            hub = None
    if hub is not None:
        source = "nacelle"
    elif conv is not None:
        hub, source = conv, "blade_axes"
    elif len(axes) >= 2:
        hub, source = common_end(axes), "common_end"
    else:
        hub, source = wider_end(blades.instances[0], axes[0]), "blade_taper"

    out = [_blade_pitch(inst, ax, hub) for inst, ax in zip(blades, axes)]
    rotor = _without_doubles(out, n_rotor)
    if len(rotor) < len(out):  # the doubles are left out like other rotors' blades
        kept = {b.source_index for b in rotor}
        others += tuple(b.source_index for b in out if b.source_index not in kept)
        out = rotor
    if candidates and len(out) < n_rotor and source != "blade_taper":
        admitted = admit_low_score_blades(candidates, list(blades), out, hub, n_rotor,
                                          contours.image_size)
        out = sorted(out + [_blade_pitch(c, ax, hub, admitted=True) for c, ax in admitted],
                     key=lambda b: b.source_index)
    where = contours.name + (f" (besides {len(others)} blade(s) of other rotors)" if others else "")
    check_blade_count(len(out), expected_blades, where, contours.dropped)
    shown = {b.source_index for b in out if b.admitted_low_score}
    if score_threshold is not None:  # the overlay draws the instances counted and admitted
        full = full[[i.score >= score_threshold or i.source_index in shown for i in full]] \
            if len(full) else full
    return PitchResult(tuple(out), (float(hub[0]), float(hub[1])), source, contours.image_size,
                       contours.image, contours.source, contours.area_threshold,
                       None if conv is None else (float(conv[0]), float(conv[1])), others,
                       full, score_threshold, candidate_floor if score_threshold is not None else None)


def _blade_pitch(inst: InstanceContours, ax: Axis, hub: np.ndarray,
                 admitted: bool = False) -> BladePitch:
    """θ, class, φ, root and tip of one blade of the rotor whose hub is ``hub``."""
    rect = rect_eq7(inst.points)
    to_centroid = np.asarray(ax.centroid) - hub
    if ax.elongation < STUB_ELONGATION and np.linalg.norm(to_centroid) > 2.0:
        # A stub (cut by the frame) has no axis of its own: hub -> its centroid instead.
        method = "hub_to_centroid"
        u = to_centroid / np.linalg.norm(to_centroid)
        region = inst.fill()
        x0, y0, _, _ = inst.bbox
        ys, xs = np.nonzero(region)
        t = (xs + x0 - hub[0]) * u[0] + (ys + y0 - hub[1]) * u[1]
        root, tip = hub + max(float(t.min()), 0.0) * u, hub + float(t.max()) * u
        phi = image_angle(u[0], u[1])
        theta = normalize_theta(phi)
    else:
        method = "principal_axis"
        a, b = ax.point(ax.t_min), ax.point(ax.t_max)
        root, tip = (a, b) if np.linalg.norm(a - hub) <= np.linalg.norm(b - hub) else (b, a)
        # φ follows the principal axis; the hub decides which way along it the tip lies.
        theta = ax.theta_deg
        phi = theta if (tip - root) @ ax.direction > 0 else theta + 180.0
    return BladePitch(
        inst.source_index, inst.score, inst.area, theta, classify_theta(theta),
        rect.angle_deg, normalize_phi(phi), rect, (float(root[0]), float(root[1])),
        (float(tip[0]), float(tip[1])), ax.centroid, ax.elongation, method, admitted)


# ---- rotor completion ------------------------------------------------------------------------------
def _angle_diff(a: float, b: float) -> float:
    """Signed a - b on the circle, in [-180, 180)."""
    return (a - b + 180.0) % 360.0 - 180.0


def _overlap(a: InstanceContours, b: InstanceContours) -> int:
    """Pixels the filled regions of ``a`` and ``b`` share (drawn in ``a``'s box only)."""
    x0, y0, x1, y1 = a.bbox
    bx0, by0, bx1, by1 = b.bbox
    if bx0 >= x1 or bx1 <= x0 or by0 >= y1 or by1 <= y0:
        return 0
    canvas = np.zeros((y1 - y0, x1 - x0), np.uint8)
    cv2.drawContours(canvas, [(c - [x0, y0]).reshape(-1, 1, 2).astype(np.int32)
                              for c in b.contours], -1, 1, thickness=cv2.FILLED)
    return int((a.fill() & canvas.astype(bool)).sum())


def admit_low_score_blades(candidates: list[InstanceContours], blades: list[InstanceContours],
                           measured: list[BladePitch], hub: np.ndarray, n: int,
                           image_size: tuple[int, int] | None = None,
                           slot_tolerance: float = SLOT_TOLERANCE_DEG,
                           inside: float = CANDIDATE_INSIDE,
                           min_reach: float = 0.25) -> list[tuple[InstanceContours, Axis]]:
    """Low-score blade detections that complete an ``n``-blade rotor of which ``measured``
    (the counted ``blades``, hub ``hub``) are fewer than ``n``; best score first, at most the
    number missing. The measured blades fix the rotor's phase (circular mean of n x φ) and
    must sit in distinct slots with gaps within ``slot_tolerance`` of even. A candidate is
    admitted when its axis passes through the hub near one of its ends (``_supports``, as for
    the rotor's own blades), its direction hub -> far end lies within ``slot_tolerance`` of a
    free slot, it reaches at least a quarter of the blades' median length beyond the hub, and
    less than ``inside`` of its pixels lie in a counted or already admitted blade."""
    missing = n - len(measured)
    if missing <= 0 or not candidates or not measured or n < 2:
        return []
    step = 360.0 / n
    phis = np.array([b.phi_deg for b in measured])
    ang = np.radians(phis * n)
    phase = math.degrees(math.atan2(np.sin(ang).sum(), np.cos(ang).sum())) / n
    slot = np.round((phis - phase) / step).astype(int) % n
    off = np.array([_angle_diff(p, phase + k * step) for p, k in zip(phis, slot)])
    if len(set(slot.tolist())) != len(phis) or off.max() - off.min() > slot_tolerance:
        return []  # the counted blades are not spaced like blades of an n-blade rotor
    free = set(range(n)) - set(slot.tolist())
    scale = float(np.median([math.dist(b.root_px, b.tip_px) for b in measured]))
    taken = list(blades)
    out: list[tuple[InstanceContours, Axis]] = []
    for cand in sorted(candidates, key=lambda c: (-c.score, c.source_index)):
        if len(out) == missing:
            break
        ax = principal_axis(cand)
        length = max(ax.t_max - ax.t_min, 1.0)
        if not _supports(ax, length, cand.area / length, hub):
            continue
        ends = (ax.point(ax.t_min), ax.point(ax.t_max))
        far = max(ends, key=lambda e: float(np.linalg.norm(e - hub)))
        if np.linalg.norm(far - hub) < min_reach * scale and not (
                image_size is not None and _touches_border(cand, image_size)):
            continue  # too short for a blade of this rotor, unless the frame cut it
        phi = image_angle(*(far - hub))
        k = min(free, key=lambda j: abs(_angle_diff(phi, phase + j * step)), default=None)
        if k is None or abs(_angle_diff(phi, phase + k * step)) > slot_tolerance:
            continue
        if any(_overlap(cand, t) >= inside * cand.area for t in taken):
            continue
        free.discard(k)
        taken.append(cand)
        out.append((cand, ax))
    return out


def pitch_from_instances(instances: Instances, area_threshold: float = DEFAULT_AREA_THRESHOLD,
                         expected_blades: int | None = 3, image: dict | None = None,
                         source: str = "", score_threshold: float | None = DEFAULT_SCORE_THRESHOLD,
                         candidate_floor: float | None = CANDIDATE_FLOOR,
                         rotor_blades: int | None = None) -> PitchResult:
    """Eq. 4-7 in one call: instances of one image -> contours -> pitch. Instances scoring
    below ``score_threshold`` (default 0.5, segment's) are not counted, but blades among them
    scoring at least ``candidate_floor`` may complete the rotor (``measure_pitch``); pass
    ``segment_image``'s output as it is (it keeps such blades)."""
    if score_threshold is not None and candidate_floor is not None and len(instances):
        low = (instances.scores < score_threshold) & ~(
            (instances.labels == "blade") & (instances.scores >= candidate_floor))
        if low.any():  # not needed at all: no contours for them (indices kept below)
            instances = Instances(instances.labels, instances.masks & ~low[:, None, None],
                                  instances.scores, instances.boxes)
    cs = require_contours(find_contours(instances, area_threshold, image=image, source=source))
    return measure_pitch(cs, expected_blades, score_threshold, candidate_floor, rotor_blades)


# ---- inputs of the pitch command -------------------------------------------------------------------
@dataclass(frozen=True)
class PitchInput:
    """One image to measure: its contours (or the error that stopped them) and where its photo
    may be found for the overlay background."""

    contours: ContourSet | None
    error: str | None
    image: dict
    background_candidates: tuple[Path, ...] = ()
    score_threshold: float | None = None  # a photo segmented here: 0.5; a file: none (all count)


def _image_candidates(file_name: str | None, *dirs: Path) -> tuple[Path, ...]:
    if not file_name:
        return ()
    out = []
    for d in dirs:
        p = d / file_name
        if p not in out:
            out.append(p)
    return tuple(out)


def load_pitch_input(paths: list[Path], area_threshold: float | None = None,
                     candidate_floor: float | None = CANDIDATE_FLOOR) -> list[PitchInput]:
    """INPUT of ``pitch``, dispatched on its type: a contours JSON, an instances JSON (contours
    found here), mask PNG(s) of one image, or photos (segmented here, keeping blades down to
    ``candidate_floor`` as rotor-completion candidates)."""
    paths = [Path(p) for p in paths]
    if not paths:
        raise InputError("no input given")
    thr = DEFAULT_AREA_THRESHOLD if area_threshold is None else float(area_threshold)
    if thr < 0 or not math.isfinite(thr):
        raise ConfigError(f"--area-threshold must be >= 0, got {area_threshold}")
    first = paths[0]
    if len(paths) == 1 and first.suffix.lower() == ".json":
        doc = read_json(first)
        if isinstance(doc, dict) and doc.get("schema") == CONTOURS_SCHEMA:
            return _from_contours_file(first, area_threshold)
        out = []
        for img, inst in read_instances(first):
            cands = _image_candidates(img.get("file_name"), first.parent)
            try:
                cs = require_contours(find_contours(inst, thr, image=img, source=str(first)))
                out.append(PitchInput(cs, None, img, cands))
            except PerceptionError as e:
                out.append(PitchInput(None, str(e), img, cands))
        if not out:
            raise InputError(f"{first}: no images in the instances file")
        return out
    photos = [p for p in paths if is_photo(p)]
    if photos:
        return [photo_input(p, thr, candidate_floor) for p in photos] \
            if len(photos) == len(paths) else \
            _mixed(photos[0])
    if all(p.suffix.lower() in MASK_SUFFIXES for p in paths):
        rec, inst = instances_from_mask_files(paths)
        try:
            cs = require_contours(find_contours(inst, thr, image=rec, source=str(first)))
            return [PitchInput(cs, None, rec)]
        except PerceptionError as e:
            return [PitchInput(None, str(e), rec)]
    bad = next(p for p in paths if p.suffix.lower() not in MASK_SUFFIXES)
    raise InputError(f"{bad}: expected a contours or instances JSON, or mask PNG files")


def is_photo(path: Path) -> bool:
    """A photo rather than a mask: a .jpg/.jpeg/.webp, or an image file with colour in it."""
    if path.suffix.lower() in PHOTO_SUFFIXES:
        return True
    if path.suffix.lower() in MASK_SUFFIXES and path.is_file():
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is not None and img.ndim == 3:
            c = img[:, :, :3]
            return not (np.array_equal(c[:, :, 0], c[:, :, 1])
                        and np.array_equal(c[:, :, 1], c[:, :, 2]))
    return False


def photo_input(path: Path, area_threshold: float,
                candidate_floor: float | None = CANDIDATE_FLOOR) -> PitchInput:
    """One photo as pitch input: segmented with the shipped model (``wtcli.segment``) at its
    default score threshold, with the blades scoring at least ``candidate_floor`` kept as
    rotor-completion candidates, then ``find_contours`` as for an instances JSON; the photo is
    the overlay's background."""
    from wtcli.segment.infer import segment_photo

    rec, inst = segment_photo(path, score_threshold=DEFAULT_SCORE_THRESHOLD,
                              candidate_floor=candidate_floor)
    try:
        cs = require_contours(find_contours(inst, area_threshold, image=rec, source=str(path)))
        return PitchInput(cs, None, rec, (path,), DEFAULT_SCORE_THRESHOLD)
    except PerceptionError as e:
        return PitchInput(None, str(e), rec, (path,), DEFAULT_SCORE_THRESHOLD)


def _mixed(photo: Path) -> list[PitchInput]:
    raise InputError(f"{photo}: a photo among mask files; give photos or masks, not both")


def _from_contours_file(path: Path, area_threshold: float | None) -> list[PitchInput]:
    out = []
    doc_source = read_json(path).get("source", "")
    src_dir = Path(doc_source).parent if doc_source else Path(".")
    for cs, err, img in read_contours(path):
        cands = _image_candidates(img.get("file_name"), src_dir, path.parent / src_dir, path.parent)
        if cs is not None and area_threshold is not None:
            if area_threshold < cs.area_threshold:
                raise ConfigError(f"{path} was filtered at {cs.area_threshold:g} px; a lower "
                                  f"--area-threshold ({area_threshold:g}) needs `wtinspect "
                                  "contours` again")
            cs = _refilter(cs, area_threshold)
            try:
                require_contours(cs)
            except PerceptionError as e:
                cs, err = None, str(e)
        out.append(PitchInput(cs, err, img, cands))
    if not out:
        raise InputError(f"{path}: no images in the contours file")
    return out


def _refilter(cs: ContourSet, threshold: float) -> ContourSet:
    kept, dropped, largest = [], cs.dropped, cs.largest_dropped_area
    for inst in cs:
        keep = [(c, a) for c, a in zip(inst.contours, inst.areas) if a > threshold]
        for a in inst.areas:
            if a <= threshold:
                dropped += 1
                largest = max(largest, a)
        if keep:
            kept.append(InstanceContours(inst.label, inst.score, inst.source_index,
                                         tuple(c for c, _ in keep), tuple(a for _, a in keep)))
    return ContourSet(tuple(kept), cs.image_size, threshold, cs.image, cs.source, dropped, largest)


# ---- batch ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PitchBatch:
    results: tuple[PitchResult | None, ...]
    errors: tuple[str | None, ...]
    inputs: tuple[PitchInput, ...]
    source: str
    expected_blades: int | None
    score_threshold: float | None = None  # as given; each image records the one it used
    candidate_floor: float | None = CANDIDATE_FLOOR

    @property
    def n_failed(self) -> int:
        return sum(e is not None for e in self.errors)

    def to_document(self, overlays: list[str | None] | None = None) -> dict[str, Any]:
        items = []
        for k, (res, err, inp) in enumerate(zip(self.results, self.errors, self.inputs)):
            item = ({"image": inp.image, "error": err} if res is None
                    else {**res.to_dict(), "error": None})
            if overlays is not None:
                item["overlay"] = overlays[k]
            items.append(item)
        return document(PITCH_SCHEMA, PITCH_VERSION, {
            "source": self.source, "expected_blades": self.expected_blades or 0,
            "score_threshold": self.score_threshold, "candidate_floor": self.candidate_floor,
            "theta_source": THETA_SOURCE, "angle_convention":
                "degrees, counter-clockwise, image y up, 0 = right; theta in [0, 180), "
                "phi hub->tip in [0, 360)",
            "classes": CLASS_INTERVALS, "images": items})


def pitch_batch(inputs: list[PitchInput], expected_blades: int | None = 3,
                source: str = "", on_done: Callable[[int, str | None], None] | None = None,
                score_threshold: float | None = None,
                candidate_floor: float | None = CANDIDATE_FLOOR) -> PitchBatch:
    """``measure_pitch`` on every input image; per-image errors are recorded, not raised.
    ``on_done(index, error)`` is called after each image (for a progress bar).
    ``score_threshold``: None uses each input's own (0.5 for a photo, none for a file)."""
    results, errors = [], []
    for k, inp in enumerate(inputs):
        if inp.contours is None:
            results.append(None)
            errors.append(inp.error or "no contours")
        else:
            try:
                thr = inp.score_threshold if score_threshold is None else score_threshold
                results.append(measure_pitch(inp.contours, expected_blades, thr, candidate_floor))
                errors.append(None)
            except PerceptionError as e:
                results.append(None)
                errors.append(str(e))
        if on_done is not None:
            on_done(k, errors[-1])
    return PitchBatch(tuple(results), tuple(errors), tuple(inputs), source, expected_blades,
                      score_threshold, candidate_floor)


def read_pitch(path: str | Path) -> list[tuple[PitchResult | None, str | None, dict]]:
    """Read a ``wtinspect.pitch`` file, version 1 or 2 (version 1 has no admitted blades):
    (result or None, error or None, image record) per image."""
    path = Path(path)
    doc = read_json(path, PITCH_SCHEMA, PITCH_VERSION)
    out = []
    for i, d in enumerate(doc.get("images") or []):
        img = d.get("image") or {}
        if d.get("error"):
            out.append((None, str(d["error"]), img))
            continue
        try:
            out.append((PitchResult.from_dict(d, source=str(path)), None, img))
        except (KeyError, TypeError, ValueError) as e:
            raise InputError(f"{path}: images[{i}]: bad pitch entry ({e})") from None
    return out


# ---- overlay ---------------------------------------------------------------------------------------
CLASS_COLORS_BGR = {HORIZONTAL: (80, 200, 40), ACUTE: (0, 165, 255), VERTICAL: (230, 60, 230)}
_PART_GREY = {"blade": 90, "tower": 55, "nacelle": 120}


def mask_canvas(result: PitchResult) -> np.ndarray:
    """A black BGR canvas with every instance's region in grey (when there is no photo)."""
    h, w = result.image_size
    canvas = np.zeros((h, w, 3), np.uint8)
    if result.contours is not None:
        for inst in result.contours:
            g = _PART_GREY.get(inst.label, 80)
            cv2.drawContours(canvas, [c.reshape(-1, 1, 2) for c in inst.contours], -1,
                             (g, g, g), thickness=cv2.FILLED)
    return canvas


def _text(img: np.ndarray, s: str, org: tuple[int, int], scale: float, color, thick: int) -> None:
    for dx, dy in ((-1, -1), (-1, 1), (1, -1), (1, 1)):  # a dark outline, same glyph widths
        cv2.putText(img, s, (org[0] + dx, org[1] + dy), cv2.FONT_HERSHEY_SIMPLEX, scale,
                    (0, 0, 0), thick, cv2.LINE_AA)
    cv2.putText(img, s, org, cv2.FONT_HERSHEY_SIMPLEX, scale, color, thick, cv2.LINE_AA)


def draw_pitch_overlay(image_bgr: np.ndarray | None, result: PitchResult) -> np.ndarray:
    """Each blade's contour, eq. 7 rectangle, axis (arrow hub -> tip), θ, class and φ on a copy
    of the image (BGR, same size as the masks), or on ``mask_canvas`` when ``image_bgr`` is None."""
    h, w = result.image_size
    if image_bgr is None:
        img = mask_canvas(result)
    else:
        img = np.ascontiguousarray(image_bgr[:, :, :3] if image_bgr.ndim == 3
                                   else cv2.cvtColor(image_bgr, cv2.COLOR_GRAY2BGR)).copy()
        if img.shape[:2] != (h, w):
            raise ValueError(f"expected an image of {w}x{h}, got {img.shape[1]}x{img.shape[0]}")
    s = max(h, w) / 1000.0
    thick = max(1, round(2 * s))
    scale = max(0.45, 0.6 * s)
    blades_contours = {}
    if result.contours is not None:
        blades_contours = {i.source_index: i for i in result.contours.of("blade")}
    for k, b in enumerate(result.blades):
        color = CLASS_COLORS_BGR[b.theta_class]
        inst = blades_contours.get(b.source_index)
        if inst is not None:
            cv2.drawContours(img, [c.reshape(-1, 1, 2) for c in inst.contours], -1, color,
                             max(1, thick // 2), cv2.LINE_AA)
        if b.rect.corners is not None:
            cv2.polylines(img, [np.round(b.rect.corners).astype(np.int32).reshape(-1, 1, 2)],
                          True, (200, 200, 200), 1, cv2.LINE_AA)
        root = tuple(int(round(v)) for v in b.root_px)
        tip = tuple(int(round(v)) for v in b.tip_px)
        length = max(1.0, math.dist(root, tip))
        cv2.arrowedLine(img, root, tip, color, thick + 1, cv2.LINE_AA,
                        tipLength=min(0.2, 30 * s / length))
        # "#k" just beyond the tip; the numbers go in the table at the top left.
        tag = f"#{k + 1}"
        (tw, th), _ = cv2.getTextSize(tag, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)
        along = (np.asarray(b.tip_px) - np.asarray(b.root_px)) / length
        anchor = np.asarray(b.tip_px) + along * (8 + tw) * max(s, 0.7)
        x = int(np.clip(anchor[0] - tw / 2, 2, max(2, w - tw - 2)))
        y = int(np.clip(anchor[1] + th / 2, th + 2, h - 4))
        _text(img, tag, (x, y), scale, color, thick)
    hub = tuple(int(round(v)) for v in result.hub_px)
    cv2.circle(img, hub, max(3, round(6 * s)), (40, 40, 255), -1, cv2.LINE_AA)
    cv2.circle(img, hub, max(3, round(6 * s)), (255, 255, 255), 1, cv2.LINE_AA)
    step = int(24 * max(s, 0.7))
    for k, b in enumerate(result.blades):
        _text(img, f"#{k + 1}  theta {b.theta_deg:5.1f}  {b.theta_class:<10}  phi {b.phi_deg:5.1f}"
                   f"  (eq. 7: {b.theta_eq7_deg:5.1f})"
                   + (f"  admitted, score {b.score:.2f}" if b.admitted_low_score else ""),
              (8, step * (k + 1)), scale,
              CLASS_COLORS_BGR[b.theta_class], thick)
    # Legend: the classes and the angle convention.
    step = int(24 * max(s, 0.7))
    y = h - 4 * step + step // 2
    for name in CLASSES:
        _text(img, f"{name} {CLASS_INTERVALS[name]}", (8, y), scale, CLASS_COLORS_BGR[name], thick)
        y += step
    _text(img, "angles CCW from right, y up", (8, y), scale, (255, 255, 255), thick)
    return img


def overlay_background(inp: PitchInput, explicit: Path | None) -> tuple[np.ndarray | None, str]:
    """The photo to draw on: ``explicit`` (must load and match the masks' size) or the first
    candidate that exists and matches; else None (black canvas). Returns (image, note)."""
    h, w = inp.contours.image_size if inp.contours is not None else (0, 0)
    if explicit is not None:
        img = cv2.imread(str(explicit), cv2.IMREAD_COLOR)
        if img is None:
            raise InputError(f"{explicit}: cannot read the image for the overlay")
        if img.shape[:2] != (h, w):
            raise InputError(f"{explicit}: {img.shape[1]}x{img.shape[0]} does not match the "
                             f"masks ({w}x{h})")
        return img, ""
    for p in inp.background_candidates:
        if p.is_file():
            img = cv2.imread(str(p), cv2.IMREAD_COLOR)
            if img is not None and img.shape[:2] == (h, w):
                return img, ""
            return None, f"{p}: unreadable or not {w}x{h}; overlay drawn on the masks"
    return None, ""
