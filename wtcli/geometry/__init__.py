"""The one geometry: turbine model, camera model and their projection (DESIGN.md)."""

from wtcli.geometry.camera import Camera, look_at_rotation
from wtcli.geometry.turbine import BLADE_SIDES, Mesh, SurfaceSamples, Turbine

__all__ = ["BLADE_SIDES", "Camera", "Mesh", "SurfaceSamples", "Turbine", "look_at_rotation"]
