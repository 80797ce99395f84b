"""Step 1.4 of the paper: a blade's angle θ (eq. 7 and the principal axis) and its class.

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
classified, so the class in a file always agrees with the θ next to it. ``classify_theta`` is
the one class function: the renderer's ground truth, the planner and ``pitch`` all use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from wtcli.contours import InstanceContours
from wtcli.errors import PerceptionError

HORIZONTAL, ACUTE, VERTICAL = "horizontal", "acute", "vertical"
CLASSES = (HORIZONTAL, ACUTE, VERTICAL)
CLASS_INTERVALS = {HORIZONTAL: "[0, 30] U [150, 180)", ACUTE: "(30, 60] U [120, 150)",
                   VERTICAL: "(60, 120)"}
ANGLE_DIGITS = 6


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



def angle_diff(a: float, b: float) -> float:
    """Signed a - b on the circle, in [-180, 180)."""
    return (a - b + 180.0) % 360.0 - 180.0


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
