"""Which blades form the rotor: the main rotor when a photo shows several turbines
(``select_rotor``), blades that double another or are the tower read as a blade, and rotor
completion.

Rotor completion: with a ``score_threshold``, blades scoring below it are not counted; when the
confident blades of the main rotor are fewer than the rotor's blade count, a low-score blade
detection (score >= ``candidate_floor``) that fits the rotor — its axis through the hub, its root
at the hub, its direction in the free slot of the evenly spaced rotor, not inside another
blade — is admitted and flagged ``admitted_low_score`` (``admit_low_score_blades``).
"""

from __future__ import annotations

import itertools
import math

import cv2
import numpy as np

from wtcli.contours import ContourSet, InstanceContours
from wtcli.pitch.angles import Axis, angle_diff, image_angle, principal_axis
from wtcli.pitch.hub import wider_end
from wtcli.pitch.result import BladePitch

# An n-blade rotor's gaps in φ are within this of 360/n: wider, and a blade was merged, split or
# missed, or belongs to another rotor. The planner's rotor check (wtcli.plan.angles) uses it too.
ROTOR_GAP_TOLERANCE_DEG = 25.0
CANDIDATE_INSIDE = 0.3  # a candidate this much inside a counted blade is that blade again
CLOSE_UP_LENGTH = 3.0  # a blade this much longer than a rotor's is of a far nearer turbine


def supports_hub(ax: Axis, length: float, width: float, c: np.ndarray) -> bool:
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


def touches_border(inst: InstanceContours, image_size: tuple[int, int], margin: int = 2) -> bool:
    """Cut by the frame: a mask seldom reaches the very edge pixel of what the frame cut."""
    x0, y0, x1, y1 = inst.bbox
    return (x0 <= margin or y0 <= margin or x1 >= image_size[1] - margin
            or y1 >= image_size[0] - margin)


def wide_end_away(inst: InstanceContours, ax: Axis, hub: np.ndarray, decisive: bool = False) -> bool:
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
    blade; two in line and no nacelle) every blade is kept, unless one is ``CLOSE_UP_LENGTH``
    times longer than every other: a close-up's blade, the rest far turbines'. In a close-up with the hub out of
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
            if (supports_hub(axes[i], lengths[i], widths[i], x)
                    and supports_hub(axes[j], lengths[j], widths[j], x)):
                cands.append(x)
    best, best_key, best_c = list(range(n)), None, None
    for c in cands:
        sup = [k for k in range(n) if supports_hub(axes[k], lengths[k], widths[k], c)]
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
    if best_c is None and n > 1:
        # No hub candidate: a close-up's blade among far turbines' blades is far longer than
        # any of them (its common end with them would be no hub at all).
        order = sorted(range(n), key=lambda k: -lengths[k])
        if lengths[order[0]] >= CLOSE_UP_LENGTH * lengths[order[1]]:
            return [order[0]], None
    if best_c is not None and len(best) > 1:
        big = max(areas[k] for k in best)
        keep = []
        for k in best:
            inst = blades.instances[k]
            if areas[k] < 0.3 * big and not touches_border(inst, blades.image_size):
                if wide_end_away(inst, axes[k], best_c):
                    continue
            keep.append(k)
        best = keep
    return best, best_c


def without_doubles(out: list[BladePitch], n: int,
                   slot_tolerance: float = ROTOR_GAP_TOLERANCE_DEG) -> list[BladePitch]:
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
        if any(min(abs(angle_diff(out[d].phi_deg, out[k].phi_deg)) for k in sub) > slot_tolerance
               for d in range(len(out)) if d not in sub):
            continue
        key = (sum(out[k].score for k in sub), sum(out[k].area for k in sub))
        if best_key is None or key > best_key:
            best, best_key = [out[k] for k in sub], key
    return best


def without_wide_tips(keep: list[int], blades: ContourSet, axes: list[Axis],
                       hub: np.ndarray) -> list[int]:
    """Too many blades on one hub: one clearly wider at its end away from the hub is not a
    blade (blades taper to the tip) but the tower under a close-up's hub, read as a blade."""
    return [k for k in keep if not wide_end_away(blades.instances[k], axes[k], hub, decisive=True)]


def longest_if_clearly(keep: list[int], axes: list[Axis], n: int) -> list[int]:
    """Too many blades on one hub: a far turbine right behind it shows shorter blades. Keep the
    ``n`` longest when each is at least 1.25x as long as every other; else keep all (and the
    count check reports them)."""
    by_length = sorted(keep, key=lambda k: axes[k].t_max - axes[k].t_min, reverse=True)
    length = [axes[k].t_max - axes[k].t_min for k in by_length]
    if length[n - 1] >= 1.25 * length[n]:
        return sorted(by_length[:n])
    return keep


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
                           slot_tolerance: float = ROTOR_GAP_TOLERANCE_DEG,
                           inside: float = CANDIDATE_INSIDE,
                           min_reach: float = 0.25) -> list[tuple[InstanceContours, Axis]]:
    """Low-score blade detections that complete an ``n``-blade rotor of which ``measured``
    (the counted ``blades``, hub ``hub``) are fewer than ``n``; best score first, at most the
    number missing. The measured blades fix the rotor's phase (circular mean of n x φ) and
    must sit in distinct slots with gaps within ``slot_tolerance`` of even. A candidate is
    admitted when its axis passes through the hub near one of its ends (``supports_hub``, as for
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
    off = np.array([angle_diff(p, phase + k * step) for p, k in zip(phis, slot)])
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
        if not supports_hub(ax, length, cand.area / length, hub):
            continue
        ends = (ax.point(ax.t_min), ax.point(ax.t_max))
        far = max(ends, key=lambda e: float(np.linalg.norm(e - hub)))
        if np.linalg.norm(far - hub) < min_reach * scale and not (
                image_size is not None and touches_border(cand, image_size)):
            continue  # too short for a blade of this rotor, unless the frame cut it
        phi = image_angle(*(far - hub))
        k = min(free, key=lambda j: abs(angle_diff(phi, phase + j * step)), default=None)
        if k is None or abs(angle_diff(phi, phase + k * step)) > slot_tolerance:
            continue
        if any(_overlap(cand, t) >= inside * cand.area for t in taken):
            continue
        free.discard(k)
        taken.append(cand)
        out.append((cand, ax))
    return out
