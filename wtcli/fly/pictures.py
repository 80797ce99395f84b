"""Pictures of a flight report, drawn with OpenCV (no plotting library needed):

- ``path.png``: the path flown beside the planned one, from above and from the side, with the
  turbines' towers and rotor discs and the photo positions;
- ``deviation.png``: distance to the planned path over time, one line per way of flying;
- ``coverage.png``: measured coverage of each blade side, automated beside the baselines;
- ``sensitivity.png`` (with ``--paper-table``): deviation against wind speed, IEC turbulence
  category and positioning mode.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from wtcli.fly.flight import FlightReport
from wtcli.geometry import BLADE_SIDES
from wtcli.jsonio import atomic_write_bytes

# BGR
COLORS = {"planned": (150, 150, 150), "automated": (60, 170, 40), "no_compensation": (40, 40, 220),
          "fixed_pattern": (0, 160, 230), "manual": (200, 110, 30)}
WHITE = (255, 255, 255)
INK = (40, 40, 40)
FONT = cv2.FONT_HERSHEY_SIMPLEX


def _write_png(path: Path, img: np.ndarray) -> Path:
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise OSError(f"cannot encode {path}")
    return atomic_write_bytes(path, buf.tobytes())


class _Axes:
    """Maps data (x, y) to pixels inside a box, y up; draws a frame and ticks."""

    def __init__(self, img: np.ndarray, box: tuple[int, int, int, int], xlim, ylim,
                 equal: bool = False, title: str = "", xlabel: str = "", ylabel: str = "",
                 xticks: bool = True):
        self.img, (self.x0, self.y0, self.x1, self.y1) = img, box
        (a, b), (c, d) = xlim, ylim
        if b - a < 1e-9:
            a, b = a - 1, b + 1
        if d - c < 1e-9:
            c, d = c - 1, d + 1
        if equal:
            sx = (self.x1 - self.x0) / (b - a)
            sy = (self.y1 - self.y0) / (d - c)
            s = min(sx, sy)
            cx, cy = (a + b) / 2, (c + d) / 2
            hw, hh = (self.x1 - self.x0) / s / 2, (self.y1 - self.y0) / s / 2
            a, b, c, d = cx - hw, cx + hw, cy - hh, cy + hh
        self.xlim, self.ylim = (a, b), (c, d)
        cv2.rectangle(img, (self.x0, self.y0), (self.x1, self.y1), INK, 1)
        cv2.putText(img, title, (self.x0, self.y0 - 10), FONT, 0.55, INK, 1, cv2.LINE_AA)
        cv2.putText(img, xlabel, ((self.x0 + self.x1) // 2 - 20, self.y1 + 38), FONT, 0.45, INK, 1,
                    cv2.LINE_AA)
        for v in (_ticks(a, b) if xticks else []):
            px = self.px(np.array([[v, c]]))[0][0]
            cv2.line(img, (px, self.y1), (px, self.y1 + 5), INK, 1)
            cv2.putText(img, f"{v:g}", (px - 12, self.y1 + 20), FONT, 0.4, INK, 1, cv2.LINE_AA)
        for v in _ticks(c, d):
            py = self.px(np.array([[a, v]]))[0][1]
            cv2.line(img, (self.x0 - 5, py), (self.x0, py), INK, 1)
            cv2.putText(img, f"{v:g}", (self.x0 - 48, py + 4), FONT, 0.4, INK, 1, cv2.LINE_AA)
        if ylabel:
            cv2.putText(img, ylabel, (self.x0 + 5, self.y0 + 16), FONT, 0.45, INK, 1, cv2.LINE_AA)

    def px(self, xy: np.ndarray) -> np.ndarray:
        (a, b), (c, d) = self.xlim, self.ylim
        x = self.x0 + (xy[:, 0] - a) / (b - a) * (self.x1 - self.x0)
        y = self.y1 - (xy[:, 1] - c) / (d - c) * (self.y1 - self.y0)
        return np.stack([x, y], 1).round().astype(np.int32)

    def line(self, xy: np.ndarray, color, thickness: int = 1) -> None:
        if len(xy) < 2:
            return
        step = max(1, len(xy) // 4000)
        pts = self.px(xy[::step])
        cv2.polylines(self.img, [pts.reshape(-1, 1, 2)], False, color, thickness, cv2.LINE_AA)

    def dots(self, xy: np.ndarray, color, r: int = 2) -> None:
        for p in self.px(xy):
            cv2.circle(self.img, (int(p[0]), int(p[1])), r, color, -1, cv2.LINE_AA)


def _ticks(a: float, b: float, n: int = 5) -> list[float]:
    span = b - a
    raw = span / n
    mag = 10 ** np.floor(np.log10(raw))
    step = min((m * mag for m in (1, 2, 5, 10)), key=lambda s: abs(s - raw))
    first = np.ceil(a / step) * step
    return [round(float(v), 6) + 0.0 for v in np.arange(first, b + 1e-9, step)]  # no "-0"


def _legend(img: np.ndarray, items: list[tuple[str, tuple]], x: int, y: int,
            across: bool = False) -> None:
    for i, (name, color) in enumerate(items):
        xi, yi = (x + 190 * i, y) if across else (x, y + 20 * i)
        cv2.line(img, (xi, yi), (xi + 25, yi), color, 3)
        cv2.putText(img, name, (xi + 32, yi + 5), FONT, 0.45, INK, 1, cv2.LINE_AA)


def path_picture(report: FlightReport) -> np.ndarray:
    img = np.full((640, 1240, 3), 255, np.uint8)
    auto = report.automated
    planned = np.concatenate([u.planned.pos for u in auto.uavs])
    flown = {k: np.concatenate([u.track.pos for u in f.uavs]) for k, f in report.flights.items()
             if k in ("automated", "manual", "fixed_pattern")}
    pts = np.concatenate([planned] + [t.base_xyz[None] for t in auto.turbines]
                         + [t.blade_tips() for t in auto.turbines])
    lo, hi = pts.min(0) - 10, pts.max(0) + 10
    top = _Axes(img, (70, 60, 600, 560), (lo[0], hi[0]), (lo[1], hi[1]), equal=True,
                title="from above (x east, y north, m)")
    side = _Axes(img, (690, 60, 1220, 560), (lo[0], hi[0]), (min(lo[2], 0), hi[2]), equal=True,
                 title="from the south (x east, z up, m)")
    for t in auto.turbines:
        b = t.base_xyz
        top.dots(b[None, :2], INK, 4)
        side.line(np.array([[b[0], b[2]], [b[0], t.hub_center[2]]]), INK, 2)
        for tip in t.blade_tips():
            top.line(np.array([t.hub_center[:2], tip[:2]]), INK, 1)
            side.line(np.array([t.hub_center[[0, 2]], tip[[0, 2]]]), INK, 2)
    top.line(planned[:, :2], COLORS["planned"], 3)
    side.line(planned[:, [0, 2]], COLORS["planned"], 3)
    for k, p in flown.items():
        top.line(p[:, :2], COLORS[k], 1)
        side.line(p[:, [0, 2]], COLORS[k], 1)
    photos = np.concatenate([u.photo_pos for u in auto.uavs]) if auto.photos else np.zeros((0, 3))
    top.dots(photos[:, :2], COLORS["automated"], 2)
    side.dots(photos[:, [0, 2]], COLORS["automated"], 2)
    _legend(img, [("planned", COLORS["planned"])] + [(k, COLORS[k]) for k in flown], 80, 612,
            across=True)
    return img


def deviation_picture(report: FlightReport) -> np.ndarray:
    img = np.full((420, 1000, 3), 255, np.uint8)
    series = {}
    for k, f in report.flights.items():
        u = f.uavs[0]
        n = min(len(u.track.t), len(f.deviation))
        series[k] = (u.track.t[:n] - u.track.t[0], f.deviation[:n])
    tmax = max(s[0][-1] for s in series.values())
    dmax = max(float(np.percentile(s[1], 99.5)) for s in series.values())
    ax = _Axes(img, (70, 50, 960, 350), (0, tmax), (0, max(dmax * 1.1, 0.1)),
               title=f"distance to the planned path ({report.automated.uavs[0].uav}), m",
               xlabel="time, s")
    for k, (t, d) in series.items():
        ax.line(np.stack([t, np.minimum(d, dmax * 1.1)], 1), COLORS[k], 1)
    _legend(img, [(k, COLORS[k]) for k in series], 760, 70)
    return img


def coverage_picture(report: FlightReport) -> np.ndarray:
    kinds = [k for k in ("automated", "fixed_pattern", "manual", "no_compensation")
             if k in report.flights]
    labels, values = [], {k: [] for k in kinds}
    for tid in report.automated.coverage:
        for blade, sides in report.automated.coverage[tid].by_blade_side().items():
            for side in BLADE_SIDES:
                labels.append(f"{tid}/{blade}" if side == BLADE_SIDES[0] else "")
                for k in kinds:
                    cov = report.flights[k].coverage.get(tid)
                    values[k].append(cov.by_blade_side()[blade][side] if cov else 0.0)
    w = max(900, 60 + len(labels) * (8 * len(kinds) + 12))
    img = np.full((460, w, 3), 255, np.uint8)
    ax = _Axes(img, (60, 50, w - 20, 330), (0, len(labels)), (0, 100),
               title="coverage per blade side, % (sides: leading edge, pressure, trailing edge, suction)",
               xticks=False)
    for i, lab in enumerate(labels):
        for j, k in enumerate(kinds):
            x0 = ax.px(np.array([[i + 0.1 + 0.8 * j / len(kinds), 0]]))[0]
            x1 = ax.px(np.array([[i + 0.1 + 0.8 * (j + 1) / len(kinds), 100 * values[k][i]]]))[0]
            cv2.rectangle(img, (int(x0[0]), int(x0[1])), (int(x1[0]) - 1, int(x1[1])), COLORS[k], -1)
        if lab:
            p = ax.px(np.array([[i + 0.1, 0]]))[0]
            cv2.putText(img, lab, (int(p[0]), 350), FONT, 0.4, INK, 1, cv2.LINE_AA)
    y97 = ax.px(np.array([[0, 97.0]]))[0][1]
    cv2.line(img, (60, int(y97)), (w - 20, int(y97)), (0, 0, 200), 1)
    _legend(img, [(k, COLORS[k]) for k in kinds], 70, 400, across=True)
    return img


def write_pictures(report: FlightReport, folder: str | Path) -> list[Path]:
    folder = Path(folder)
    return [_write_png(folder / "path.png", path_picture(report)),
            _write_png(folder / "deviation.png", deviation_picture(report)),
            _write_png(folder / "coverage.png", coverage_picture(report))]


def sensitivity_picture(sens: dict[str, list], title: str) -> np.ndarray:
    """Three panels: mean and 99.9th-percentile deviation against wind speed, turbulence
    category and positioning mode (``wtcli.fly.run.sensitivity``)."""
    img = np.full((440, 1240, 3), 255, np.uint8)
    cv2.putText(img, title, (70, 25), FONT, 0.55, INK, 1, cv2.LINE_AA)
    ymax = max(p["p99_9_m"] for pts in sens.values() for p in pts) * 1.1 or 0.1
    panels = (("wind_ms", "hub-height wind, m/s"), ("turbulence_class", "IEC turbulence category"),
              ("positioning", "positioning"))
    for i, (key, label) in enumerate(panels):
        pts = sens[key]
        x0 = 70 + i * 400
        numeric = key == "wind_ms"
        xs = [float(p["x"]) for p in pts] if numeric else list(range(len(pts)))
        ax = _Axes(img, (x0, 60, x0 + 330, 360), (min(xs) - 0.5, max(xs) + 0.5), (0, ymax),
                   title=f"deviation (m) vs {label}", xticks=numeric)
        for name, color in (("mean_m", COLORS["automated"]), ("p99_9_m", COLORS["fixed_pattern"])):
            xy = np.array([[x, p[name]] for x, p in zip(xs, pts)])
            ax.line(xy, color, 2)
            ax.dots(xy, color, 4)
        if not numeric:
            for x, p in zip(xs, pts):
                px = ax.px(np.array([[x, 0.0]]))[0]
                cv2.putText(img, str(p["x"]), (int(px[0]) - 20, 380), FONT, 0.42, INK, 1, cv2.LINE_AA)
    _legend(img, [("mean", COLORS["automated"]), ("99.9th percentile", COLORS["fixed_pattern"])],
            70, 415, across=True)
    return img


def write_sensitivity(sens: dict[str, list], folder: str | Path, title: str) -> Path:
    return _write_png(Path(folder) / "sensitivity.png", sensitivity_picture(sens, title))
