"""Blade angles for the planner: from photos (segment -> contours -> pitch), pitch JSON files, or
the turbines.yaml, turned into rotor azimuths by back-projection (zone.azimuths_from_pitch).

Which turbine a photo or pitch result belongs to: an ``ID=path`` prefix, else the turbine whose
``photo`` key names the same file, else the only turbine of the mission.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wtcli.errors import InputError, PerceptionError
from wtcli.plan.config import CameraPose, Mission
from wtcli.plan.zone import azimuths_from_pitch

PITCH_SUFFIXES = (".json",)


def _parse(arg: str, ids: set[str]) -> tuple[str | None, Path]:
    if "=" in arg:
        tid, _, path = arg.partition("=")
        if tid in ids:
            return tid, Path(path)
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
    raise InputError(f"{path}: which turbine is this? prefix it with the turbine id "
                     f"({ids[0]}={path}) or name it in that turbine's 'photo' key")


def _pitch_results(path: Path, expected: int):
    """[(result, image name)] of a pitch JSON or of a photo run through segment/contours/pitch."""
    if not path.exists():
        raise InputError(f"{path}: file not found")
    if path.suffix.lower() in PITCH_SUFFIXES:
        from wtcli.pitch import read_pitch

        out = []
        for res, err, img in read_pitch(path):
            if res is None:
                raise PerceptionError(f"{path}: {img.get('file_name', 'image')}: {err}")
            out.append((res, img.get("file_name")))
        if not out:
            raise InputError(f"{path}: no image in this pitch file")
        return out
    from wtcli.pitch import pitch_from_instances
    from wtcli.segment.batch import read_image
    from wtcli.segment.infer import segment_image

    image = read_image(path)
    inst = segment_image(image)
    h, w = image.shape[:2]
    res = pitch_from_instances(inst, expected_blades=expected,
                               image={"file_name": path.name, "width": w, "height": h},
                               source=str(path))
    return [(res, path.name)]


# Rotor blades are evenly spaced; a measured gap further than this from 360/N means a merged,
# split or missed blade (a wrong 3D blade would put the flight where no blade is, and a real
# blade where the plan thinks there is free air).
MAX_SPACING_ERROR_DEG = 25.0


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


def blade_azimuths(mission: Mission, inputs: list[str], pose: CameraPose | None = None
                   ) -> tuple[dict[str, list[float]], dict[str, str]]:
    """Rotor azimuths per turbine from the given inputs and the turbines' ``photo`` keys.

    Returns (azimuths, where each came from). Turbines without any photo keep their YAML angles
    (not in the result)."""
    ids = {t.id for t in mission.turbines}
    todo: list[tuple[str | None, Path]] = [_parse(a, ids) for a in inputs]
    named = {tid for tid, _ in todo if tid}
    if not inputs:
        for t in mission.turbines:
            photo = mission.extra(t.id).photo
            if photo is not None and t.id not in named:
                todo.append((t.id, photo))
    azimuths: dict[str, list[float]] = {}
    sources: dict[str, str] = {}
    for tid, path in todo:
        expected = mission.turbine(tid).n_blades if tid else mission.turbines[0].n_blades
        for res, image_name in _pitch_results(path, expected):
            owner = _owner(mission, tid, path, image_name)
            if owner in azimuths:
                # Two photos of one rotor could disagree; silently keeping the last one hides that.
                raise InputError(f"{path}: turbine {owner} gets blade angles from more than one image "
                                 f"({sources[owner].split(' (')[0]} and {image_name}); give one photo "
                                 "or one pitch result per turbine")
            t = mission.turbine(owner)
            if len(res.blades) != t.n_blades:
                raise PerceptionError(f"{path}: found {len(res.blades)} blade(s), turbine {owner} "
                                      f"has {t.n_blades}")
            p = pose or mission.extra(owner).camera_pose
            try:
                azimuths[owner] = azimuths_from_pitch(t, res, mission.camera, p)
            except ValueError as e:
                raise InputError(f"{path}: {e}") from None
            check_rotor_spacing(azimuths[owner], f"{path}: turbine {owner}")
            sources[owner] = f"{path} (back-projected from "
            sources[owner] += "the given camera pose)" if p else "S_p looking at the rotor centre)"
    return azimuths, sources
