"""The one pinhole camera model: intrinsics from sensor and lens, pose, projection, rays, GSD.

Camera frame (OpenCV): x right, y down, z forward (the viewing direction). ``R`` maps world
(ENU) vectors to camera vectors, so its rows are the camera's right, down and forward axes in
world coordinates. Pixels: x right, y down, pixel centres at integer coordinates.
Image angles (DESIGN.md) are counter-clockwise positive with image y pointing up, 0° = right.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

Z = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Camera:
    width_px: int
    height_px: int
    focal_mm: float
    sensor_width_mm: float
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    R: np.ndarray = field(default_factory=lambda: np.eye(3))  # world -> camera rotation

    def __post_init__(self) -> None:
        if self.width_px <= 0 or self.height_px <= 0:
            raise ValueError(f"expected a positive resolution, got {self.width_px}x{self.height_px}")
        if self.focal_mm <= 0 or self.sensor_width_mm <= 0:
            raise ValueError(f"expected focal_mm and sensor_width_mm > 0, got {self.focal_mm}, "
                             f"{self.sensor_width_mm}")
        pos = np.asarray(self.position, dtype=float).reshape(3)
        R = np.asarray(self.R, dtype=float).reshape(3, 3)
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError("expected R to be a rotation matrix")
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "R", R)

    # ---- intrinsics -------------------------------------------------------------------------
    @property
    def fx(self) -> float:
        """Focal length in pixels (square pixels)."""
        return self.focal_mm * self.width_px / self.sensor_width_mm

    @property
    def cx(self) -> float:
        return (self.width_px - 1) / 2.0

    @property
    def cy(self) -> float:
        return (self.height_px - 1) / 2.0

    @property
    def sensor_height_mm(self) -> float:
        return self.sensor_width_mm * self.height_px / self.width_px

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fx, self.cy], [0, 0, 1.0]])

    @property
    def hfov_deg(self) -> float:
        return math.degrees(2 * math.atan(self.sensor_width_mm / (2 * self.focal_mm)))

    @property
    def vfov_deg(self) -> float:
        return math.degrees(2 * math.atan(self.sensor_height_mm / (2 * self.focal_mm)))

    def gsd_mm(self, distance_m: float | np.ndarray) -> float | np.ndarray:
        """Ground sampling distance in mm per pixel at a distance (formats.md)."""
        return np.asarray(distance_m) * 1000.0 * self.sensor_width_mm / (self.focal_mm * self.width_px)

    def distance_for_gsd(self, gsd_mm: float) -> float:
        return gsd_mm * self.focal_mm * self.width_px / (1000.0 * self.sensor_width_mm)

    def footprint_m(self, distance_m: float) -> tuple[float, float]:
        """Width and height (m) of the area imaged on a fronto-parallel plane at a distance."""
        return (distance_m * self.sensor_width_mm / self.focal_mm,
                distance_m * self.sensor_height_mm / self.focal_mm)

    # ---- pose -------------------------------------------------------------------------------
    @property
    def forward(self) -> np.ndarray:
        return self.R[2]

    @property
    def right(self) -> np.ndarray:
        return self.R[0]

    @property
    def down(self) -> np.ndarray:
        return self.R[1]

    def with_pose(self, position: np.ndarray, R: np.ndarray) -> Camera:
        return Camera(self.width_px, self.height_px, self.focal_mm, self.sensor_width_mm,
                      np.asarray(position, float), np.asarray(R, float))

    def looking_at(self, position: np.ndarray, target: np.ndarray, roll_deg: float = 0.0) -> Camera:
        return self.with_pose(position, look_at_rotation(position, target, roll_deg))

    @staticmethod
    def rotation_from_yaw_pitch(yaw_deg: float, pitch_deg: float, roll_deg: float = 0.0) -> np.ndarray:
        """World->camera rotation for a camera aimed at compass heading ``yaw_deg`` (0 = north)
        and elevation ``pitch_deg`` (positive up, -90 straight down)."""
        y, p = math.radians(yaw_deg), math.radians(pitch_deg)
        fwd = np.array([math.sin(y) * math.cos(p), math.cos(y) * math.cos(p), math.sin(p)])
        return _rotation_from_forward(fwd, roll_deg, heading_hint=y)

    # ---- projection -------------------------------------------------------------------------
    def to_camera(self, points: np.ndarray) -> np.ndarray:
        return (np.atleast_2d(np.asarray(points, float)) - self.position) @ self.R.T

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points (M, 3) -> pixels (M, 2) and depth along the view axis (M,).
        Points behind the camera get depth <= 0 and meaningless pixels."""
        pc = self.to_camera(points)
        z = pc[:, 2]
        zs = np.where(np.abs(z) < 1e-9, 1e-9, z)
        uv = np.stack([self.fx * pc[:, 0] / zs + self.cx, self.fx * pc[:, 1] / zs + self.cy], 1)
        return uv, z

    def rays(self, uv: np.ndarray) -> np.ndarray:
        """Pixels (M, 2) -> unit viewing directions in world (M, 3)."""
        uv = np.atleast_2d(np.asarray(uv, float))
        dc = np.stack([(uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fx,
                       np.ones(len(uv))], 1)
        dw = dc @ self.R
        return dw / np.linalg.norm(dw, axis=1, keepdims=True)

    def intersect_plane(self, uv: np.ndarray, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
        """Back-project pixels onto a world plane; NaN rows where the ray misses it."""
        d = self.rays(uv)
        denom = d @ normal
        t = ((np.asarray(point) - self.position) @ normal) / np.where(np.abs(denom) < 1e-12, np.nan, denom)
        t = np.where(t > 0, t, np.nan)
        return self.position + t[:, None] * d

    def image_angle_deg(self, p_from: np.ndarray, p_to: np.ndarray) -> float:
        """Direction in the image, degrees in [0, 360), of the segment from p_from to p_to
        (counter-clockwise, image y up, 0 = right)."""
        uv, _ = self.project(np.array([p_from, p_to], float))
        dx, dy = uv[1, 0] - uv[0, 0], uv[1, 1] - uv[0, 1]
        return math.degrees(math.atan2(-dy, dx)) % 360.0

    # ---- serialisation ------------------------------------------------------------------------
    def intrinsics_dict(self) -> dict[str, Any]:
        return {"width_px": self.width_px, "height_px": self.height_px,
                "focal_mm": self.focal_mm, "sensor_width_mm": self.sensor_width_mm}

    def to_dict(self) -> dict[str, Any]:
        return {**self.intrinsics_dict(), "position": self.position.tolist(), "R": self.R.tolist()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Camera:
        return cls(int(d["width_px"]), int(d["height_px"]), float(d["focal_mm"]),
                   float(d["sensor_width_mm"]), np.asarray(d.get("position", np.zeros(3)), float),
                   np.asarray(d.get("R", np.eye(3)), float))


def look_at_rotation(position: np.ndarray, target: np.ndarray, roll_deg: float = 0.0) -> np.ndarray:
    """World->camera rotation looking from ``position`` at ``target`` with world z as up.

    ``roll_deg`` turns the camera counter-clockwise about its viewing axis (as the operator
    sees it from behind), so the scene appears turned clockwise in the image."""
    fwd = np.asarray(target, float) - np.asarray(position, float)
    n = np.linalg.norm(fwd)
    if n < 1e-9:
        raise ValueError("look_at: position and target coincide")
    return _rotation_from_forward(fwd / n, roll_deg)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """np.cross of two 3-vectors, with its arithmetic (the same bits) at a tenth of its cost:
    the planner makes a rotation for each of tens of thousands of photos."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _rotation_from_forward(fwd: np.ndarray, roll_deg: float, heading_hint: float = 0.0) -> np.ndarray:
    fwd = fwd / np.linalg.norm(fwd)
    right = _cross(fwd, Z)
    if np.linalg.norm(right) < 1e-6:  # looking straight up or down: take right from the heading
        right = np.array([math.cos(heading_hint), -math.sin(heading_hint), 0.0])
    right /= np.linalg.norm(right)
    down = _cross(fwd, right)
    r = math.radians(roll_deg)
    # Rolling the camera CCW (seen from behind) turns its right axis towards its up (= -down).
    right2 = math.cos(r) * right - math.sin(r) * down
    down2 = math.sin(r) * right + math.cos(r) * down
    return np.stack([right2, down2, fwd])
