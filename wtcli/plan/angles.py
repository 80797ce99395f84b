"""Blade angles for the planner: from photos (segment -> contours -> pitch), pitch JSON files, or
the turbines.yaml, turned into rotor azimuths by back-projection (zone.azimuths_from_pitch).

Which turbine a photo or pitch result belongs to: an ``ID=path`` prefix, else the turbine whose
``photo`` key names the same file, else the only turbine of the mission.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from wtcli.console import StageProgress, stage_ticker
from wtcli.errors import InputError, PerceptionError, UsageError
from wtcli.pitch.rotor import ROTOR_GAP_TOLERANCE_DEG
from wtcli.plan.config import CameraPose, Mission
from wtcli.plan.zone import azimuths_from_pitch

PITCH_SUFFIXES = (".json",)


def _parse(arg: str, ids: set[str]) -> tuple[str | None, Path]:
    if "=" in arg:
        tid, _, path = arg.partition("=")
        if tid in ids:
            return tid, Path(path)
        if not Path(arg).exists() and "/" not in tid:  # ID=FILE with an ID the YAML lacks
            raise UsageError(f"{arg}: no turbine {tid!r} in the turbines YAML (its ids: {', '.join(sorted(ids))})")
    return None, Path(arg)


def _owner(mission: Mission, tid: str | None, path: Path, image_name: str | None) -> str:
    ids = [t.id for t in mission.turbines]
    if tid is not None:
        return tid
    names = {Path(str(image_name)).name} if image_name else set()
    names.add(path.name)
    for t in mission.turbines:
        photo = mission.extra(t.id).photo
        if photo is not None and photo.name in names:
            return t.id
    if len(ids) == 1:
        return ids[0]
    raise UsageError(f"{path}: which turbine is this? prefix it with the turbine id "
                     f"({ids[0]}={path}) or name it in that turbine's 'photo' key")


def _pitch_results(path: Path, expected: int, fast: bool = False):
    """[(result, image name)] of a pitch JSON or of a photo run through segment/contours/pitch
    (``fast``: one pass of the network, ``chain.photo_input``)."""
    if not path.exists():
        from wtcli.jsonio import missing

        raise InputError(f"{path}: {missing(path)}")
    if path.suffix.lower() in PITCH_SUFFIXES:
        from wtcli.pitch.result import read_pitch

        out = []
        for res, err, img in read_pitch(path):
            if res is None:
                raise PerceptionError(f"{path}: {img.get('file_name', 'image')}: {err}")
            out.append((res, img.get("file_name")))
        if not out:
            raise InputError(f"{path}: no image in this pitch file")
        return out
    from wtcli.chain import photo_to_pitch

    # One blade short is kept (blade_azimuths completes the rotor); any other count gets pitch's
    # own treatment: trimmed to the rotor's blades where that is clear, else refused.
    found = photo_to_pitch(path, expected, one_short_ok=True, fast=fast)
    if found.error is not None:
        raise PerceptionError(found.error)
    res = found.result
    return [(res, path.name)]


# Rotor blades are evenly spaced; a measured gap further than this from 360/N means a merged,
# split or missed blade (a wrong 3D blade would put the flight where no blade is, and a real
# blade where the plan thinks there is free air). The same tolerance as pitch's rotor checks.
MAX_SPACING_ERROR_DEG = ROTOR_GAP_TOLERANCE_DEG


def check_rotor_spacing(azimuths: list[float], where: str) -> None:
    n = len(azimuths)
    if n < 2:
        return
    a = np.sort(np.asarray(azimuths, float) % 360.0)
    gaps = np.diff(np.concatenate([a, [a[0] + 360.0]]))
    if np.abs(gaps - 360.0 / n).max() > MAX_SPACING_ERROR_DEG:
        raise PerceptionError(
            f"{where}: measured blade azimuths {', '.join(f'{x:.1f}' for x in a)} deg are not "
            f"spread like a {n}-blade rotor (gaps {', '.join(f'{g:.0f}' for g in gaps)}, expected "
            f"{360.0 / n:.0f} +- {MAX_SPACING_ERROR_DEG:.0f}): a blade was probably merged or "
            "missed; give a pitch JSON or blade_azimuths_deg in the YAML instead")


def complete_rotor(azimuths: list[float], n: int, where: str) -> tuple[list[float], float]:
    """The azimuths of an ``n``-blade rotor (n >= 3) of which a photo showed ``n - 1`` blades: the
    missing blade is where the even spacing leaves a slot free. The measured blades fix the
    rotor's phase (circular mean of n x azimuth); each must have a slot of its own and the gaps
    between them be within MAX_SPACING_ERROR_DEG of even, else PerceptionError (two blades
    merged or split, a far rotor's blade).
    Returns (the measured azimuths and the inferred one last, the inferred one)."""
    a = np.asarray(azimuths, float) % 360.0
    if n < 3 or len(a) != n - 1:
        raise ValueError(f"expected {n - 1} azimuths of a rotor of n >= 3 blades, got {len(a)} of {n}")
    step = 360.0 / n
    ang = np.radians(a * n)
    phase = math.degrees(math.atan2(np.sin(ang).sum(), np.cos(ang).sum())) / n
    slot = np.round((a - phase) / step).astype(int) % n
    off = (a - phase - slot * step + 180.0) % 360.0 - 180.0
    # The spread of the offsets is how far a gap between measured blades is from even, the
    # figure check_rotor_spacing limits.
    if len(set(slot.tolist())) != len(a) or off.max() - off.min() > MAX_SPACING_ERROR_DEG:
        raise PerceptionError(
            f"{where}: found {len(a)} of {n} blades, at {', '.join(f'{x:.1f}' for x in np.sort(a))} "
            f"deg, not spaced like blades of a {n}-blade rotor (gaps within "
            f"{MAX_SPACING_ERROR_DEG:.0f} deg of a multiple of {step:.0f}), so the missing one "
            "cannot be inferred; give a pitch JSON or blade_azimuths_deg in the YAML instead")
    free = sorted(set(range(n)) - set(slot.tolist()))[0]
    inferred = float((phase + free * step) % 360.0)
    return [float(x) for x in a] + [inferred], inferred


# Several photos of one (locked) rotor should agree to within the pitch error; more than this
# means the rotor turned between them or one photo was segmented wrongly.
MAX_PHOTO_DISAGREEMENT_DEG = 10.0


def combine_azimuths(sets: list[list[float]], names: list[str], where: str) -> list[float]:
    """One rotor's blade azimuths from several images: each image's blades matched to the first
    image's by nearest angle, then averaged on the circle. Images that disagree by more than
    MAX_PHOTO_DISAGREEMENT_DEG on any blade are refused (PerceptionError) naming both."""
    ref = np.asarray(sets[0], float)
    stacks = [ref]
    for az, name in zip(sets[1:], names[1:]):
        az = np.asarray(az, float)
        d = (az[None, :] - ref[:, None] + 180.0) % 360.0 - 180.0  # [ref blade, this blade]
        order = np.argmin(np.abs(d), axis=1)
        if len(set(order.tolist())) != len(ref):
            order = np.arange(len(ref))  # ambiguous match: the spread check below says so
        off = d[np.arange(len(ref)), order]
        worst = int(np.argmax(np.abs(off)))
        if abs(off[worst]) > MAX_PHOTO_DISAGREEMENT_DEG:
            raise PerceptionError(
                f"{where}: {names[0]} and {name} disagree by {abs(off[worst]):.1f} deg on a blade "
                f"(limit {MAX_PHOTO_DISAGREEMENT_DEG:.0f}): did the rotor turn between the photos? "
                "give only the photos of the rotor as it stands now")
        stacks.append(ref + off)
    mean = np.mean(stacks, axis=0)  # offsets are unwrapped around ref, so a plain mean is circular
    return [float(a % 360.0) for a in mean]


def blade_azimuths(mission: Mission, inputs: list[str], pose: CameraPose | None = None,
                   fast: bool = False, progress: StageProgress | None = None
                   ) -> tuple[dict[str, list[float]], dict[str, str]]:
    """Rotor azimuths per turbine from the given inputs and the turbines' ``photo`` keys.

    Several images of one turbine (several photos, or a pitch file with several images) are
    combined: each is back-projected on its own, checked, and the blade angles averaged
    (``combine_azimuths``). Returns (azimuths, where they came from). Turbines without any photo
    keep their YAML angles (not in the result). ``fast``: photos get one pass of the network
    (``chain.photo_input``). ``progress``: stage "photos", per input (a photo is segmented:
    seconds each)."""
    ids = {t.id for t in mission.turbines}
    todo: list[tuple[str | None, Path]] = [_parse(a, ids) for a in inputs]
    named = {tid for tid, _ in todo if tid}
    if not inputs:
        for t in mission.turbines:
            photo = mission.extra(t.id).photo
            if photo is not None and t.id not in named:
                todo.append((t.id, photo))
    per: dict[str, list[tuple[list[float], str]]] = {}
    how: dict[str, str] = {}
    notes: dict[str, list[str]] = {}
    tick = stage_ticker(progress, "photos", len(todo)) if todo else (lambda: None)
    for tid, path in todo:
        expected = mission.turbine(tid).n_blades if tid else mission.turbines[0].n_blades
        for res, image_name in _pitch_results(path, expected, fast):
            owner = _owner(mission, tid, path, image_name)
            t = mission.turbine(owner)
            name = f"{path}" if not image_name or Path(str(image_name)).name == path.name \
                else f"{path}:{image_name}"
            if not res.direction_known:  # an axis without its sense would put a blade 180° off
                raise PerceptionError(f"{name}: unusable for blade angles: the hub is out of "
                                      "frame and cannot be placed, so a blade's direction "
                                      "(hub -> tip) is unknown; give a photo showing the hub")
            short = t.n_blades >= 3 and len(res.blades) == t.n_blades - 1
            if len(res.blades) != t.n_blades and not short:
                raise PerceptionError(f"{name}: found {len(res.blades)} blade(s), turbine {owner} "
                                      f"has {t.n_blades}")
            p = pose or mission.extra(owner).camera_pose
            own = None  # the photo's own tags, where no pose was given (docs/photo-pose.md)
            if p is None:
                from wtcli.photo_pose import camera_pose_of_photo, photo_beside

                src = path if path.suffix.lower() not in PITCH_SUFFIXES else \
                    photo_beside(path, image_name)
                if src is not None:
                    p, own = camera_pose_of_photo(src, t, mission, name)
            try:
                az = azimuths_from_pitch(t, res, mission.camera, p)
            except ValueError as e:
                raise InputError(f"{name}: {e}") from None
            for b in res.admitted:
                notes.setdefault(owner, []).append(
                    f"{name}: the blade at image angle {b.phi_deg:.1f} deg was detected at score "
                    f"{b.score:.2f}, below {res.score_threshold:g}, and admitted to complete the rotor")
            if short:
                az, inferred = complete_rotor(az, t.n_blades, f"{name}: turbine {owner}")
                az = sorted(az, key=lambda a: (a - 90.0) % 360.0)  # as azimuths_from_pitch
                notes.setdefault(owner, []).append(
                    f"{name}: {len(res.blades)} of {t.n_blades} blades found; the blade at "
                    f"{inferred:.1f} deg is inferred from the rotor's even spacing")
            check_rotor_spacing(az, f"{name}: turbine {owner}")
            per.setdefault(owner, []).append((az, name))
            how[owner] = ("the given camera pose" if p and not own else own if p else
                          "S_p looking at the rotor centre" + (f" ({own})" if own else ""))
        tick()
    azimuths: dict[str, list[float]] = {}
    sources: dict[str, str] = {}
    for owner, found in per.items():
        names = [n for _, n in found]
        azimuths[owner] = combine_azimuths([a for a, _ in found], names, f"turbine {owner}")
        what = names[0] if len(names) == 1 else f"{len(names)} images ({', '.join(names)}), averaged"
        sources[owner] = f"{what} (back-projected from {how[owner]})" + "".join(
            f"; {n}" for n in notes.get(owner, []))
    return azimuths, sources
