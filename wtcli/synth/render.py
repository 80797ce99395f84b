"""Render synthetic drone photos of wind turbines with their instance masks and ground truth.

``render_sample(seed)`` draws a scene (``wtcli.synth.scene``), paints the background from the
camera's rays (``wtcli.synth.background``), projects the turbines' meshes through the one camera
model with ``wtcli.geometry.projection`` at twice the resolution (so edges and thin distant blades are
antialiased), shades every face, composites, and applies camera effects (``wtcli.synth.post``).
Masks come from the very face map the colours come from, so occlusion always agrees.

Image arrays are BGR uint8 [H, W, 3]; masks bool [N, H, W]. Angles follow DESIGN.md: image
angles counter-clockwise with y up, 0 = right; θ in [0, 180), φ hub -> tip in [0, 360).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

import cv2
import numpy as np

from wtcli.geometry import Camera, Mesh, Turbine
from wtcli.geometry.projection import ProjectedMesh, paint, project_mesh
from wtcli.errors import OutputError, WtError
from wtcli.jsonio import atomic_write_bytes, document, read_json, write_failed, write_json
from wtcli.masks import CATEGORIES, INSTANCES_SCHEMA, INSTANCES_VERSION, Instances
from wtcli.pitch.angles import classify_theta
from wtcli.synth import clutter
from wtcli.synth.background import render_background, sky_colours, sun_direction
from wtcli.synth.noise import fbm
from wtcli.synth.post import apply_blur, camera_effects
from wtcli.synth.scene import VIEWS, Scene, sample_scene
from wtcli.synth.views import WIDE_VIEWS, sample_wide_scene

TRUTH_SCHEMA = "wtinspect.synth_truth"
TRUTH_VERSION = 1
SUPERSAMPLE = 2
# Label conventions. "outline" (the default): every pixel a part visibly tints, as people
# annotate photos -- the part's coverage, blurred as the camera blurred the photo, reaches 5 %.
# Measured: the real photos' blade masks end on pixels carrying 3 % of the blade's contrast
# (median of 38 photos); "half" labels (a part covering at least half of the pixel, before
# the blur; what models trained before 2026-12-02 learnt) ended on 61 %.
LABELS = {"outline": 0.05, "half": 0.5}
_LOGO_COLOURS = ((0.55, 0.25, 0.05), (0.2, 0.45, 0.1), (0.15, 0.15, 0.6), (0.3, 0.3, 0.3))
# Every view render_sample takes: the whole-rotor views (the default mix, VIEW_ODDS) and the
# wider, opt-in ones (wtcli.synth.views). A view's index seeds its scenes, so new views go last.
ALL_VIEWS = VIEWS + WIDE_VIEWS
ROUND_TIP_CHORDS = 1.0  # a wider view's blade tips: rounded over one tip chord of span
VIEW_MIX_STREAM = 7_000_003  # the stream a view mix draws each image's view from
WAVES_STREAM = 7_000_004  # the wider views' waves on the sea (a stream of their own)


def min_instance_pixels(width: int, height: int) -> int:
    """Smallest visible part that is labelled (smaller bits of distant turbines stay unlabelled
    background, as they would be lost in any real annotation too)."""
    return max(6, int(round(3e-5 * width * height)))


@dataclass(frozen=True)
class SynthSample:
    image: np.ndarray  # (H, W, 3) uint8 BGR
    instances: Instances  # main turbine first (blades by index, tower, nacelle), then others
    truth: dict[str, Any]  # JSON-ready ground truth (see docs/synth.md)

    def __post_init__(self) -> None:
        if self.image.ndim != 3 or self.image.shape[2] != 3 or self.image.dtype != np.uint8:
            raise ValueError(f"expected a BGR uint8 image (H, W, 3), got {self.image.shape} "
                             f"{self.image.dtype}")
        if self.instances.image_size != self.image.shape[:2]:
            raise ValueError(f"expected masks of size {self.image.shape[:2]}, got "
                             f"{self.instances.image_size}")


def _check_args(seed: int, width: int, height: int, view: str | None) -> None:
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"expected a seed >= 0, got {seed!r}")
    if not (32 <= width <= 8192 and 32 <= height <= 8192):
        raise ValueError(f"expected width and height in 32..8192, got {width}x{height}")
    if view is not None and view not in ALL_VIEWS:
        raise ValueError(f"expected view in {ALL_VIEWS} or None, got {view!r}")


def parse_view_mix(text: str | dict[str, float] | None) -> dict[str, float] | None:
    """A view mix as shares per view, normalised to sum to 1, from a mapping or a text:
    ``"front,closeup,nadir"`` (equal shares) or ``"front=0.5,closeup=0.3,nadir=0.2"`` (any
    weights in [0, 1e6], at least one positive). ``"mixed"`` stands for the default mix
    (VIEW_ODDS). None -> None; ValueError naming the view for anything else."""
    from wtcli.synth.scene import VIEW_ODDS

    if text is None:
        return None
    if isinstance(text, dict):
        items = [(str(k), v) for k, v in text.items()]
    else:
        items = []
        for part in str(text).split(","):
            part = part.strip()
            if not part:
                continue
            name, eq, w = part.partition("=")
            name = name.strip()
            if not eq:
                items.append((name, 1.0))
                continue
            try:
                items.append((name, float(w)))
            except ValueError:
                raise ValueError(f"expected a number after {name}=, got {w.strip()!r}") from None
    if not items:
        raise ValueError("expected at least one view in the view mix, got none")
    mix: dict[str, float] = {}
    for name, w in items:
        if name != "mixed" and name not in ALL_VIEWS:
            raise ValueError(f"expected views from {', '.join(ALL_VIEWS + ('mixed',))}, got {name!r}")
        # bool is an int; a share above 1e6 is a typo, and a sum of huge ones overflows to inf
        if isinstance(w, bool) or not (isinstance(w, (int, float)) and math.isfinite(w)
                                       and 0 <= w <= 1e6):
            raise ValueError(f"expected a share in [0, 1e6] for {name}, got {w!r}")
        if name == "mixed":
            for v, odds in VIEW_ODDS.items():
                mix[v] = mix.get(v, 0.0) + float(w) * odds
            continue
        mix[name] = mix.get(name, 0.0) + float(w)
    total = sum(mix.values())
    if total <= 0:
        raise ValueError("expected a view mix with a positive share, got all zero")
    return {k: v / total for k, v in mix.items() if v > 0}


def draw_view(seed: int, width: int, height: int, view_mix: dict[str, float]) -> str:
    """The view a view mix gives image ``seed`` (a stream of its own, so the image is then the
    very render of that view: ``render_sample(seed, view=draw_view(...))``)."""
    names = sorted(view_mix)
    p = np.array([view_mix[n] for n in names], float)
    vrng = np.random.default_rng([int(seed), width, height, VIEW_MIX_STREAM])
    return names[int(vrng.choice(len(names), p=p / p.sum()))]


def render_sample(seed: int, width: int = 640, height: int = 480,
                  view: str | None = None, stops: float = 0.0,
                  labels: str = "outline", view_mix: str | dict[str, float] | None = None) -> SynthSample:
    """One synthetic photo; a pure function of (seed, width, height, view, stops, labels,
    view_mix).

    ``view``: "front", "oblique", "side", "rear", or None to draw one (VIEW_ODDS); or one of
    the wider views (WIDE_VIEWS: "closeup", "nadir", "hub", "cut", "broadside", "overtower",
    "distant"; docs/synth.md).
    ``view_mix``: with ``view`` None, draw the view from these shares instead of VIEW_ODDS
    (``parse_view_mix``: a mapping or text such as "front=0.5,closeup=0.5"); the image is then
    the render of the drawn view. None (the default) leaves every render as it was.
    ``stops``: the chance that the rotor stands where crews stop it for an inspection, a "Y"
    or an inverted "Y" (a blade straight up or down, +-10 deg; training's emphasis on the blade
    in front of the tower); decided on a stream of its own, so with 0 (the held-out sets) or
    when not drawn the photo is the same as without.
    ``labels``: the label convention, "outline" or "half" (LABELS); the photo does not depend
    on it."""
    _check_args(seed, width, height, view)
    if labels not in LABELS:
        raise ValueError(f"expected labels in {tuple(LABELS)}, got {labels!r}")
    if not 0.0 <= stops <= 1.0:
        raise ValueError(f"expected stops in [0, 1], got {stops!r}")
    mix = parse_view_mix(view_mix)
    if mix is not None:
        if view is not None:
            raise ValueError(f"expected a view or a view mix, got both ({view!r} and {view_mix!r})")
        view = draw_view(seed, width, height, mix)
    azimuth = None
    if stops > 0:
        srng = np.random.default_rng([int(seed), width, height, 7_000_001])
        if srng.random() < stops:
            azimuth = float(srng.choice([90.0, 270.0]) + srng.uniform(-10.0, 10.0))
    rng = np.random.default_rng([int(seed), width, height, (ALL_VIEWS.index(view) + 1) if view else 0])
    wide = view in WIDE_VIEWS
    if wide:
        scene = sample_wide_scene(rng, width, height, view, rotor_azimuth=azimuth)
    else:
        scene = sample_scene(rng, width, height, view, rotor_azimuth=azimuth)
    cam = scene.camera
    zenith, horizon = sky_colours(scene.env, rng)
    waves = np.random.default_rng([int(seed), width, height, WAVES_STREAM]) if wide else None
    bg = render_background(cam, scene.env, scene.turbine, rng, zenith, horizon, waves=waves)
    if wide:
        bg = clutter.paint_tracks(bg, scene, rng, horizon)
    bg = _shadows(bg, scene)
    bg = _distractors(bg, scene, rng)
    bg = _buildings(bg, scene, rng, horizon)
    structures: list[clutter.Structure] = []
    if wide:
        near, _ = clutter.turbine_distances((scene.turbine,) + scene.others + scene.spares, cam)
        _, far = clutter.turbine_distances((scene.turbine,) + scene.spares, cam)
        structures = clutter.sample_structures(rng, scene, (near, far))
        bg = clutter.paint_background_structures(
            bg, cam, [s for s in structures if not s.foreground], scene.env, horizon, rng)

    turbines = (scene.turbine,) + scene.others + scene.spares
    colour, (parts, boxes) = _render_turbines(turbines, scene, rng, zenith, horizon,
                                              blade_only=len(scene.spares))
    premult, alpha = colour
    img = premult + bg * (1.0 - alpha[..., None])
    front = [s for s in structures if s.foreground]
    if front:
        img, parts = clutter.paint_foreground_structures(img, parts, cam, front, scene.env,
                                                         horizon, rng, SUPERSAMPLE)
    img = _lens_flare(img.astype(np.float32), scene, rng)
    if wide:
        img = clutter.glare(img, scene)
    image, effects = camera_effects(img, rng)

    blur = effects.get("blur") if labels == "outline" else None
    instances, owners = _instances(parts, boxes, turbines, width, height, blur, LABELS[labels])
    truth = {**_truth(seed, scene, instances, owners, effects, along_blade=wide), "labels": labels}
    if wide:
        truth.update(_wide_truth(scene, structures))
    if mix is not None:
        truth["view_mix"] = mix
    return SynthSample(image=image, instances=instances, truth=truth)


def _wide_truth(scene: Scene, structures) -> dict[str, Any]:
    """What only the wider views record: what the view aimed at, the spare blades on the
    ground (labelled blades of turbines ``S1``...) and the distractors (never labelled), with
    their members so their pixels can be drawn again."""
    return {"view_detail": scene.detail,
            "spare_blades": [s.to_dict() for s in scene.spares],
            "distractors": [s.to_dict() for s in structures],
            "distractor_members": [{"members": np.round(s.members, 4).tolist(),
                                    "radius": np.round(s.radius, 4).tolist(),
                                    "foreground": s.foreground} for s in structures]}


# ---- turbines -------------------------------------------------------------------------------
def _mesh_detail(turbine: Turbine, camera: Camera) -> tuple[int, int]:
    dist = float(np.linalg.norm(turbine.hub_center - camera.position))
    px = turbine.rotor_diameter * camera.fx / max(dist, 1.0)
    if px > 500:
        return 20, 40
    if px > 150:
        return 14, 28
    return 8, 14


def _render_turbines(turbines, scene: Scene, rng, zenith, horizon, blade_only: int = 0):
    """Paint every turbine's faces at SUPERSAMPLE x resolution; return (premultiplied colour,
    coverage) at the output resolution and the supersampled global part map. Of the last
    ``blade_only`` turbines (spare blades on the ground) only the blades are drawn."""
    cam = scene.camera
    ss = SUPERSAMPLE
    W, H = cam.width_px, cam.height_px
    cam2 = Camera(W * ss, H * ss, cam.focal_mm, cam.sensor_width_mm, cam.position, cam.R)
    env = scene.env

    verts, faces, gparts, owner, local = [], [], [], [], []
    off_v, off_p = 0, 0
    # The wider views (close-ups above all) draw a blade's rounded end; the whole-rotor views
    # keep the flat tip section their renders and the held-out benchmark were made with.
    round_tip = ROUND_TIP_CHORDS if scene.view in WIDE_VIEWS else 0.0
    for j, t in enumerate(turbines):
        m = t.mesh(*_mesh_detail(t, cam), round_tip=round_tip)
        if j >= len(turbines) - blade_only:
            keep = m.face_part < t.n_blades
            m = Mesh(m.vertices, m.faces[keep], m.face_part[keep])
        verts.append(m.vertices)
        faces.append(m.faces + off_v)
        gparts.append(m.face_part.astype(np.int32) + off_p)
        owner.append(np.full(len(m.faces), j, np.int32))
        local.append(m.face_part.astype(np.int32))
        off_v += len(m.vertices)
        off_p += t.n_blades + 2
    mesh = Mesh(np.concatenate(verts), np.concatenate(faces), np.concatenate(gparts))
    face_owner = np.concatenate(owner)
    face_local = np.concatenate(local)

    proj = project_mesh(mesh, cam2)
    fi = proj.face_index
    tri = mesh.vertices[mesh.faces[fi]]
    centroid = tri.mean(axis=1)
    normal = mesh.face_normals()[fi]
    to_cam = cam.position - centroid
    to_cam /= np.linalg.norm(to_cam, axis=1, keepdims=True)
    facing = np.sum(normal * to_cam, axis=1)
    n_bl = np.array([t.n_blades for t in turbines])[face_owner[fi]]
    is_blade_or_tower = face_local[fi] <= n_bl  # blades 0..N-1 and tower N: outward-wound tubes
    # Back faces of the closed tubes are hidden anyway; skip them, and faces off the canvas.
    u, v = proj.uv[..., 0], proj.uv[..., 1]
    onscreen = (u.max(1) >= -2) & (u.min(1) <= W * ss + 2) & (v.max(1) >= -2) & (v.min(1) <= H * ss + 2)
    keep = onscreen & ~(is_blade_or_tower & (facing < -0.02))
    proj = ProjectedMesh(proj.uv[keep], proj.depth[keep], fi[keep], proj.face_part[keep])
    fi, centroid, normal, facing = fi[keep], centroid[keep], normal[keep], facing[keep]
    to_cam = to_cam[keep]
    normal = np.where(facing[:, None] < 0, -normal, normal)

    albedo, light = _shade(turbines, face_owner[fi], face_local[fi], centroid, normal, env, rng,
                           zenith, horizon, mesh.vertices[mesh.faces[fi]])
    # Smooth (Gouraud) shading: light the vertices with normals averaged over the visible faces
    # around them, interpolate across each face; paint colour (albedo) stays per face.
    V = mesh.vertices
    vidx = mesh.faces[fi]
    vn = np.zeros_like(V)
    np.add.at(vn, vidx.ravel(), np.repeat(normal, 3, axis=0))
    vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-9)
    used = np.unique(vidx)
    vtc = cam.position - V[used]
    vtc /= np.linalg.norm(vtc, axis=1, keepdims=True)
    lv = np.zeros((len(V), 4), np.float32)
    lv[used] = light(vn[used], vtc)
    fog = (1.0 - np.exp(-proj.depth / env.visibility_m)).astype(np.float32)

    ids = np.full((H * ss, W * ss), -1, np.int32)
    paint(ids, proj, np.arange(len(fi)))
    inside = ids >= 0
    colour2 = np.zeros((H * ss, W * ss, 3), np.float32)
    ys, xs = np.nonzero(inside)
    f = ids[ys, xs]
    # Barycentric coordinates of each pixel centre in its face (clamped for edge pixels).
    a = proj.uv[:, 0]
    e0, e1 = proj.uv[:, 1] - a, proj.uv[:, 2] - a
    d00, d01, d11 = (e0 * e0).sum(1), (e0 * e1).sum(1), (e1 * e1).sum(1)
    den = d00 * d11 - d01 * d01
    inv = np.where(np.abs(den) > 1e-9, 1.0 / np.where(den == 0, 1.0, den), 0.0)
    px = xs - a[f, 0]
    py = ys - a[f, 1]
    d20 = px * e0[f, 0] + py * e0[f, 1]
    d21 = px * e1[f, 0] + py * e1[f, 1]
    b1 = np.clip((d11[f] * d20 - d01[f] * d21) * inv[f], 0, 1).astype(np.float32)
    b2 = np.clip((d00[f] * d21 - d01[f] * d20) * inv[f], 0, 1).astype(np.float32)
    over = b1 + b2 > 1
    b1[over], b2[over] = b1[over] / (b1 + b2)[over], b2[over] / (b1 + b2)[over]
    flat = inv[f] == 0
    b1[flat], b2[flat] = 1 / 3, 1 / 3
    b0 = 1 - b1 - b2
    vv = vidx[f]
    lp = b0[:, None] * lv[vv[:, 0]] + b1[:, None] * lv[vv[:, 1]] + b2[:, None] * lv[vv[:, 2]]
    sun_col = _sun_colour(env)
    col = albedo[f] * lp[:, :3] + lp[:, 3:4] * sun_col
    fo = fog[f][:, None]
    colour2[ys, xs] = col * (1 - fo) + horizon * fo
    # Paint-like surface variation (dirt, erosion, uneven paint) in screen space, subtle.
    var = fbm(rng, H * ss // 4 + 1, W * ss // 4 + 1, 24, octaves=3)
    var = cv2.resize(var, (W * ss, H * ss), interpolation=cv2.INTER_LINEAR)
    colour2 *= (0.94 + 0.12 * var)[..., None]
    premult = cv2.resize(colour2, (W, H), interpolation=cv2.INTER_AREA)
    alpha = cv2.resize(inside.astype(np.float32), (W, H), interpolation=cv2.INTER_AREA)
    part2 = np.full((H * ss, W * ss), -1, np.int32)
    part2[inside] = proj.face_part[ids[inside]]
    # Each part's box on the supersampled canvas, from its faces' corners (masks are cut there).
    n_parts = int(mesh.face_part.max()) + 1
    lo = np.full((n_parts, 2), np.inf)
    hi = np.full((n_parts, 2), -np.inf)
    np.minimum.at(lo, proj.face_part, proj.uv.min(axis=1))
    np.maximum.at(hi, proj.face_part, proj.uv.max(axis=1))
    boxes = np.concatenate([np.floor(lo) - 2, np.ceil(hi) + 2], axis=1)
    return (premult, alpha), (part2, boxes)


def _sun_colour(env) -> np.ndarray:
    return np.array([0.97, 0.99, 1.0], np.float32) if env.sky != "sunset" else \
        np.array([0.6, 0.8, 1.0], np.float32)


def _shade(turbines, owner, local, centroid, normal, env, rng, zenith, horizon, corners):
    """Paint colour per face (white paint, tip bands, nacelle stripe) and a lighting function
    (normals, unit vectors to the camera) -> (M, 4): RGB light and specular strength.
    ``corners`` (M, 3, 3): each face's vertices."""
    F = len(owner)
    L = sun_direction(env)
    s = env.sun_strength
    albedo = np.tile(np.asarray(env.turbine_albedo, np.float32), (F, 1))
    # Tower a touch different from blades sometimes; nacelle a touch brighter.
    n_bl = np.array([t.n_blades for t in turbines])[owner]
    albedo[local == n_bl] *= float(rng.uniform(0.95, 1.03))
    albedo[local == n_bl + 1] *= float(rng.uniform(0.97, 1.05))
    albedo = np.clip(albedo, 0, 1)
    if env.tip_bands or env.logo:
        for j, t in enumerate(turbines):
            sel = owner == j
            if env.tip_bands:
                band = float(rng.uniform(0.06, 0.14))
                red = np.array([0.18, 0.2, 0.75], np.float32)
                for k in range(t.n_blades):
                    b = sel & (local == k)
                    # A band edge runs along a ring of the blade's mesh, as a painted edge runs
                    # straight across the blade: both triangles of a quad between two rings
                    # take their colour from the quad's middle span (by centroid, the two halves
                    # differ by a third of a ring's spacing and a close-up showed the edge as a
                    # sawtooth).
                    vs = (corners[b] - t.hub_center) @ t.blade_direction(k) / t.tip_radius
                    sp = 0.5 * (vs.min(axis=1) + vs.max(axis=1))
                    stripe = ((sp > 1 - band) & (sp < 1 - band * 0.66)) | (sp > 1 - band * 0.33)
                    idx = np.nonzero(b)[0][stripe]
                    albedo[idx] = red
            if env.logo:
                b = sel & (local == t.n_blades + 1)
                side = np.cross(np.array([0, 0, 1.0]), t.axis)
                rel = centroid[b] - t.nacelle_center
                zr = rel[:, 2] / t.nacelle_height
                ar = rel @ t.axis / t.nacelle_length
                on_side = np.abs(normal[b] @ side) > 0.9
                stripe = on_side & (zr > 0.0) & (zr < 0.25) & (ar > -0.3) & (ar < 0.45)
                colour = _LOGO_COLOURS[int(rng.integers(len(_LOGO_COLOURS)))]
                albedo[np.nonzero(b)[0][stripe]] = colour
    # Ambient: the sky dome above, light bounced off the ground below. Under overcast skies the
    # dome is the only light and photos expose for it, so white paint still reads near white.
    sky_amb = (0.6 * horizon + 0.4 * zenith) * (0.62 + 0.55 * (1 - s)) * float(rng.uniform(0.9, 1.15))
    ground_amb = np.array([0.36, 0.44, 0.48], np.float32) * (0.5 + 0.3 * s)
    sun_col = _sun_colour(env)
    kd = float(rng.uniform(0.7, 0.95))
    ks = float(rng.uniform(0.05, 0.3))
    shininess = float(rng.uniform(12, 60))

    def light(n: np.ndarray, to_cam: np.ndarray) -> np.ndarray:
        nz = n[:, 2:3]
        amb = sky_amb * (0.5 + 0.5 * nz) + ground_amb * (0.5 - 0.5 * nz)
        diffuse = np.clip(n @ L, 0, None)[:, None] * s * sun_col * kd
        h = L[None, :] + to_cam
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        spec = ks * s * np.clip(np.sum(n * h, 1), 0, 1) ** shininess
        return np.concatenate([amb + diffuse, spec[:, None]], axis=1).astype(np.float32)

    return albedo.astype(np.float32), light


def _instances(part2: np.ndarray, boxes: np.ndarray, turbines, width: int, height: int,
               blur: dict[str, Any] | None = None, level: float = 0.5):
    """Labelled masks at the output resolution: a pixel belongs to the part that covers most of
    it (its supersampled coverage, blurred as the camera blurred the photo), if that part covers
    at least ``level`` of it."""
    ss = SUPERSAMPLE
    # How far the camera's blur carries a part's coverage beyond its box, in output pixels.
    spread = 0 if not blur else int(math.ceil(4 * blur["sigma_px"])) if blur["kind"] == "defocus" \
        else int(blur["length_px"])
    minpix = min_instance_pixels(width, height)
    counts = np.bincount(part2.ravel() + 1)
    cand, info = [], []
    gid = 0
    for j, t in enumerate(turbines):
        n = t.n_blades
        for p in range(n + 2):
            g = gid + p
            if g + 1 < len(counts) and counts[g + 1] >= minpix * ss * ss * 0.5:
                cand.append(g)
                info.append(("blade" if p < n else ("tower" if p == n else "nacelle"),
                             {"turbine": j, "turbine_id": t.id, "blade": p if p < n else None}))
        gid += n + 2
    if not cand:
        return Instances.empty(height, width), []
    best = np.zeros((height, width), np.float32)
    best_i = np.full((height, width), -1, np.int32)
    for i, g in enumerate(cand):
        # Work inside the part's box, on whole output pixels (ss x ss blocks).
        x0, y0, x1, y1 = boxes[g]
        x0 = int(np.clip(np.floor(x0 / ss) - spread, 0, width))
        y0 = int(np.clip(np.floor(y0 / ss) - spread, 0, height))
        x1 = int(np.clip(np.ceil(x1 / ss) + spread, 0, width))
        y1 = int(np.clip(np.ceil(y1 / ss) + spread, 0, height))
        if x1 <= x0 or y1 <= y0:
            continue
        block = part2[y0 * ss:y1 * ss, x0 * ss:x1 * ss] == g
        c = block.reshape(y1 - y0, ss, x1 - x0, ss).mean(axis=(1, 3), dtype=np.float32)
        c = apply_blur(c, blur)
        b, bi = best[y0:y1, x0:x1], best_i[y0:y1, x0:x1]
        win = c > b  # ties keep the earlier part
        b[win] = c[win]
        bi[win] = i
    best_i[best < level] = -1
    labels, masks, owners = [], [], []
    for i, (label, owner) in enumerate(info):
        m = best_i == i
        if int(m.sum()) >= minpix:
            labels.append(label)
            masks.append(m)
            owners.append(owner)
    if not labels:
        return Instances.empty(height, width), []
    return Instances(np.array(labels, dtype=object), np.stack(masks)), owners


def blade_image_angle(turbine: Turbine, camera: Camera, k: int, near: float = 0.5) -> float:
    """Blade k's image angle φ (hub -> tip, DESIGN.md), from the projection of its axis.
    With the hub and the tip in front of the camera this is ``image_angle_deg(hub, tip)``;
    when one of them lies behind it (close-ups), the direction of the axis's projection at
    its nearest point in front, towards the tip (a straight line projects to a straight line,
    so it is the same direction wherever both ends are visible)."""
    hub = turbine.hub_center
    d = turbine.blade_direction(k)
    tip = hub + turbine.tip_radius * d
    zh, zt = ((np.array([hub, tip]) - camera.position) @ camera.forward)
    if zh > near and zt > near:
        return camera.image_angle_deg(hub, tip)
    dz = float(d @ camera.forward)
    # The stretch of the axis in front of the camera: s with zh + s * dz > near, s in [0, R].
    s0 = 0.0 if zh > near else (near - zh) / dz if dz > 0 else np.inf
    if not s0 <= turbine.tip_radius:
        s0 = turbine.tip_radius  # wholly behind: any direction is as good; keep it defined
    a = hub + (s0 + 1e-3) * d
    return camera.image_angle_deg(a, a + 0.01 * d)


def _truth(seed, scene: Scene, instances: Instances, owners, effects,
           along_blade: bool = False) -> dict[str, Any]:
    t, cam = scene.turbine, scene.camera
    W, H = cam.width_px, cam.height_px
    hub = t.hub_center
    tips = t.blade_tips()
    uv, z = cam.project(np.vstack([hub, tips]))
    visible_px = {o["blade"]: int(instances.masks[i].sum()) for i, o in enumerate(owners)
                  if o["turbine"] == 0 and o["blade"] is not None}
    blades = []
    for k in range(t.n_blades):
        phi = blade_image_angle(t, cam, k) if along_blade else cam.image_angle_deg(hub, tips[k])
        theta = phi % 180.0
        tip_uv = uv[k + 1]
        blades.append({
            "index": k, "theta_deg": theta, "phi_deg": phi, "class": classify_theta(theta),
            "rotor_azimuth_deg": t.azimuths_deg[k], "visible": k in visible_px,
            "pixels": visible_px.get(k, 0),
            "tip_px": tip_uv.tolist(),
            "tip_in_frame": bool(z[k + 1] > 0 and 0 <= tip_uv[0] <= W - 1 and 0 <= tip_uv[1] <= H - 1),
        })
    hub_in = bool(z[0] > 0 and 0 <= uv[0, 0] <= W - 1 and 0 <= uv[0, 1] <= H - 1)
    return {
        "seed": int(seed), "width": W, "height": H,
        "view": scene.view, "view_offset_deg": scene.view_offset_deg,
        "camera_elevation_deg": scene.camera_elevation_deg, "roll_deg": scene.roll_deg,
        "fill": scene.fill,
        "camera": cam.to_dict(), "turbine": t.to_dict(),
        "hub_px": uv[0].tolist(), "hub_in_frame": hub_in,
        "blades": blades,
        "blades_visible": sum(b["visible"] for b in blades),
        "blades_whole_in_frame": sum(b["tip_in_frame"] for b in blades) if hub_in else 0,
        "other_turbines": [o.to_dict() for o in scene.others],
        "instances": owners,
        "environment": scene.env.to_dict(),
        "camera_effects": effects,
    }


def _shadows(bg: np.ndarray, scene: Scene) -> np.ndarray:
    """The turbines' shadows on the flat ground in direct sun: blade-shaped dark streaks that
    are not blades. Each face of a coarse mesh is cast along the sun onto z = 0 and projected
    through the scene camera."""
    env, cam = scene.env, scene.camera
    L = sun_direction(env)
    if env.sun_strength < 0.3 or L[2] < 0.1:
        return bg
    H, W = bg.shape[:2]
    shadow = np.zeros((H, W), np.float32)
    meshes = [t.mesh(6, 12) for t in (scene.turbine,) + scene.others]
    meshes += [clutter.blade_mesh(t) for t in scene.spares]
    for m in meshes:
        ground = m.vertices - L[None, :] * (m.vertices[:, 2:3] / L[2])
        uv, z = cam.project(ground)
        tri = uv[m.faces]
        ok = (z[m.faces] > 0.5).all(axis=1)
        u, v = tri[..., 0], tri[..., 1]
        ok &= (u.max(1) >= 0) & (u.min(1) < W) & (v.max(1) >= 0) & (v.min(1) < H)
        ok &= np.abs(tri).max(axis=(1, 2)) < 1e6
        for pts in np.round(tri[ok] * 16).astype(np.int32):
            cv2.fillConvexPoly(shadow, pts, 1.0, cv2.LINE_AA, 4)
    if not shadow.any():
        return bg
    k = 0.55 * env.sun_strength * (1.0 - 0.5 * math.exp(-L[2] * 3))
    return bg * (1.0 - k * np.clip(shadow, 0, 1))[..., None]


def _lens_flare(img: np.ndarray, scene: Scene, rng) -> np.ndarray:
    """Ghosts of the sun along the line through the image centre, when the sun is in or near
    the frame (backlit drone photos show them)."""
    env, cam = scene.env, scene.camera
    if env.sun_strength < 0.4 or rng.random() > 0.6:
        return img
    uv, z = cam.project(cam.position[None] + 1e5 * sun_direction(env)[None])
    H, W = img.shape[:2]
    if z[0] <= 0:
        return img
    sx, sy = uv[0]
    if not (-0.3 * W < sx < 1.3 * W and -0.3 * H < sy < 1.3 * H):
        return img
    f = max(1, W // 320)
    small = np.zeros((H // f + 1, W // f + 1, 3), np.float32)
    c = np.array([W / 2, H / 2])
    sun = np.array([sx, sy])
    tint = np.array([0.9, 0.8, 0.6], np.float32) + rng.normal(0, 0.08, 3).astype(np.float32)
    for _ in range(int(rng.integers(3, 7))):
        t = float(rng.uniform(0.3, 2.0))
        p = (sun + (c - sun) * t) / f
        r = float(rng.uniform(0.01, 0.06)) * W / f
        col = tuple(float(x) for x in np.clip(tint * rng.uniform(0.04, 0.12), 0, 1))
        cv2.circle(small, (int(p[0]), int(p[1])), max(1, int(r)), col, -1, cv2.LINE_AA)
    small = cv2.GaussianBlur(small, (0, 0), max(1.0, 1.5 / f))
    return img + env.sun_strength * cv2.resize(small, (W, H), interpolation=cv2.INTER_LINEAR)


def _buildings(bg: np.ndarray, scene: Scene, rng, horizon: np.ndarray) -> np.ndarray:
    """A few white, grey or beige boxes (substations, farm houses) on the ground beyond the
    turbine: bright blocky shapes that are not nacelles. Always farther from the camera than
    the turbine's foot, so painting them under the turbines keeps occlusion right."""
    if rng.random() > 0.45:
        return bg
    cam, t, env = scene.camera, scene.turbine, scene.env
    out = bg.copy()
    L = sun_direction(env)
    d_t = float(np.linalg.norm(t.base_xyz[:2] - cam.position[:2]))
    boxes = []
    for _ in range(int(rng.integers(1, 7))):
        if rng.random() < 0.5:  # near the turbine's foot (substation, storage)
            c = t.base_xyz[:2] + rng.uniform(-250, 250, 2)
        else:  # farther off, in view
            fwd = cam.forward[:2] / max(float(np.linalg.norm(cam.forward[:2])), 1e-6)
            ang = math.atan2(fwd[0], fwd[1]) + float(rng.uniform(-0.7, 0.7))
            c = cam.position[:2] + (d_t + float(rng.uniform(50, 1500))) * np.array(
                [math.sin(ang), math.cos(ang)])
        if float(np.linalg.norm(c - cam.position[:2])) < d_t + 25 or \
                float(np.linalg.norm(c - t.base_xyz[:2])) < t.tower_base_radius + 12:
            continue
        size = np.array([rng.uniform(5, 22), rng.uniform(5, 30), rng.uniform(3, 8)])
        yaw = float(rng.uniform(0, math.pi))
        tone = np.clip(np.array([0.85, 0.86, 0.88]) * float(rng.uniform(0.7, 1.05))
                       + rng.normal(0, 0.04, 3), 0, 1)
        if rng.random() < 0.3:
            tone = tone * np.array([0.75, 0.88, 0.95])  # beige
        boxes.append((float(np.linalg.norm(c - cam.position[:2])), c, size, yaw, tone))
    for dist, c, size, yaw, tone in sorted(boxes, key=lambda b: -b[0]):
        ax = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        ay = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
        az = np.array([0.0, 0.0, 1.0])
        centre = np.array([c[0], c[1], size[2] / 2])
        faces = []
        for axis, half, others in ((ax, size[0] / 2, (ay * size[1] / 2, az * size[2] / 2)),
                                   (ay, size[1] / 2, (ax * size[0] / 2, az * size[2] / 2)),
                                   (az, size[2] / 2, (ax * size[0] / 2, ay * size[1] / 2))):
            for sign in (1.0, -1.0):
                n = sign * axis
                fc = centre + n * half
                if n @ (cam.position - fc) <= 0 or (n[2] < 0):
                    continue
                u, v = others
                quad = np.array([fc - u - v, fc + u - v, fc + u + v, fc - u + v])
                uv, z = cam.project(quad)
                if (z <= 1).any():
                    continue
                shade = 0.45 + 0.3 * (0.5 + 0.5 * n[2]) + 0.5 * env.sun_strength * max(float(n @ L), 0)
                col = tone * shade
                fog = 1.0 - math.exp(-dist / env.visibility_m)
                col = col * (1 - fog) + horizon * fog
                faces.append((uv, col))
        for uv, col in faces:
            cv2.fillConvexPoly(out, np.round(uv * 16).astype(np.int32),
                               tuple(float(x) for x in col), cv2.LINE_AA, 4)
    return out


def _distractors(bg: np.ndarray, scene: Scene, rng) -> np.ndarray:
    """Power pylons (lattice towers with lines) on the ground: thin structures that are not
    turbines, projected through the scene camera."""
    if rng.random() > 0.3:
        return bg
    cam = scene.camera
    t = scene.turbine
    out = bg.copy()
    H, W = bg.shape[:2]
    d0 = float(np.linalg.norm(t.base_xyz[:2] - cam.position[:2]))
    fwd = cam.forward[:2] / max(np.linalg.norm(cam.forward[:2]), 1e-6)
    heading = math.atan2(fwd[0], fwd[1])
    line_dir = float(rng.uniform(0, 2 * math.pi))
    start = cam.position[:2] + (d0 + float(rng.uniform(100, 1500))) * np.array(
        [math.sin(heading + rng.uniform(-0.6, 0.6)), math.cos(heading + rng.uniform(-0.6, 0.6))])
    colour = tuple(float(x) for x in np.clip(np.array([0.35, 0.36, 0.37]) + rng.normal(0, 0.05), 0, 1))
    h = float(rng.uniform(25, 45))
    tops = []
    for i in range(int(rng.integers(2, 6))):
        p = start + i * float(rng.uniform(250, 400)) * np.array([math.sin(line_dir), math.cos(line_dir)])
        base = np.array([p[0], p[1], 0.0])
        w = h * 0.12
        corners = [base + np.array([sx * w, sy * w, 0]) for sx in (-1, 1) for sy in (-1, 1)]
        apex = base + np.array([0, 0, h])
        arm = [base + np.array([-h * 0.3, 0, h * 0.8]), base + np.array([h * 0.3, 0, h * 0.8])]
        segs = [(c, apex) for c in corners] + [(arm[0], arm[1])]
        segs += [(corners[0], corners[3] * 0.5 + apex * 0.5), (corners[1], corners[2] * 0.5 + apex * 0.5)]
        for a, b in segs:
            uv, z = cam.project(np.array([a, b]))
            if (z > 1).all():
                cv2.line(out, tuple(int(x) for x in uv[0]), tuple(int(x) for x in uv[1]), colour, 1,
                         cv2.LINE_AA)
        tops.append(arm)
    for a, b in zip(tops[:-1], tops[1:]):
        for side in (0, 1):
            uv, z = cam.project(np.array([a[side], b[side]]))
            if (z > 1).all():
                cv2.line(out, tuple(int(x) for x in uv[0]), tuple(int(x) for x in uv[1]), colour, 1,
                         cv2.LINE_AA)
    return out


# ---- datasets -------------------------------------------------------------------------------
def sample_seed(seed: int, index: int) -> int:
    """The render_sample seed of image ``index`` in a dataset made with ``seed``."""
    return int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1, np.uint32)[0])


# What a dataset folder of render_dataset holds: images/NNNNN.jpg, the two index files, and the
# ".NAME.k2x9q0ab" temporaries a kill between write and rename leaves (jsonio.atomic_write_bytes).
_IMAGE_NAME = re.compile(r"^(\d{5,})\.jpg$")
_INDEX_NAMES = ("instances.json", "ground_truth.json")
_TEMP_OF = re.compile(r"^\.(.+)\.[a-z0-9_]{8}$")


def _is_ours(name: str, names: Iterable[str] | re.Pattern) -> bool:
    temp = _TEMP_OF.match(name)
    name = temp.group(1) if temp else name
    return bool(names.match(name)) if isinstance(names, re.Pattern) else name in names


def _foreign(out: Path) -> str | None:
    """The first entry of ``out`` that render_dataset did not write (None if all are its own):
    a dataset is replaced, never a folder of someone's photos or labels."""
    for p in sorted(out.iterdir()):
        if p.name == "images" and p.is_dir() and not p.is_symlink():
            for q in sorted(p.iterdir()):
                if not (q.is_file() and _is_ours(q.name, _IMAGE_NAME)):
                    return f"images/{q.name}"
        elif not (p.is_file() and _is_ours(p.name, _INDEX_NAMES)):
            return p.name
    index = out / "instances.json"
    if index.is_file():
        try:
            head = read_json(index)
        except WtError:
            return "instances.json"
        if not (isinstance(head, dict) and head.get("schema") == INSTANCES_SCHEMA
                and isinstance(head.get("synth"), dict)):
            return "instances.json"
    return None


def _clear_previous(out: Path) -> None:
    """Make ``out`` ready for a dataset: missing or empty, or holding one render_dataset wrote
    (whose index files go first, so a run stopped half-way leaves no index over the old images).
    OutputError (exit 3) for a folder holding anything else."""
    if not out.exists():
        return
    if not out.is_dir():
        raise OutputError(f"{out}: exists and is not a folder; choose another output folder")
    try:
        other = _foreign(out)
        if other is not None:
            raise OutputError(f"{out}: holds {other}, which synth did not write; a dataset "
                              "replaces only a dataset: choose an empty or new folder")
        for name in _INDEX_NAMES:
            (out / name).unlink(missing_ok=True)
    except OSError as e:
        raise write_failed(out, e) from None


def _remove_beyond(out: Path, count: int) -> None:
    """Drop the images a previous, larger dataset left past ``count`` and any temporaries, so
    the folder holds what its index lists."""
    images = out / "images"
    try:
        for p in images.iterdir():
            m = _IMAGE_NAME.match(p.name)
            if (m is None or int(m.group(1)) >= count) and p.is_file():
                p.unlink()
        for p in out.iterdir():
            if _TEMP_OF.match(p.name) and p.is_file():
                p.unlink()
    except OSError as e:
        raise write_failed(out, e) from None


def render_dataset(out_dir: str | Path, count: int, seed: int, width: int = 640,
                   height: int = 480, view: str | None = None, progress: bool = True,
                   on_image: Callable[[int], None] | None = None,
                   labels: str = "outline",
                   view_mix: str | dict[str, float] | None = None) -> dict[str, Any]:
    """Write ``count`` renders to ``out_dir``: images/NNNNN.jpg, instances.json (COCO-compatible,
    RLE masks) and ground_truth.json. Returns a summary dict. Existing files of the same names
    are replaced; each file is written atomically. ``out_dir`` must be new, empty or a dataset
    this function wrote (which is replaced: images past ``count`` removed); OutputError else. ``view_mix``: as for ``render_sample`` (its
    shares are recorded in the parameters; without it the files are as they always were)."""
    if count < 1:
        raise ValueError(f"expected count >= 1, got {count}")
    _check_args(seed, width, height, view)
    if labels not in LABELS:
        raise ValueError(f"expected labels in {tuple(LABELS)}, got {labels!r}")
    mix = parse_view_mix(view_mix)
    if mix is not None and view is not None:
        raise ValueError(f"expected a view or a view mix, got both ({view!r} and {view_mix!r})")
    out = Path(out_dir)
    _clear_previous(out)
    # Annotations are RLE-encoded image by image (a dataset's masks would not fit in memory).
    images, anns, truth = [], [], {}
    views: dict[str, int] = {}
    n_inst = 0

    def run(step: Callable[[], None]) -> None:
        for i in range(count):
            s = sample_seed(seed, i)
            smp = render_sample(s, width, height, view, labels=labels, view_mix=mix)
            name = f"images/{i:05d}.jpg"
            ok, buf = cv2.imencode(".jpg", smp.image, [cv2.IMWRITE_JPEG_QUALITY, 92])
            if not ok:
                raise RuntimeError("JPEG encoding failed")
            atomic_write_bytes(out / name, buf.tobytes())
            images.append({"id": i + 1, "file_name": name, "width": width, "height": height})
            anns.extend(smp.instances.annotations(i + 1, first_id=len(anns) + 1))
            truth[name] = smp.truth
            views[smp.truth["view"]] = views.get(smp.truth["view"], 0) + 1
            nonlocal n_inst
            n_inst += len(smp.instances)
            step()
            if on_image:
                on_image(i)

    if progress:
        from wtcli.console import count_bar

        with count_bar("rendering", count) as advance:
            run(advance)
    else:
        run(lambda: None)

    params = {"count": count, "seed": seed, "width": width, "height": height,
              "view": view or "mixed", "labels": labels}
    if mix is not None:
        params.update(view="mix", view_mix=mix)
    # The same document as wtcli.masks.instances_document builds, from the encoded annotations.
    body = {"info": {"description": "wtinspect instances"}, "licenses": [], "images": images,
            "annotations": anns, "categories": CATEGORIES, "synth": params}
    write_json(out / "instances.json", document(INSTANCES_SCHEMA, INSTANCES_VERSION, body))
    write_json(out / "ground_truth.json",
               document(TRUTH_SCHEMA, TRUTH_VERSION, {"params": params, "images": truth}))
    _remove_beyond(out, count)
    return {"out_dir": str(out), **params, "images": len(images), "instances": n_inst,
            "views": views, "files": {"instances": str(out / "instances.json"),
                                      "ground_truth": str(out / "ground_truth.json"),
                                      "images": str(out / "images")}}


__all__ = ["SynthSample", "render_sample", "render_dataset", "sample_seed",
           "TRUTH_SCHEMA", "TRUTH_VERSION", "LABELS", "ALL_VIEWS", "parse_view_mix", "draw_view",
           "blade_image_angle"]
