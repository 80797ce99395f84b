"""Where a rotor's hub is in the image: the nacelle/hub instance's pixels near the blades'
convergence point if there is a nacelle, else the convergence point (least-squares intersection
of the blade axes; not one outside the frame beyond a blade's tip: ``tip_at``), else the blades'
common end. One blade alone: beyond the end the frame cuts when its other end lies inside the
frame (``cut_ends``: a tip, the hub out of frame), else its wider end when the whole blade is in
frame and clearly tapers; else the hub cannot be placed.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from wtcli.contours import ContourSet, InstanceContours
from wtcli.pitch.angles import Axis


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


def ends_meet(axes: list[Axis], point: np.ndarray, share: float = 0.25) -> bool:
    """Does an end of every blade lie within ``share`` of its length of ``point`` (their
    common end): blades of one hub, not blades of turbines apart?"""
    p = np.asarray(point, float)
    return all(min(np.linalg.norm(ax.point(ax.t_min) - p), np.linalg.norm(ax.point(ax.t_max) - p))
               <= share * max(ax.t_max - ax.t_min, 1.0) for ax in axes)


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


def region_centroid(inst: InstanceContours) -> np.ndarray:
    m = cv2.moments(inst.fill().astype(np.uint8), binaryImage=True)
    x0, y0, _, _ = inst.bbox
    if m["m00"] <= 0:
        return np.asarray(inst.points.mean(axis=0), float)
    return np.array([m["m10"] / m["m00"] + x0, m["m01"] / m["m00"] + y0])


def cut_ends(inst: InstanceContours, ax: Axis, image_size: tuple[int, int], margin: float = 2.0,
             reach: float = 0.2) -> tuple[bool, bool]:
    """Which ends of the blade's axis (``t_min``, ``t_max``) the frame cuts: the region has
    pixels within ``margin`` px of the image border in that end's last ``reach`` of its length.
    A cut end is where the frame stopped the mask, not where the blade ends: its width says
    nothing about root or tip."""
    h, w = image_size
    region = inst.fill()
    x0, y0, _, _ = inst.bbox
    ys, xs = np.nonzero(region)
    xs, ys = xs + x0, ys + y0
    edge = (xs <= margin) | (ys <= margin) | (xs >= w - 1 - margin) | (ys >= h - 1 - margin)
    if not edge.any():
        return False, False
    u = ax.direction
    t = (xs[edge] - ax.centroid[0]) * u[0] + (ys[edge] - ax.centroid[1]) * u[1]
    q = reach * (ax.t_max - ax.t_min)
    return bool(t.min() <= ax.t_min + q), bool(t.max() >= ax.t_max - q)


def tip_at(inst: InstanceContours, ax: Axis, point: np.ndarray,
           image_size: tuple[int, int]) -> bool:
    """Does the blade show its tip at its end nearer ``point``, a hub placed outside the frame:
    that end inside the frame and the other cut by it? A hub out of frame would have the frame
    cut the blade on its way there; so the hub lies beyond the cut end, not at ``point`` (a tip
    close-up whose axis meets a far blade's beyond the tip). Where the point is in the frame
    nothing is said: a root end can look narrower than a cut mid-span (the hub hides it)."""
    h, w = image_size
    if 0 <= point[0] <= w - 1 and 0 <= point[1] <= h - 1:
        return False
    low, high = cut_ends(inst, ax, image_size)
    if low == high:
        return False
    ends = (ax.point(ax.t_min), ax.point(ax.t_max))
    near = 0 if np.linalg.norm(ends[0] - point) <= np.linalg.norm(ends[1] - point) else 1
    return not (low, high)[near]


def touches(parts: ContourSet, point: np.ndarray, radius: float) -> bool:
    """Does any of ``parts`` (towers, nacelles) have pixels within ``radius`` of ``point``?"""
    p = np.asarray(point, float)
    for other in parts:
        x0, y0, x1, y1 = other.bbox
        if not (x0 - radius <= p[0] <= x1 + radius and y0 - radius <= p[1] <= y1 + radius):
            continue
        ys, xs = np.nonzero(other.fill())
        if len(xs) and float(np.min(np.hypot(xs + x0 - p[0], ys + y0 - p[1]))) <= radius:
            return True
    return False
