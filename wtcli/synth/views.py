"""The wider views of a real inspection folder, beyond whole-rotor photos: blade close-ups,
nadir and steep-down views, close hub views from above, frames cutting the nacelle, hub or a
blade end, side-on broad blades, the lower blade in front of the tower, and distant turbines
among other structures.

Each view places the camera with the one turbine and camera model (``wtcli.geometry``) and
records what it aimed at in ``Scene.detail``; everything else (environment, other turbines) is
drawn as for the whole-rotor views, then the light is made harder more often (backlight, haze,
glare: ``_harden_light``). Opt-in: ``render_sample(view="closeup")`` or a view mix; the four
whole-rotor views and their renders do not change.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from wtcli.geometry import Camera, Turbine
from wtcli.synth.scene import (SENSOR_WIDTH_MM, VIEW_ODDS, WIDE_SAMPLERS, Environment, Scene,
                               _choice, _sample_environment, _sample_others, _view_offset,
                               sample_turbine)

WIDE_VIEWS = ("closeup", "nadir", "hub", "cut", "broadside", "overtower", "distant")
Z = np.array([0.0, 0.0, 1.0])
MIN_CLEARANCE_M = 3.0  # the camera never closer to the structure (a drone would not be)


def _lens(rng: np.random.Generator, width: int, height: int) -> Camera:
    return _camera_of_hfov(width, height, float(rng.uniform(55.0, 84.0)))


def _camera_of_hfov(width: int, height: int, hfov_deg: float) -> Camera:
    focal = SENSOR_WIDTH_MM / (2 * math.tan(math.radians(hfov_deg) / 2))
    return Camera(width, height, focal, SENSOR_WIDTH_MM)


def _horizontal(heading_deg: float) -> np.ndarray:
    h = math.radians(heading_deg)
    return np.array([math.sin(h), math.cos(h), 0.0])


def _keep_clear(turbine: Turbine, pos: np.ndarray, away_from: np.ndarray) -> np.ndarray:
    """Move the camera away from ``away_from`` until the structure is MIN_CLEARANCE_M off."""
    for _ in range(40):
        if turbine.clearance(pos[None])[0] > MIN_CLEARANCE_M and pos[2] > 2.0:
            return pos
        step = pos - away_from
        if np.linalg.norm(step) < 1e-6:
            step = Z.copy()
        pos = away_from + step * 1.15
        pos[2] = max(pos[2], 2.0)
    return pos


def _aim_at_pixel(cam0: Camera, pos: np.ndarray, point: np.ndarray, u: float, v: float,
                  roll: float) -> Camera:
    """A camera at ``pos``, rolled by ``roll``, turned so that ``point`` appears at pixel
    (u, v): the aim moves by the pixel error times the distance over the focal length, a few
    times over (within a pixel or two even at the frame's edges)."""
    dist = float(np.linalg.norm(point - pos))
    target = np.asarray(point, float)
    cam = cam0.looking_at(pos, target, roll_deg=roll)
    for _ in range(6):
        uv, _ = cam.project(point[None])
        du, dv = uv[0, 0] - u, uv[0, 1] - v
        if abs(du) + abs(dv) < 0.5:
            break
        target = target + (du * cam.right + dv * cam.down) * dist / cam0.fx
        cam = cam0.looking_at(pos, target, roll_deg=roll)
    return cam


def _angles(turbine: Turbine, pos: np.ndarray) -> tuple[float, float]:
    """(view offset, elevation) of a camera position seen from the hub, as the whole-rotor
    views record them: horizontal angle between the rotor axis and hub->camera, and the
    camera's elevation above the hub."""
    rel = pos - turbine.hub_center
    heading = math.degrees(math.atan2(rel[0], rel[1]))
    offset = (heading - turbine.yaw_deg + 180.0) % 360.0 - 180.0
    elev = math.degrees(math.atan2(rel[2], max(float(np.linalg.norm(rel[:2])), 1e-9)))
    return offset, elev


def _harden_light(rng: np.random.Generator, env: Environment, camera: Camera) -> Environment:
    """Backlight, haze and glare, more often than in the whole-rotor views (real folders hold
    many photos against the sun and through haze): backlit 35 % of sunny skies, haze 25 %,
    glare (a veil of scattered light over the frame, strongest towards the sun) 30 %."""
    cam_heading = math.degrees(math.atan2(camera.forward[0], camera.forward[1]))
    kw: dict[str, Any] = {}
    extras = dict(env.extras)
    if env.sky != "overcast" and rng.random() < 0.35:
        kw.update(backlit=True, sun_azimuth_deg=float((cam_heading + rng.uniform(-30, 30)) % 360),
                  sun_elevation_deg=float(rng.uniform(4, 30)),
                  sun_strength=float(max(env.sun_strength, rng.uniform(0.75, 1.0))))
    if rng.random() < 0.25:
        kw["visibility_m"] = float(rng.uniform(500, 2500))
        extras["haze"] = True
    if rng.random() < 0.3:
        extras["glare"] = float(rng.uniform(0.12, 0.45))
    return replace(env, extras=extras, **kw)


def sample_wide_scene(rng: np.random.Generator, width: int, height: int, view: str,
                      rotor_azimuth: float | None = None) -> Scene:
    """A scene of one of WIDE_VIEWS; ``rotor_azimuth`` (blade 1's, deg) replaces the drawn one,
    as in ``sample_scene``."""
    if view not in WIDE_VIEWS:
        raise ValueError(f"expected view in {WIDE_VIEWS}, got {view!r}")
    make = {"closeup": _closeup, "nadir": _nadir, "hub": _hub, "cut": _cut,
            "broadside": _broadside, "overtower": _overtower, "distant": _distant}[view]
    turbine, camera, spares, others_n, detail, env_edit = make(rng, width, height, rotor_azimuth)
    offset, elev = _angles(turbine, camera.position)
    dist = float(np.linalg.norm(turbine.hub_center - camera.position))
    fill = turbine.rotor_diameter * camera.fx / (max(dist, 1e-6) * height)
    others = _sample_others(rng, turbine, camera, n=others_n)
    env = _sample_environment(rng, turbine, camera)
    if env_edit:
        env = env_edit(rng, env, camera)
    env = _harden_light(rng, env, camera)
    return Scene(view=view, view_offset_deg=offset, camera_elevation_deg=elev, fill=fill,
                 roll_deg=float(detail.pop("roll_deg")), turbine=turbine, camera=camera,
                 others=tuple(others), env=env, spares=tuple(spares), detail=detail)


WIDE_SAMPLERS.update(dict.fromkeys(WIDE_VIEWS, sample_wide_scene))  # scene.sample_scene asks here

# ---- the views ------------------------------------------------------------------------------
def _closeup(rng, width, height, rotor_azimuth):
    """One blade filling the frame (tip, mid-span or root), seen from the front or the rear
    against the ground (from above), the sea (from above, a coast behind the turbine) or the
    sky (from below): half of them with the chord across a quarter to most of the frame (what
    an inspection takes, hundreds per turbine), half wider, with more of the blade's length."""
    t = sample_turbine(rng, rotor_azimuth=rotor_azimuth)
    cam0 = _lens(rng, width, height)
    k = int(rng.integers(t.n_blades))
    region = _choice(rng, ("tip", "mid", "root"), (0.45, 0.35, 0.2))
    # Half are the inspection photo proper: the chord across a quarter to most of the frame
    # (a tip's rounded end in it), taken with a longer lens (a zoom or a long prime).
    filling = rng.random() < 0.5
    f = {"tip": (0.94, 1.0) if filling else (0.78, 0.96), "mid": (0.4, 0.75),
         "root": (0.1, 0.35)}[region]
    f = float(rng.uniform(*f))
    d = t.blade_direction(k)
    r0 = t.blade_root_offset
    point = t.hub_center + (r0 + f * (t.tip_radius - r0)) * d
    backdrop = _choice(rng, ("ground", "sea", "sky"), (0.5, 0.2, 0.3))
    if filling:
        # 4-12 m off (a drone keeps its distance; the lens, 8-60 deg wide, frames the chord)
        chord = 2.0 * float(t.blade_semi_axes(np.array([f]))[0][0])
        frame_m = chord * float(rng.uniform(1.3, 4.0))
        want = float(rng.uniform(4.0, 12.0))
        hfov = float(np.clip(2 * math.degrees(math.atan(frame_m / (2 * want))), 8.0, 60.0))
        cam0 = _camera_of_hfov(width, height, hfov)
    else:
        # Frame width at the blade: 15-55 % of the blade's length (the chord fills a good part).
        frame_m = float(rng.uniform(0.15, 0.55)) * t.tip_radius
    dist = frame_m * cam0.focal_mm / cam0.sensor_width_mm
    side = 0.0 if rng.random() < 0.65 else 180.0
    heading = t.yaw_deg + side + float(rng.uniform(-55, 55))
    elev = float(rng.uniform(-45, -10)) if backdrop == "sky" else float(rng.uniform(18, 65))
    pos = point + dist * (math.cos(math.radians(elev)) * _horizontal(heading)
                          + math.sin(math.radians(elev)) * Z)
    if pos[2] < 4.0:  # too low to look up at it: look down at it instead
        backdrop, elev = "ground", float(rng.uniform(18, 50))
        pos = point + dist * (math.cos(math.radians(elev)) * _horizontal(heading)
                              + math.sin(math.radians(elev)) * Z)
    pos = _keep_clear(t, pos, point)
    roll = float(rng.uniform(-25, 25))
    # The region near the centre, shifted a little along the blade and across it.
    u = cam0.cx + float(rng.uniform(-0.2, 0.2)) * width
    v = cam0.cy + float(rng.uniform(-0.2, 0.2)) * height
    camera = _aim_at_pixel(cam0, pos, point, u, v, roll)
    detail = {"roll_deg": roll, "blade": k, "region": region, "span_fraction": f,
              "backdrop": backdrop}

    def env_edit(rng, env, camera):
        if backdrop != "sea":
            return env
        # The turbine at a coast: the sea starts just behind it as the camera looks.
        heading = math.degrees(math.atan2(camera.forward[0], camera.forward[1]))
        return replace(env, sea_distance_m=float(rng.uniform(-700, -150)),
                       sea_bearing_deg=float((heading + rng.uniform(-30, 30)) % 360))

    return t, camera, [], None, detail, env_edit


def spare_blades(rng: np.random.Generator, turbine: Turbine, count: int) -> list[Turbine]:
    """Blades lying flat on the ground near the tower foot (a blade exchange, a delivery): each
    a one-blade Turbine of the main one's size whose blade is horizontal, feathered (chord
    flat), its underside resting on the ground; only the blade is drawn and labelled."""
    out: list[Turbine] = []
    R = turbine.tip_radius
    for i in range(count):
        for _ in range(20):
            dist = float(rng.uniform(20.0, R + 60.0))
            ang = float(rng.uniform(0, 2 * math.pi))
            xy = turbine.base_xyz[:2] + dist * np.array([math.cos(ang), math.sin(ang)])
            if all(np.linalg.norm(xy - s.hub_center[:2]) > 0.25 * R for s in out):
                break
        yaw = float(rng.uniform(0, 360))
        probe = Turbine.with_rotor_azimuth(0.0, blades=1, id=f"S{i + 1}", base=(0.0, 0.0, 0.0),
                                           hub_height=R + 2.0, rotor_diameter=2 * R, yaw_deg=yaw,
                                           blade_pitch_deg=float(rng.uniform(85, 95)),
                                           blade_root_chord=turbine.blade_root_chord,
                                           blade_max_chord=turbine.blade_max_chord,
                                           blade_tip_chord=turbine.blade_tip_chord,
                                           hub_radius=turbine.hub_radius,
                                           nacelle_length=turbine.nacelle_length)
        # Lift so the root's round underside rests on the ground, centre the blade on xy.
        lift = turbine.blade_root_chord / 2 + 0.1
        hub_xy = xy - 0.5 * R * probe.blade_direction(0)[:2]
        base = (hub_xy[0] - probe.axis[0] * probe.overhang, hub_xy[1] - probe.axis[1] * probe.overhang,
                lift - probe.hub_height)
        out.append(replace(probe, base=base))
    return out


def _nadir(rng, width, height, rotor_azimuth):
    """Looking steeply down (50-88 deg) from above the hub: the nacelle and blades from above,
    the tower foreshortened to a short stub or a line, the pad, tracks and sometimes spare
    blades lying on the ground."""
    t = sample_turbine(rng, rotor_azimuth=rotor_azimuth)
    cam0 = _lens(rng, width, height)
    R = t.tip_radius
    lam = float(rng.uniform(0.0, 1.0))
    target = t.base_xyz * (1 - lam) + t.hub_center * lam
    target = target + np.array([*rng.uniform(-0.6, 0.6, 2) * R, 0.0])
    target[2] = max(target[2], 0.0)
    pitch = float(rng.uniform(50, 88))
    heading = float(rng.uniform(0, 360))
    z_cam = t.hub_center[2] + float(rng.uniform(0.3, 1.6)) * R + 10.0
    dist = (z_cam - target[2]) / math.sin(math.radians(pitch))
    view_dir = math.cos(math.radians(pitch)) * _horizontal(heading) - math.sin(math.radians(pitch)) * Z
    pos = _keep_clear(t, target - dist * view_dir, target)
    roll = float(rng.uniform(-10, 10))
    camera = cam0.looking_at(pos, target, roll_deg=roll)
    n_spare = int(rng.choice([0, 1, 2, 3], p=[0.3, 0.35, 0.2, 0.15]))
    detail = {"roll_deg": roll, "camera_pitch_deg": -pitch, "spare_blades": n_spare}
    return t, camera, spare_blades(rng, t, n_spare), None, detail, None


def _hub(rng, width, height, rotor_azimuth):
    """Close in front of the hub and slightly above it, one blade pointing down past the
    tower: the lower blade's root half fills the lower frame, the other two are cut."""
    if rotor_azimuth is None:
        rotor_azimuth = 270.0 + float(rng.uniform(-35, 35))
    t = sample_turbine(rng, rotor_azimuth=rotor_azimuth)
    cam0 = _lens(rng, width, height)
    fill = float(rng.uniform(1.8, 5.0))
    dist = t.rotor_diameter * cam0.fx / (fill * height)
    heading = t.yaw_deg + float(rng.uniform(-30, 30))
    elev = float(rng.uniform(6, 35))
    hub = t.hub_center
    pos = hub + dist * (math.cos(math.radians(elev)) * _horizontal(heading)
                        + math.sin(math.radians(elev)) * Z)
    pos = _keep_clear(t, pos, hub)
    roll = float(rng.normal(0, 5))
    u = cam0.cx + float(rng.uniform(-0.3, 0.3)) * width
    v = float(rng.uniform(0.12, 0.5)) * height  # hub in the upper half: the lower blade below
    camera = _aim_at_pixel(cam0, pos, hub, u, v, roll)
    return t, camera, [], None, {"roll_deg": roll}, None


def _cut(rng, width, height, rotor_azimuth):
    """A close frame whose edge cuts the nacelle, the hub or a blade's end (tip or root)."""
    t = sample_turbine(rng, rotor_azimuth=rotor_azimuth)
    cam0 = _lens(rng, width, height)
    view = _choice(rng, tuple(VIEW_ODDS), tuple(VIEW_ODDS.values()))
    heading = t.yaw_deg + _view_offset(rng, view)
    fill = float(rng.uniform(1.2, 4.0))
    dist = t.rotor_diameter * cam0.fx / (fill * height)
    elev = float(rng.uniform(-12, 30))
    hub = t.hub_center
    pos = hub + dist * (math.cos(math.radians(elev)) * _horizontal(heading)
                        + math.sin(math.radians(elev)) * Z)
    pos = _keep_clear(t, pos, hub)
    part = _choice(rng, ("nacelle", "hub", "blade"), (0.4, 0.3, 0.3))
    edge = int(rng.integers(4))  # left, right, top, bottom
    along = float(rng.uniform(0.15, 0.85))
    inset = float(rng.uniform(-0.005, 0.03))  # its centre on the edge or just inside
    if part == "nacelle":
        point = t.nacelle_center
    elif part == "hub":
        point = hub
    else:
        # A blade cut across by the edge it points to, its hub end inside the frame.
        k = int(rng.integers(t.n_blades))
        point = hub + float(rng.uniform(0.35, 0.85)) * t.tip_radius * t.blade_direction(k)
        phi = math.radians(cam0.looking_at(pos, hub).image_angle_deg(hub, point))
        c, s = math.cos(phi), math.sin(phi)
        edge = (1 if c > 0 else 0) if abs(c) >= abs(s) else (2 if s > 0 else 3)
        inset = float(rng.uniform(0.0, 0.03))
    u, v = [(inset * width, along * height), ((1 - inset) * width, along * height),
            (along * width, inset * height), (along * width, (1 - inset) * height)][edge]
    roll = float(rng.normal(0, 6))
    camera = _aim_at_pixel(cam0, pos, point, u, v, roll)
    detail = {"roll_deg": roll, "cut": part, "edge": ("left", "right", "top", "bottom")[edge],
              "from": view}
    return t, camera, [], None, detail, None


def _broadside(rng, width, height, rotor_azimuth):
    """From the side of a feathered rotor, one blade pointing roughly towards the camera: its
    chord faces the camera, broad and foreshortened, and the light is flat and pale."""
    cam0 = _lens(rng, width, height)
    side = 1.0 if rng.random() < 0.5 else -1.0
    offset = side * float(rng.uniform(55, 100))
    # Blade 1 towards the camera's side of the rotor plane (azimuth 0 is the front viewer's
    # right; a camera at a positive offset stands on the front viewer's left).
    toward = 180.0 if offset > 0 else 0.0
    az = toward + float(rng.uniform(-35, 35)) if rotor_azimuth is None else rotor_azimuth
    t = sample_turbine(rng, rotor_azimuth=az)
    t = replace(t, blade_pitch_deg=float(rng.uniform(78, 98)))
    fill = float(rng.uniform(0.7, 2.2))
    dist = t.rotor_diameter * cam0.fx / (fill * height)
    elev = float(rng.uniform(-15, 15))
    hub = t.hub_center
    pos = hub + dist * (math.cos(math.radians(elev)) * _horizontal(t.yaw_deg + offset)
                        + math.sin(math.radians(elev)) * Z)
    pos = _keep_clear(t, pos, hub)
    mid = hub + 0.5 * t.tip_radius * t.blade_direction(0)
    roll = float(rng.normal(0, 5))
    u = cam0.cx + float(rng.uniform(-0.2, 0.2)) * width
    v = cam0.cy + float(rng.uniform(-0.2, 0.2)) * height
    camera = _aim_at_pixel(cam0, pos, mid, u, v, roll)

    def env_edit(rng, env, camera):
        sky = _choice(rng, ("overcast", "hazy", "clear"), (0.5, 0.3, 0.2))
        tone = float(rng.uniform(0.92, 1.0))
        return replace(env, sky=sky, sun_strength=float(rng.uniform(0.0, 0.35)),
                       cloud_cover=float(rng.uniform(0.6, 1.0)) if sky == "overcast" else env.cloud_cover,
                       visibility_m=float(rng.uniform(1200, 6000)),
                       turbine_albedo=(tone, tone, tone), backlit=False)

    return t, camera, [], None, {"roll_deg": roll, "blade": 0}, env_edit


def _overtower(rng, width, height, rotor_azimuth):
    """A blade pointing straight down (+-10 deg) over the tower, seen from the front (the blade
    in front of the tower) or from behind (the tower in front of the blade)."""
    if rotor_azimuth is None:
        rotor_azimuth = 270.0 + float(rng.uniform(-10, 10))
    t = sample_turbine(rng, rotor_azimuth=rotor_azimuth)
    cam0 = _lens(rng, width, height)
    front = rng.random() < 0.7
    heading = t.yaw_deg + (float(rng.uniform(-20, 20)) if front else 180.0 + float(rng.uniform(-25, 25)))
    fill = float(rng.uniform(0.5, 2.0))
    dist = t.rotor_diameter * cam0.fx / (fill * height)
    elev = float(rng.uniform(-15, 20))
    hub = t.hub_center
    pos = hub + dist * (math.cos(math.radians(elev)) * _horizontal(heading)
                        + math.sin(math.radians(elev)) * Z)
    pos = _keep_clear(t, pos, hub)
    low = hub - Z * float(rng.uniform(0.1, 0.6)) * t.tip_radius
    roll = float(rng.normal(0, 4))
    u = cam0.cx + float(rng.uniform(-0.15, 0.15)) * width
    v = cam0.cy + float(rng.uniform(-0.15, 0.15)) * height
    camera = _aim_at_pixel(cam0, pos, low, u, v, roll)
    return t, camera, [], None, {"roll_deg": roll, "blade_in_front": bool(front)}, None


def _distant(rng, width, height, rotor_azimuth):
    """A small, distant turbine (and usually others) seen from a low drone, with poles,
    pylons, chimneys, roads and buildings around (the distractors are drawn by the renderer)."""
    t = sample_turbine(rng, rotor_azimuth=rotor_azimuth)
    cam0 = _lens(rng, width, height)
    view = _choice(rng, tuple(VIEW_ODDS), tuple(VIEW_ODDS.values()))
    heading = t.yaw_deg + _view_offset(rng, view)
    fill = float(rng.uniform(0.06, 0.3))
    dist = t.rotor_diameter * cam0.fx / (fill * height)
    hub = t.hub_center
    z_cam = 6.0 + 100.0 * float(rng.random()) ** 2  # mostly low: structures nearby stand in the view
    horiz = math.sqrt(max(dist * dist - (hub[2] - z_cam) ** 2, 1.0))
    pos = hub + horiz * _horizontal(heading) + np.array([0, 0, z_cam - hub[2]])
    roll = float(rng.normal(0, 3))
    u = cam0.cx + float(rng.uniform(-0.35, 0.35)) * width
    v = cam0.cy + float(rng.uniform(-0.3, 0.2)) * height
    camera = _aim_at_pixel(cam0, pos, t.base_xyz * 0.4 + hub * 0.6, u, v, roll)
    n_others = int(rng.integers(1, 7))
    return t, camera, [], n_others, {"roll_deg": roll, "from": view}, None
