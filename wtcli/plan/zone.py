"""Step 1.1 (eq. 1-3): the turbine's zone sphere and the initial point S_p, and blade angles in 3D.

* ``zone(turbine, tips)``: C_i = mean of the blade tips (eq. 2), R_i = the largest tip distance
  from C_i (eq. 3). Tips are the measured ones from turbines.yaml when given, else the model's.
* ``initial_point``: S_p = C_i + R_i * axis (eq. 1's sphere, generalising the paper's
  (x_i + R_i, y_i, z_i) from a rotor facing +x to any yaw).
* ``azimuths_from_pitch``: blade directions φ measured in a photo, back-projected through the
  camera that took it onto the rotor plane (through the hub, normal = rotor axis), so a photo
  taken off-axis still gives the right rotor azimuth (Turbine's convention: counter-clockwise
  from the front viewer's right).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wtcli.geometry import Camera, Turbine
from wtcli.geometry.camera import look_at_rotation


@dataclass(frozen=True)
class Zone:
    center: np.ndarray  # C_i, ENU m
    radius: float  # R_i, m

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Eq. 1: which points lie inside the sphere."""
        return np.linalg.norm(np.atleast_2d(points) - self.center, axis=1) <= self.radius


def zone(turbine: Turbine, tips: np.ndarray | None = None) -> Zone:
    tips = turbine.blade_tips() if tips is None else np.asarray(tips, float).reshape(-1, 3)
    c = tips.mean(axis=0)  # eq. 2
    r = float(np.linalg.norm(tips - c, axis=1).max())  # eq. 3
    if len(tips) == 1 or r < 1e-6:  # one blade: the sphere around hub and tip
        c = 0.5 * (turbine.hub_center + tips[0])
        r = float(np.linalg.norm(tips[0] - c))
    return Zone(c, r)


def initial_point(turbine: Turbine, z: Zone) -> np.ndarray:
    """S_p: in front of the rotor, on its axis through C_i, at distance R_i (eq. 1-3)."""
    return z.center + z.radius * turbine.axis


def azimuth_of(turbine: Turbine, vec: np.ndarray) -> float:
    """Rotor azimuth (deg, [0, 360)) of a direction, projected onto the rotor plane."""
    v = np.asarray(vec, float)
    x, y = float(v @ turbine.right), float(v[2])
    if math.hypot(x, y) < 1e-9:
        raise ValueError("direction is along the rotor axis: no azimuth")
    return math.degrees(math.atan2(y, x)) % 360.0


def azimuths_from_tips(turbine: Turbine, tips: np.ndarray) -> list[float]:
    """Blade azimuths from measured tip positions (ENU) relative to the model's hub centre."""
    tips = np.asarray(tips, float).reshape(-1, 3)
    out = []
    for k, p in enumerate(tips):
        v = p - turbine.hub_center
        inplane = v - (v @ turbine.axis) * turbine.axis
        if np.linalg.norm(inplane) < 0.25 * turbine.tip_radius:
            raise ValueError(f"tip {k + 1} {p.tolist()} is only {np.linalg.norm(inplane):.1f} m from "
                             f"the hub in the rotor plane (rotor radius {turbine.tip_radius:g} m)")
        out.append(azimuth_of(turbine, inplane))
    return out


def default_photo_camera(turbine: Turbine, camera: Camera, z: Zone | None = None) -> Camera:
    """The overview photo's camera: at S_p looking at C_i (the paper's step 1.2 position)."""
    z = z or zone(turbine)
    return camera.looking_at(initial_point(turbine, z), z.center)


def photo_camera(camera: Camera, width_px: int, height_px: int, position, look_at,
                 roll_deg: float = 0.0) -> Camera:
    """The camera intrinsics at a photo's resolution (a resized photo keeps the field of view).
    The scale goes by the longer sides, so a photo turned upright (portrait, of a landscape
    camera) keeps the camera's angle per pixel."""
    fx = camera.fx * max(width_px, height_px) / max(camera.width_px, camera.height_px)
    cam = Camera(int(width_px), int(height_px), camera.focal_mm, camera.focal_mm * width_px / fx)
    return cam.with_pose(np.asarray(position, float),
                         look_at_rotation(np.asarray(position, float), np.asarray(look_at, float),
                                          roll_deg))


def azimuths_from_image_directions(turbine: Turbine, cam: Camera, hub_px, phis_deg,
                                   lengths_px=None) -> list[float]:
    """Back-project blade directions measured in an image onto the rotor plane.

    hub_px: (x, y) pixel of the hub; phis_deg: each blade's image direction hub -> tip
    (counter-clockwise, image y up, 0 = right); lengths_px: how far along φ to take the second
    point (default a quarter of the image width). Returns rotor azimuths in Turbine's convention.
    """
    hub_px = np.asarray(hub_px, float)
    phis = np.radians(np.asarray(phis_deg, float))
    if lengths_px is None:
        lengths_px = np.full(len(phis), 0.25 * cam.width_px)
    L = np.maximum(np.asarray(lengths_px, float), 10.0)
    tips_px = hub_px + np.stack([np.cos(phis), -np.sin(phis)], axis=1) * L[:, None]
    pts = cam.intersect_plane(np.vstack([hub_px, tips_px]), turbine.hub_center, turbine.axis)
    if not np.isfinite(pts).all():
        raise ValueError("the photo's camera does not see the rotor plane (rays miss it): check "
                         "camera_pose")
    return [azimuth_of(turbine, p - pts[0]) for p in pts[1:]]


def azimuths_from_pitch(turbine: Turbine, pitch, camera: Camera, pose=None) -> list[float]:
    """Rotor azimuths from a ``wtcli.pitch.PitchResult`` of a photo of ``turbine``.

    pose: a ``CameraPose`` (position, look_at, roll) of the photo; default at S_p looking at C_i.
    """
    h, w = pitch.image_size
    if pose is None:
        z = zone(turbine)
        position, look_at, roll = initial_point(turbine, z), z.center, 0.0
    else:
        position, look_at, roll = pose.position, pose.look_at, pose.roll_deg
    cam = photo_camera(camera, w, h, position, look_at, roll)
    hub = np.asarray(pitch.hub_px, float)
    lengths = [max(math.dist(b.tip_px, pitch.hub_px), 0.05 * w) for b in pitch.blades]
    az = azimuths_from_image_directions(turbine, cam, hub, [b.phi_deg for b in pitch.blades], lengths)
    return sorted(az, key=lambda a: (a - 90.0) % 360.0)  # blade 1 the one nearest "up"
