"""A picture of the planned path around the turbine(s): front, side and top views side by side.

Orthographic views: front (as a viewer in front of the first turbine's rotor sees it: right =
the viewer's right, up = z) and side (seen from that viewer's right: the rotor's front to the
left), both framing the first turbine; top (east right, north up) shows the whole site. Turbines are drawn from
the one turbine model (blade axes with their chord as width, tower, nacelle, hub); each UAV's path
is a coloured line, photo waypoints dots. BGR uint8 image, [H, W, 3].
"""

from __future__ import annotations

import cv2
import numpy as np

from wtcli.plan_file import Plan

PANEL = 520
MARGIN = 30
UAV_COLORS = [(40, 110, 240), (60, 180, 60), (200, 120, 30), (180, 60, 180), (30, 190, 200),
              (120, 120, 220)]
TURBINE_COLOR = (150, 150, 150)
BLADE_COLOR = (90, 90, 90)


def _axes(plan: Plan) -> list[tuple[str, np.ndarray]]:
    t = plan.turbines[0]
    z = np.array([0.0, 0.0, 1.0])
    front = np.stack([t.right, z])  # rows: image-right axis, image-up axis
    side = np.stack([-t.axis, z])
    top = np.stack([np.array([1.0, 0, 0]), np.array([0, 1.0, 0])])
    return [("front", front), ("side", side), ("top", top)]


def _turbine_polylines(t) -> list[tuple[np.ndarray, float, tuple]]:
    """(3-D polyline, width in m, colour) pieces that draw a turbine."""
    out = []
    for k in range(t.n_blades):
        out.append((np.array([t.hub_center, t.blade_tips()[k]]), t.blade_max_chord * 0.6, BLADE_COLOR))
    top = t.base_xyz + np.array([0, 0, t.tower_height])
    out.append((np.array([t.base_xyz, top]), 2 * t.tower_top_radius, TURBINE_COLOR))
    a = t.axis
    c = t.nacelle_center
    out.append((np.array([c - a * t.nacelle_length / 2, c + a * t.nacelle_length / 2]),
                t.nacelle_height, TURBINE_COLOR))
    out.append((np.array([t.hub_center, t.hub_center]), 2 * t.hub_radius, BLADE_COLOR))
    return out


def draw_plan(plan: Plan, panel: int = PANEL) -> np.ndarray:
    views = _axes(plan)
    allpts = np.vstack([r.pos for r in plan.routes] + [t.blade_tips() for t in plan.turbines]
                       + [t.base_xyz[None] for t in plan.turbines])
    t0 = plan.turbines[0]  # front and side views frame the first turbine
    near = np.vstack([t0.blade_tips(), t0.base_xyz[None]] +
                     [r.pos[np.linalg.norm(r.pos - t0.hub_center, axis=1) < 1.3 * t0.tip_radius + 15]
                      for r in plan.routes])
    panels = []
    for v, (name, M) in enumerate(views):
        canvas = np.full((panel + 40, panel, 3), 255, np.uint8)  # each view clips to its own panel
        pts = allpts if name == "top" else near
        uv = pts @ M.T
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        scale = (panel - 2 * MARGIN) / max(float((hi - lo).max()), 1e-6)
        center = 0.5 * (lo + hi)

        def px(P: np.ndarray) -> np.ndarray:
            q = (np.atleast_2d(P) @ M.T - center) * scale
            return np.stack([panel / 2 + q[:, 0], 40 + panel / 2 - q[:, 1]], axis=1)

        for t in (plan.turbines if name == "top" else [t0]):
            for line, width, color in _turbine_polylines(t):
                p = np.round(px(line)).astype(np.int32)
                w = max(1, int(round(width * scale)))
                if np.allclose(p[0], p[-1]):
                    cv2.circle(canvas, tuple(int(x) for x in p[0]), max(1, w // 2), color, -1, cv2.LINE_AA)
                else:
                    cv2.polylines(canvas, [p.reshape(-1, 1, 2)], False, color, min(w, 60), cv2.LINE_AA)
        for i, r in enumerate(plan.routes):
            color = UAV_COLORS[i % len(UAV_COLORS)]
            p = np.round(np.clip(px(r.pos), -10 * panel, 10 * panel)).astype(np.int32)
            keep = np.ones(len(p), bool)
            if name != "top":  # front/side: only the first turbine's neighbourhood
                keep = np.linalg.norm(r.pos - t0.hub_center, axis=1) < 1.3 * t0.tip_radius + 15
                keep[0] = True
            for run in np.split(np.arange(len(p)), np.nonzero(np.diff(keep.astype(int)))[0] + 1):
                if keep[run[0]] and len(run) > 1:
                    cv2.polylines(canvas, [p[run].reshape(-1, 1, 2)], False, color, 1, cv2.LINE_AA)
            for q in p[r.photo & keep]:
                cv2.circle(canvas, (int(q[0]), int(q[1])), 2, color, -1)
            cv2.drawMarker(canvas, tuple(int(x) for x in p[0]), (0, 0, 0), cv2.MARKER_TRIANGLE_UP, 12, 2)
        label = name if name == "top" or len(plan.turbines) == 1 else f"{name} ({t0.id})"
        cv2.rectangle(canvas, (0, 0), (panel, 36), (255, 255, 255), -1)
        cv2.putText(canvas, label, (10, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 0, 0), 2, cv2.LINE_AA)
        if v:
            cv2.line(canvas, (0, 0), (0, panel + 40), (200, 200, 200), 1)
        panels.append(canvas)
    canvas = np.hstack(panels)
    s = plan.summary
    if s:
        text = (f"{s.get('pattern', '')}  length {s.get('total_length_m', 0):.0f} m  time "
                f"{s.get('total_time_s', 0) / 60:.1f} min  photos {s.get('photos', 0)}  min clearance "
                f"{s.get('min_clearance_m', 0):.2f} m")
        cv2.rectangle(canvas, (0, panel + 16), (3 * panel, panel + 40), (255, 255, 255), -1)
        cv2.putText(canvas, text, (10, panel + 34), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                    (0, 0, 0), 1, cv2.LINE_AA)
    return canvas
