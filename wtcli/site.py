"""Turbine lists users already own -> ``turbines.yaml``: the U.S. Wind Turbine Database (USWTDB)
CSV and OpenStreetMap GeoJSON of wind generators. docs/site.md

Nothing is invented silently: a value a source lacks is either filled from a default the user gave
(and reported for that row) or the row is skipped (and reported); the rotor heading (``yaw_deg``),
which no database holds, is written from ``yaw_deg`` and said so. Every kept turbine is written by
latitude/longitude, so ``wtcli.plan.config`` converts it exactly through the site origin.

Everything the turbines.yaml loader checks of what is written here (ranges, hub above the rotor,
unique ids, towers a rotor apart, positions within its reach of the origin) is checked here first,
per row, so a problem is reported by its row and the written file always loads.
"""

from __future__ import annotations

import csv
import difflib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from wtcli.errors import ConfigError, InputError
from wtcli.jsonio import MAX_JSON_BYTES, read_capped, read_json, shown
from wtcli.plan.config import SITE_REACH_M, SITE_Z_M
from wtcli.plan.geodesy import MAX_SITE_RADIUS_M, geodetic_to_enu

USWTDB_COLUMNS = ("case_id", "xlong", "ylat", "t_hh", "t_rd", "t_cap", "p_name")
# Ranges the turbines.yaml loader accepts (docs/turbines-yaml.md): a row outside them is skipped
# here with its reason, rather than written and refused later without the row number.
HUB_RANGE_M = (10.0, 250.0)
DIAMETER_RANGE_M = (5.0, 300.0)
_MISSING = {"", "na", "nan", "null", "none", "-9999", "-9999.0"}
# OSM length units (wiki "Map features/Units"): metres by default; feet/inches also as 4'11"
_OSM_UNITS_M = {"": 1.0, "m": 1.0, "km": 1000.0, "ft": 0.3048, "mi": 1609.344, "nmi": 1852.0}
_OSM_LENGTH = re.compile(r"([+-]?(?:[0-9]+(?:[.,][0-9]+)?|[.,][0-9]+))\s*(m|km|ft|mi|nmi)?", re.I)
_OSM_FEET_INCHES = re.compile(r"(?:([0-9]+(?:\.[0-9]+)?)\s*')?\s*(?:([0-9]+(?:\.[0-9]+)?)\s*\")?")


@dataclass(frozen=True)
class SiteTurbine:
    id: str
    lat: float
    lon: float
    hub_height_m: float
    rotor_diameter_m: float
    source: str  # "row 12 (case_id 3001234)" or "feature 3 (node/123)"
    capacity_kw: float | None = None


@dataclass
class Site:
    """Turbines read from one source, the origin chosen, and every row-level problem."""

    source: str
    turbines: list[SiteTurbine]
    origin: dict
    yaw_deg: float
    problems: list[str] = field(default_factory=list)  # "row 7 (case_id 12): t_rd is 0: skipped"

    def to_yaml_dict(self) -> dict:
        return {
            "site": {"origin": self.origin},
            "turbines": [{"id": t.id, "lat": round(t.lat, 8), "lon": round(t.lon, 8),
                          "hub_height_m": round(t.hub_height_m, 2),
                          "rotor_diameter_m": round(t.rotor_diameter_m, 2), "yaw_deg": self.yaw_deg}
                         for t in self.turbines],
        }

    def to_yaml_text(self) -> str:
        head = [f"# turbines.yaml built by `wtinspect site` from {self.source}",
                f"# {len(self.turbines)} turbine(s); every key: docs/turbines-yaml.md.",
                "# site.origin.alt is metres above mean sea level of the ground at the origin and",
                "# every tower base is taken at that altitude: correct both before exporting missions.",
                f"# yaw_deg ({self.yaw_deg:g}) is not in any turbine database: set each rotor's heading",
                "# on the day of the flight (or let the photo tell the blade angles, docs/plan.md)."]
        head += [f"# {p}" for p in self.problems]
        return "\n".join(head) + "\n" + yaml.safe_dump(self.to_yaml_dict(), sort_keys=False,
                                                       default_flow_style=None, width=100)


@dataclass(frozen=True)
class Unreadable:
    """A value present in the source but not readable as a number: reported as such, never
    taken for a missing one (which a default would fill)."""

    text: str  # the value as written, quoted and cut (jsonio.shown)


def _value(raw) -> float | None | Unreadable:
    """A finite number, None for the databases' spellings of 'missing', else Unreadable."""
    if raw is None:
        return None
    try:
        if isinstance(raw, (int, float)) and not isinstance(raw, bool):
            v = float(raw)
        else:
            s = str(raw).strip()
            if s.lower() in _MISSING:
                return None
            v = float(s)
    except (ValueError, OverflowError):  # OverflowError: a JSON integer past a float's range
        return Unreadable(shown(raw))
    if not math.isfinite(v):
        return Unreadable(shown(raw))
    return None if v == -9999 else v


def _number(raw) -> float | None:
    """``_value`` where an unreadable value counts as missing (coordinates, capacity)."""
    v = _value(raw)
    return None if isinstance(v, Unreadable) else v


def _length_m(raw) -> float | None | Unreadable:
    """An OSM length tag -> metres: ``80``, ``80 m``, ``80.5m``, ``90,5`` (a decimal comma),
    ``1.2 km``, ``262 ft``, ``262'``, ``4'11"``; None when absent or empty; Unreadable otherwise."""
    if raw is None:
        return None
    if isinstance(raw, (int, float)) and not isinstance(raw, bool):
        return _value(raw)
    s = str(raw).strip()
    if not s:
        return None
    v = None
    if m := _OSM_LENGTH.fullmatch(s):
        v = float(m.group(1).replace(",", ".")) * _OSM_UNITS_M[(m.group(2) or "").lower()]
    elif (m := _OSM_FEET_INCHES.fullmatch(s)) and (m.group(1) or m.group(2)):
        v = float(m.group(1) or 0) * 0.3048 + float(m.group(2) or 0) * 0.0254
    return v if v is not None and math.isfinite(v) else Unreadable(shown(raw))


def _bbox_ok(lon: float, lat: float, bbox) -> bool:
    if bbox is None:
        return True
    # min_lon > max_lon: the box crosses the antimeridian (e.g. 179.5 .. -179.5)
    lon_ok = (bbox[0] <= lon <= bbox[2]) if bbox[0] < bbox[2] else (lon >= bbox[0] or lon <= bbox[2])
    return lon_ok and bbox[1] <= lat <= bbox[3]


def _check(where: str, lat, lon, hub, diam, hub_default, diam_default, problems: list[str]):
    """(hub, diameter) to write, or None when the row is skipped; ``problems`` gets the reason
    (a skipped row reports why it was skipped, not which of its values would have been filled).
    Checked as written (2 decimals), so the loader sees the values judged here."""
    if lat is None or lon is None or not (-90 <= lat <= 90 and -180 <= lon <= 180):
        problems.append(f"{where}: missing or invalid coordinates: skipped")
        return None
    checks = (("hub height", hub, hub_default, "--hub-height", HUB_RANGE_M),
              ("rotor diameter", diam, diam_default, "--rotor-diameter", DIAMETER_RANGE_M))
    for name, v, default, flag, (lo, hi) in checks:
        if isinstance(v, Unreadable):
            problems.append(f"{where}: {name} {v.text} unreadable: skipped")
            return None
        if v is None and default is None:
            problems.append(f"{where}: {name} missing: skipped (give {flag} to fill it)")
            return None
        if v is not None and v <= 0:
            problems.append(f"{where}: {name} is {v:g}: skipped")
            return None
        if v is not None and not lo <= round(v, 2) <= hi:
            problems.append(f"{where}: {name} {v:g} m outside [{lo:g}, {hi:g}]: skipped")
            return None
    out = [round(default if v is None else v, 2) for _, v, default, _, _ in checks]
    if out[0] <= out[1] / 2 + 1:
        problems.append(f"{where}: hub height {out[0]:g} m leaves no room for a {out[1]:g} m "
                        "rotor: skipped")
        return None
    for name, v, default, flag, _ in checks:
        if v is None:
            problems.append(f"{where}: {name} missing: {default:g} m from {flag}")
    return out


def read_uswtdb(path: str | Path, project: str | None = None, bbox=None,
                hub_default: float | None = None, diam_default: float | None = None,
                ) -> tuple[list[SiteTurbine], list[str], set[str]]:
    """Turbines of a USWTDB CSV, filtered by project name (case-insensitive) and/or bounding box
    ``(min_lon, min_lat, max_lon, max_lat)``; rows are numbered as in a spreadsheet (header = 1).
    Also returns the id of every matching row, skipped ones included (renames avoid them all)."""
    path = Path(path)
    try:  # the size capped as every input's (docs/exit-codes.md); a BOM allowed
        text = read_capped(path, MAX_JSON_BYTES, "CSV").removeprefix("\ufeff")
    except UnicodeDecodeError as e:
        raise InputError(f"{path}: cannot read the CSV (not UTF-8 text: {e.reason} at byte "
                         f"{e.start})") from None
    reader = csv.DictReader(text.splitlines())
    cols = [c.strip() for c in (reader.fieldnames or [])]
    missing = [c for c in USWTDB_COLUMNS if c not in cols]
    if missing:
        raise InputError(f"{path}: not a USWTDB CSV: missing column(s) {', '.join(missing)} "
                         f"(expected {', '.join(USWTDB_COLUMNS)})")
    turbines, problems, names, ids = [], [], set(), set()
    for n, row in enumerate(reader, start=2):
        row = {(k or "").strip(): v for k, v in row.items()}
        name = (row.get("p_name") or "").strip()
        names.add(name)
        if project is not None and name.lower() != project.strip().lower():
            continue
        case = (row.get("case_id") or "").strip()
        where = f"row {n} (case_id {case or '?'})"
        lat, lon = _number(row.get("ylat")), _number(row.get("xlong"))
        if lat is not None and lon is not None and not _bbox_ok(lon, lat, bbox):
            continue
        tid = case or f"row{n}"
        ids.add(tid)
        hd = _check(where, lat, lon, _value(row.get("t_hh")), _value(row.get("t_rd")),
                    hub_default, diam_default, problems)
        if hd is None:
            continue
        if not case:
            problems.append(f"{where}: no case_id: named by its row")
        turbines.append(SiteTurbine(tid, round(lat, 8), round(lon, 8), hd[0], hd[1], where,
                                    _number(row.get("t_cap"))))
    if not turbines and not problems:
        hint = ""
        if project is not None:
            close = difflib.get_close_matches(project, sorted(names), n=3, cutoff=0.5)
            hint = f" (did you mean {', '.join(repr(c) for c in close)}?)" if close else ""
        raise InputError(f"{path}: no turbine matches"
                         + (f" --project {project!r}" if project is not None else "")
                         + (" and --bbox" if bbox is not None else "") + hint)
    return turbines, problems, ids


def read_osm_geojson(path: str | Path, bbox=None, hub_default: float | None = None,
                     diam_default: float | None = None
                     ) -> tuple[list[SiteTurbine], list[str], set[str]]:
    """Wind generators of an OpenStreetMap GeoJSON (Overpass export): Point features tagged
    ``power=generator`` and ``generator:source=wind``; ``height`` (the hub height, as the OSM wiki
    defines it for wind turbines) and ``rotor:diameter`` where tagged. Tags are read from the
    feature's properties or their ``tags`` member. Also returns the id of every matching feature,
    skipped ones included."""
    path = Path(path)
    doc = read_json(path, header_required=False)  # a byte-order mark allowed, as the CSV's
    feats = doc.get("features") if isinstance(doc, dict) else None
    if not isinstance(feats, list):
        raise InputError(f"{path}: not a GeoJSON FeatureCollection (no 'features' list)")
    turbines, problems, ids = [], [], set()
    for n, f in enumerate(feats):
        if not isinstance(f, dict):
            problems.append(f"feature {n}: not an object: skipped")
            continue
        props = f.get("properties") if isinstance(f.get("properties"), dict) else {}
        tags = {**props, **(props.get("tags") if isinstance(props.get("tags"), dict) else {})}
        if tags.get("power") != "generator" or tags.get("generator:source") != "wind":
            continue
        osm_id = str(f.get("id") or props.get("@id") or props.get("id") or "")
        where = f"feature {n}" + (f" ({osm_id})" if osm_id else "")
        geom = f.get("geometry") if isinstance(f.get("geometry"), dict) else {}
        lat = lon = None
        if geom.get("type") == "Point" and isinstance(geom.get("coordinates"), list) \
                and len(geom["coordinates"]) >= 2:
            lon, lat = _number(geom["coordinates"][0]), _number(geom["coordinates"][1])
        elif geom:
            problems.append(f"{where}: geometry {geom.get('type')!r} is not a Point: skipped")
            continue
        if lat is not None and lon is not None and not _bbox_ok(lon, lat, bbox):
            continue
        ref = str(tags.get("ref") or "").strip()
        digits = re.sub(r"\D", "", osm_id)
        tid = ref if ref and "/" not in ref else (f"osm{digits}" if digits else f"feature{n}")
        ids.add(tid)
        hd = _check(where, lat, lon, _length_m(tags.get("height")),
                    _length_m(tags.get("rotor:diameter")), hub_default, diam_default, problems)
        if hd is None:
            continue
        turbines.append(SiteTurbine(tid, round(lat, 8), round(lon, 8), hd[0], hd[1], where))
    if not turbines and not problems:
        raise InputError(f"{path}: no Point feature tagged power=generator and "
                         "generator:source=wind" + (" inside --bbox" if bbox is not None else ""))
    return turbines, problems, ids


def _choose_origin(turbines: list[SiteTurbine], how: str, alt: float) -> dict:
    lat = np.radians([t.lat for t in turbines])
    lon = np.radians([t.lon for t in turbines])
    if how == "first":
        o_lat, o_lon = turbines[0].lat, turbines[0].lon
    else:  # the centroid of the points on the sphere: fine at a wind farm's size, and across ±180
        v = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)],
                     axis=1).mean(axis=0)
        o_lat = float(np.degrees(np.arctan2(v[2], np.hypot(v[0], v[1]))))
        o_lon = float(np.degrees(np.arctan2(v[1], v[0])))
    return {"lat": round(o_lat, 8), "lon": round(o_lon, 8), "alt": float(alt)}


def _enu(t: SiteTurbine, o: dict) -> np.ndarray:
    # one turbine at a time, as the loader converts it, so the checks below see its numbers
    return geodetic_to_enu(t.lat, t.lon, o["alt"], o)


def _within_reach(path: Path, turbines: list[SiteTurbine], xyz: np.ndarray, how: str) -> None:
    """The loader refuses a position farther than SITE_REACH_M from the origin (in x or y): the
    whole source is refused then, naming its two farthest turbines, rather than cutting an
    arbitrary part off a site that is too wide (which part depends on the origin)."""
    reach = np.abs(xyz[:, :2]).max(axis=1)
    out = (reach > SITE_REACH_M) | (xyz[:, 2] < SITE_Z_M[0]) | (xyz[:, 2] > SITE_Z_M[1])
    if not out.any():
        return
    i = int(np.argmax(np.where(out, reach, -1.0)))
    j = int(np.argmax(np.hypot(*(xyz[:, :2] - xyz[i, :2]).T)))
    span = float(np.hypot(*(xyz[i, :2] - xyz[j, :2])))
    raise ConfigError(
        f"{path}: the turbines span {span / 1000:.1f} km ({turbines[j].source} to "
        f"{turbines[i].source}, {float(np.hypot(*xyz[i, :2])) / 1000:.1f} km from "
        f"{'the first turbine' if how == 'first' else 'their centroid'}), but a turbines.yaml "
        f"holds turbines within {SITE_REACH_M / 1000:g} km of its origin (mission exports "
        f"{MAX_SITE_RADIUS_M / 1000:g} km): narrow it with --bbox or --project")


def _too_close(turbines: list[SiteTurbine], xyz: np.ndarray) -> dict[int, tuple[int, float]]:
    """Towers closer than their two rotor radii, which the loader refuses: each turbine against
    those kept before it, in input order, so the later row of a pair is the one skipped.
    Returns {skipped index: (the kept turbine it is too close to, distance m)}. A grid of cells
    two of the largest radii wide keeps this linear for a whole database."""
    r = np.array([t.rotor_diameter_m / 2 for t in turbines])
    cell = 2 * float(r.max())
    grid: dict[tuple[int, int], list[int]] = {}
    skipped = {}
    for i in range(len(turbines)):
        cx, cy = int(xyz[i, 0] // cell), int(xyz[i, 1] // cell)
        hits = [(float(np.linalg.norm(xyz[i, :2] - xyz[j, :2])), j)
                for dx in (-1, 0, 1) for dy in (-1, 0, 1) for j in grid.get((cx + dx, cy + dy), ())]
        hits = [(d, j) for d, j in hits if d < r[i] + r[j]]
        if hits:
            d, j = min(hits)
            skipped[i] = (j, d)
        else:
            grid.setdefault((cx, cy), []).append(i)
    return skipped


def _unique_ids(turbines: list[SiteTurbine], taken: set[str], problems: list[str]):
    """A repeated id: the first keeps it, the next become ID-2, ID-3, ... skipping any id the
    source already holds (``taken``: every matching row's), each rename reported."""
    taken = set(taken) | {t.id for t in turbines}
    used, next_k, out = set(), {}, []
    for t in turbines:
        if t.id in used:
            k = next_k.get(t.id, 2)
            while f"{t.id}-{k}" in taken:
                k += 1
            new = f"{t.id}-{k}"
            next_k[t.id] = k + 1
            taken.add(new)
            problems.append(f"{t.source}: id {t.id!r} repeats an earlier row: written as {new!r}")
            t = SiteTurbine(new, t.lat, t.lon, t.hub_height_m, t.rotor_diameter_m, t.source,
                            t.capacity_kw)
        used.add(t.id)
        out.append(t)
    return out


def _check_options(bbox, origin, origin_alt_m, yaw_deg, hub_default, diam_default):
    """Each option against what the written file may hold: one line naming the option."""
    if bbox is not None:
        ok = len(bbox) == 4 and all(map(math.isfinite, bbox))
        if not (ok and -180 <= bbox[0] <= 180 and -180 <= bbox[2] <= 180 and bbox[0] != bbox[2]
                and -90 <= bbox[1] < bbox[3] <= 90):
            raise ConfigError(
                "--bbox: expected MIN_LON,MIN_LAT,MAX_LON,MAX_LAT in degrees with min_lat < max_lat "
                "(a box across the antimeridian has min_lon > max_lon, e.g. 179.5,-17.5,-179.5,-16.5), "
                f"got {','.join(f'{v:g}' for v in bbox)}")
    if origin not in ("centroid", "first"):
        raise ConfigError(f"--origin: expected centroid or first, got {origin!r}")
    for flag, v, lo, hi, unit in (("--origin-alt", origin_alt_m, -500, 9000, " m"),
                                  ("--yaw-deg", yaw_deg, 0, 360, ""),
                                  ("--hub-height", hub_default, *HUB_RANGE_M, " m"),
                                  ("--rotor-diameter", diam_default, *DIAMETER_RANGE_M, " m")):
        if v is not None and not (math.isfinite(v) and lo <= v <= hi):  # NaN fails too
            raise ConfigError(f"{flag}: expected a number in [{lo:g}, {hi:g}]{unit} (what "
                              f"turbines.yaml accepts), got {v:g}")
    if hub_default is not None and diam_default is not None \
            and not round(hub_default, 2) > round(diam_default, 2) / 2 + 1:
        raise ConfigError(f"--hub-height {hub_default:g} leaves no room for --rotor-diameter "
                          f"{diam_default:g}: the hub must stand more than the rotor's radius + 1 m "
                          f"({diam_default / 2 + 1:g} m) above the ground")


def build_site(path: str | Path, project: str | None = None, bbox=None, origin: str = "centroid",
               origin_alt_m: float = 0.0, yaw_deg: float = 180.0, hub_default: float | None = None,
               diam_default: float | None = None) -> Site:
    """Read a USWTDB ``.csv`` or an OSM ``.geojson``/``.json`` into a Site whose YAML the
    turbines.yaml loader accepts."""
    path = Path(path)
    if bbox is not None:
        bbox = tuple(float(v) for v in bbox)
    _check_options(bbox, origin, origin_alt_m, yaw_deg, hub_default, diam_default)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        turbines, problems, ids = read_uswtdb(path, project, bbox, hub_default, diam_default)
        source = f"the USWTDB CSV {path.name}" + (f", project {project!r}" if project else "")
    elif suffix in (".geojson", ".json"):
        if project is not None:
            raise ConfigError("--project filters a USWTDB CSV; an OSM GeoJSON is filtered with --bbox")
        turbines, problems, ids = read_osm_geojson(path, bbox, hub_default, diam_default)
        source = f"the OpenStreetMap GeoJSON {path.name}"
    else:
        raise InputError(f"{path}: expected a USWTDB .csv or an OpenStreetMap .geojson/.json")
    if bbox is not None:
        source += ", bbox " + ",".join(f"{v:g}" for v in bbox)
    if not turbines:
        raise InputError(f"{path}: every matching row was skipped: "
                         + "; ".join(problems[:5]) + (" ..." if len(problems) > 5 else ""))
    while True:  # a skipped turbine moves the centroid: check again until nothing changes
        o = _choose_origin(turbines, origin, origin_alt_m)
        xyz = np.array([_enu(t, o) for t in turbines])
        _within_reach(path, turbines, xyz, origin)
        close = _too_close(turbines, xyz)
        for i, (j, d) in close.items():
            a, b = turbines[i], turbines[j]
            problems.append(
                f"{a.source}: stands {d:.1f} m from {b.source}, closer than their rotor radii "
                f"allow ({b.rotor_diameter_m / 2:g} + {a.rotor_diameter_m / 2:g} m): skipped "
                "(a duplicate entry or a wrong position)")
        if not close:
            break
        turbines = [t for i, t in enumerate(turbines) if i not in close]
    turbines = _unique_ids(turbines, ids, problems)
    far = float(np.hypot(xyz[:, 0], xyz[:, 1]).max())
    if far > MAX_SITE_RADIUS_M:
        problems.append(f"the farthest turbine is {far / 1000:.1f} km from the origin: mission "
                        f"exports need every turbine within {MAX_SITE_RADIUS_M / 1000:g} km "
                        "(narrow it with --bbox or --project)")
    return Site(source, turbines, o, float(yaw_deg), problems)
