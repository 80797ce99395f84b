"""Everything behind the turbines, per pixel from the camera's viewing rays: sky gradient, sun
glow, clouds on a plane overhead, flat ground textured in world metres (so perspective, scale
and horizon tilt follow the camera), sea beyond a coastline, distant ridges, and haze that grows
with distance. Colours are BGR float32 in [0, 1]."""

from __future__ import annotations

import math

import cv2
import numpy as np

from wtcli.geometry import Camera, Turbine
from wtcli.synth.noise import bank_tile, fbm, noise_1d, smoothstep, tile_fbm
from wtcli.synth.scene import Environment

MAX_GROUND_M = 40000.0

# Sky colours (zenith, horizon), BGR.
_SKY = {
    "clear": ((0.66, 0.42, 0.16), (0.95, 0.86, 0.74)),
    "hazy": ((0.82, 0.70, 0.55), (0.93, 0.90, 0.86)),
    "overcast": ((0.66, 0.64, 0.62), (0.82, 0.81, 0.79)),
    "sunset": ((0.55, 0.38, 0.30), (0.50, 0.70, 0.93)),
}

# Land palettes: (base colours to mix by low-frequency noise, bush/tree colour), BGR.
_LAND = {
    "scrub": ([(0.36, 0.50, 0.58), (0.30, 0.42, 0.47), (0.42, 0.56, 0.62)], (0.12, 0.22, 0.19)),
    "fields": ([(0.20, 0.48, 0.40), (0.30, 0.58, 0.62), (0.22, 0.38, 0.30), (0.40, 0.60, 0.66)],
               (0.10, 0.24, 0.16)),
    "forest": ([(0.12, 0.26, 0.18), (0.15, 0.30, 0.24), (0.20, 0.34, 0.30)], (0.07, 0.14, 0.09)),
    "dry": ([(0.48, 0.62, 0.70), (0.40, 0.55, 0.64), (0.55, 0.66, 0.72)], (0.22, 0.32, 0.30)),
}


_BUSH_BANK: list[np.ndarray] = []
BUSH_TILE = 512
BUSH_TILE_M = 0.5  # metres per texel of a bank tile before the scene's own scale


def _bush_bank() -> list[np.ndarray]:
    """Three tiles of scattered bushes, made once per process from a fixed seed (so every scene
    stays a pure function of its own seed). Channels: coverage, rank (a bush shows where the
    local density exceeds its rank), shade (lit top, dark shadowed side), soil grain."""
    if _BUSH_BANK:
        return _BUSH_BANK
    rng = np.random.default_rng(20261123)
    T = BUSH_TILE
    for _ in range(3):
        cov = np.zeros((T, T), np.float32)
        rank = np.ones((T, T), np.float32)
        shade = np.full((T, T), 0.5, np.float32)
        n = 9000
        xs, ys = rng.uniform(0, T, n), rng.uniform(0, T, n)
        rs = np.exp(rng.uniform(np.log(1.5), np.log(6.0), n))
        rk = rng.random(n)
        order = np.argsort(-rk)  # low ranks (shown first) drawn last, on top
        for i in order:
            for ox in (0, -T, T):  # wrap across the tile's edges
                for oy in (0, -T, T):
                    cx, cy = xs[i] + ox, ys[i] + oy
                    if -8 < cx < T + 8 and -8 < cy < T + 8:
                        c = (int(cx * 16), int(cy * 16))
                        r = int(rs[i] * 16)
                        cv2.circle(cov, c, r, 1.0, -1, cv2.LINE_AA, 4)
                        cv2.circle(rank, c, r, float(rk[i]), -1, cv2.LINE_8, 4)
                        cv2.circle(shade, c, r, 0.25, -1, cv2.LINE_8, 4)
                        hl = (int((cx - 0.3 * rs[i]) * 16), int((cy - 0.3 * rs[i]) * 16))
                        cv2.circle(shade, hl, int(r * 0.55), 0.85, -1, cv2.LINE_AA, 4)
        shade = cv2.GaussianBlur(shade, (0, 0), 0.8)
        grain = tile_fbm(rng, T, 128, octaves=2)
        _BUSH_BANK.append(np.ascontiguousarray(np.dstack([cov, rank, shade, grain])))
    return _BUSH_BANK


def _jitter(rng: np.random.Generator, c, amount: float = 0.04) -> np.ndarray:
    return np.clip(np.asarray(c, np.float32) + rng.normal(0, amount, 3).astype(np.float32), 0, 1)


def _remap_wrap(tile: np.ndarray, mx: np.ndarray, my: np.ndarray) -> np.ndarray:
    size = np.float32(tile.shape[0])
    mx = np.asarray(mx, np.float32)
    my = np.asarray(my, np.float32)
    return cv2.remap(tile, mx - np.floor(mx / size) * size, my - np.floor(my / size) * size,
                     cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)


def sky_colours(env: Environment, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    zen, hor = _SKY[env.sky]
    return _jitter(rng, zen, 0.05), _jitter(rng, hor, 0.03)


def sun_direction(env: Environment) -> np.ndarray:
    a, e = math.radians(env.sun_azimuth_deg), math.radians(env.sun_elevation_deg)
    return np.array([math.sin(a) * math.cos(e), math.cos(a) * math.cos(e), math.sin(e)])


def pixel_rays(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit viewing directions (world x, y, z components, each float32 (H, W)) of every pixel.

    From ``Camera.rays`` at three pixels: a ray scaled to unit depth along the view axis is
    affine in (u, v), so the whole grid follows exactly from those three."""
    H, W = camera.height_px, camera.width_px
    r = camera.rays(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]))
    r = r / (r @ camera.forward)[:, None]
    du, dv = (r[1] - r[0]).astype(np.float32), (r[2] - r[0]).astype(np.float32)
    us = np.arange(W, dtype=np.float32)[None, :]
    vs = np.arange(H, dtype=np.float32)[:, None]
    comps = [r[0, i].astype(np.float32) + us * du[i] + vs * dv[i] for i in range(3)]
    inv = 1.0 / np.sqrt(comps[0] ** 2 + comps[1] ** 2 + comps[2] ** 2)
    return comps[0] * inv, comps[1] * inv, comps[2] * inv


def render_background(camera: Camera, env: Environment, turbine: Turbine,
                      rng: np.random.Generator, zenith: np.ndarray, horizon: np.ndarray,
                      waves: np.random.Generator | None = None) -> np.ndarray:
    """The background, BGR float32 (H, W, 3). Smooth fields (sky, clouds, land colour, haze,
    sea, ridges) are computed on a half-resolution grid of the same camera and enlarged; the
    ground's fine detail (bushes, soil grain) is sampled at full resolution on top.
    ``waves``: a generator of its own for waves on the sea, seen from close above (the wider
    views' close-ups); None leaves the sea smooth, as the whole-rotor views have it."""
    H, W = camera.height_px, camera.width_px
    f = 2 if W * H >= 100_000 else 1
    lo = Camera(-(-W // f), -(-H // f), camera.focal_mm, camera.sensor_width_mm,
                camera.position, camera.R)
    img, det = _background_lo(lo, env, turbine, rng, zenith, horizon, f, waves)
    if f > 1:
        img = cv2.resize(img, (W, H), interpolation=cv2.INTER_LINEAR)
    if det is None:
        return img
    # Enlarge the smooth per-pixel fields in one go, then draw the bushes at full resolution:
    # pixel = bare ground + bush coverage * (lit, hazed bush colour - bare ground).
    packed = np.dstack([det["X"], det["Y"], det["w"], det["dens"], det["land"], det["k"],
                        det["hazefog"]]).astype(np.float32)
    if f > 1:
        packed = cv2.resize(packed, (W, H), interpolation=cv2.INTER_LINEAR)
    X, Y, w, dens, land, k = (packed[..., i] for i in range(6))
    hazefog = packed[..., 6:9]
    m = det["m"]
    fs = _remap_wrap(det["tile"], X / m, -Y / m)
    near = smoothstep(-0.06, 0.0, dens - fs[..., 1]) * fs[..., 0]
    bm = (w * near + (1 - w) * dens * det["cover"]) * land
    shade = (w * fs[..., 2] + (1 - w) * 0.45)
    bush = det["bush"] * (0.55 + 0.9 * shade)[..., None] * k[..., None] + hazefog
    grain = 1.0 + w * land * (fs[..., 3] - 0.5) * det["grain"]
    img = img * grain[..., None]
    return img + bm[..., None] * (bush - img)


def _background_lo(camera: Camera, env: Environment, turbine: Turbine, rng: np.random.Generator,
                   zenith: np.ndarray, horizon: np.ndarray, f: int, waves=None):
    dx, dy, dz = pixel_rays(camera)
    sun = sun_direction(env).astype(np.float32)
    cos_sun = dx * sun[0] + dy * sun[1] + dz * sun[2]
    elev = np.degrees(np.arcsin(np.clip(dz, -1, 1)))
    az = np.degrees(np.arctan2(dx, dy)) % 360.0

    # ---- sky --------------------------------------------------------------------------------
    t = np.clip(elev / 70.0, 0, 1) ** 0.55
    sky = horizon + (zenith - horizon) * t[..., None]
    warm = np.array([0.85, 0.95, 1.0], np.float32) if env.sky != "sunset" else \
        np.array([0.55, 0.80, 1.0], np.float32)
    s = env.sun_strength
    glow = s * (0.55 * np.exp((cos_sun - 1) / 0.0009) + 0.35 * np.exp((cos_sun - 1) / 0.02)
                + 0.22 * np.exp((cos_sun - 1) / 0.25))
    if env.sky == "overcast":  # a bright patch where the sun hides behind the clouds
        glow = glow + 0.12 * np.exp((cos_sun - 1) / 0.2)
    sky = sky + glow[..., None] * (warm - sky * 0.6)

    # Clouds on a plane ~2 km up; fade towards the horizon where they would alias.
    up = dz > 0.01
    cloud_tile = bank_tile(rng, 256, int(rng.integers(3, 7)), octaves=5, gain=0.55)
    shade_tile = bank_tile(rng, 256, int(rng.integers(4, 9)), octaves=4)
    hc, mpp = 2000.0, float(rng.uniform(20, 60))
    dzc = np.maximum(dz, 0.01)
    cx_, cy_ = dx / dzc * hc / mpp, dy / dzc * hc / mpp
    cn = _remap_wrap(cloud_tile, cx_, cy_)
    sn = _remap_wrap(shade_tile, cx_ * 1.7, cy_ * 1.7)
    cov = env.cloud_cover
    # Towards the horizon the cloud plane's texture shrinks below a pixel: fade to its mean.
    detail = smoothstep(0.03, 0.3, dz)
    cn = cn * detail + 0.5 * (1 - detail)
    sn = sn * detail + 0.5 * (1 - detail)
    dens = smoothstep(1.0 - cov - 0.15, 1.0 - cov + 0.25, cn) * smoothstep(0.01, 0.18, dz) * up
    if env.sky == "overcast":
        dens = np.maximum(dens, 0.85 * smoothstep(0.0, 0.05, dz))
        base = float(rng.uniform(0.42, 0.75))
        ccol = (base * (0.75 + 0.45 * sn))[..., None] * np.array([1.0, 1.0, 0.98], np.float32)
    else:
        lit = 0.82 + 0.2 * s
        ccol = (lit * (0.72 + 0.32 * sn))[..., None] * np.array([0.98, 0.99, 1.0], np.float32)
        ccol = ccol + (0.4 * glow)[..., None]
        if env.sky == "sunset":
            ccol = ccol * np.array([0.75, 0.85, 1.0], np.float32)
    sky = sky * (1 - dens[..., None]) + ccol * dens[..., None]

    # ---- ground (flat, z = 0) -----------------------------------------------------------------
    img = sky
    det = None
    down = dz < -1e-4
    if down.any():
        img, det = _ground(camera, env, turbine, rng, dx, dy, dz, down, horizon, glow, sky, img, f,
                           waves)
    if env.hills:
        img, hill = _hills(camera, env, rng, dz, elev, az, horizon, img)
        if det is not None:
            det["land"] = det["land"] * (1.0 - hill)
    return np.clip(img, 0, 1.2), det


def _ground(camera, env, turbine, rng, dx, dy, dz, down, horizon, glow, sky, img, scale, waves=None):
    H, W = dz.shape
    h = max(float(camera.position[2]), 0.5)
    tt = np.minimum(h / np.maximum(-dz, 1e-6), MAX_GROUND_M)
    X = camera.position[0] + tt * dx
    Y = camera.position[1] + tt * dy

    base_cols, bush_col = _LAND[env.ground]
    base_cols = [_jitter(rng, c, 0.03) for c in base_cols]
    bush_col = _jitter(rng, bush_col, 0.02)

    # Land use: a 4-5 km tile at ~8 m per texel; fields as a patchwork of cells.
    T = 512
    mL = float(rng.uniform(6.0, 10.0))
    sel = bank_tile(rng, T, int(rng.integers(3, 8)), octaves=4)
    land = np.zeros((T, T, 3), np.float32)
    k = len(base_cols)
    if env.ground == "fields":
        # Fields: a rotated grid of plots of uneven size, their borders bent by noise.
        n = float(rng.uniform(6, 16))
        ang = float(rng.uniform(0, math.pi))
        yy, xx = np.mgrid[0:T, 0:T].astype(np.float32)
        warp = (bank_tile(rng, T, 4, octaves=2) - 0.5) * float(rng.uniform(0, 60))
        a = (xx * math.cos(ang) + yy * math.sin(ang) + warp) / (T / n)
        b = (-xx * math.sin(ang) + yy * math.cos(ang) + warp) / (T / n) * float(rng.uniform(0.4, 1.0))
        ia, ib = np.floor(a).astype(np.int64), np.floor(b).astype(np.int64)
        salt = int(rng.integers(1 << 20))
        idx = ((((ia * 73856093) ^ (ib * 19349663) ^ salt) >> 5) % k).astype(np.int64)
        land = np.stack([np.asarray(base_cols)[idx][..., c] for c in range(3)], -1)
        land = land * (0.85 + 0.3 * sel[..., None])
    else:
        pos = sel * (k - 1)
        i0 = np.floor(pos).astype(int)
        f = (pos - i0)[..., None]
        i1 = np.minimum(i0 + 1, k - 1)
        bc = np.asarray(base_cols, np.float32)
        land = bc[i0] * (1 - f) + bc[i1] * f
    bright = bank_tile(rng, T, int(rng.integers(6, 14)), octaves=3)
    land = land * (0.8 + 0.4 * bright[..., None])
    # 4th channel: how bushy the land is here (patches of dense scrub, bare slopes).
    density = 0.25 + 0.75 * bank_tile(rng, T, int(rng.integers(4, 12)), octaves=4)
    land = np.ascontiguousarray(np.dstack([land, density]).astype(np.float32))
    # Dirt roads and the gravel pad at the turbine's foot, drawn into the land tile.
    road = tuple(float(x) for x in _jitter(rng, (0.60, 0.70, 0.76), 0.04)) + (0.0,)
    bx, by = turbine.base[0] / mL, -turbine.base[1] / mL
    for _ in range(int(rng.integers(0, 4))):
        pts = [(bx, by)]
        ang = rng.uniform(0, 2 * math.pi)
        for _ in range(int(rng.integers(8, 20))):
            ang += rng.normal(0, 0.35)
            step = rng.uniform(6, 16)
            pts.append((pts[-1][0] + step * math.cos(ang), pts[-1][1] + step * math.sin(ang)))
        p = np.round(np.mod(np.asarray(pts), T) * 16).astype(np.int32)
        for a, b in zip(p[:-1], p[1:]):
            if np.abs(a - b).max() < T * 8:
                cv2.line(land, tuple(int(x) for x in a), tuple(int(x) for x in b), road, 1,
                         cv2.LINE_AA, shift=4)
    pad = max(1, int(round(float(rng.uniform(12, 30)) / mL)))
    cv2.circle(land, (int(bx) % T, int(by) % T), pad, road, -1, cv2.LINE_AA)
    # The land as seen from far away (about a 4-texel blur), cheaply: shrink, then enlarge.
    land_blur = cv2.resize(cv2.resize(land, (T // 4, T // 4), interpolation=cv2.INTER_AREA),
                           (T, T), interpolation=cv2.INTER_LINEAR)

    # Bushes / trees: a tile of the bush bank at the scene's scale (bushes of ~1-6 m).
    tile = _bush_bank()[int(rng.integers(len(_bush_bank())))]
    mF = BUSH_TILE_M * float(rng.uniform(0.6, 1.5))
    amount = {"scrub": float(rng.uniform(0.5, 0.85)), "fields": float(rng.uniform(0.05, 0.3)),
              "forest": float(rng.uniform(0.85, 1.0)), "dry": float(rng.uniform(0.15, 0.5))}[env.ground]
    cover = 0.8  # share of a bush's footprint its disc covers, on average (far-field mix)

    # Metres per pixel on the ground: picks texture detail vs its average (no aliasing). The
    # bushes themselves are drawn at full resolution by render_background from `det`.
    foot = tt / camera.fx / np.sqrt(np.maximum(-dz, 0.02))
    w_fine = np.clip(1.2 * scale * mF / np.maximum(foot, 1e-6), 0, 1)
    w_land = np.clip(1.5 * mL / np.maximum(foot, 1e-6), 0, 1)[..., None]
    lx, ly = X / mL, -Y / mL
    lc = _remap_wrap(land, lx, ly) * w_land + _remap_wrap(land_blur, lx, ly) * (1 - w_land)
    dens = np.clip(amount * (0.4 + 0.9 * lc[..., 3]), 0, 1).astype(np.float32)
    col = lc[..., :3]
    # Light: sun on flat ground, sky light everywhere.
    light = 0.5 + 0.6 * env.sun_strength * max(math.sin(math.radians(env.sun_elevation_deg)), 0.1)
    col = col * light
    if env.backlit:  # the side of everything facing the camera is in shade
        light *= 0.7
        col = col * 0.7

    if env.sea_distance_m is not None:
        b = math.radians(env.sea_bearing_deg)
        u = np.array([math.sin(b), math.cos(b)])
        rel_x, rel_y = X - turbine.base[0], Y - turbine.base[1]
        along = rel_x * u[0] + rel_y * u[1]
        across = -rel_x * u[1] + rel_y * u[0]
        prof = noise_1d(rng, 4096, 12, octaves=5)
        ai = np.mod((across / 20.0).astype(np.int64), 4096)
        coast = env.sea_distance_m + (prof[ai] - 0.5) * float(rng.uniform(200, 1500))
        sea = along > coast
        deep = _jitter(rng, (0.45, 0.27, 0.06), 0.05)
        if env.sky == "overcast":
            deep = deep * 0.6 + np.array([0.25, 0.2, 0.15], np.float32)
        fres = 0.03 + 0.8 * (1 - np.abs(dz)) ** 8
        sea_col = deep * (1 - fres[..., None]) + horizon * 0.9 * fres[..., None]
        # Sun glitter: reflection of the sun on waves.
        sun = sun_direction(env)
        refl = dx * sun[0] + dy * sun[1] - dz * sun[2]
        wave_rng = waves
        waves = _remap_wrap(np.ascontiguousarray(tile[..., 3]), X / 1.5, Y / 0.5)
        glit = env.sun_strength * np.exp((refl - 1) / 0.004) * smoothstep(0.55, 0.8, waves)
        sea_col = sea_col + glit[..., None] * 0.8
        if wave_rng is not None:
            sea_col = _sea_waves(sea_col, wave_rng, X, Y, foot, env)
        shore = sea & (along < coast + 15)
        sea_col[shore] = sea_col[shore] * 0.6 + 0.3
        col = np.where(sea[..., None], sea_col, col)

    haze_col = horizon + (glow * 0.6)[..., None] * (1 - horizon)
    fog = 1.0 - np.exp(-tt / env.visibility_m)
    col = col * (1 - fog[..., None]) + haze_col * fog[..., None]
    # Soft horizon: blend the last fraction of a degree into the sky.
    edge = smoothstep(0.0, 0.004, -dz)
    col = col * edge[..., None] + sky * (1 - edge[..., None])
    land = (edge * down).astype(np.float32)
    if env.sea_distance_m is not None:
        land = land * ~sea
    det = {"X": X, "Y": Y, "w": w_fine, "dens": dens, "land": land,
           "k": (light * (1 - fog)).astype(np.float32),
           "hazefog": (haze_col * fog[..., None]).astype(np.float32),
           "tile": tile, "m": mF, "cover": cover, "bush": bush_col,
           "grain": float(rng.uniform(0.15, 0.4))}
    return np.where(down[..., None], col, img), det


def _sea_waves(sea_col, rng, X, Y, foot, env):
    """Wind waves on the sea in world metres: long crests across the wind, lit on their
    windward slopes, fading to their average where a wave spans less than a pixel."""
    tile = bank_tile(rng, 256, int(rng.integers(10, 24)), octaves=4, gain=0.6)
    ang = float(rng.uniform(0, math.pi))
    m = float(rng.uniform(0.6, 2.0))  # metres per texel across the crests
    c, s = math.cos(ang), math.sin(ang)
    wx = (X * c + Y * s) / m
    wy = (-X * s + Y * c) / (m * float(rng.uniform(2.5, 5.0)))
    w = _remap_wrap(tile, wx, wy) - 0.5
    seen = np.clip(1.5 * m / np.maximum(foot, 1e-6) - 0.5, 0, 1)
    k = float(rng.uniform(0.25, 0.5)) * (0.6 + 0.4 * env.sun_strength)
    return sea_col * (1.0 + k * w * seen)[..., None] + (0.12 * np.clip(w, 0, None) * seen)[..., None]


def _hills(camera, env, rng, dz, elev, az, horizon, img):
    hcam = float(camera.position[2])
    hill = np.zeros(dz.shape, np.float32)
    for layer in range(env.hills):
        D = float(rng.uniform(5000, 15000)) if layer == 0 else float(rng.uniform(1200, 4500))
        height = float(rng.uniform(200, 1000)) if layer == 0 else float(rng.uniform(80, 400))
        prof = noise_1d(rng, 3600, int(rng.integers(3, 12)), octaves=6, gain=0.5)
        prof = np.clip((prof - 0.35) / 0.65, 0, 1) ** float(rng.uniform(0.8, 1.6))
        ridge = np.degrees(np.arctan((height * prof - hcam) / D))
        r = ridge[(az * 10).astype(np.int64) % 3600]
        # Below the ridge and beyond the ground's distance D: the hill hides what lies behind.
        ground_dist = np.where(dz < -1e-6, hcam / np.maximum(-dz, 1e-6), np.inf)
        mask = (elev < r) & (ground_dist > D)
        if not mask.any():
            continue
        # Vegetated ridges: mostly bush colour over soil, darker than the plain in front.
        soils, bush = _LAND["scrub" if env.ground != "forest" else "forest"]
        soil = np.asarray(soils[int(rng.integers(len(soils)))], np.float32)
        base = _jitter(rng, 0.65 * np.asarray(bush, np.float32) + 0.35 * soil, 0.02)
        base = base * float(rng.uniform(0.7, 1.1)) * (0.6 + 0.5 * env.sun_strength)
        H, W = dz.shape
        tex = fbm(rng, H, W, float(rng.uniform(20, 60)), octaves=4)
        # Slopes facing the sun are lighter: a soft gradient down from the ridge line.
        col = base * (0.75 + 0.5 * tex[..., None])
        # Aerial perspective: distant land takes on the bluish haze of the horizon.
        fog = 1.0 - math.exp(-D / (0.8 * env.visibility_m))
        col = col * (1 - fog) + horizon * fog * np.array([1.04, 0.98, 0.92], np.float32)
        # Antialias the ridge line.
        a = smoothstep(0.0, 0.08, r - elev) * mask
        img = img * (1 - a[..., None]) + col * a[..., None]
        hill = np.maximum(hill, a)
    return img, hill
