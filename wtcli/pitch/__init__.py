"""Step 1.4 of the paper: each blade's angle θ (eq. 7), its class, and its direction φ hub -> tip,
from one image's contours (``wtcli.contours``). Photos are segmented first by ``wtcli.chain``;
this package never runs the segmenter.

Modules: ``angles`` (eq. 7, the principal axis, θ/φ conventions, ``classify_theta``), ``hub``
(where the hub is), ``rotor`` (which blades form the rotor, rotor completion), ``measure``
(``measure_pitch``, ``pitch_from_instances``), ``result`` (``BladePitch``, ``PitchResult``,
the pitch JSON), ``inputs`` (files given to ``pitch``, ``pitch_batch``), ``overlay`` (drawing).
"""

from wtcli.pitch.angles import (ACUTE, ANGLE_DIGITS, CLASS_INTERVALS, CLASSES, HORIZONTAL, VERTICAL,
                                Axis, BladeRect, angle_diff, classify_theta, image_angle,
                                normalize_angle, normalize_phi, normalize_theta, principal_axis,
                                rect_eq7)
from wtcli.pitch.hub import axes_convergence, common_end, nacelle_hub, wider_end
from wtcli.pitch.inputs import (PHOTO_SUFFIXES, PitchBatch, PitchInput, area_threshold_px,
                                is_photo, load_pitch_input, pitch_batch)
from wtcli.pitch.measure import (DEFAULT_ROTOR_BLADES, STUB_ELONGATION, check_blade_count,
                                 measure_pitch, pitch_from_instances)
from wtcli.pitch.overlay import (CLASS_COLORS_BGR, draw_pitch_overlay, mask_canvas,
                                 overlay_background, overlay_names)
from wtcli.pitch.result import (PITCH_SCHEMA, PITCH_VERSION, THETA_SOURCE, BladePitch,
                                PitchResult, read_pitch)
from wtcli.pitch.rotor import (CANDIDATE_INSIDE, CLOSE_UP_LENGTH, ROTOR_GAP_TOLERANCE_DEG,
                               admit_low_score_blades, select_rotor)
from wtcli.segment.defaults import CANDIDATE_FLOOR, DEFAULT_SCORE_THRESHOLD

__all__ = [
    "ACUTE", "ANGLE_DIGITS", "CANDIDATE_FLOOR", "CANDIDATE_INSIDE", "CLASSES", "CLASS_COLORS_BGR",
    "CLASS_INTERVALS", "CLOSE_UP_LENGTH", "DEFAULT_ROTOR_BLADES", "DEFAULT_SCORE_THRESHOLD",
    "HORIZONTAL", "PHOTO_SUFFIXES", "PITCH_SCHEMA", "PITCH_VERSION", "ROTOR_GAP_TOLERANCE_DEG",
    "STUB_ELONGATION", "THETA_SOURCE", "VERTICAL", "Axis", "BladePitch", "BladeRect", "PitchBatch",
    "PitchInput", "PitchResult", "admit_low_score_blades", "angle_diff", "area_threshold_px",
    "axes_convergence", "check_blade_count", "classify_theta", "common_end", "draw_pitch_overlay",
    "image_angle", "is_photo", "load_pitch_input", "mask_canvas", "measure_pitch", "nacelle_hub",
    "normalize_angle", "normalize_phi", "normalize_theta", "overlay_background", "overlay_names",
    "pitch_batch", "pitch_from_instances", "principal_axis", "read_pitch", "rect_eq7",
    "select_rotor", "wider_end",
]
