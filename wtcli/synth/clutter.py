"""What else a drone photo of a wind farm holds, for the wider views (``wtcli.synth.views``):
dirt tracks and roads on the ground, lattice pylons with their lines, poles, chimneys; and glare.
None of it is a turbine part, so none of it is ever labelled.

Structures are thin members (world segments with a radius) projected through the scene
camera. A structure is drawn only where its depth order against the turbines is certain: behind
every part of the main turbine and the spare blades (painted into the background, under the
turbines), or in front of every turbine part in the scene (painted over them; the pixels it
covers are taken out of the masks at the supersampled resolution the masks are made at). Colours
are BGR float32 in [0, 1].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from wtcli.geometry import Camera, Turbine
from wtcli.synth.background import sun_direction

NEAR_M = 1.0  # members are clipped to this depth in front of the camera
_SHIFT = 4


@dataclass(frozen=True)
class Structure:
    """A distractor: ``members`` (M, 2, 3) segment ends in world metres, ``radius`` (M,) m,
    one colour, and whether it stands in front of every turbine part (``foreground``)."""

    kind: str  # "pylon", "pole", "chimney", "line"
    members: np.ndarray
    radius: np.ndarray
    colour: tuple[float, float, float]
    foreground: bool

    def centre_and_size(self) -> tuple[np.ndarray, float]:
        pts = self.members.reshape(-1, 3)
        lo, hi = pts.min(0), pts.max(0)
        return (lo + hi) / 2, float(np.linalg.norm(hi - lo) / 2 + self.radius.max())

    def to_dict(self) -> dict[str, Any]:
        c, r = self.centre_and_size()
        return {"kind": self.kind, "foreground": self.foreground,
                "centre": [round(float(x), 2) for x in c], "size_m": round(2 * r, 2),
                "members": len(self.members)}


# ---- depth limits ---------------------------------------------------------------------------
def turbine_distances(turbines, camera: Camera) -> tuple[float, float]:
    """(nearest, farthest) distance from the camera to any point of these turbines, from a
    coarse mesh's vertices widened by the thickest part (vertices lie on the surface; the
    surface between them is within a root radius of them)."""
    lo, hi = math.inf, 0.0
    for t in turbines:
        m = t.mesh(6, 10)
        d = np.linalg.norm(m.vertices - camera.position, axis=1)
        pad = max(t.blade_root_chord, t.tower_base_radius, t.nacelle_length / 2) + 1.0
        lo, hi = min(lo, float(d.min()) - pad), max(hi, float(d.max()) + pad)
    return lo, hi


# ---- structures -----------------------------------------------------------------------------
def _pylon(base: np.ndarray, h: float, yaw: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """A lattice power pylon: four legs tapering to a waist, X-bracing on each face, two
    cross-arms and a peak."""
    c, s = math.cos(yaw), math.sin(yaw)
    ex, ey, ez = np.array([c, s, 0.0]), np.array([-s, c, 0.0]), np.array([0.0, 0.0, 1.0])
    w0, w1 = 0.1 * h, 0.025 * h
    levels = np.array([0.0, 0.22, 0.42, 0.6, 0.75, 0.9])
    half = w0 + (w1 - w0) * np.minimum(levels / 0.75, 1.0)
    corners = [(1, 1), (1, -1), (-1, -1), (-1, 1)]
    ring = [[base + hw * (a * ex + b * ey) + lv * h * ez for a, b in corners]
            for lv, hw in zip(levels, half)]
    segs, legs = [], []
    for i in range(len(levels) - 1):
        for k in range(4):
            segs.append((ring[i][k], ring[i + 1][k]))  # legs
            segs.append((ring[i][k], ring[i + 1][(k + 1) % 4]))  # bracing, both diagonals
            segs.append((ring[i][(k + 1) % 4], ring[i + 1][k]))
            legs += [True, False, False]
        for k in range(4):
            segs.append((ring[i + 1][k], ring[i + 1][(k + 1) % 4]))  # horizontals
            legs.append(False)
    apex = base + h * ez
    segs += [(ring[-1][k], apex) for k in range(4)]
    arm = float(rng.uniform(0.25, 0.4)) * h
    for lv in (0.75, 0.9):
        p = base + lv * h * ez
        segs.append((p - arm * ey, p + arm * ey))
        segs.append((p - arm * ey, p - 0.4 * arm * ey + 0.06 * h * ez))
        segs.append((p + arm * ey, p + 0.4 * arm * ey + 0.06 * h * ez))
    m = np.array(segs, float)
    r = np.full(len(m), max(0.08, 0.004 * h))
    r[:len(legs)][np.array(legs)] *= 2.0  # legs thicker than the bracing
    return m, r


def _pole(base: np.ndarray, h: float, yaw: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """A wooden or concrete utility pole with a cross-arm."""
    top = base + np.array([0, 0, h])
    ey = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    arm = float(rng.uniform(0.8, 1.4))
    m = np.array([(base, top), (top - 0.4 * np.array([0, 0, 1.0]) - arm * ey,
                               top - 0.4 * np.array([0, 0, 1.0]) + arm * ey)])
    return m, np.array([float(rng.uniform(0.12, 0.2)), 0.06])


def _chimney(base: np.ndarray, h: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """A factory chimney: a tall tapering column (a tower that is not a turbine's)."""
    r0 = float(rng.uniform(0.03, 0.06)) * h
    n = 6
    zs = np.linspace(0, h, n + 1)
    m = np.array([(base + [0, 0, zs[i]], base + [0, 0, zs[i + 1]]) for i in range(n)])
    r = r0 * (1.0 - 0.35 * (zs[:-1] + zs[1:]) / (2 * h))
    return m, r


def on_sea(xy: np.ndarray, env, turbine: Turbine) -> np.ndarray:
    """Whether ground points (..., 2) may lie on the sea: beyond the coast less its largest
    wiggle (background.py bends the coastline by at most 750 m either way)."""
    xy = np.asarray(xy, float)
    if env.sea_distance_m is None:
        return np.zeros(xy.shape[:-1], bool)
    b = math.radians(env.sea_bearing_deg)
    along = (xy - turbine.base_xyz[:2]) @ np.array([math.sin(b), math.cos(b)])
    return along >= env.sea_distance_m - 800.0


def sample_structures(rng: np.random.Generator, scene, limits: tuple[float, float]) -> list[Structure]:
    """Pylons (with their lines), poles and chimneys around the turbine; the distant view also
    stands some between the camera and the turbines. ``limits``: the (nearest, farthest)
    turbine distances (``turbine_distances``)."""
    cam, t = scene.camera, scene.turbine
    near, far = limits
    fwd = cam.forward[:2] / max(float(np.linalg.norm(cam.forward[:2])), 1e-6)
    heading = math.atan2(fwd[0], fwd[1])
    half = math.radians(cam.hfov_deg) / 2
    d_main = float(np.linalg.norm(t.base_xyz[:2] - cam.position[:2]))

    def grey() -> tuple[float, ...]:  # galvanised steel
        c = np.array([0.42, 0.43, 0.44]) * rng.uniform(0.7, 1.3) + rng.normal(0, 0.03, 3)
        return tuple(float(x) for x in np.clip(c, 0, 1))

    out: list[Structure] = []
    fg_odds = 0.6 if scene.view == "distant" else (0.25 if scene.view in ("overtower", "cut") else 0.0)

    to_main = t.base_xyz[:2] - cam.position[:2]
    main_bearing = math.atan2(to_main[0], to_main[1])

    def place(dist: float, fg: bool = False) -> np.ndarray:
        # Half of the structures in front stand in the line of sight to the turbine.
        if fg and rng.random() < 0.5:
            ang = main_bearing + float(rng.uniform(-0.12, 0.12)) * half
        else:
            ang = heading + float(rng.uniform(-1.1, 1.1)) * half
        xy = cam.position[:2] + dist * np.array([math.sin(ang), math.cos(ang)])
        return np.array([xy[0], xy[1], 0.0])

    def keep(s: Structure) -> bool:
        c, r = s.centre_and_size()
        if on_sea(c[:2], scene.env, t):
            return False
        d = float(np.linalg.norm(c - cam.position))
        return (d + r < near - 3.0) if s.foreground else (d - r > far + 3.0)

    # A power line: 2-5 pylons in a row, wires between the arms' ends.
    if rng.random() < 0.55:
        fg = rng.random() < fg_odds
        d0 = float(rng.uniform(25, max(30.0, 0.7 * near))) if fg else d_main + float(rng.uniform(60, 900))
        h = float(rng.uniform(22, 48))
        p = place(d0, fg)
        line_dir = float(rng.uniform(0, 2 * math.pi))
        step = np.array([math.sin(line_dir), math.cos(line_dir), 0.0]) * float(rng.uniform(180, 350))
        colour = grey()
        arms = []
        for i in range(int(rng.integers(2, 6))):
            base = p + (i - 1) * step
            m, r = _pylon(base, h, line_dir, rng)
            s = Structure("pylon", m, r, colour, bool(fg))
            if keep(s):
                out.append(s)
                arms.append((m[-6], m[-3]))  # the two arm members (lower, upper)
        wires = []
        for a, b in zip(arms[:-1], arms[1:]):
            for i in range(2):
                for end in (0, 1):
                    wires.append((a[i][end], b[i][end]))
        if wires:
            s = Structure("line", np.array(wires), np.full(len(wires), 0.02), colour, bool(fg))
            if keep(s):
                out.append(s)
    # Utility poles along a road.
    if rng.random() < 0.5:
        fg = rng.random() < fg_odds
        d0 = float(rng.uniform(12, max(15.0, 0.6 * near))) if fg else d_main + float(rng.uniform(40, 600))
        p = place(d0, fg)
        ang = float(rng.uniform(0, 2 * math.pi))
        step = np.array([math.sin(ang), math.cos(ang), 0.0]) * float(rng.uniform(35, 60))
        wood = rng.random() < 0.6
        tone = np.array([0.22, 0.30, 0.36]) if wood else np.array([0.62, 0.63, 0.63])
        colour = tuple(float(x) for x in tone * rng.uniform(0.8, 1.2))
        for i in range(int(rng.integers(2, 7))):
            m, r = _pole(p + i * step, float(rng.uniform(8, 13)), ang, rng)
            s = Structure("pole", m, r, colour, bool(fg))
            if keep(s):
                out.append(s)
    # A chimney or two (industry on the coast, a power station).
    if rng.random() < 0.25:
        fg = rng.random() < fg_odds * 0.5
        d0 = float(rng.uniform(60, max(70.0, 0.8 * near))) if fg else d_main + float(rng.uniform(200, 2500))
        for _ in range(int(rng.integers(1, 3))):
            m, r = _chimney(place(d0 + float(rng.uniform(0, 60)), fg), float(rng.uniform(35, 120)), rng)
            tone = float(rng.uniform(0.55, 0.9))
            s = Structure("chimney", m, r, (tone, tone, tone * 1.02), bool(fg))
            if keep(s):
                out.append(s)
    return out


# ---- drawing --------------------------------------------------------------------------------
def _member_quads(camera: Camera, s: Structure, scale: float = 1.0):
    """Screen quads (K, 4, 2) of a structure's members (at ``scale`` x the camera's pixels),
    their mean depth and their width in pixels."""
    a, b = s.members[:, 0], s.members[:, 1]
    za = (a - camera.position) @ camera.forward
    zb = (b - camera.position) @ camera.forward
    ok = (za > NEAR_M) | (zb > NEAR_M)
    a, b, za, zb, r = a[ok], b[ok], za[ok], zb[ok], s.radius[ok]
    # Clip the part behind the near plane.
    ta = np.clip((NEAR_M - za) / np.where(zb - za == 0, 1e-9, zb - za), 0, 1)[:, None]
    tb = np.clip((NEAR_M - zb) / np.where(za - zb == 0, 1e-9, za - zb), 0, 1)[:, None]
    a2 = np.where((za < NEAR_M)[:, None], a + ta * (b - a), a)
    b2 = np.where((zb < NEAR_M)[:, None], b + tb * (a - b), b)
    uva, da = camera.project(a2)
    uvb, db = camera.project(b2)
    uva, uvb = uva * scale, uvb * scale
    d = uvb - uva
    n = np.stack([-d[:, 1], d[:, 0]], 1) / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
    wa = (r * camera.fx * scale / np.maximum(da, NEAR_M))[:, None]
    wb = (r * camera.fx * scale / np.maximum(db, NEAR_M))[:, None]
    quads = np.stack([uva + n * wa, uvb + n * wb, uvb - n * wb, uva - n * wa], 1)
    return quads, (da + db) / 2, (wa + wb)[:, 0]


def _shaded(s: Structure, depth: np.ndarray, env, horizon, rng_shade: float) -> np.ndarray:
    col = np.asarray(s.colour, np.float32) * rng_shade * (0.55 + 0.45 * env.sun_strength
                                                         * (0.5 if env.backlit else 1.0) + 0.2)
    fog = 1.0 - np.exp(-depth / env.visibility_m)
    return col[None] * (1 - fog[:, None]) + horizon[None] * fog[:, None]


def paint_background_structures(bg: np.ndarray, camera: Camera, structures, env, horizon,
                                rng) -> np.ndarray:
    """Structures behind the turbines, painted into the background (antialiased). Members
    thinner than a pixel are drawn a pixel wide and faded by their width."""
    out = bg.copy()
    lim = 1 << 26
    for s in structures:
        quads, depth, width = _member_quads(camera, s)
        cols = _shaded(s, depth, env, horizon, float(rng.uniform(0.85, 1.1)))
        thin = None
        for q, c, w in zip(quads, cols, width):
            if not np.isfinite(q).all():
                continue
            if w >= 1.0:
                pts = np.clip(np.round(q * (1 << _SHIFT)), -lim, lim).astype(np.int32)
                cv2.fillConvexPoly(out, pts, tuple(float(x) for x in c), cv2.LINE_AA, _SHIFT)
                continue
            # Thinner than a pixel: a pixel-wide line, faded by its width (one layer per
            # structure, blended once in the structure's mean colour).
            if thin is None:
                thin = np.zeros(out.shape[:2], np.float32)
            p0 = np.clip(np.round((q[0] + q[3]) / 2 * (1 << _SHIFT)), -lim, lim).astype(int)
            p1 = np.clip(np.round((q[1] + q[2]) / 2 * (1 << _SHIFT)), -lim, lim).astype(int)
            cv2.line(thin, (int(p0[0]), int(p0[1])), (int(p1[0]), int(p1[1])), float(max(w, 0.15)),
                     1, cv2.LINE_AA, _SHIFT)
        if thin is not None:
            a = np.clip(thin, 0, 1)[..., None]
            out = out * (1 - a) + cols.mean(0)[None, None] * a
    return out


def _ss_points(q: np.ndarray, ss: int) -> np.ndarray:
    """A quad at ss x the camera's pixels -> fixed-point corners on the supersampled canvas,
    whose pixel centres sit (ss - 1) / 2 off the scaled ones (as the renderer's ss camera)."""
    lim = 1 << 26
    return np.clip(np.round((q + (ss - 1) / 2) * (1 << _SHIFT)), -lim, lim).astype(np.int32)


def foreground_coverage(camera: Camera, structures, ss: int) -> np.ndarray:
    """Supersampled (H*ss, W*ss) bool map of the pixels these structures cover: the map the
    renderer takes out of the masks (tests redraw it from the ground truth's members)."""
    cov = np.zeros((camera.height_px * ss, camera.width_px * ss), np.uint8)
    for s in structures:
        quads, _, _ = _member_quads(camera, s, scale=ss)
        for q in quads:
            if np.isfinite(q).all():
                cv2.fillConvexPoly(cov, _ss_points(q, ss), 1, cv2.LINE_8, _SHIFT)
    return cov.astype(bool)


def paint_foreground_structures(img: np.ndarray, part2: np.ndarray, camera: Camera, structures,
                                env, horizon, rng, ss: int) -> tuple[np.ndarray, np.ndarray]:
    """Structures in front of every turbine part: painted over the composite at ``ss`` x
    resolution and reduced (antialiased edges), and their pixels set to background (-1) in the
    supersampled part map, so the masks end where the structure hides a part."""
    H, W = img.shape[:2]
    col2 = np.zeros((H * ss, W * ss, 3), np.float32)
    for s in structures:
        quads, depth, _ = _member_quads(camera, s, scale=ss)
        cols = _shaded(s, depth, env, horizon, float(rng.uniform(0.85, 1.1)))
        for q, c in zip(quads, cols):
            if np.isfinite(q).all():
                cv2.fillConvexPoly(col2, _ss_points(q, ss), tuple(float(x) for x in c), cv2.LINE_8, _SHIFT)
    cov2 = foreground_coverage(camera, structures, ss)
    if not cov2.any():
        return img, part2
    part2 = part2.copy()
    part2[cov2] = -1
    a = cv2.resize(cov2.astype(np.float32), (W, H), interpolation=cv2.INTER_AREA)
    premult = cv2.resize(col2, (W, H), interpolation=cv2.INTER_AREA)
    return img * (1 - a[..., None]) + premult, part2


# ---- ground ---------------------------------------------------------------------------------
def paint_tracks(bg: np.ndarray, scene, rng, horizon) -> np.ndarray:
    """Dirt tracks and roads on the flat ground (z = 0), in world metres: from the tower's
    pad outwards, meandering, 3-7 m wide, pale gravel or dark asphalt; drawn as short ground
    quads projected through the camera (those behind it are skipped)."""
    cam, t, env = scene.camera, scene.turbine, scene.env
    if cam.position[2] <= 0.5:
        return bg
    out = bg.copy()
    lim = 1 << 26
    n = int(rng.integers(1, 4)) if scene.view in ("nadir", "distant", "closeup") else int(rng.integers(0, 3))
    L = sun_direction(env)
    light = 0.5 + 0.6 * env.sun_strength * max(L[2], 0.1)
    for i in range(n):
        asphalt = rng.random() < 0.25
        base = np.array([0.32, 0.33, 0.34]) if asphalt else np.array([0.62, 0.72, 0.80])
        col = np.clip(base * rng.uniform(0.85, 1.15) + rng.normal(0, 0.03, 3), 0, 1) * light
        width = float(rng.uniform(3.0, 7.0))
        if i == 0 or rng.random() < 0.5:
            p = t.base_xyz[:2].copy()
        else:
            p = t.base_xyz[:2] + rng.uniform(-300, 300, 2)
        ang = float(rng.uniform(0, 2 * math.pi))
        pts = [p]
        for _ in range(int(rng.integers(40, 120))):
            ang += float(rng.normal(0, 0.06))
            pts.append(pts[-1] + 5.0 * np.array([math.cos(ang), math.sin(ang)]))
        pts = np.asarray(pts)
        land = ~on_sea(pts, env, t)  # tracks stay on land: cut where one would reach the sea
        if not land.all():
            pts = pts[:int(np.argmin(land))]
        if len(pts) < 2:
            continue
        d = np.diff(pts, axis=0)
        nrm = np.stack([-d[:, 1], d[:, 0]], 1) / np.linalg.norm(d, axis=1, keepdims=True)
        left, right = pts[:-1] + nrm * width / 2, pts[:-1] - nrm * width / 2
        left2, right2 = pts[1:] + nrm * width / 2, pts[1:] - nrm * width / 2
        quads = np.stack([left, left2, right2, right], 1)
        q3 = np.concatenate([quads, np.full(quads.shape[:2] + (1,), 0.02)], -1).reshape(-1, 3)
        uv, z = cam.project(q3)
        uv, z = uv.reshape(-1, 4, 2), z.reshape(-1, 4)
        depth = z.mean(1)
        fog = 1.0 - np.exp(-np.maximum(depth, 0) / env.visibility_m)
        for q, zz, f in zip(uv, z, fog):
            if (zz < NEAR_M).any():
                continue
            c = col * (1 - f) + horizon * f
            pts_i = np.clip(np.round(q * (1 << _SHIFT)), -lim, lim).astype(np.int32)
            cv2.fillConvexPoly(out, pts_i, tuple(float(x) for x in c), cv2.LINE_AA, _SHIFT)
    return out


# ---- light ----------------------------------------------------------------------------------
def glare(img: np.ndarray, scene) -> np.ndarray:
    """Veiling glare (``env.extras["glare"]``): light scattered in the lens lifts the dark
    parts of the frame towards the sun's colour, most near the sun (in the frame or just out of
    it). The parts stay where they are; only their contrast drops."""
    k = scene.env.extras.get("glare")
    if not k:
        return img
    cam = scene.camera
    H, W = img.shape[:2]
    uv, z = cam.project(cam.position[None] + 1e5 * sun_direction(scene.env)[None])
    if z[0] > 0:
        sx, sy = np.clip(uv[0], [-W, -H], [2 * W, 2 * H])
    else:  # the sun behind the camera: a faint even veil
        sx, sy = W / 2, -3.0 * H
    vs, us = np.mgrid[0:H, 0:W].astype(np.float32)
    r = np.sqrt((us - sx) ** 2 + (vs - sy) ** 2) / max(W, H)
    g = (k * (0.3 + 0.7 * np.exp(-r / 0.45))).astype(np.float32)
    tint = np.array([0.92, 0.97, 1.0], np.float32)
    return img * (1 - g[..., None]) + g[..., None] * tint


def blade_mesh(spare: Turbine, around: int = 6, spans: int = 12):
    """The blade faces of a spare blade's mesh (its tower and nacelle are never drawn)."""
    from wtcli.geometry import Mesh

    m = spare.mesh(around, spans)
    keep = m.face_part < spare.n_blades
    used, faces = np.unique(m.faces[keep], return_inverse=True)
    return Mesh(m.vertices[used], faces.reshape(-1, 3), m.face_part[keep])
