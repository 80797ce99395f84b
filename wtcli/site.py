"""Turbine lists users already own -> ``turbines.yaml``: the U.S. Wind Turbine Database (USWTDB)
CSV and OpenStreetMap GeoJSON of wind generators. docs/site.md

Nothing is invented silently: a value a source lacks is either filled from a default the user gave
(and reported for that row) or the row is skipped (and reported); the rotor heading (``yaw_deg``),
which no database holds, is written from ``yaw_deg`` and said so. Every kept turbine is written by
latitude/longitude, so ``wtcli.plan.config`` converts it exactly through the site origin.
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
from wtcli.jsonio import MAX_JSON_BYTES, read_capped, read_json
from wtcli.plan.geodesy import MAX_SITE_RADIUS_M, geodetic_to_enu

USWTDB_COLUMNS = ("case_id", "xlong", "ylat", "t_hh", "t_rd", "t_cap", "p_name")
# Ranges the turbines.yaml loader accepts (docs/turbines-yaml.md): a row outside them is skipped
# here with its reason, rather than written and refused later without the row number.
HUB_RANGE_M = (10.0, 250.0)
DIAMETER_RANGE_M = (5.0, 300.0)
_MISSING = {"", "na", "nan", "null", "none", "-9999", "-9999.0"}


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


def _number(raw) -> float | None:
    """A finite number, or None for the databases' spellings of 'missing'."""
    if raw is None:
        return None
    if isinstance(raw, (int, float)) and not isinstance(raw, bool):
        v = float(raw)
    else:
        s = str(raw).strip()
        if s.lower() in _MISSING:
            return None
        try:
            v = float(s)
        except ValueError:
            return None
    return v if math.isfinite(v) and v != -9999 else None


def _length_m(raw) -> float | None:
    """An OSM length tag: ``80``, ``80 m``, ``80m``, ``262 ft``, ``262'`` -> metres."""
    if raw is None:
        return None
    m = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]+)?)\s*(m|ft|')?\s*", str(raw))
    if not m:
        return None
    v = float(m.group(1))
    return v * 0.3048 if m.group(2) in ("ft", "'") else v


def _bbox_ok(lon: float, lat: float, bbox) -> bool:
    return bbox is None or (bbox[0] <= lon <= bbox[2] and bbox[1] <= lat <= bbox[3])


def _check(where: str, lat, lon, hub, diam, hub_default, diam_default, problems: list[str]):
    """(hub, diameter) to write, or None when the row is skipped; ``problems`` gets the reason
    (a skipped row reports why it was skipped, not which of its values would have been filled)."""
    if lat is None or lon is None or not (-90 <= lat <= 90 and -180 <= lon <= 180):
        problems.append(f"{where}: missing or invalid coordinates: skipped")
        return None
    checks = (("hub height", hub, hub_default, "--hub-height", HUB_RANGE_M),
              ("rotor diameter", diam, diam_default, "--rotor-diameter", DIAMETER_RANGE_M))
    for name, v, default, flag, (lo, hi) in checks:
        if v is None and default is None:
            problems.append(f"{where}: {name} missing: skipped (give {flag} to fill it)")
            return None
        if v is not None and v <= 0:
            problems.append(f"{where}: {name} is {v:g}: skipped")
            return None
        if v is not None and not lo <= v <= hi:
            problems.append(f"{where}: {name} {v:g} m outside [{lo:g}, {hi:g}]: skipped")
            return None
    out = [default if v is None else v for _, v, default, _, _ in checks]
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
                ) -> tuple[list[SiteTurbine], list[str]]:
    """Turbines of a USWTDB CSV, filtered by project name (case-insensitive) and/or bounding box
    ``(min_lon, min_lat, max_lon, max_lat)``; rows are numbered as in a spreadsheet (header = 1)."""
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
    turbines, problems, names = [], [], set()
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
        hd = _check(where, lat, lon, _number(row.get("t_hh")), _number(row.get("t_rd")),
                    hub_default, diam_default, problems)
        if hd is None:
            continue
        if not case:
            problems.append(f"{where}: no case_id: named by its row")
        tid = case or f"row{n}"
        turbines.append(SiteTurbine(tid, lat, lon, hd[0], hd[1], where, _number(row.get("t_cap"))))
    if not turbines and not problems:
        hint = ""
        if project is not None:
            close = difflib.get_close_matches(project, sorted(names), n=3, cutoff=0.5)
            hint = f" (did you mean {', '.join(repr(c) for c in close)}?)" if close else ""
        raise InputError(f"{path}: no turbine matches"
                         + (f" --project {project!r}" if project is not None else "")
                         + (" and --bbox" if bbox is not None else "") + hint)
    return turbines, problems


def read_osm_geojson(path: str | Path, bbox=None, hub_default: float | None = None,
                     diam_default: float | None = None) -> tuple[list[SiteTurbine], list[str]]:
    """Wind generators of an OpenStreetMap GeoJSON (Overpass export): Point features tagged
    ``power=generator`` and ``generator:source=wind``; ``height`` (the hub height, as the OSM wiki
    defines it for wind turbines) and ``rotor:diameter`` where tagged. Tags are read from the
    feature's properties or their ``tags`` member."""
    path = Path(path)
    doc = read_json(path)  # size cap, NaN refused, errors naming the file (docs/exit-codes.md)
    feats = doc.get("features") if isinstance(doc, dict) else None
    if not isinstance(feats, list):
        raise InputError(f"{path}: not a GeoJSON FeatureCollection (no 'features' list)")
    turbines, problems, seen = [], [], set()
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
        hd = _check(where, lat, lon, _length_m(tags.get("height")),
                    _length_m(tags.get("rotor:diameter")), hub_default, diam_default, problems)
        if hd is None:
            continue
        ref = str(tags.get("ref") or "").strip()
        digits = re.sub(r"\D", "", osm_id)
        tid = ref if ref and "/" not in ref else (f"osm{digits}" if digits else f"feature{n}")
        if tid in seen:
            tid = f"{tid}-{n}"
        seen.add(tid)
        turbines.append(SiteTurbine(tid, lat, lon, hd[0], hd[1], where))
    if not turbines and not problems:
        raise InputError(f"{path}: no Point feature tagged power=generator and "
                         "generator:source=wind" + (" inside --bbox" if bbox is not None else ""))
    return turbines, problems


def build_site(path: str | Path, project: str | None = None, bbox=None, origin: str = "centroid",
               origin_alt_m: float = 0.0, yaw_deg: float = 180.0, hub_default: float | None = None,
               diam_default: float | None = None) -> Site:
    """Read a USWTDB ``.csv`` or an OSM ``.geojson``/``.json`` into a Site."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    if bbox is not None:
        bbox = tuple(float(v) for v in bbox)
        if len(bbox) != 4 or not all(map(math.isfinite, bbox)) or not (
                -180 <= bbox[0] < bbox[2] <= 180 and -90 <= bbox[1] < bbox[3] <= 90):
            raise ConfigError(f"--bbox: expected MIN_LON,MIN_LAT,MAX_LON,MAX_LAT with min < max, "
                              f"got {bbox!r}")
    if origin not in ("centroid", "first"):
        raise ConfigError(f"--origin: expected centroid or first, got {origin!r}")
    if not (-500 <= origin_alt_m <= 9000 and 0 <= yaw_deg <= 360):
        raise ConfigError("--origin-alt must lie in [-500, 9000] m and --yaw-deg in [0, 360]")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        turbines, problems = read_uswtdb(path, project, bbox, hub_default, diam_default)
        source = f"the USWTDB CSV {path.name}" + (f", project {project!r}" if project else "")
    elif suffix in (".geojson", ".json"):
        if project is not None:
            raise ConfigError("--project filters a USWTDB CSV; an OSM GeoJSON is filtered with --bbox")
        turbines, problems = read_osm_geojson(path, bbox, hub_default, diam_default)
        source = f"the OpenStreetMap GeoJSON {path.name}"
    else:
        raise InputError(f"{path}: expected a USWTDB .csv or an OpenStreetMap .geojson/.json")
    if bbox is not None:
        source += ", bbox " + ",".join(f"{v:g}" for v in bbox)
    if not turbines:
        raise InputError(f"{path}: every matching row was skipped: "
                         + "; ".join(problems[:5]) + (" ..." if len(problems) > 5 else ""))
    seen: dict[str, int] = {}
    unique = []
    for t in turbines:
        if t.id in seen:
            new = f"{t.id}-{seen[t.id] + 1}"
            problems.append(f"{t.source}: id {t.id!r} repeats an earlier row: written as {new!r}")
            seen[t.id] += 1
            t = SiteTurbine(new, t.lat, t.lon, t.hub_height_m, t.rotor_diameter_m, t.source,
                            t.capacity_kw)
        else:
            seen[t.id] = 0
        unique.append(t)
    lat = np.array([t.lat for t in unique])
    lon = np.array([t.lon for t in unique])
    if origin == "first":
        o_lat, o_lon = float(lat[0]), float(lon[0])
    else:  # the centroid of the points on the sphere, fine at a wind farm's size
        v = np.stack([np.cos(np.radians(lat)) * np.cos(np.radians(lon)),
                      np.cos(np.radians(lat)) * np.sin(np.radians(lon)),
                      np.sin(np.radians(lat))], axis=1).mean(axis=0)
        o_lat = float(np.degrees(np.arctan2(v[2], np.hypot(v[0], v[1]))))
        o_lon = float(np.degrees(np.arctan2(v[1], v[0])))
    o = {"lat": round(o_lat, 8), "lon": round(o_lon, 8), "alt": float(origin_alt_m)}
    enu = geodetic_to_enu(lat, lon, np.full(len(lat), o["alt"]), o)
    far = float(np.hypot(enu[:, 0], enu[:, 1]).max())
    if far > MAX_SITE_RADIUS_M:
        problems.append(f"the farthest turbine is {far / 1000:.1f} km from the origin: mission "
                        f"exports need every turbine within {MAX_SITE_RADIUS_M / 1000:g} km "
                        "(narrow it with --bbox or --project)")
    return Site(source, unique, o, float(yaw_deg), problems)
