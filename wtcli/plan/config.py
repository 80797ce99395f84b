"""``turbines.yaml`` -> a frozen, validated ``Mission`` (docs/turbines-yaml.md).

The packaged ``wtcli/data/turbines-defaults.yaml`` (commented) is merged under the user's file,
every key is checked (unknown keys get a "did you mean" hint, values name their allowed range),
then the result is frozen. A ``Mission`` can also be built in code, or from a dict with
``mission_from_dict``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from wtcli.errors import ConfigError
from wtcli.jsonio import shown
from wtcli.geometry import Camera, Turbine
from wtcli.plan.geodesy import geodetic_to_enu
from wtcli.yamlcheck import (merge, check_keys, load_yaml, need_mapping, number, string,
                             vector)

DEFAULTS_PATH = Path(__file__).resolve().parents[1] / "data" / "turbines-defaults.yaml"


def default_dict() -> dict:
    """The packaged defaults, freshly read (callers may change their copy)."""
    return yaml.safe_load(DEFAULTS_PATH.read_text(encoding="utf-8"))


# The packaged YAML is the one source of every default: the dataclasses below read theirs from
# it, so a Mission built in code plans exactly like a turbines.yaml that leaves the key out
# (tests/test_plan.py checks the docs' tables against both).
_DEFAULTS = default_dict()


def _default(section: str, key: str) -> Any:
    return _DEFAULTS[section][key]

UAV_ID = re.compile(r"(?!\.{1,2}$)[^/\\\x00-\x1f\x7f]{1,64}")
TOP_KEYS = ("site", "camera", "fleet", "mission", "turbines")
CAMERA_KEYS = ("sensor_width_mm", "focal_mm", "width_px", "height_px", "min_photo_interval_s",
               "shutter_s", "max_blur_px")
FLEET_KEYS = ("uavs", "launch", "inspection_speed_m_s", "cruise_speed_m_s", "max_speed_m_s",
              "climb_rate_m_s", "battery_minutes", "battery_reserve_minutes", "wind_margin",
              "battery_swap_s", "gimbal_pitch_min_deg", "gimbal_pitch_max_deg")
MISSION_KEYS = ("safe_distance_m", "tracking_margin_m", "target_gsd_mm", "overlap",
                "max_incidence_deg", "min_altitude_m", "takeoff_altitude_m", "min_side_coverage",
                "coverage_spacing_m", "inspect_tower", "inspect_nacelle", "tower_columns",
                "allow_coarser_gsd", "geometry_uncertainty_m")
TURBINE_KEYS = ("id", "position", "lat", "lon", "alt", "hub_height_m", "rotor_diameter_m",
                "blades", "yaw_deg", "blade_azimuths_deg", "rotor_azimuth_deg", "blade_pitch_deg",
                "tower", "nacelle", "blade", "hub_radius_m", "overhang_m", "blade_tips", "photo",
                "camera_pose", "geometry_uncertainty_m")
TOWER_KEYS = ("base_radius_m", "top_radius_m")
NACELLE_KEYS = ("length_m", "width_m", "height_m", "ahead_m", "above_hub_m")
BLADE_KEYS = ("root_chord_m", "max_chord_m", "tip_chord_m", "max_chord_span_fraction",
              "root_thickness_ratio", "max_chord_thickness_ratio", "tip_thickness_ratio")
# How far the real surfaces may lie outside the modelled ones, m: the allowed range of
# geometry_uncertainty_m (mission-wide and per turbine).
UNCERTAINTY_RANGE_M = (0.0, 10.0)
POSE_KEYS = ("position", "look_at", "roll_deg")
# Where a point of a site may be, in ENU metres from the site origin: a real site is a few km
# across (and exports are checked for sites of 10 km); beyond, a position is a typo or in
# the wrong unit (a 1e12 once planned and exported a home altitude of 1.4e12 m).
SITE_REACH_M = 50_000.0
SITE_Z_M = (-1000.0, 9000.0)


@dataclass(frozen=True)
class Fleet:
    uavs: tuple[str, ...] = tuple(f"UAV{k + 1}" for k in range(_default("fleet", "uavs")))
    launch: tuple[float, float, float] | None = None  # ENU m on the ground; None = automatic
    inspection_speed_m_s: float = float(_default("fleet", "inspection_speed_m_s"))
    cruise_speed_m_s: float = float(_default("fleet", "cruise_speed_m_s"))
    max_speed_m_s: float = float(_default("fleet", "max_speed_m_s"))
    climb_rate_m_s: float = float(_default("fleet", "climb_rate_m_s"))
    battery_minutes: float = float(_default("fleet", "battery_minutes"))
    battery_reserve_minutes: float = float(_default("fleet", "battery_reserve_minutes"))
    # Share of a sortie's planned time kept for what wind and the controller add to it, so the
    # reserve is still there at landing (docs/plan.md "Battery").
    wind_margin: float = float(_default("fleet", "wind_margin"))
    battery_swap_s: float = float(_default("fleet", "battery_swap_s"))
    # Camera elevation the gimbal can reach (0 level, -90 straight down, +90 straight up): the
    # default needs one that can look straight up (top-mounted); under-slung ones stop near +30.
    gimbal_pitch_min_deg: float = float(_default("fleet", "gimbal_pitch_min_deg"))
    gimbal_pitch_max_deg: float = float(_default("fleet", "gimbal_pitch_max_deg"))

    def __post_init__(self) -> None:
        if not self.uavs or len(set(self.uavs)) != len(self.uavs):
            raise ValueError(f"expected unique UAV ids, got {self.uavs}")
        for name in ("inspection_speed_m_s", "cruise_speed_m_s", "max_speed_m_s", "climb_rate_m_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"expected {name} > 0, got {getattr(self, name)}")
        if self.battery_minutes <= self.battery_reserve_minutes:
            raise ValueError(f"expected battery_minutes ({self.battery_minutes}) > "
                             f"battery_reserve_minutes ({self.battery_reserve_minutes})")
        if not 0.0 <= self.wind_margin <= 1.0:
            raise ValueError(f"expected wind_margin in [0, 1], got {self.wind_margin}")
        if not -90.0 <= self.gimbal_pitch_min_deg <= 0.0 <= self.gimbal_pitch_max_deg <= 90.0:
            raise ValueError(f"expected -90 <= gimbal_pitch_min_deg ({self.gimbal_pitch_min_deg}) "
                             f"<= 0 <= gimbal_pitch_max_deg ({self.gimbal_pitch_max_deg}) <= 90")
        if self.launch is not None:
            object.__setattr__(self, "launch", tuple(float(v) for v in self.launch))

    @property
    def gimbal_pitch_range(self) -> tuple[float, float]:
        return (self.gimbal_pitch_min_deg, self.gimbal_pitch_max_deg)

    @property
    def usable_battery_s(self) -> float:
        return 60.0 * (self.battery_minutes - self.battery_reserve_minutes)

    @property
    def sortie_limit_s(self) -> float:
        """The longest sortie planned: one that, flown ``wind_margin`` longer, still lands with
        the reserve."""
        return self.usable_battery_s / (1.0 + self.wind_margin)


@dataclass(frozen=True)
class Capture:
    """How fast the inspection camera can shoot while the UAV moves (turbines.yaml ``camera``):
    photos at least ``min_photo_interval_s`` apart, and a motion blur of at most ``max_blur_px``
    pixels during the ``shutter_s`` exposure."""

    min_photo_interval_s: float = float(_default("camera", "min_photo_interval_s"))
    shutter_s: float = float(_default("camera", "shutter_s"))
    max_blur_px: float = float(_default("camera", "max_blur_px"))

    def __post_init__(self) -> None:
        for name in ("min_photo_interval_s", "shutter_s", "max_blur_px"):
            if not getattr(self, name) > 0:
                raise ValueError(f"expected {name} > 0, got {getattr(self, name)}")

    def blur_speed_m_s(self, gsd_mm: float) -> float:
        """The fastest a camera imaging at ``gsd_mm`` may move across the surface: the image
        moves v * shutter_s / GSD pixels during the exposure."""
        return self.max_blur_px * gsd_mm / 1000.0 / self.shutter_s

    def interval_speed_m_s(self, spacing_m: float) -> float:
        """The fastest a UAV may fly photos ``spacing_m`` apart at the camera's photo interval."""
        return spacing_m / self.min_photo_interval_s


@dataclass(frozen=True)
class Settings:
    safe_distance_m: float = float(_default("mission", "safe_distance_m"))
    tracking_margin_m: float = float(_default("mission", "tracking_margin_m"))
    target_gsd_mm: float = float(_default("mission", "target_gsd_mm"))
    overlap: float = float(_default("mission", "overlap"))
    max_incidence_deg: float = float(_default("mission", "max_incidence_deg"))
    min_altitude_m: float = float(_default("mission", "min_altitude_m"))
    takeoff_altitude_m: float = float(_default("mission", "takeoff_altitude_m"))
    min_side_coverage: float = float(_default("mission", "min_side_coverage"))
    coverage_spacing_m: float = float(_default("mission", "coverage_spacing_m"))
    inspect_tower: bool = bool(_default("mission", "inspect_tower"))
    inspect_nacelle: bool = bool(_default("mission", "inspect_nacelle"))
    tower_columns: int = int(_default("mission", "tower_columns"))
    allow_coarser_gsd: bool = bool(_default("mission", "allow_coarser_gsd"))
    # How far a turbine's real surfaces may lie outside the modelled ones: the planner keeps
    # safe_distance_m from the model grown by it (a turbine may override it).
    geometry_uncertainty_m: float = float(_default("mission", "geometry_uncertainty_m"))

    def __post_init__(self) -> None:
        if not self.safe_distance_m > 0:
            raise ValueError(f"expected safe_distance_m > 0, got {self.safe_distance_m}")
        if not self.geometry_uncertainty_m >= 0:
            raise ValueError(f"expected geometry_uncertainty_m >= 0, got {self.geometry_uncertainty_m}")
        if self.tracking_margin_m < 0:
            raise ValueError(f"expected tracking_margin_m >= 0, got {self.tracking_margin_m}")
        if not 0 <= self.overlap < 1:
            raise ValueError(f"expected overlap in [0, 1), got {self.overlap}")
        if not self.target_gsd_mm > 0:
            raise ValueError(f"expected target_gsd_mm > 0, got {self.target_gsd_mm}")

    @property
    def required_clearance_m(self) -> float:
        """What the planner keeps from every part of the model grown by the geometry
        uncertainty: safe distance plus the tracking margin."""
        return self.safe_distance_m + self.tracking_margin_m


@dataclass(frozen=True)
class CameraPose:
    """Where the photo of a turbine was taken from (ENU m) and the point it looked at."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    roll_deg: float = 0.0


@dataclass(frozen=True)
class TurbineExtras:
    """What a turbines.yaml entry says beyond the turbine model."""

    photo: Path | None = None  # photo (or pitch JSON) of this turbine, taken from camera_pose
    measured_tips: np.ndarray | None = None  # (N, 3) ENU m: the paper's eq. 2 input
    camera_pose: CameraPose | None = None  # default: at S_p looking at the zone centre
    # photo (a photo or pitch JSON, plan_mission's azimuths) | yaml | tips | default (evenly
    # spaced, blade 1 up)
    azimuth_source: str = "default"
    geometry_uncertainty_m: float | None = None  # this turbine's; None: the mission's


@dataclass(frozen=True)
class Mission:
    turbines: tuple[Turbine, ...]
    camera: Camera  # intrinsics of the inspection camera (also the overview photo's)
    fleet: Fleet = field(default_factory=Fleet)
    settings: Settings = field(default_factory=Settings)
    site_origin: dict | None = None  # {"lat", "lon", "alt"} of ENU (0, 0, 0)
    extras: dict = field(default_factory=dict)  # turbine id -> TurbineExtras
    capture: Capture = field(default_factory=Capture)  # the camera's photo interval and shutter

    def __post_init__(self) -> None:
        object.__setattr__(self, "turbines", tuple(self.turbines))
        if not self.turbines:
            raise ValueError("a mission needs at least one turbine")
        ids = [t.id for t in self.turbines]
        if len(set(ids)) != len(ids):
            raise ValueError(f"expected unique turbine ids, got {ids}")
        unknown = set(self.extras) - set(ids)
        if unknown:
            raise ValueError(f"extras for unknown turbines {sorted(unknown)}")

    def extra(self, turbine_id: str) -> TurbineExtras:
        return self.extras.get(turbine_id) or TurbineExtras()

    def geometry_uncertainty(self, turbine_id: str) -> float:
        """How far turbine ``turbine_id``'s real surfaces may lie outside the model, m: its own
        ``geometry_uncertainty_m``, else the mission's."""
        u = self.extra(turbine_id).geometry_uncertainty_m
        return self.settings.geometry_uncertainty_m if u is None else u

    def geometry_uncertainties(self) -> list[float]:
        """``geometry_uncertainty`` of every turbine, in ``turbines`` order (``Site``'s input)."""
        return [self.geometry_uncertainty(t.id) for t in self.turbines]

    def turbine(self, turbine_id: str) -> Turbine:
        for t in self.turbines:
            if t.id == turbine_id:
                return t
        raise KeyError(turbine_id)

    def with_azimuths(self, azimuths: dict[str, list[float]], source: str = "photo") -> Mission:
        """The same mission with some turbines' blade azimuths replaced, ``source`` recorded as
        where they came from (``TurbineExtras.azimuth_source``)."""
        ts = []
        for t in self.turbines:
            if t.id in azimuths:
                az = tuple(float(a) for a in azimuths[t.id])
                if len(az) != t.n_blades:
                    raise ValueError(f"turbine {t.id!r}: expected {t.n_blades} azimuths, got {len(az)}")
                t = replace(t, azimuths_deg=az)
            ts.append(t)
        extras = {**self.extras, **{tid: replace(self.extra(tid), azimuth_source=source)
                                    for tid in azimuths}}
        return replace(self, turbines=tuple(ts), extras=extras)


# ---- loading -----------------------------------------------------------------------------------
_merge = merge  # the one deep merge lives in wtcli.yamlcheck


def load_mission(path: str | Path) -> Mission:
    """Read, merge over the packaged defaults, validate and freeze a turbines.yaml."""
    path = Path(path)
    data = load_yaml(path)
    if data is None:
        raise ConfigError(f"{path}: the file is empty")
    return mission_from_dict(data, where=path.name, base_dir=path.parent)


def _boolean(m: dict, key: str, where: str) -> bool:
    v = m.get(key)
    if not isinstance(v, bool):
        raise ConfigError(f"{where}.{key}: expected true or false, got {v!r}")
    return v


def _point(m: dict, where: str, origin: dict | None, what: str) -> tuple[float, float, float]:
    """``position: [x, y, z]`` (ENU m) or ``lat``/``lon``/``alt`` (needs site.origin)."""
    if "position" in m and m["position"] is not None:
        if any(k in m for k in ("lat", "lon")):
            raise ConfigError(f"{where}: give either position or lat/lon/alt for the {what}, not both")
        return _on_site(tuple(vector(m, "position", where, 3)), f"{where}.position")
    if "lat" in m or "lon" in m:
        if origin is None:
            raise ConfigError(f"{where}: lat/lon needs site.origin (lat, lon, alt) to convert to "
                              "local ENU metres")
        lat = number(m, "lat", where, -90, 90)
        lon = number(m, "lon", where, -180, 180)
        alt = number(m, "alt", where, -500, 9000, default=float(origin["alt"]))
        e = geodetic_to_enu(lat, lon, alt, origin)
        return _on_site((float(e[0]), float(e[1]), float(e[2])), f"{where}.lat/lon")
    raise ConfigError(f"{where}: missing the {what}: give position: [x, y, z] (ENU m) or "
                      "lat/lon/alt")


def _on_site(p: tuple[float, float, float], where: str) -> tuple[float, float, float]:
    """The point, if it lies within ``SITE_REACH_M`` of the site origin and ``SITE_Z_M``."""
    if max(abs(p[0]), abs(p[1])) > SITE_REACH_M or not SITE_Z_M[0] <= p[2] <= SITE_Z_M[1]:
        raise ConfigError(f"{where}: expected a point within {SITE_REACH_M / 1000:g} km of the "
                          f"site origin (ENU x, y in [-{SITE_REACH_M:g}, {SITE_REACH_M:g}] m, z in "
                          f"[{SITE_Z_M[0]:g}, {SITE_Z_M[1]:g}] m), got "
                          f"[{', '.join(f'{v:.6g}' for v in p)}]")
    return p


def _spread_like_a_rotor(azimuths: tuple[float, ...], where: str) -> None:
    """Blades of a rotor are evenly spaced: each gap between neighbours within the tolerance the
    photo path allows (``plan.angles.MAX_SPACING_ERROR_DEG``) of 360/n, else a typo such as
    [90, 90, 210]."""
    from wtcli.pitch.rotor import ROTOR_GAP_TOLERANCE_DEG as MAX_SPACING_ERROR_DEG

    n = len(azimuths)
    if n < 2:
        return
    a = np.sort(np.asarray(azimuths, float) % 360.0)
    gaps = np.diff(np.r_[a, a[0] + 360.0])
    if np.abs(gaps - 360.0 / n).max() > MAX_SPACING_ERROR_DEG:
        raise ConfigError(f"{where}.blade_azimuths_deg: expected blades spread like a rotor (gaps "
                          f"of {360.0 / n:g} +- {MAX_SPACING_ERROR_DEG:g} deg between neighbours), "
                          f"got {[round(float(x), 3) for x in azimuths]} (gaps "
                          f"{[round(float(g), 1) for g in gaps]})")


def _apart(turbines: list[Turbine], where: str) -> None:
    """Two turbines whose towers stand closer than their two rotor radii would strike each
    other's blades: a duplicate entry or a wrong position, refused naming both."""
    if len(turbines) < 2:
        return
    xy = np.array([t.base[:2] for t in turbines])
    r = np.array([t.tip_radius for t in turbines])
    order = np.argsort(xy[:, 0], kind="stable")
    reach = 2 * float(r.max())
    for a_i, i in enumerate(order):  # sweep along x: only neighbours within two rotor radii
        for j in order[a_i + 1:]:
            if xy[j, 0] - xy[i, 0] > reach:
                break
            d = float(np.linalg.norm(xy[i] - xy[j]))
            if d < r[i] + r[j]:
                a, b = sorted((int(i), int(j)))
                raise ConfigError(
                    f"{where}: turbines[{b}].position: turbine {turbines[b].id!r} stands "
                    f"{d:.1f} m from {turbines[a].id!r}, closer than their rotor radii allow "
                    f"({r[a]:g} + {r[b]:g} m): a duplicate entry or a wrong position")


def _blades_clear_the_tower(t: Turbine, where: str) -> None:
    """A blade turned to point straight down must pass the tower: a turbine whose modelled blade
    would cut into its tower cannot turn, so its tower, overhang or blade sizes are wrong (and
    a plan around it would rest on a surface that is not there). Checked at every azimuth's
    worst, straight down, so angles read later from a photo cannot change the answer."""
    down = replace(t, azimuths_deg=(270.0,))
    q = down.blade_outline(0) - down.base_xyz
    h = q[:, 2]
    radius = down.tower_radius_at(h)
    depth = np.where((h >= 0) & (h <= down.tower_height), radius - np.hypot(q[:, 0], q[:, 1]),
                     -np.inf)
    i = int(np.argmax(depth))
    if depth[i] > 0:
        raise ConfigError(
            f"{where}: a blade pointing down would pass {depth[i]:.2f} m into the tower "
            f"({h[i]:.1f} m above its base, tower radius {radius[i]:.2f} m there, hub "
            f"{down.overhang:.2f} m ahead of the tower axis): check tower.base_radius_m / "
            f"top_radius_m, overhang_m and the blade chord")


def mission_from_dict(d: Any, where: str = "turbines.yaml", base_dir: str | Path = ".") -> Mission:
    """Validate a turbines.yaml mapping (merged over the packaged defaults) into a Mission."""
    base_dir = Path(base_dir)
    d = need_mapping(d, where)
    check_keys(d, TOP_KEYS, where, required=("turbines",))
    d = _merge(default_dict(), d)

    # site
    origin = None
    site = d.get("site")
    if site is not None:
        w = f"{where}: site"
        site = need_mapping(site, w)
        check_keys(site, ("origin",), w)
        if site.get("origin") is not None:
            o = need_mapping(site["origin"], f"{w}.origin")
            check_keys(o, ("lat", "lon", "alt"), f"{w}.origin", required=("lat", "lon"))
            origin = {"lat": number(o, "lat", f"{w}.origin", -90, 90),
                      "lon": number(o, "lon", f"{w}.origin", -180, 180),
                      "alt": number(o, "alt", f"{w}.origin", -500, 9000, default=0.0)}

    # camera
    w = f"{where}: camera"
    c = need_mapping(d["camera"], w)
    check_keys(c, CAMERA_KEYS, w)
    camera = Camera(number(c, "width_px", w, 64, 100000, integer=True),
                    number(c, "height_px", w, 64, 100000, integer=True),
                    number(c, "focal_mm", w, 1, 2000), number(c, "sensor_width_mm", w, 1, 100))
    capture = Capture(number(c, "min_photo_interval_s", w, 0.05, 60),
                      number(c, "shutter_s", w, 1e-5, 1), number(c, "max_blur_px", w, 0.05, 10))

    # mission settings
    w = f"{where}: mission"
    m = need_mapping(d["mission"], w)
    check_keys(m, MISSION_KEYS, w)
    settings = Settings(
        safe_distance_m=number(m, "safe_distance_m", w, 0.5, 100),
        tracking_margin_m=number(m, "tracking_margin_m", w, 0, 20),
        target_gsd_mm=number(m, "target_gsd_mm", w, 0.1, 50),
        overlap=number(m, "overlap", w, 0, 0.9),
        max_incidence_deg=number(m, "max_incidence_deg", w, 10, 85),
        min_altitude_m=number(m, "min_altitude_m", w, 0, 200),
        takeoff_altitude_m=number(m, "takeoff_altitude_m", w, 1, 500),
        min_side_coverage=number(m, "min_side_coverage", w, 0, 1),
        coverage_spacing_m=number(m, "coverage_spacing_m", w, 0.2, 5),
        inspect_tower=_boolean(m, "inspect_tower", w),
        inspect_nacelle=_boolean(m, "inspect_nacelle", w),
        tower_columns=number(m, "tower_columns", w, 0, 16, integer=True),
        allow_coarser_gsd=_boolean(m, "allow_coarser_gsd", w),
        geometry_uncertainty_m=number(m, "geometry_uncertainty_m", w, *UNCERTAINTY_RANGE_M))

    # fleet
    w = f"{where}: fleet"
    f = need_mapping(d["fleet"], w)
    check_keys(f, FLEET_KEYS, w)
    uavs = f.get("uavs", 1)
    if isinstance(uavs, int) and not isinstance(uavs, bool):
        if not 1 <= uavs <= 50:
            raise ConfigError(f"{w}.uavs: expected a count in [1, 50] or a list of ids, got {uavs!r}")
        uav_ids = tuple(f"UAV{k + 1}" for k in range(uavs))
    elif isinstance(uavs, list) and uavs and all(isinstance(u, (str, int)) and not isinstance(u, bool)
                                                 for u in uavs):
        uav_ids = tuple(str(u) for u in uavs)
        if len(set(uav_ids)) != len(uav_ids):
            raise ConfigError(f"{w}.uavs: expected unique ids, got {uavs!r}")
        for i, u in enumerate(uav_ids):
            # an id names the export files (STEM_UAV_sN.plan): a file name's part, no path
            if not UAV_ID.fullmatch(u):
                raise ConfigError(f"{w}.uavs[{i}]: expected an id of 1-64 characters without "
                                  f"'/', '\\' or control characters, not '.' or '..' (it names "
                                  f"export files), got {shown(u)}")
    else:
        raise ConfigError(f"{w}.uavs: expected a count in [1, 50] or a list of ids, got {uavs!r}")
    launch = None
    if f.get("launch") is not None:
        lw = f"{w}.launch"
        lm = need_mapping(f["launch"], lw)
        check_keys(lm, ("position", "lat", "lon", "alt"), lw)
        launch = _point(lm, lw, origin, "launch point")
    try:
        fleet = Fleet(
            uavs=uav_ids, launch=launch,
            inspection_speed_m_s=number(f, "inspection_speed_m_s", w, 0.2, 15),
            cruise_speed_m_s=number(f, "cruise_speed_m_s", w, 0.5, 30),
            max_speed_m_s=number(f, "max_speed_m_s", w, 0.5, 40),
            climb_rate_m_s=number(f, "climb_rate_m_s", w, 0.2, 15),
            battery_minutes=number(f, "battery_minutes", w, 1, 300),
            battery_reserve_minutes=number(f, "battery_reserve_minutes", w, 0, 100),
            wind_margin=number(f, "wind_margin", w, 0, 1),
            battery_swap_s=number(f, "battery_swap_s", w, 0, 3600),
            gimbal_pitch_min_deg=number(f, "gimbal_pitch_min_deg", w, -90, 0),
            gimbal_pitch_max_deg=number(f, "gimbal_pitch_max_deg", w, 0, 90))
    except ValueError as e:
        raise ConfigError(f"{w}: {e}") from None

    # turbines
    ts = d["turbines"]
    if not isinstance(ts, list) or not ts:
        raise ConfigError(f"{where}: turbines: expected a non-empty list of turbines, got {ts!r}")
    turbines, extras, seen = [], {}, set()
    for i, td in enumerate(ts):
        t, ex = _turbine(td, f"{where}: turbines[{i}]", origin, base_dir)
        if t.id in seen:
            raise ConfigError(f"{where}: turbines[{i}].id: duplicate turbine id {t.id!r}")
        seen.add(t.id)
        _blades_clear_the_tower(t, f"{where}: turbines[{i}]")
        turbines.append(t)
        extras[t.id] = ex
    _apart(turbines, where)
    return Mission(tuple(turbines), camera, fleet, settings, origin, extras, capture)


def _turbine(td: Any, w: str, origin: dict | None, base_dir: Path) -> tuple[Turbine, TurbineExtras]:
    td = need_mapping(td, w)
    check_keys(td, TURBINE_KEYS, w, required=("id", "hub_height_m", "rotor_diameter_m", "yaw_deg"))
    tid = string(td, "id", w)
    base = _point(td, w, origin, "tower base position")
    hub = number(td, "hub_height_m", w, 10, 250)
    diam = number(td, "rotor_diameter_m", w, 5, 300)
    blades = number(td, "blades", w, 1, 6, integer=True, default=3)
    yaw = number(td, "yaw_deg", w, 0, 360)
    pitch = number(td, "blade_pitch_deg", w, 0, 90, default=90.0)
    kw: dict[str, Any] = {}
    if td.get("tower") is not None:
        tw = f"{w}.tower"
        tm = need_mapping(td["tower"], tw)
        check_keys(tm, TOWER_KEYS, tw)
        kw["tower_base_radius"] = number(tm, "base_radius_m", tw, 0.2, 20, default=None)
        kw["tower_top_radius"] = number(tm, "top_radius_m", tw, 0.2, 20, default=None)
    if td.get("nacelle") is not None:
        nw = f"{w}.nacelle"
        nm = need_mapping(td["nacelle"], nw)
        check_keys(nm, NACELLE_KEYS, nw)
        kw["nacelle_length"] = number(nm, "length_m", nw, 1, 40, default=None)
        kw["nacelle_width"] = number(nm, "width_m", nw, 0.5, 20, default=None)
        kw["nacelle_height"] = number(nm, "height_m", nw, 0.5, 20, default=None)
        kw["nacelle_ahead"] = number(nm, "ahead_m", nw, -20, 20, default=None)
        above = number(nm, "above_hub_m", nw, -10, 10, default=None)
        if above is not None:
            kw["nacelle_above_hub"] = above
    if td.get("blade") is not None:
        bw = f"{w}.blade"
        bm = need_mapping(td["blade"], bw)
        check_keys(bm, BLADE_KEYS, bw)
        kw["blade_root_chord"] = number(bm, "root_chord_m", bw, 0.1, 15, default=None)
        kw["blade_max_chord"] = number(bm, "max_chord_m", bw, 0.1, 15, default=None)
        kw["blade_tip_chord"] = number(bm, "tip_chord_m", bw, 0.05, 15, default=None)
        for key, field_name, lo in (("max_chord_span_fraction", "blade_max_chord_at", 0.05),
                                    ("root_thickness_ratio", "blade_root_thickness_ratio", 0.1),
                                    ("max_chord_thickness_ratio", "blade_max_chord_thickness_ratio", 0.1),
                                    ("tip_thickness_ratio", "blade_tip_thickness_ratio", 0.05)):
            hi = 0.6 if key == "max_chord_span_fraction" else 1.0
            v = number(bm, key, bw, lo, hi, default=None)
            if v is not None:
                kw[field_name] = v
    kw["hub_radius"] = number(td, "hub_radius_m", w, 0.2, 10, default=None)
    kw["overhang"] = number(td, "overhang_m", w, 0, 30, default=None)
    uncertainty = number(td, "geometry_uncertainty_m", w, *UNCERTAINTY_RANGE_M, default=None)

    tips = None
    if td.get("blade_tips") is not None:
        raw = td["blade_tips"]
        if not isinstance(raw, list) or len(raw) != blades:
            raise ConfigError(f"{w}.blade_tips: expected {blades} tips (one [x, y, z] per blade), "
                              f"got {raw!r}")
        tips = np.array([vector({"tip": p}, "tip", f"{w}.blade_tips[{k}]", 3)
                         for k, p in enumerate(raw)])
    if "blade_azimuths_deg" in td and "rotor_azimuth_deg" in td:
        raise ConfigError(f"{w}: give blade_azimuths_deg or rotor_azimuth_deg, not both")
    source = "default"
    if td.get("blade_azimuths_deg") is not None:
        az = td["blade_azimuths_deg"]
        if not isinstance(az, list) or len(az) != blades:
            raise ConfigError(f"{w}.blade_azimuths_deg: expected a list of {blades} angles in "
                              f"[0, 360), got {az!r}")
        azimuths = tuple(number({"a": a}, "a", f"{w}.blade_azimuths_deg[{k}]", 0, 360)
                         for k, a in enumerate(az))
        _spread_like_a_rotor(azimuths, w)
        source = "yaml"
    else:
        a1 = number(td, "rotor_azimuth_deg", w, 0, 360, default=None)
        if a1 is not None:
            source = "yaml"
        azimuths = tuple(((90.0 if a1 is None else a1) + k * 360.0 / blades) % 360.0
                         for k in range(blades))
    try:
        turbine = Turbine(id=tid, base=base, hub_height=hub, rotor_diameter=diam, yaw_deg=yaw,
                          azimuths_deg=azimuths, blade_pitch_deg=pitch, **kw)
    except ValueError as e:
        raise ConfigError(f"{w}: {e}") from None
    if tips is not None:
        from wtcli.plan.zone import azimuths_from_tips

        try:
            turbine = replace(turbine, azimuths_deg=tuple(azimuths_from_tips(turbine, tips)))
        except ValueError as e:
            raise ConfigError(f"{w}.blade_tips: {e}") from None
        source = "tips"

    pose = None
    if td.get("camera_pose") is not None:
        pw = f"{w}.camera_pose"
        pm = need_mapping(td["camera_pose"], pw)
        check_keys(pm, POSE_KEYS, pw, required=("position", "look_at"))
        pose = CameraPose(tuple(vector(pm, "position", pw, 3)), tuple(vector(pm, "look_at", pw, 3)),
                          number(pm, "roll_deg", pw, -180, 180, default=0.0))
        if math.dist(pose.position, pose.look_at) < 1e-6:
            raise ConfigError(f"{pw}: position and look_at coincide")
    photo = None
    if td.get("photo") is not None:
        photo = Path(string(td, "photo", w))
        if not photo.is_absolute():
            photo = base_dir / photo
    return turbine, TurbineExtras(photo, tips, pose, source, uncertainty)
