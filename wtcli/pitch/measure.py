"""One image's contours -> each blade's θ, class and φ: the rotor's blades chosen (``rotor``),
its hub found (``hub``), every blade measured (``angles``), the count checked.
"""

from __future__ import annotations

import numpy as np

from wtcli.contours import (DEFAULT_AREA_THRESHOLD, ContourSet, InstanceContours, find_contours,
                            require_contours)
from wtcli.errors import PerceptionError
from wtcli.masks import Instances
from wtcli.pitch.angles import (Axis, angle_diff, classify_theta, image_angle, normalize_phi,
                                normalize_theta, principal_axis, rect_eq7)
from wtcli.pitch.hub import (axes_convergence, common_end, cut_ends, ends_meet, nacelle_hub,
                             region_centroid, tip_at, touches, wider_end)
from wtcli.pitch.result import UNPLACED, BladePitch, PitchResult
from wtcli.pitch.rotor import (admit_low_score_blades, longest_if_clearly, select_rotor,
                               touches_border, without_doubles, without_wide_tips)
from wtcli.segment.defaults import CANDIDATE_FLOOR, DEFAULT_SCORE_THRESHOLD

STUB_ELONGATION = 3.0  # below this a blade region has no reliable axis of its own
DEFAULT_ROTOR_BLADES = 3


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
    keep, candidate = select_rotor(all_blades, all_axes, [region_centroid(n) for n in nacelles])
    n_rotor = rotor_blades or expected_blades or DEFAULT_ROTOR_BLADES
    trim_to = expected_blades or n_rotor  # also when any count is accepted: a rotor has n_rotor
    if len(keep) > trim_to:
        keep = longest_if_clearly(keep, all_axes, trim_to)
    if len(keep) > trim_to and candidate is not None:
        fewer = without_wide_tips(keep, all_blades, all_axes, candidate)
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
    tipped = [] if conv is None or hub is not None else \
        [k for k, (b, ax) in enumerate(zip(blades.instances, axes))
         if tip_at(b, ax, conv, contours.image_size)]
    alone = None  # the one blade measured alone, the others left out as other rotors'
    if tipped:
        # The axes meet beyond a blade's own tip, out of frame: no rotor's hub there. That
        # blade (the largest such) is measured alone, its hub beyond the frame's cut.
        alone, conv = tipped, None
    if hub is not None and len(axes) == 1:
        # One blade cannot check a nacelle against other blades; its taper can, unless the
        # frame cut its wider end (a cut end is as wide as the blade where the frame cut it).
        hub = _nacelle_if_taper_agrees(blades.instances[0], axes[0], hub, contours.image_size)
    if (alone is None and hub is None and conv is None and len(axes) >= 2
            and not ends_meet(axes, common_end(axes))
            and not all(touches_border(b, contours.image_size) for b in blades)):
        # Blades that neither cross nor share an end (nor are all cut by the frame, their hub
        # beyond it) are no rotor: the largest one (the nearest turbine's, a close-up's) is
        # measured alone, the others are other turbines' blades.
        alone = range(len(keep))
    if alone is not None:
        big = max(alone, key=lambda k: blades.instances[k].area)
        others += tuple(blades.instances[k].source_index for k in range(len(keep)) if k != big)
        keep, axes, lengths = [keep[big]], [axes[big]], [lengths[big]]
        blades = all_blades[keep]
    if hub is not None:
        source = "nacelle"
    elif conv is not None:
        hub, source = conv, "blade_axes"
    elif len(axes) >= 2:
        hub, source = common_end(axes), "common_end"
    else:
        hub, source = _lone_blade_hub(blades.instances[0], axes[0], contours)

    if hub is None:  # the hub cannot be placed: the blade's axis, its sense unknown
        out = [_blade_pitch(inst, ax, np.asarray(ax.point(ax.t_min)), known=False)
               for inst, ax in zip(blades, axes)]
    else:
        out = [_blade_pitch(inst, ax, hub) for inst, ax in zip(blades, axes)]
    rotor = without_doubles(out, n_rotor)
    if len(rotor) < len(out):  # the doubles are left out like other rotors' blades
        kept = {b.source_index for b in rotor}
        others += tuple(b.source_index for b in out if b.source_index not in kept)
        out = rotor
    if candidates and len(out) < n_rotor and source in ("nacelle", "blade_axes", "common_end"):
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
    hub_px = None if source in UNPLACED else (float(hub[0]), float(hub[1]))
    return PitchResult(tuple(out), hub_px, source, contours.image_size,
                       contours.image, contours.source, contours.area_threshold,
                       None if conv is None else (float(conv[0]), float(conv[1])), others,
                       full, score_threshold, candidate_floor if score_threshold is not None else None)


def _nacelle_if_taper_agrees(inst: InstanceContours, ax: Axis, hub: np.ndarray,
                             image_size: tuple[int, int]) -> np.ndarray | None:
    """``hub`` (a nacelle near one end of a lone blade), unless the blade clearly tapers
    towards that end (a far turbine's nacelle beyond its tip), its wider end not cut by the
    frame."""
    root = wider_end(inst, ax, decisive=True)
    if root is None:
        return hub
    ends = (ax.point(ax.t_min), ax.point(ax.t_max))
    near_end = min(ends, key=lambda e: float(np.linalg.norm(e - hub)))
    if np.allclose(root, near_end):
        return hub
    cut = cut_ends(inst, ax, image_size)
    return hub if cut[0 if np.allclose(root, ends[0]) else 1] else None


def _lone_blade_hub(inst: InstanceContours, ax: Axis,
                    contours: ContourSet) -> tuple[np.ndarray | None, str]:
    """Where the hub of a blade seen alone (no nacelle at its end) lies, and how that is known.

    * ``nacelle``: one end (only) touches a nacelle region, and the blade does not clearly
      taper the other way: that end.
    * ``frame_edge``: the frame cuts one end and the other lies inside the frame clear of any
      tower or nacelle: that end is the tip (a root in frame would show its hub), and the hub
      is out of frame beyond the cut end (the point returned: the cut end, a direction only).
    * ``blade_taper``: the whole blade is in frame and clearly wider at one end (its root).
    * ``none`` (None returned): both ends cut (a mid-span close-up), an inner end touching a
      tower (a root at a hub labelled tower, or a tip in front of the tower: no telling), or a
      blade that does not clearly taper."""
    low, high = cut_ends(inst, ax, contours.image_size)
    ends = (ax.point(ax.t_min), ax.point(ax.t_max))
    width = inst.area / max(ax.t_max - ax.t_min, 1.0)
    reach = 0.5 * width + 3.0
    nacelles = contours.of("nacelle")
    at_nacelle = [touches(nacelles, e, reach) for e in ends]
    if at_nacelle[0] != at_nacelle[1]:
        # Its root on a nacelle too wide or off-axis to be taken for the hub from the blade's
        # axis (a close view): the hub is at that end, unless the taper says otherwise.
        hub = _nacelle_if_taper_agrees(inst, ax, ends[0 if at_nacelle[0] else 1],
                                       contours.image_size)
        if hub is not None:
            return np.asarray(hub, float), "nacelle"
    if low != high:
        inner = ends[1] if low else ends[0]
        if not any(touches(contours.of(part), inner, reach) for part in ("tower", "nacelle")):
            return np.asarray(ends[0] if low else ends[1], float), "frame_edge"
        return None, "none"
    if not low:
        root = wider_end(inst, ax, decisive=True)
        if root is not None:
            return np.asarray(root, float), "blade_taper"
    return None, "none"


def _blade_pitch(inst: InstanceContours, ax: Axis, hub: np.ndarray,
                 admitted: bool = False, known: bool = True) -> BladePitch:
    """θ, class, φ, root and tip of one blade of the rotor whose hub is ``hub``. With ``known``
    False the blade's sense is unknown (the hub could not be placed): φ is θ, root and tip the
    axis ends in that order, and the blade says so (``direction_known``)."""
    rect = rect_eq7(inst.points)
    to_centroid = np.asarray(ax.centroid) - hub
    if not known:
        a, b = ax.point(ax.t_min), ax.point(ax.t_max)
        theta = ax.theta_deg
        root, tip = (a, b) if abs(angle_diff(image_angle(*(b - a)), theta)) < 90.0 else (b, a)
        return BladePitch(
            inst.source_index, inst.score, inst.area, theta, classify_theta(theta),
            rect.angle_deg, normalize_phi(theta), rect, (float(root[0]), float(root[1])),
            (float(tip[0]), float(tip[1])), ax.centroid, ax.elongation, "principal_axis",
            admitted, False)
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
        (float(tip[0]), float(tip[1])), ax.centroid, ax.elongation, method, admitted, True)


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
