"""Mission exports of a Plan: QGroundControl ``.plan``, MAVLink ``QGC WPL 110``, GeoJSON, and
DJI WPML ``.kmz`` on request (``wtcli.plan.dji_kmz``). docs/plan.md "Mission exports".

One file per UAV and sortie (a battery swap ends a sortie: a mission file is flown on one
battery). Every position is the exact WGS84 conversion of the plan's ENU point
(``wtcli.plan.geodesy``). Waypoints are in frame 3: altitude relative to the launch point (home)
= the point's height minus home's, both exact (not the ENU z difference, which is d^2/2R lower
at d from the origin). Home is the launch point in frame 0, AMSL (site.origin.alt plus the
ellipsoid-height difference). Commands used:

* 22 NAV_TAKEOFF to the take-off altitude, 16 NAV_WAYPOINT (p2 acceptance radius, p4 yaw = the
  camera heading: PX4 turns to it, ArduPilot Copter ignores it), 21 NAV_LAND at home;
* 178 DO_CHANGE_SPEED (p1 = 1 ground speed, p2 m/s, rounded down to 0.1) whenever the planned
  speed changes;
* 205 DO_MOUNT_CONTROL (p1 gimbal pitch, p7 = 2 MAVLink targeting) whenever the gimbal pitch
  changes, placed before the waypoint it is for;
* 203 DO_DIGICAM_CONTROL (p5 = 1: shoot) after each photo waypoint.

ArduPilot's 196 DO_SET_ROI_WPNEXT_OFFSET is never used.
"""

from __future__ import annotations

import errno
import json
import math
import os
import re
import shutil
import socket
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from wtcli.errors import ConfigError, InputError, OutputError
from wtcli.jsonio import read_json, write_failed
from wtcli.plan.geodesy import MAX_SITE_RADIUS_M, check_site_extent, enu_to_geodetic
from wtcli.plan_file import Plan, Route

ACCEPT_RADIUS_M = 0.5
ALTITUDE_REFERENCE = ("metres above mean sea level: site.origin.alt plus the exact WGS84 "
                      "ellipsoid-height difference from the origin (geoid taken as parallel to "
                      "the ellipsoid across the site)")
FIRMWARE_ARDUPILOT = 3
VEHICLE_QUAD = 2


@dataclass(frozen=True)
class Item:
    command: int
    frame: int
    params: tuple  # 7 values: p1..p4, then lat, lon, alt (None where unset)

    @property
    def has_coordinate(self) -> bool:
        return self.command in (16, 22, 21)


def sorties(route: Route) -> list[tuple[int, int]]:
    """(first, last) waypoint indices of each flight between take-off and landing."""
    ground = np.isclose(route.pos[:, 2], route.pos[0, 2]) & \
        (np.linalg.norm(route.pos[:, :2] - route.pos[0, :2], axis=1) < 0.5)
    g = np.nonzero(ground)[0]
    return [(int(a), int(b)) for a, b in zip(g[:-1], g[1:]) if b > a + 1]


def _require_origin(plan: Plan) -> dict:
    if not plan.site_origin:
        raise ConfigError("exports to lat/lon need site.origin (lat, lon, alt) in turbines.yaml")
    return plan.site_origin


def check_plan_extent(plan: Plan) -> None:
    """Refuse (ConfigError) a plan whose turbines or routes reach beyond the site radius."""
    check_site_extent({f"turbines[{i}] ({t.id}).position": t.base_xyz
                       for i, t in enumerate(plan.turbines)})
    for r in plan.routes:
        far = np.nonzero(~(np.hypot(r.pos[:, 0], r.pos[:, 1]) <= MAX_SITE_RADIUS_M))[0]
        if far.size:
            check_site_extent({f"{r.uav} route point {int(far[0])} (launch point or leg)":
                               r.pos[far[0]]})


def mission_items(plan: Plan, route: Route, first: int, last: int) -> tuple[list[Item], np.ndarray]:
    """The items of one sortie (without the home row) and home [lat, lon, alt AMSL]."""
    origin = _require_origin(plan)
    llh = enu_to_geodetic(route.pos[first:last + 1], origin)
    home = llh[0]
    rel = llh[:, 2] - home[2]  # exact height above home, not the ENU z difference
    items: list[Item] = []
    speed, pitch = None, None
    n = last - first + 1
    for j in range(1, n - 1):  # skip the ground points: take-off and landing are commands
        i = first + j
        lat, lon = float(llh[j, 0]), float(llh[j, 1])
        alt = float(rel[j])
        yaw = float(route.yaw_deg[i])
        if j == 1:
            items.append(Item(22, 3, (0.0, 0.0, 0.0, yaw, lat, lon, alt)))
            continue
        # Rounded down to 0.1 m/s: a photo leg never faster than its blur and interval limits.
        v = max(0.1, math.floor(float(route.speed[i]) * 10 + 1e-6) / 10) if route.speed[i] > 0 else 0.0
        if v > 0 and v != speed:
            items.append(Item(178, 2, (1.0, v, -1.0, 0.0, None, None, None)))
            speed = v
        g = round(float(route.gimbal_pitch_deg[i]), 1)
        if g != pitch:
            items.append(Item(205, 2, (g, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0)))
            pitch = g
        items.append(Item(16, 3, (0.0, ACCEPT_RADIUS_M, 0.0, yaw, lat, lon, alt)))
        if route.photo[i]:
            items.append(Item(203, 2, (0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0)))
    items.append(Item(21, 3, (0.0, 0.0, 0.0, float(route.yaw_deg[last]), float(llh[-1, 0]),
                              float(llh[-1, 1]), round(float(rel[-1]), 3) + 0.0)))
    return items, home


def wpl_text(items: list[Item], home: np.ndarray) -> str:
    """MAVLink plain-text mission: header, home row 0 (frame 0, AMSL), items from index 1."""
    lines = ["QGC WPL 110",
             "\t".join(["0", "1", "0", "16", "0", "0", "0", "0", f"{home[0]:.8f}", f"{home[1]:.8f}",
                        f"{home[2]:.3f}", "1"])]
    for k, it in enumerate(items, start=1):
        p = list(it.params)
        lat = f"{p[4]:.8f}" if p[4] is not None else "0"
        lon = f"{p[5]:.8f}" if p[5] is not None else "0"
        alt = f"{p[6]:.3f}" if p[6] is not None else "0"
        lines.append("\t".join([str(k), "0", str(it.frame), str(it.command)]
                               + [f"{float(x):.6g}" for x in p[:4]] + [lat, lon, alt, "1"]))
    return "\n".join(lines) + "\n"


def qgc_plan_dict(items: list[Item], home: np.ndarray, cruise: float, hover: float) -> dict:
    out = []
    for k, it in enumerate(items, start=1):
        params = [None if x is None else (round(float(x), 8)) for x in it.params]
        d = {"type": "SimpleItem", "command": it.command, "frame": it.frame, "autoContinue": True,
             "doJumpId": k, "params": params}
        if it.has_coordinate:
            d.update({"Altitude": params[6], "AltitudeMode": 1, "AMSLAltAboveTerrain": None})
        out.append(d)
    return {"fileType": "Plan", "version": 1, "groundStation": "wtinspect",
            "mission": {"version": 2, "firmwareType": FIRMWARE_ARDUPILOT, "vehicleType": VEHICLE_QUAD,
                        "cruiseSpeed": round(cruise, 3), "hoverSpeed": round(hover, 3),
                        "globalPlanAltitudeMode": 1,
                        "plannedHomePosition": [round(float(home[0]), 8), round(float(home[1]), 8),
                                                round(float(home[2]), 3)],
                        "items": out},
            "geoFence": {"circles": [], "polygons": [], "version": 2},
            "rallyPoints": {"points": [], "version": 2}}


def geojson_dict(plan: Plan) -> dict:
    """RFC 7946 FeatureCollection: turbines (points), each route (line) and its photo points;
    coordinates [lon, lat, alt AMSL], exact WGS84; the foreign member ``altitude_reference``
    says so in the file."""
    origin = _require_origin(plan)
    check_plan_extent(plan)
    feats = []
    for t in plan.turbines:
        ll = enu_to_geodetic(t.base_xyz[None], origin)[0]
        feats.append({"type": "Feature", "geometry": {"type": "Point", "coordinates":
                      [round(float(ll[1]), 8), round(float(ll[0]), 8), round(float(ll[2]), 3)]},
                      "properties": {"kind": "turbine", "id": t.id, "hub_height_m": t.hub_height,
                                     "rotor_diameter_m": t.rotor_diameter, "yaw_deg": t.yaw_deg}})
    for r in plan.routes:
        ll = enu_to_geodetic(r.pos, origin)
        coords = [[round(float(p[1]), 8), round(float(p[0]), 8), round(float(p[2]), 3)] for p in ll]
        feats.append({"type": "Feature", "geometry": {"type": "LineString", "coordinates": coords},
                      "properties": {"kind": "route", "uav": r.uav, "length_m": round(r.length_m, 2),
                                     "time_s": round(r.duration_s, 2), "photos": int(r.photo.sum())}})
        photos = [c for c, f in zip(coords, r.photo) if f]
        if photos:
            feats.append({"type": "Feature", "geometry": {"type": "MultiPoint", "coordinates": photos},
                          "properties": {"kind": "photos", "uav": r.uav}})
    return {"type": "FeatureCollection", "altitude_reference": ALTITUDE_REFERENCE, "features": feats}


@dataclass(frozen=True)
class ExportSet:
    """What ``export_all`` did in its folder: this plan's files, and the files of an earlier
    export of the same stem it replaced (same name) or removed (a sortie or UAV this plan
    has not)."""

    written: tuple[Path, ...]
    replaced: tuple[Path, ...] = ()
    removed: tuple[Path, ...] = ()
    stale: tuple[Path, ...] = ()  # staging folders of killed runs, removed


# STEM_UAV_sN.EXT: the sortie files of one export set (STEM.geojson is the set's map).
_SORTIE_FILE = re.compile(r"_s[1-9][0-9]*\.(plan|waypoints|kmz)$")
STAGING_PREFIX = ".wtinspect-exports."


def export_all(plan: Plan, out_dir: str | Path, stem: str = "mission", cruise: float = 8.0,
               hover: float = 2.0, dji: str | None = None,
               before_swap: Callable[[], None] | None = None) -> ExportSet:
    """Write ``STEM_UAV_sN.plan`` and ``.waypoints`` per UAV sortie and ``STEM.geojson``; with
    ``dji`` (a key of ``wtcli.plan.dji_kmz.AIRCRAFT``) also a DJI WPML ``STEM_UAV_sN.kmz``.

    The files are one set: written into a staging folder inside ``out_dir`` first; only when
    all are written are the earlier export files of ``stem`` removed and the new ones renamed
    in. A failure before that (a full disk: OutputError naming the file) leaves the earlier set
    whole; files of other stems and other files are never touched. ``before_swap`` runs once
    the set is staged, before the earlier set is touched (``plan`` writes its plan JSON there,
    so a failed export leaves the earlier plan and its export together); if it raises, nothing
    is swapped.

    A staging folder that a killed run left (its owner file names a process of this host that
    no longer runs) is removed first; one of a running or another host's run is left alone."""
    from wtcli.plan import dji_kmz

    _require_origin(plan)
    check_plan_extent(plan)
    for r in plan.routes:
        if "/" in r.uav or os.sep in r.uav or r.uav in (".", "..") or "\0" in r.uav:
            raise ConfigError(f"fleet.uavs: {r.uav!r} cannot be part of a file name "
                              f"(exports are named {stem}_UAV_sN)")
    ac = dji_kmz.aircraft(dji) if dji is not None else None
    kmz = []  # built before anything is written: a refused DJI export creates nothing
    if ac is not None:
        for r in plan.routes:
            for s, (a, b) in enumerate(sorties(r), start=1):
                kmz.append((f"{stem}_{r.uav}_s{s}.kmz", dji_kmz.kmz_bytes(
                    dji_kmz.sortie_waypoints(plan, r, a, b), ac, cruise, hover)))

    def files():
        yield from kmz
        for r in plan.routes:
            for s, (a, b) in enumerate(sorties(r), start=1):
                items, home = mission_items(plan, r, a, b)
                base = f"{stem}_{r.uav}_s{s}"
                yield base + ".waypoints", wpl_text(items, home).encode("utf-8")
                yield base + ".plan", _text(json.dumps(qgc_plan_dict(items, home, cruise, hover),
                                                        indent=1, allow_nan=False))
        yield f"{stem}.geojson", _text(json.dumps(geojson_dict(plan), allow_nan=False))

    return _write_set(Path(out_dir), stem, files(), before_swap)


def _text(s: str) -> bytes:
    return (s if s.endswith("\n") else s + "\n").encode("utf-8")


def _write_set(out_dir: Path, stem: str, files, before_swap=None) -> ExportSet:
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        stale = _remove_stale_staging(out_dir)
        staging = Path(tempfile.mkdtemp(prefix=STAGING_PREFIX, dir=out_dir))
        (staging / OWNER_FILE).write_text(f"{socket.gethostname()}\n{os.getpid()}\n", encoding="utf-8")
    except OSError as e:
        raise write_failed(out_dir, e) from None
    try:
        names = []
        for name, data in files:
            _stage(staging / name, out_dir / name, data)
            names.append(name)
        for name in names:  # checked before the earlier set is touched
            _check_in_the_way(out_dir / name)
        check_map_is_ours(out_dir, stem)
        if before_swap is not None:
            before_swap()
        earlier = earlier_exports(out_dir, stem)
        # The earlier set goes before the new one comes in: an interruption in between leaves
        # part of one plan (the map last), never the sorties of two plans side by side.
        for p in earlier:
            try:
                p.unlink(missing_ok=True)
            except OSError as e:
                raise write_failed(p, e) from None
        for name in names:
            try:
                os.replace(staging / name, out_dir / name)
            except OSError as e:
                raise write_failed(out_dir / name, e) from None
    finally:  # also on KeyboardInterrupt: no staging folder is left behind
        shutil.rmtree(staging, ignore_errors=True)
    new = set(names)
    return ExportSet(tuple(out_dir / n for n in names),
                     tuple(p for p in earlier if p.name in new),
                     tuple(p for p in earlier if p.name not in new), stale)


OWNER_FILE = "owner"  # in a staging folder: "HOST\nPID\n" of the run writing it


def _remove_stale_staging(out_dir: Path) -> tuple[Path, ...]:
    """Remove the staging folders in ``out_dir`` whose run was killed (SIGKILL, power loss):
    their owner file names this host and a process id that no longer runs. A folder of a
    running export, of another host (a shared disk) or without a readable owner file is kept."""
    host, gone = socket.gethostname(), []
    for e in os.scandir(out_dir):
        if not e.name.startswith(STAGING_PREFIX) or not e.is_dir(follow_symlinks=False):
            continue
        try:
            owner_host, pid = (Path(e.path) / OWNER_FILE).read_text(encoding="utf-8").split()
            pid = int(pid)
        except (OSError, ValueError):
            continue
        if owner_host != host or pid <= 0 or _running(pid):
            continue
        shutil.rmtree(e.path, ignore_errors=True)
        if not os.path.lexists(e.path):
            gone.append(Path(e.path))
    return tuple(gone)


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # PermissionError: another user's process runs under that id
        return True
    return True


def _stage(tmp: Path, final: Path, data: bytes) -> None:
    """Write one export file into the staging folder. Not ``jsonio.atomic_write_bytes``: the
    staging folder is already the temporary, and a failure must name the file the user asked
    for (``final``), not the staging path."""
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # the umask applies
        with os.fdopen(fd, "wb") as f:
            f.write(data)
    except OSError as e:
        raise write_failed(final, e) from None


def _check_in_the_way(path: Path) -> None:
    if path.is_symlink() or not path.exists() or path.is_file():
        return
    if path.is_dir():
        raise write_failed(path, IsADirectoryError(errno.EISDIR, "a folder is in the way"))
    raise OutputError(f"{path}: is not a regular file (a device, pipe or socket); write to a file")


MAP_KINDS = ("turbine", "route", "photos")  # the features' properties.kind in STEM.geojson
MAX_MAP_BYTES = 512 * 2 ** 20


def check_export_names(out_dir: str | Path, stem: str, uavs: tuple[str, ...]) -> None:
    """OutputError (exit 3) before planning when a sortie file's name, ``STEM_UAV_sN.waypoints``
    with N up to 999, would pass the 255-byte limit on a file name (a long ``--out`` name)."""
    from wtcli.jsonio import NAME_MAX

    for uav in uavs:
        name = f"{stem}_{uav}_s999.waypoints"
        if len(os.fsencode(name)) > NAME_MAX:
            raise OutputError(f"{Path(out_dir) / name}: the export's file names would be over the "
                              f"{NAME_MAX}-byte limit of a file name; give --out a shorter name "
                              "(the exports are named after it)")


def check_map_is_ours(out_dir: str | Path, stem: str) -> None:
    """OutputError (exit 3) when ``STEM.geojson`` in ``out_dir`` is not the map of an earlier
    export (a user's own GeoJSON under that name: a site boundary, a survey), which the export
    would replace. Ours: a FeatureCollection whose features are all turbines, routes and photo
    points (``properties.kind``), at least one route among them."""
    path = Path(out_dir) / f"{stem}.geojson"
    if not path.is_file():
        return
    ours = False
    try:
        doc = read_json(path, max_bytes=MAX_MAP_BYTES)
        kinds = [f["properties"]["kind"] for f in doc["features"]]
        ours = (doc.get("type") == "FeatureCollection" and "route" in kinds
                and all(k in MAP_KINDS for k in kinds))
    except (InputError, KeyError, TypeError, AttributeError):  # unreadable or another shape
        pass
    if not ours:
        raise OutputError(f"{path}: is not the map of an earlier wtinspect export, and this "
                          f"export's map would replace it; move it, or pick another --out name "
                          f"(the exports are named after it)")


def earlier_exports(out_dir: str | Path, stem: str) -> list[Path]:
    """The files of an earlier export of ``stem`` in ``out_dir``: ``STEM.geojson`` and
    ``STEM_UAV_sN.plan|waypoints|kmz``, sorted. A UAV id may hold "_", so a file another
    stem's set may own (``STEM_X_UAV1_s1.plan`` beside a ``STEM_X.geojson`` whose routes include
    UAV1) is left to that set."""
    out_dir = Path(out_dir)
    found, maps = [], {}
    try:
        entries = sorted(os.scandir(out_dir), key=lambda e: e.name)
    except FileNotFoundError:
        return []
    except OSError as e:
        raise write_failed(out_dir, e) from None
    for e in entries:
        if e.is_dir(follow_symlinks=False):
            continue
        if e.name == f"{stem}.geojson":
            found.append(Path(e.path))
            continue
        m = _SORTIE_FILE.search(e.name)
        if m is None or not e.name.startswith(stem + "_") or m.start() <= len(stem) + 1:
            continue
        head = e.name[:m.start()]  # STEM_UAV
        cuts = [k for k in range(1, len(head)) if head[k] == "_" and k != len(stem)]
        if not any(_owned_by(out_dir / f"{head[:k]}.geojson", head[k + 1:], maps) for k in cuts):
            found.append(Path(e.path))
    return found


def _owned_by(geojson: Path, uav: str, maps: dict) -> bool:
    """Whether the export whose map is ``geojson`` has a route of ``uav``; a map that cannot be
    read owns every id (its files are left alone rather than guessed at)."""
    if geojson not in maps:
        uavs: set[str] | None = set()
        if geojson.is_file():
            try:
                doc = json.loads(geojson.read_text(encoding="utf-8"))
                uavs = {str(f["properties"]["uav"]) for f in doc["features"]
                        if f["properties"].get("kind") == "route"}
            except (OSError, ValueError, KeyError, TypeError, AttributeError):
                uavs = None
        maps[geojson] = uavs
    return maps[geojson] is None or uav in maps[geojson]
