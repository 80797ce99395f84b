"""The flight plan as a typed result and as a file: what ``plan`` writes and ``fly`` reads.

A plan holds the turbines (as the one turbine model), the camera intrinsics, the mission
limits, and one route per UAV. A route is a time-stamped list of waypoints in local ENU metres;
each waypoint says where to be, how fast to go there, where the camera looks and whether to
take a photo. Documented for users in ``docs/plan.md`` ("The plan file").
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wtcli.errors import InputError
from wtcli.geometry import Camera, Turbine
from wtcli.jsonio import document, number, read_json, shown, write_json

PLAN_SCHEMA = "wtinspect.plan"
PLAN_VERSION = 1

# What ``read_plan`` accepts: a plan is read back by ``fly`` and by flight software, so a number
# that ``plan`` could never have written (an edit, a truncation) is refused, naming it.
MAX_COORD_M = 1e6  # any position or length, m from the site origin (1000 km)
LIMITS: dict[str, tuple[float, float]] = {
    "safe_distance_m": (1e-3, 1000.0), "target_gsd_mm": (1e-3, 1000.0),
    "t": (0.0, 1e7), "speed": (0.0, 100.0), "yaw_deg": (-360.0, 720.0),
    "gimbal_pitch_deg": (-180.0, 180.0),
    "hub_height": (1.0, 1000.0), "rotor_diameter": (1.0, 1000.0),
    "width_px": (1, 100_000), "height_px": (1, 100_000), "focal_mm": (1e-3, 1e4),
    "sensor_width_mm": (1e-3, 1e4), "lat": (-90.0, 90.0), "lon": (-180.0, 180.0),
}


@dataclass(frozen=True)
class Route:
    """One UAV's flight. Arrays are columnar, one row per waypoint."""

    uav: str
    t: np.ndarray  # (M,) s from take-off, non-decreasing
    pos: np.ndarray  # (M, 3) ENU m
    speed: np.ndarray  # (M,) m/s commanded on the leg that ends at this waypoint
    yaw_deg: np.ndarray  # (M,) camera heading, compass degrees (0 = north)
    gimbal_pitch_deg: np.ndarray  # (M,) camera elevation, degrees (0 level, -90 down)
    photo: np.ndarray  # (M,) bool: take a photo at this waypoint
    component: np.ndarray  # (M,) str, e.g. "T1/blade2/leading_edge", "T1/tower", "transit"
    summary: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        m = len(self.t)
        arrays = {"t": (np.asarray(self.t, float), (m,)), "pos": (np.asarray(self.pos, float), (m, 3)),
                  "speed": (np.asarray(self.speed, float), (m,)),
                  "yaw_deg": (np.asarray(self.yaw_deg, float), (m,)),
                  "gimbal_pitch_deg": (np.asarray(self.gimbal_pitch_deg, float), (m,)),
                  "photo": (np.asarray(self.photo, bool), (m,)),
                  "component": (np.asarray(self.component, dtype=object), (m,))}
        for name, (arr, shape) in arrays.items():
            if arr.shape != shape:
                raise ValueError(f"route {self.uav!r}: expected {name} of shape {shape}, got {arr.shape}")
            if arr.dtype.kind == "f" and not np.isfinite(arr).all():
                raise ValueError(f"route {self.uav!r}: {name} has non-finite values")
            object.__setattr__(self, name, arr)
        if m < 2:
            raise ValueError(f"route {self.uav!r}: expected at least 2 waypoints, got {m}")
        if (np.diff(self.t) < -1e-9).any():
            raise ValueError(f"route {self.uav!r}: waypoint times must not decrease")
        if (self.speed < 0).any():
            raise ValueError(f"route {self.uav!r}: speeds must be >= 0")

    def __len__(self) -> int:
        return len(self.t)

    @property
    def duration_s(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(np.diff(self.pos, axis=0), axis=1).sum())

    def to_dict(self) -> dict[str, Any]:
        wps = [{"t": float(self.t[i]), "pos": self.pos[i].tolist(), "speed": float(self.speed[i]),
                "yaw_deg": float(self.yaw_deg[i]), "gimbal_pitch_deg": float(self.gimbal_pitch_deg[i]),
                "photo": bool(self.photo[i]), "component": str(self.component[i])}
               for i in range(len(self))]
        return {"uav": self.uav, "summary": self.summary, "waypoints": wps}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Route:
        wps = d["waypoints"]
        return cls(uav=str(d["uav"]), t=np.array([w["t"] for w in wps], float),
                   pos=np.array([w["pos"] for w in wps], float).reshape(-1, 3),
                   speed=np.array([w["speed"] for w in wps], float),
                   yaw_deg=np.array([w["yaw_deg"] for w in wps], float),
                   gimbal_pitch_deg=np.array([w["gimbal_pitch_deg"] for w in wps], float),
                   photo=np.array([w["photo"] for w in wps], bool),
                   component=np.array([w["component"] for w in wps], dtype=object),
                   summary=dict(d.get("summary", {})))


@dataclass(frozen=True)
class Plan:
    turbines: list[Turbine]
    camera: Camera  # intrinsics; the pose changes along the route
    routes: list[Route]
    safe_distance_m: float
    target_gsd_mm: float
    site_origin: dict | None = None  # {"lat", "lon", "alt"} of ENU (0, 0, 0), for exports
    summary: dict = field(default_factory=dict)  # totals, per component, coverage, clearance

    def __post_init__(self) -> None:
        if not self.turbines:
            raise ValueError("a plan needs at least one turbine")
        if not self.routes:
            raise ValueError("a plan needs at least one route")
        if self.safe_distance_m <= 0:
            raise ValueError(f"expected safe_distance_m > 0, got {self.safe_distance_m}")

    def turbine(self, turbine_id: str) -> Turbine:
        for t in self.turbines:
            if t.id == turbine_id:
                return t
        raise KeyError(turbine_id)

    def to_dict(self) -> dict[str, Any]:
        return {"turbines": [t.to_dict() for t in self.turbines],
                "camera": self.camera.intrinsics_dict(),
                "safe_distance_m": self.safe_distance_m, "target_gsd_mm": self.target_gsd_mm,
                "site_origin": self.site_origin, "summary": self.summary,
                "routes": [r.to_dict() for r in self.routes]}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Plan:
        return cls(turbines=[Turbine.from_dict(t) for t in d["turbines"]],
                   camera=Camera.from_dict(d["camera"]),
                   routes=[Route.from_dict(r) for r in d["routes"]],
                   safe_distance_m=float(d["safe_distance_m"]),
                   target_gsd_mm=float(d["target_gsd_mm"]),
                   site_origin=d.get("site_origin"), summary=dict(d.get("summary", {})))


def write_plan(path: str | Path, plan: Plan) -> Path:
    return write_json(path, document(PLAN_SCHEMA, PLAN_VERSION, plan.to_dict()))


def check_plan_numbers(doc: dict[str, Any], path: str | Path) -> None:
    """Every number a plan file holds: finite (``read_json`` refuses NaN and Infinity), and in
    range: the named ones within LIMITS, any other within +-MAX_COORD_M. InputError naming the
    file, the place (``routes[0].waypoints[5].speed``) and the value."""

    def walk(value: Any, where: str, key: str) -> None:
        if isinstance(value, dict):
            for k, v in value.items():
                if where == "summary" or k == "summary":
                    continue  # reporting only; fly and the exports never read it
                walk(v, f"{where}.{k}" if where else str(k), str(k))
        elif isinstance(value, list):
            for i, v in enumerate(value):
                walk(v, f"{where}[{i}]", key)
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            lo, hi = LIMITS.get(key, (-MAX_COORD_M, MAX_COORD_M))
            number(value, f"{path}: {where}", lo, hi)

    walk({k: v for k, v in doc.items() if k not in ("schema_version", "summary")}, "", "")


def read_plan(path: str | Path) -> Plan:
    doc = read_json(path, schema=PLAN_SCHEMA, max_version=PLAN_VERSION)
    check_plan_numbers(doc, path)
    try:
        return Plan.from_dict(doc)
    except KeyError as e:
        raise InputError(f"{path}: plan is missing key {shown(e.args[0])}") from None
    except (TypeError, ValueError, AttributeError, IndexError) as e:
        raise InputError(f"{path}: invalid plan: {str(e)[:200]}") from None
