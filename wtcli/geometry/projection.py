"""Project the turbine mesh through the camera: per-pixel part ids (instance masks) and a
painter's-order face list the synthetic renderer shades. Part of the one geometry: the
renderer, tests and benchmarks get their masks from here, never from a private projection."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from wtcli.geometry.camera import Camera
from wtcli.geometry.turbine import Mesh, Turbine

_SHIFT = 4  # sub-pixel bits for cv2.fillConvexPoly: edges placed to 1/16 px
NEAR_M = 0.3


@dataclass(frozen=True)
class ProjectedMesh:
    """Faces in front of the camera, sorted far -> near (paint in this order)."""

    uv: np.ndarray  # (F, 3, 2) pixel coordinates of each face's corners
    depth: np.ndarray  # (F,) mean depth
    face_index: np.ndarray  # (F,) index into the mesh's faces
    face_part: np.ndarray  # (F,)


def project_mesh(mesh: Mesh, camera: Camera) -> ProjectedMesh:
    uv, z = camera.project(mesh.vertices)
    fz = z[mesh.faces]
    keep = (fz > NEAR_M).all(axis=1)
    # A face is drawn whole or not at all; a face crossing the near plane is dropped (the
    # camera is never that close to the structure in our renders).
    idx = np.nonzero(keep)[0]
    depth = fz[idx].mean(axis=1)
    order = idx[np.argsort(-depth, kind="stable")]
    return ProjectedMesh(uv[mesh.faces[order]], fz[order].mean(axis=1), order,
                         mesh.face_part[order])


def paint(canvas: np.ndarray, projected: ProjectedMesh, values: np.ndarray) -> np.ndarray:
    """Fill each face (far to near) with ``values[i]`` (scalar or colour) on ``canvas``, in place."""
    pts = np.round(projected.uv * (1 << _SHIFT)).astype(np.int64)
    limit = 1 << 28  # keep far-off-screen corners inside cv2's integer range
    pts = np.clip(pts, -limit, limit).astype(np.int32)
    for tri, val in zip(pts, values):
        color = [float(x) for x in val] if np.ndim(val) else float(val)
        cv2.fillConvexPoly(canvas, tri, color, lineType=cv2.LINE_AA if canvas.ndim == 3 else cv2.LINE_8,
                           shift=_SHIFT)
    return canvas


def part_id_map(turbine: Turbine, camera: Camera, mesh: Mesh | None = None) -> np.ndarray:
    """(H, W) int16: -1 background, 0..N-1 blade k, N tower, N+1 nacelle (with hub)."""
    mesh = mesh if mesh is not None else turbine.mesh()
    projected = project_mesh(mesh, camera)
    canvas = np.full((camera.height_px, camera.width_px), -1, np.int16)
    # fillConvexPoly needs a type it can draw into: int32 then cast.
    ids = canvas.astype(np.int32)
    paint(ids, projected, projected.face_part.astype(np.int64))
    return ids.astype(np.int16)


def instance_masks(turbine: Turbine, camera: Camera, min_pixels: int = 1,
                   mesh: Mesh | None = None) -> list[tuple[str, int, np.ndarray]]:
    """Visible instances as (label, index, mask bool (H, W)); label is blade|tower|nacelle and
    index is the blade number (0-based) for blades, 0 otherwise. Occlusion respected."""
    ids = part_id_map(turbine, camera, mesh)
    out = []
    n = turbine.n_blades
    for p in range(n + 2):
        m = ids == p
        if int(m.sum()) < min_pixels:
            continue
        if p < n:
            out.append(("blade", p, m))
        else:
            out.append(("tower" if p == n else "nacelle", 0, m))
    return out
