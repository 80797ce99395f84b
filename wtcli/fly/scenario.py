"""A flight scenario: wind, terrain, vehicle, controller gains, baselines and seed.

The packaged, commented ``wtcli/data/scenarios/defaults.yaml`` holds every key; a scenario file
overrides some of them (and may name a mission file to plan from); the merge is validated with
``wtcli.yamlcheck`` (unknown keys get a did-you-mean hint, values are range-checked) and frozen
into a ``Scenario``. Documented for users in ``docs/scenarios.md``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Any

from wtcli.errors import ConfigError
from wtcli.yamlcheck import merge, check_keys, choice, load_yaml, need_mapping, number, string

SCENARIO_DIR = Path(str(resources.files("wtcli") / "data" / "scenarios"))
DEFAULTS_PATH = SCENARIO_DIR / "defaults.yaml"
INF = float("inf")


@dataclass(frozen=True)
class Wind:
    speed_ms: float
    reference_height_m: float
    direction_deg: float
    shear_exponent: float
    turbulence_model: str
    turbulence_intensity: str
    turbulence_sigma_ms: float | None
    gust_rate_per_min: float
    gust_amplitude_ms: float
    gust_duration_s: float
    turbulence_class: str = "B"  # IEC 61400-1 category (Kaimal): A+, A, B, C
    # Kaimal: sigma_2 / sigma_1 and sigma_3 / sigma_1 (IEC 61400-1 NTM 0.8 / 0.5; complex
    # terrain has more lateral and vertical turbulence, docs/scenarios.md)
    lateral_ratio: float = 0.8
    vertical_ratio: float = 0.5
    wake: bool = True  # tower and nacelle wake (wtcli.fly.wake)


@dataclass(frozen=True)
class Terrain:
    kind: str
    amplitude_m: float
    wavelength_m: float
    turbulence_factor: float
    min_agl_m: float
    min_transit_agl_m: float


@dataclass(frozen=True)
class Vehicle:
    max_speed_ms: float
    max_climb_ms: float
    max_descent_ms: float
    max_tilt_deg: float
    max_vertical_accel_ms2: float
    velocity_time_constant_s: float
    rotor_drag_per_s: float
    body_drag_per_m: float
    yaw_rate_deg_s: float
    yaw_time_constant_s: float
    gimbal_rate_deg_s: float
    gimbal_time_constant_s: float
    gimbal_roll_leak: float
    mass_kg: float
    hover_power_w: float
    battery_wh: float
    propulsion_efficiency: float
    position_noise_m: float
    velocity_noise_ms: float
    gimbal_pitch_min_deg: float = -90.0  # the camera elevation the gimbal reaches
    gimbal_pitch_max_deg: float = 90.0
    model: str = "rigid"  # rigid (attitude and motor dynamics) or kinematic
    attitude_time_constant_s: float = 0.15  # inner attitude loop: tilt rate = error / this
    max_tilt_rate_deg_s: float = 150.0
    motor_time_constant_s: float = 0.05  # thrust and body-rate response


@dataclass(frozen=True)
class Positioning:
    mode: str  # rtk_fixed, rtk_float, gnss, ideal (wtcli.fly.navigation)
    rtk_degrades_near_tower: bool
    rtk_degrade_distance_m: float
    rtk_refix_s: float


@dataclass(frozen=True)
class Control:
    physics_hz: float
    control_hz: float
    reference_accel_ms2: float
    corner_deviation_m: float
    reference_smoothing_s: float
    divergence_m: float
    leash_m: float  # the set-point waits for the vehicle (0: off); see wtcli.fly.sim


@dataclass(frozen=True)
class Gains:
    kp: float
    ki: float
    kd: float
    derivative_filter_s: float
    integral_limit_ms: float
    feed_forward: bool


@dataclass(frozen=True)
class ManualPilot:
    speed_factor: float
    max_speed_ms: float
    hover_per_photo_s: float
    reaction_delay_s: float
    gain_per_s: float
    deadband_m: float
    perception_sigma_m: float
    perception_time_s: float
    stick_noise_ms: float
    aim_sigma_deg: float


@dataclass(frozen=True)
class Baselines:
    no_compensation: bool
    fixed_pattern: bool
    manual: bool


@dataclass(frozen=True)
class Scenario:
    name: str
    seed: int
    wind: Wind
    terrain: Terrain
    vehicle: Vehicle
    control: Control
    gains: Gains
    baselines: Baselines
    manual_pilot: ManualPilot
    sample_spacing_m: float
    positioning: Positioning = Positioning("ideal", False, 8.0, 30.0)
    mission: Path | None = None  # turbines/mission YAML to plan from (absolute)
    azimuths: dict | None = None  # {turbine id: [deg, ...]} real blade stop positions, optional
    description: str = ""
    source: Path | None = None
    paper: dict | None = None  # Table 1 row this scenario reproduces (for --paper-table)

    def __post_init__(self) -> None:
        if self.control.physics_hz < self.control.control_hz:
            raise ValueError(f"expected physics_hz >= control_hz, got {self.control.physics_hz} < "
                             f"{self.control.control_hz}")

    @property
    def substeps(self) -> int:
        return max(1, int(round(self.control.physics_hz / self.control.control_hz)))

    def with_seed(self, seed: int) -> Scenario:
        return replace(self, seed=int(seed))

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["mission"] = str(self.mission) if self.mission else None
        d["source"] = str(self.source) if self.source else None
        return d


# ---- loading ---------------------------------------------------------------------------------

_SECTIONS = ("wind", "terrain", "vehicle", "control", "gains", "coverage", "baselines",
             "manual_pilot", "positioning")
_TOP = ("name", "description", "mission", "seed", "azimuths", "paper") + _SECTIONS

# key -> (lo, hi, lo_open) for plain numbers of each section
_NUM = {
    "wind": {"speed_ms": (0, 40, False), "reference_height_m": (1, 300, False),
             "direction_deg": (-360, 360, False), "shear_exponent": (0, 0.6, False)},
    "terrain": {"amplitude_m": (0, 200, False), "wavelength_m": (50, 5000, False),
                "min_agl_m": (0, 100, False)},
    "vehicle": {"max_speed_ms": (0.5, 30, False), "max_climb_ms": (0.2, 15, False),
                "max_descent_ms": (0.2, 15, False), "max_tilt_deg": (5, 60, False),
                "max_vertical_accel_ms2": (0.5, 20, False),
                "velocity_time_constant_s": (0.02, 5, False), "rotor_drag_per_s": (0, 2, False),
                "body_drag_per_m": (0, 0.2, False), "yaw_rate_deg_s": (1, 720, False),
                "yaw_time_constant_s": (0.01, 10, False), "gimbal_rate_deg_s": (1, 720, False),
                "gimbal_time_constant_s": (0.01, 10, False), "gimbal_roll_leak": (0, 1, False),
                "gimbal_pitch_min_deg": (-90, 0, False), "gimbal_pitch_max_deg": (0, 90, False),
                "mass_kg": (0.1, 100, False), "hover_power_w": (1, 20000, False),
                "battery_wh": (1, 20000, False), "propulsion_efficiency": (0.05, 1, False),
                "position_noise_m": (0, 5, False), "velocity_noise_ms": (0, 5, False),
                "attitude_time_constant_s": (0.02, 2, False), "max_tilt_rate_deg_s": (5, 1000, False),
                "motor_time_constant_s": (0.005, 1, False)},
    "control": {"physics_hz": (5, 1000, False), "control_hz": (1, 500, False),
                "reference_accel_ms2": (0.1, 20, False), "corner_deviation_m": (0, 5, False),
                "reference_smoothing_s": (0, 10, False), "divergence_m": (1, 10000, False),
                "leash_m": (0, 100, False)},
    "gains": {"kp": (0, 20, False), "ki": (0, 20, False), "kd": (0, 20, False),
              "derivative_filter_s": (0, 5, False), "integral_limit_ms": (0, 30, False)},
    "coverage": {"sample_spacing_m": (0.1, 5, False)},
    "positioning": {"rtk_degrade_distance_m": (0, 100, False), "rtk_refix_s": (0, 600, False)},
    "manual_pilot": {"speed_factor": (0.05, 1, False), "max_speed_ms": (0.2, 30, False),
                     "hover_per_photo_s": (0, 60, False), "reaction_delay_s": (0, 5, False),
                     "gain_per_s": (0, 5, False), "deadband_m": (0, 20, False),
                     "perception_sigma_m": (0, 20, False), "perception_time_s": (0.1, 600, False),
                     "stick_noise_ms": (0, 10, False), "aim_sigma_deg": (0, 45, False)},
}
_BOOL = {"gains": ("feed_forward",), "baselines": ("no_compensation", "fixed_pattern", "manual"),
         "positioning": ("rtk_degrades_near_tower",)}
_INTENSITY = ("auto", "light", "moderate", "severe")


_merge = merge  # the one deep merge lives in wtcli.yamlcheck


def _defaults() -> dict:
    return load_yaml(DEFAULTS_PATH)


def _bool(m: dict, key: str, where: str) -> bool:
    v = m.get(key)
    if not isinstance(v, bool):
        raise ConfigError(f"{where}.{key}: expected true or false, got {v!r}")
    return v


def _section(raw: dict, name: str, where: str, defaults: dict) -> dict:
    m = need_mapping(raw.get(name, {}) or {}, f"{where}{name}")
    check_keys(m, defaults[name].keys(), f"{where}{name}")
    return m


def scenario_from_dict(d: Any, where: str = "scenario", base_dir: Path | None = None,
                       source: Path | None = None) -> Scenario:
    """Validate a scenario mapping (already merged or not) and freeze it."""
    defaults = _defaults()
    d = need_mapping(d if d is not None else {}, where)
    check_keys(d, _TOP, where)
    for s in _SECTIONS:
        _section(d, s, f"{where}: ", defaults)
    if "turbulence" in (d.get("wind") or {}):
        t = need_mapping(d["wind"]["turbulence"], f"{where}: wind.turbulence")
        check_keys(t, defaults["wind"]["turbulence"].keys(), f"{where}: wind.turbulence")
    if "gusts" in (d.get("wind") or {}):
        g = need_mapping(d["wind"]["gusts"], f"{where}: wind.gusts")
        check_keys(g, defaults["wind"]["gusts"].keys(), f"{where}: wind.gusts")
    m = _merge(defaults, d)
    w = f"{where}: "

    vals: dict[str, dict[str, Any]] = {}
    for sec, spec in _NUM.items():
        vals[sec] = {k: number(m[sec], k, f"{w}{sec}", lo=lo, hi=hi, lo_open=lo_open)
                     for k, (lo, hi, lo_open) in spec.items()}
    for sec, keys in _BOOL.items():
        vals.setdefault(sec, {})
        for k in keys:
            vals[sec][k] = _bool(m[sec], k, f"{w}{sec}")

    turb, gust = m["wind"]["turbulence"], m["wind"]["gusts"]
    model = choice(turb, "model", f"{w}wind.turbulence", ("kaimal", "dryden", "none"))
    iec = str(turb.get("iec_class"))
    if iec not in ("A+", "A", "B", "C"):
        raise ConfigError(f"{w}wind.turbulence.iec_class: expected one of A+, A, B, C (IEC "
                          f"61400-1 turbulence categories), got {str(turb.get('iec_class'))[:20]!r}")
    intensity = choice(turb, "intensity", f"{w}wind.turbulence", _INTENSITY)
    sigma = number(turb, "sigma_ms", f"{w}wind.turbulence", lo=0, hi=15, default=None)
    wind = Wind(**vals["wind"], turbulence_model=model, turbulence_intensity=intensity,
                turbulence_sigma_ms=sigma,
                gust_rate_per_min=number(gust, "rate_per_min", f"{w}wind.gusts", lo=0, hi=30),
                gust_amplitude_ms=number(gust, "amplitude_ms", f"{w}wind.gusts", lo=0, hi=20),
                gust_duration_s=number(gust, "duration_s", f"{w}wind.gusts", lo=0.2, hi=60),
                turbulence_class=iec, wake=_bool(m["wind"], "wake", f"{w}wind"),
                lateral_ratio=number(turb, "lateral_ratio", f"{w}wind.turbulence", lo=0.3, hi=1.5),
                vertical_ratio=number(turb, "vertical_ratio", f"{w}wind.turbulence", lo=0.2,
                                      hi=1.2))

    kind = choice(m["terrain"], "kind", f"{w}terrain", ("flat", "hilly"))
    tf = number(m["terrain"], "turbulence_factor", f"{w}terrain", lo=0, hi=5, default=None)
    if tf is None:
        tf = 1.3 if kind == "hilly" else 1.0
    mt = number(m["terrain"], "min_transit_agl_m", f"{w}terrain", lo=0, hi=300, default=None)
    if mt is None:
        mt = 20.0 if kind == "hilly" else 0.0
    terrain = Terrain(kind=kind, turbulence_factor=tf, min_transit_agl_m=mt, **vals["terrain"])
    if kind == "flat" and terrain.amplitude_m > 0:
        raise ConfigError(f"{w}terrain.amplitude_m: flat terrain has no hills; use kind: hilly "
                          f"or amplitude_m: 0, got {terrain.amplitude_m}")

    from wtcli.fly.navigation import MODES

    positioning = Positioning(mode=choice(m["positioning"], "mode", f"{w}positioning", MODES),
                              **vals["positioning"])
    vmodel = choice(m["vehicle"], "model", f"{w}vehicle", ("rigid", "kinematic"))
    seed = number(m, "seed", where, lo=0, hi=2 ** 32 - 1, integer=True)
    name = string(m, "name", where, default=(source.stem if source else "scenario"))
    desc = string(m, "description", where, default="")
    mission = None
    if m.get("mission") is not None:
        mission = Path(string(m, "mission", where))
        if not mission.is_absolute():
            mission = (base_dir or Path.cwd()) / mission
    azimuths = _azimuths(m.get("azimuths"), f"{w}azimuths")
    paper = m.get("paper")
    if paper is not None:
        paper = _paper_row(paper, f"{w}paper")
    try:
        return Scenario(name=name, seed=seed, wind=wind, terrain=terrain,
                        vehicle=Vehicle(**vals["vehicle"], model=vmodel),
                        control=Control(**vals["control"]),
                        gains=Gains(**vals["gains"]), baselines=Baselines(**vals["baselines"]),
                        manual_pilot=ManualPilot(**vals["manual_pilot"]),
                        sample_spacing_m=vals["coverage"]["sample_spacing_m"],
                        positioning=positioning, mission=mission,
                        azimuths=azimuths, description=desc, source=source, paper=paper)
    except ValueError as e:
        raise ConfigError(f"{where}: {e}") from None


def _azimuths(v: Any, where: str) -> dict | None:
    if v is None:
        return None
    v = need_mapping(v, where)
    out = {}
    for tid, az in v.items():
        if not isinstance(az, list) or not az or not all(
                isinstance(a, (int, float)) and not isinstance(a, bool) and math.isfinite(a)
                for a in az):
            raise ConfigError(f"{where}.{tid}: expected a list of blade azimuths in degrees, "
                              f"got {az!r}")
        out[str(tid)] = [float(a) for a in az]
    return out


_PAPER_KEYS = ("scenario", "manual", "automated")
_PAPER_METRICS = ("time_min", "length_m", "coverage_pct", "deviation_m")


def _paper_row(v: Any, where: str) -> dict:
    v = need_mapping(v, where)
    check_keys(v, _PAPER_KEYS, where, required=_PAPER_KEYS)
    out = {"scenario": string(v, "scenario", where)}
    for k in ("manual", "automated"):
        row = need_mapping(v[k], f"{where}.{k}")
        check_keys(row, _PAPER_METRICS, f"{where}.{k}", required=_PAPER_METRICS)
        out[k] = {mk: number(row, mk, f"{where}.{k}", lo=0) for mk in _PAPER_METRICS}
    return out


def load_scenario(path: str | Path) -> Scenario:
    """Read, merge with the defaults, validate and freeze a scenario YAML file."""
    path = Path(path)
    raw = load_yaml(path)
    return scenario_from_dict(raw, where=path.name, base_dir=path.parent.resolve(), source=path)


def default_scenario(**sections: dict) -> Scenario:
    """The defaults, with optional section overrides: ``default_scenario(wind={"speed_ms": 5})``."""
    return scenario_from_dict(dict(sections), where="scenario")


def shipped_scenarios() -> dict[str, Path]:
    """Packaged scenario files by stem (``paper-s1`` ... ``paper-s4``, ``tiny``)."""
    return {p.stem: p for p in sorted(SCENARIO_DIR.glob("*.yaml"))
            if p.stem != "defaults" and not p.stem.endswith("-turbines")}


def resolve_scenario(name_or_path: str | Path) -> Path:
    """A path, or the stem of a shipped scenario."""
    p = Path(name_or_path)
    if p.exists() or p.suffix in (".yaml", ".yml"):
        return p
    shipped = shipped_scenarios()
    if str(name_or_path) in shipped:
        return shipped[str(name_or_path)]
    from wtcli.yamlcheck import hint
    raise ConfigError(f"{name_or_path}: no such scenario file or shipped scenario"
                      f"{hint(str(name_or_path), shipped)}; shipped: {', '.join(shipped)}")


__all__ = ["Baselines", "Control", "Gains", "ManualPilot", "Positioning", "Scenario", "Terrain", "Vehicle", "Wind",
           "default_scenario", "load_scenario", "resolve_scenario", "scenario_from_dict",
           "shipped_scenarios"]
