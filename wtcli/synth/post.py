"""What the drone's camera does to the picture: exposure and gamma, white balance, vignetting,
defocus or motion blur, sensor noise, and JPEG re-encoding. Pixel-only: the renderer applies
the same blur to the parts' coverage for the labels (``apply_blur``)."""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np


def apply_blur(img: np.ndarray, blur: dict[str, Any] | None) -> np.ndarray:
    """The blur ``camera_effects`` drew (its ``fx["blur"]``, or None for none) applied to a float
    image or map; the renderer blurs the parts' coverage with it too (labels, render.py)."""
    if not blur:
        return img
    if blur["kind"] == "defocus":
        return cv2.GaussianBlur(img, (0, 0), blur["sigma_px"])
    n, ang = blur["length_px"], blur["angle_deg"]
    k = np.zeros((n, n), np.float32)
    c = (n - 1) / 2
    dxy = np.array([math.cos(math.radians(ang)), math.sin(math.radians(ang))]) * c
    cv2.line(k, (int(round(c - dxy[0])), int(round(c - dxy[1]))),
             (int(round(c + dxy[0])), int(round(c + dxy[1]))), 1.0, 1)
    k /= max(k.sum(), 1e-6)
    return cv2.filter2D(img, -1, k)


def camera_effects(img: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, dict[str, Any]]:
    """``img``: BGR float32 in about [0, 1] -> BGR uint8, plus the settings drawn."""
    H, W = img.shape[:2]
    fx: dict[str, Any] = {}
    gain = float(rng.uniform(0.78, 1.22))
    gamma = float(rng.uniform(0.8, 1.25))
    # White balance errors run mostly along blue-amber (colour temperature), a little along
    # green-magenta (tint).
    temp, tint = float(rng.normal(0, 0.045)), float(rng.normal(0, 0.012))
    wb = np.array([1 + temp, 1 + tint, 1 - temp], np.float32)
    fx.update(exposure=gain, gamma=gamma, white_balance=wb.tolist())
    # Bloom: light from the sun and bright sky bleeds over nearby edges (thin blades too).
    if rng.random() < 0.5:
        small = cv2.resize(img, (max(1, W // 4), max(1, H // 4)), interpolation=cv2.INTER_AREA)
        glow = cv2.GaussianBlur(np.clip(small - 0.85, 0, None), (0, 0), max(1.0, W / 160))
        k = float(rng.uniform(0.3, 1.2))
        img = img + k * cv2.resize(glow, (W, H), interpolation=cv2.INTER_LINEAR)
        fx["bloom"] = k
    # Exposure and white balance, then a tone curve (optional soft highlight roll-off, gamma)
    # applied as a lookup table.
    x = np.linspace(0, 2, 2049, dtype=np.float32)
    curve = 1.0 - np.exp(-x * 1.6) if rng.random() < 0.3 else np.clip(x, 0, 1)
    curve = np.power(np.clip(curve, 0, 1), gamma).astype(np.float32)
    idx = np.clip(img * (gain * wb * 1024.0), 0, 2048).astype(np.int32)
    img = curve[idx]
    sat = float(rng.uniform(0.75, 1.25))
    grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    img = cv2.addWeighted(img, sat, cv2.merge([grey, grey, grey]), 1.0 - sat, 0.0)
    fx["saturation"] = sat
    if rng.random() < 0.4:
        vs, us = np.ogrid[0:H, 0:W]
        r2 = ((us - W / 2) / (W / 2)) ** 2 + ((vs - H / 2) / (H / 2)) ** 2
        k = float(rng.uniform(0.05, 0.25))
        img = img * (1 - k * r2 / 2)[..., None].astype(np.float32)
        fx["vignette"] = k
    u = rng.random()
    if u < 0.3:
        fx["blur"] = {"kind": "defocus", "sigma_px": float(rng.uniform(0.4, 1.4)) * W / 640}
    elif u < 0.42:
        fx["blur"] = {"kind": "motion", "length_px": int(rng.integers(3, 10)),
                      "angle_deg": float(rng.uniform(0, 180))}
    img = apply_blur(img, fx.get("blur"))
    sigma = float(rng.uniform(0.0, 0.012))
    if sigma > 0.002:
        noise = rng.standard_normal((H, W, 1), dtype=np.float32) * np.float32(sigma)
        # Chroma noise is blotchier than luma noise: draw it at half resolution.
        chroma = rng.standard_normal(((H + 1) // 2, (W + 1) // 2, 3), dtype=np.float32)
        chroma = cv2.resize(chroma, (W, H), interpolation=cv2.INTER_LINEAR) * np.float32(sigma * 0.5)
        img = img + noise + chroma
    fx["noise_sigma"] = sigma
    out = np.clip(img * 255.0 + 0.5, 0, 255).astype(np.uint8)
    if rng.random() < 0.6:
        q = int(rng.integers(35, 96))
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, q])
        if ok:
            out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
            fx["jpeg_quality"] = q
    return out, fx
