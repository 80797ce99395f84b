"""Random scenes: the main turbine, the camera that photographs it (view, distance, height,
aim, roll), other turbines in the distance, and the environment (sky, sun, ground, haze).

A scene is drawn from one ``numpy.random.Generator``; the renderer turns it into pixels. All
geometry is the one turbine and camera model of ``wtcli.geometry``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wtcli.geometry import Camera, Turbine

VIEWS = ("front", "oblique", "side", "rear")
# "mixed" draws a view with these odds: front photos are what the pipeline consumes, the rest
# teach the segmenter the shapes real flights also see.
VIEW_ODDS = {"front": 0.42, "oblique": 0.30, "side": 0.13, "rear": 0.15}
# The wider views' sampler per view name, registered by wtcli.synth.views (loaded with the
# package): views builds on this module, so this module does not import it back.
WIDE_SAMPLERS: dict = {}

SENSOR_WIDTH_MM = 13.2  # 1-inch drone sensor
SKIES = ("clear", "hazy", "overcast", "sunset")
SKY_ODDS = (0.42, 0.18, 0.30, 0.10)
GROUNDS = ("scrub", "fields", "forest", "dry", "sea")
GROUND_ODDS = (0.34, 0.22, 0.16, 0.16, 0.12)


@dataclass(frozen=True)
class Environment:
    """Everything about light and land, as plain numbers (recorded in the ground truth)."""

    sky: str  # one of SKIES
    sun_azimuth_deg: float  # compass, 0 = north
    sun_elevation_deg: float
    sun_strength: float  # direct light, 0 (overcast) .. 1
    backlit: bool  # the sun was placed behind the turbine, towards the camera's view
    visibility_m: float  # haze: distance at which 63 % of the colour is haze
    cloud_cover: float  # 0 clear .. 1 overcast
    ground: str  # one of GROUNDS
    sea_distance_m: float | None  # coast this far beyond the turbine (None: no sea)
    sea_bearing_deg: float  # compass direction from the turbine towards the sea
    hills: int  # distant ridge layers
    turbine_albedo: tuple[float, float, float]  # BGR in [0, 1]
    tip_bands: bool  # red warning bands at the blade tips
    logo: bool  # a coloured stripe on the nacelle sides
    extras: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class Scene:
    view: str
    view_offset_deg: float  # horizontal angle between the rotor axis and hub->camera
    camera_elevation_deg: float  # elevation of the camera seen from the hub
    fill: float  # rotor diameter / frame height at the hub's distance (> 1: cropped)
    roll_deg: float
    turbine: Turbine
    camera: Camera
    others: tuple[Turbine, ...]
    env: Environment
    # The wider views (wtcli.synth.views) only: blades lying on the ground, each a one-blade
    # Turbine of which only the blade is drawn, and what the view aimed at.
    spares: tuple[Turbine, ...] = ()
    detail: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"view": self.view, "view_offset_deg": self.view_offset_deg,
                "camera_elevation_deg": self.camera_elevation_deg, "fill": self.fill,
                "roll_deg": self.roll_deg}


def _choice(rng: np.random.Generator, items: tuple, odds: tuple) -> Any:
    return items[int(rng.choice(len(items), p=np.asarray(odds) / np.sum(odds)))]


def sample_turbine(rng: np.random.Generator, tid: str = "T1", base=(0.0, 0.0, 0.0),
                   like: Turbine | None = None, rotor_azimuth: float | None = None) -> Turbine:
    """A random three-blade turbine; ``like`` makes a sibling of the same farm (similar size,
    similar yaw), as turbines of one farm usually are. ``rotor_azimuth`` (blade 1's, deg)
    replaces the drawn one (the draw still happens: the rest of the scene stays the same)."""
    if like is None:
        D = float(rng.uniform(60.0, 170.0))
        R = D / 2
        hub = max(R + float(rng.uniform(12.0, 40.0)), D * float(rng.uniform(0.7, 1.05)))
        yaw = float(rng.uniform(0, 360))
        scale = {k: float(rng.uniform(0.8, 1.25)) for k in
                 ("tower", "nl", "nw", "nh", "hub", "chord", "tip")}
    else:
        D = like.rotor_diameter * float(rng.uniform(0.9, 1.1))
        R = D / 2
        hub = max(R + 8.0, like.hub_height * D / like.rotor_diameter)
        yaw = like.yaw_deg + float(rng.normal(0, 6))
        scale = {k: 1.0 for k in ("tower", "nl", "nw", "nh", "hub", "chord", "tip")}
    parked = rng.random() < 0.8
    pitch = float(rng.uniform(78, 92)) if parked else float(rng.uniform(0, 25))
    azimuth = float(rng.uniform(0, 360))
    return Turbine.with_rotor_azimuth(
        azimuth if rotor_azimuth is None else float(rotor_azimuth), blades=3, id=tid, base=tuple(base), hub_height=hub,
        rotor_diameter=D, yaw_deg=yaw % 360, blade_pitch_deg=pitch,
        tower_base_radius=max(1.0, 0.026 * hub) * scale["tower"],
        nacelle_length=0.25 * R * scale["nl"], nacelle_width=0.09 * R * scale["nw"],
        nacelle_height=0.09 * R * scale["nh"], hub_radius=0.05 * R * scale["hub"],
        blade_root_chord=0.055 * R * scale["chord"], blade_max_chord=0.075 * R * scale["chord"],
        blade_tip_chord=0.015 * R * scale["tip"],
        # The blade sections the renders were drawn with (the trained models learnt them),
        # thinner than the planner's conservative defaults.
        blade_max_chord_thickness_ratio=0.40, blade_tip_thickness_ratio=0.18)


def _view_offset(rng: np.random.Generator, view: str) -> float:
    sign = 1.0 if rng.random() < 0.5 else -1.0
    if view == "front":
        return float(rng.uniform(-15, 15))
    if view == "oblique":
        return sign * float(rng.uniform(20, 70))
    if view == "side":
        return sign * float(rng.uniform(72, 105))
    return 180.0 + float(rng.uniform(-35, 35))


def _sample_fill(rng: np.random.Generator) -> float:
    u = rng.random()
    if u < 0.18:
        return float(rng.uniform(0.15, 0.35))  # small, whole turbine and surroundings
    if u < 0.72:
        return float(rng.uniform(0.35, 0.95))  # the rotor well inside the frame
    return float(rng.uniform(0.95, 3.0))  # close: blades cut by the frame


def sample_scene(rng: np.random.Generator, width: int, height: int, view: str | None,
                 rotor_azimuth: float | None = None,
                 view_mix: dict[str, float] | None = None) -> Scene:
    """A scene of ``view``; None draws the view from VIEW_ODDS, or from ``view_mix`` (shares
    per view, whole-rotor or wider: ``wtcli.synth.render.parse_view_mix``) when given. The
    wider views come from ``wtcli.synth.views.sample_wide_scene``."""
    if view is None and view_mix is not None:
        names = sorted(view_mix)
        view = _choice(rng, tuple(names), tuple(view_mix[n] for n in names))
    if view is not None and view not in VIEWS:
        if view not in WIDE_SAMPLERS:
            raise ValueError(f"expected view in {VIEWS + tuple(WIDE_SAMPLERS)}, got {view!r}")
        return WIDE_SAMPLERS[view](rng, width, height, view, rotor_azimuth=rotor_azimuth)
    if view is None:
        view = _choice(rng, tuple(VIEW_ODDS), tuple(VIEW_ODDS.values()))
    turbine = sample_turbine(rng, rotor_azimuth=rotor_azimuth)
    hfov = float(rng.uniform(55.0, 84.0))
    focal = SENSOR_WIDTH_MM / (2 * math.tan(math.radians(hfov) / 2))
    cam0 = Camera(width, height, focal, SENSOR_WIDTH_MM)

    offset = _view_offset(rng, view)
    fill = _sample_fill(rng)
    # Distance from the hub at which the rotor spans `fill` of the frame height.
    dist = turbine.rotor_diameter * cam0.fx / (fill * height)
    hub = turbine.hub_center
    # Camera height: drones fly from a little below to well above the hub; never too low.
    # Mostly at or above the hub looking slightly down (the ground behind the turbine), as
    # inspection flights do; sometimes from well below.
    u = rng.random()
    elev = float(rng.uniform(-10.0, 25.0)) if u < 0.75 else (
        float(rng.uniform(-25.0, -10.0)) if u < 0.9 else float(rng.uniform(25.0, 45.0)))
    heading = math.radians(turbine.yaw_deg + offset)
    horiz = np.array([math.sin(heading), math.cos(heading), 0.0])
    pos = hub + dist * (math.cos(math.radians(elev)) * horiz
                        + np.array([0, 0, math.sin(math.radians(elev))]))
    if pos[2] < 3.0:
        pos[2] = 3.0 + float(rng.uniform(0, 10))
        elev = math.degrees(math.atan2(pos[2] - hub[2], dist))
    # Keep a safe distance from the structure (a real drone would).
    for _ in range(20):
        if turbine.clearance(pos[None])[0] > 4.0:
            break
        pos = hub + (pos - hub) * 1.15

    # Aim: the hub, shifted so it is not always centred; often lower, to show the tower.
    fw, fh = cam0.footprint_m(dist)
    roll = float(rng.normal(0, 4.0)) if rng.random() < 0.75 else float(rng.uniform(-15, 15))
    look0 = Camera.looking_at(cam0, pos, hub)
    spread = 0.32 if fill < 1.0 else 0.22
    dx = float(rng.uniform(-spread, spread)) * fw
    dy = float(rng.uniform(-spread, spread * 0.7)) * fh
    target = hub + dx * look0.right - dy * look0.down
    if rng.random() < 0.4:  # look down more: tower and ground below the rotor in the frame
        target = target - np.array([0, 0, 1.0]) * float(rng.uniform(0.1, 0.45)) * fh
    camera = cam0.looking_at(pos, target, roll_deg=roll)

    others = _sample_others(rng, turbine, camera)
    env = _sample_environment(rng, turbine, camera)
    return Scene(view=view, view_offset_deg=offset, camera_elevation_deg=elev, fill=fill,
                 roll_deg=roll, turbine=turbine, camera=camera, others=tuple(others), env=env)


def _sample_others(rng: np.random.Generator, main: Turbine, camera: Camera,
                   n: int | None = None) -> list[Turbine]:
    if n is None:
        n = int(rng.choice([0, 1, 2, 3, 4, 5], p=[0.3, 0.2, 0.2, 0.15, 0.1, 0.05]))
    out: list[Turbine] = []
    d_main = float(np.linalg.norm(main.base_xyz[:2] - camera.position[:2]))
    fwd = camera.forward[:2].copy()
    if np.linalg.norm(fwd) < 1e-6:
        fwd = np.array([0.0, 1.0])
    base_heading = math.atan2(fwd[0], fwd[1])
    half = math.radians(camera.hfov_deg) / 2
    tries = 0
    while len(out) < n and tries < 40:
        tries += 1
        ang = base_heading + float(rng.uniform(-1.15, 1.15)) * half
        d = d_main + main.rotor_diameter * float(rng.uniform(1.2, 3.0)) + float(rng.uniform(0, 1800))
        xy = camera.position[:2] + d * np.array([math.sin(ang), math.cos(ang)])
        bases = [main] + out
        if any(np.linalg.norm(xy - t.base_xyz[:2]) < 1.3 * max(t.rotor_diameter, main.rotor_diameter)
               for t in bases):
            continue
        out.append(sample_turbine(rng, f"B{len(out) + 1}", (xy[0], xy[1], 0.0), like=main))
    return out


def _sample_environment(rng: np.random.Generator, turbine: Turbine, camera: Camera) -> Environment:
    sky = _choice(rng, SKIES, SKY_ODDS)
    cam_heading = math.degrees(math.atan2(camera.forward[0], camera.forward[1]))
    backlit = sky in ("clear", "hazy", "sunset") and rng.random() < 0.3
    if backlit:
        sun_az = cam_heading + float(rng.uniform(-35, 35))
        sun_el = float(rng.uniform(8, 35))
    else:
        sun_az = float(rng.uniform(0, 360))
        sun_el = float(rng.uniform(15, 70))
    if sky == "sunset":
        sun_el = float(rng.uniform(2, 14))
    strength = {"clear": rng.uniform(0.8, 1.0), "hazy": rng.uniform(0.5, 0.8),
                "overcast": rng.uniform(0.0, 0.2), "sunset": rng.uniform(0.5, 0.85)}[sky]
    vis = {"clear": rng.uniform(6000, 25000), "hazy": rng.uniform(1500, 5000),
           "overcast": rng.uniform(2500, 10000), "sunset": rng.uniform(3000, 12000)}[sky]
    cover = {"clear": rng.uniform(0.0, 0.35), "hazy": rng.uniform(0.0, 0.3),
             "overcast": rng.uniform(0.75, 1.0), "sunset": rng.uniform(0.1, 0.6)}[sky]
    ground = _choice(rng, GROUNDS, GROUND_ODDS)
    sea_d = None
    if ground == "sea" or rng.random() < 0.5:
        sea_d = float(rng.uniform(-400, 200)) if ground == "sea" else float(rng.uniform(300, 4000))
    # The sea lies mostly beyond the turbine as the camera sees it.
    sea_bearing = cam_heading + float(rng.uniform(-70, 70))
    if ground == "sea":
        ground = _choice(rng, ("scrub", "dry", "fields"), (0.4, 0.4, 0.2))
    tone = float(rng.uniform(0.80, 0.97))
    tint = rng.normal(0, 0.015, 3)
    albedo = tuple(float(np.clip(tone + t, 0.6, 1.0)) for t in tint)
    return Environment(
        sky=sky, sun_azimuth_deg=float(sun_az % 360), sun_elevation_deg=float(sun_el),
        sun_strength=float(strength), backlit=bool(backlit), visibility_m=float(vis),
        cloud_cover=float(cover), ground=ground, sea_distance_m=sea_d,
        sea_bearing_deg=float(sea_bearing % 360), hills=int(rng.choice([0, 1, 2], p=[0.15, 0.35, 0.5])),
        turbine_albedo=albedo, tip_bands=bool(rng.random() < 0.12), logo=bool(rng.random() < 0.5))
