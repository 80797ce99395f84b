"""Typed pitch results: ``BladePitch`` per blade, ``PitchResult`` per image; the pitch JSON's
schema, and ``read_pitch`` to read one (``inputs.PitchBatch.to_document`` writes it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wtcli.contours import DEFAULT_AREA_THRESHOLD, ContourSet
from wtcli.errors import InputError
from wtcli.jsonio import read_json
from wtcli.pitch.angles import BladeRect, classify_theta

PITCH_SCHEMA = "wtinspect.pitch"
# 2: admitted_low_score per blade, score_threshold and candidate_floor; 3: direction_known per
# blade and image, hub_in_frame, hub_source frame_edge / none (hub_px null when none is placed)
PITCH_VERSION = 3
HUB_SOURCES = ("nacelle", "blade_axes", "common_end", "blade_taper", "frame_edge", "none")
UNPLACED = ("frame_edge", "none")  # hub sources that place no hub point (hub_px None)
THETA_SOURCE = "principal_axis"


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
    direction_known: bool = True  # False: the hub could not be placed; φ is then θ, sense unknown

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
        if not self.direction_known and abs(self.phi_deg - self.theta_deg) > 1e-4:
            raise ValueError(f"expected φ = θ ({self.theta_deg}) when the direction is unknown, "
                             f"got {self.phi_deg}")

    def to_dict(self) -> dict[str, Any]:
        r = self.rect
        return {"source_index": self.source_index, "score": self.score, "area": self.area,
                "theta_deg": self.theta_deg, "theta_class": self.theta_class,
                "theta_eq7_deg": self.theta_eq7_deg, "phi_deg": self.phi_deg,
                "rect": {"center": list(r.center), "size": [r.length, r.width],
                         "angle_deg": r.angle_deg, "top": list(r.top), "bottom": list(r.bottom)},
                "root_px": list(self.root_px), "tip_px": list(self.tip_px),
                "centroid_px": list(self.centroid_px), "elongation": self.elongation,
                "theta_method": self.theta_method, "admitted_low_score": self.admitted_low_score,
                "direction_known": self.direction_known}

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
                   bool(d.get("admitted_low_score", False)),  # absent in version 1
                   bool(d.get("direction_known", True)))  # absent before version 3


@dataclass(frozen=True)
class PitchResult:
    blades: tuple[BladePitch, ...]
    hub_px: tuple[float, float] | None  # None: not placed (hub_source frame_edge or none)
    hub_source: str  # one of HUB_SOURCES
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
        if self.hub_source not in HUB_SOURCES:
            raise ValueError(f"unknown hub_source {self.hub_source!r}")
        if (self.hub_px is None) != (self.hub_source in UNPLACED):
            raise ValueError(f"expected hub_px {'null' if self.hub_source in UNPLACED else 'a point'}"
                             f" with hub_source {self.hub_source!r}")
        if self.hub_source == "none" and self.direction_known:
            raise ValueError("expected the blades' direction unknown with hub_source 'none'")
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
    def hub_in_frame(self) -> bool:
        """The hub was placed, inside the image."""
        if self.hub_px is None:
            return False
        h, w = self.image_size
        return 0.0 <= self.hub_px[0] <= w - 1 and 0.0 <= self.hub_px[1] <= h - 1

    @property
    def direction_known(self) -> bool:
        """Every blade's direction hub -> tip is known (not only its axis)."""
        return all(b.direction_known for b in self.blades)

    @property
    def admitted(self) -> tuple[BladePitch, ...]:
        """The blades admitted below the score threshold to complete the rotor."""
        return tuple(b for b in self.blades if b.admitted_low_score)

    def to_dict(self) -> dict[str, Any]:
        return {"image": self.image, "image_size": list(self.image_size),
                "area_threshold": self.area_threshold, "n_blades": len(self.blades),
                "hub_px": None if self.hub_px is None else list(self.hub_px),
                "hub_source": self.hub_source, "hub_in_frame": self.hub_in_frame,
                "direction_known": self.direction_known,
                "axes_convergence_px": (None if self.axes_convergence_px is None
                                        else list(self.axes_convergence_px)),
                "other_rotor_blades": list(self.other_rotor_blades),
                "score_threshold": self.score_threshold, "candidate_floor": self.candidate_floor,
                "blades": [b.to_dict() for b in self.blades]}

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = "") -> PitchResult:
        conv = d.get("axes_convergence_px")
        hub = d["hub_px"]
        return cls(tuple(BladePitch.from_dict(b) for b in d["blades"]),
                   None if hub is None else tuple(hub),
                   d["hub_source"], tuple(d["image_size"]), d.get("image") or {}, source,
                   float(d.get("area_threshold", DEFAULT_AREA_THRESHOLD)),
                   None if conv is None else tuple(conv),
                   tuple(int(i) for i in d.get("other_rotor_blades", ())), None,
                   _opt_float(d.get("score_threshold")), _opt_float(d.get("candidate_floor")))


def _opt_float(v: Any) -> float | None:
    return None if v is None else float(v)


def read_pitch(path: str | Path) -> list[tuple[PitchResult | None, str | None, dict]]:
    """Read a ``wtinspect.pitch`` file, version 1 to 3 (version 1 has no admitted blades,
    before 3 every blade's direction counts as known):
    (result or None, error or None, image record) per image."""
    path = Path(path)
    doc = read_json(path, PITCH_SCHEMA, PITCH_VERSION)
    out = []
    if not isinstance(doc.get("images"), list):
        raise InputError(f"{path}: expected an 'images' list")
    for i, d in enumerate(doc["images"]):
        if not isinstance(d, dict):
            raise InputError(f"{path}: images[{i}] is not an object")
        img = d.get("image") or {}
        if d.get("error"):
            out.append((None, str(d["error"]), img))
            continue
        try:
            out.append((PitchResult.from_dict(d, source=str(path)), None, img))
        except (KeyError, TypeError, ValueError) as e:
            raise InputError(f"{path}: images[{i}]: bad pitch entry ({e})") from None
    return out
