"""Mission exports parse back with strict readers (formats.md), and match golden files.

Regenerate the golden files after an intended format change with
``WTINSPECT_UPDATE_GOLDEN=1 python -m pytest tests/test_plan_exports.py``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from wtcli.errors import ConfigError
from wtcli.geometry import Camera, Turbine
from wtcli.plan.exports import (export_all, geojson_dict, mission_items, qgc_plan_dict, sorties,
                                wpl_text)
from wtcli.plan.geodesy import enu_to_geodetic, geodetic_to_enu
from wtcli.plan_file import Plan, Route

GOLDEN = Path(__file__).resolve().parent / "golden"
ORIGIN = {"lat": 53.5511, "lon": 9.9937, "alt": 12.0}


def small_plan(origin=ORIGIN) -> Plan:
    """A hand-made plan: take off, two photo waypoints, a battery swap, one more, land."""
    t = Turbine.with_rotor_azimuth(90, id="T1", base=(0, 0, 0), hub_height=80, rotor_diameter=90,
                                   yaw_deg=180)
    launch = [60.0, -40.0, 0.0]
    pos = np.array([launch, [60, -40, 10], [10, -20, 80], [12, -20, 82], [60, -40, 10], launch,
                    launch, [60, -40, 10], [14, -20, 84], [60, -40, 10], launch])
    n = len(pos)
    comp = ["launch", "launch", "T1/blade1/leading_edge", "T1/blade1/leading_edge", "return",
            "return", "launch", "launch", "T1/tower", "return", "return"]
    route = Route("UAV1", t=np.cumsum(np.r_[0, np.ones(n - 1) * 10.0]), pos=pos,
                  speed=np.r_[0, 3.0, 8.0, 2.0, 8.0, 3.0, 0.0, 3.0, 8.0, 8.0, 3.0],
                  yaw_deg=np.r_[0, 0, 0, 0, 0, 0, 0, 0, 90, 90, 90],
                  gimbal_pitch_deg=np.r_[0, 0, -10, -10, 0, 0, 0, 0, 0, 0, 0],
                  photo=np.array([0, 0, 1, 1, 0, 0, 0, 0, 1, 0, 0], bool),
                  component=np.array(comp, dtype=object))
    return Plan([t], Camera(5456, 3632, 16, 23.2), [route], 3.0, 1.5, origin, {})


# ---- strict readers ------------------------------------------------------------------------------
def parse_wpl(text: str) -> list[dict]:
    lines = text.split("\n")
    assert lines[0] == "QGC WPL 110", "line 1 must be exactly 'QGC WPL 110'"
    assert lines[-1] == "", "file ends with a newline"
    rows = []
    for k, line in enumerate(lines[1:-1]):
        f = line.split("\t")
        assert len(f) == 12, f"row {k}: expected 12 TAB-separated fields, got {len(f)}"
        ints = [int(f[i]) for i in (0, 1, 2, 3, 11)]  # raises on non-integers
        floats = [float(x) for x in f[4:11]]
        assert all(np.isfinite(floats))
        idx, cur, frame, cmd, auto = ints
        assert idx == k, f"row {k}: index {idx} (numbering must have no gaps)"
        assert cur in (0, 1) and auto in (0, 1)
        assert frame in (0, 1, 2, 3, 4, 10)
        for i in (8, 9):  # lat/lon with at least 7 decimals
            if "." in f[i]:
                assert len(f[i].split(".")[1]) >= 7
        rows.append({"index": idx, "current": cur, "frame": frame, "command": cmd,
                     "params": floats, "autocontinue": auto})
    assert rows and rows[0]["index"] == 0 and rows[0]["current"] == 1 and rows[0]["frame"] == 0 \
        and rows[0]["command"] == 16, "row 0 is home: index 0, current 1, frame 0, command 16"
    assert all(r["current"] == 0 for r in rows[1:])
    return rows


def check_qgc_plan(doc: dict) -> None:
    assert set(doc) == {"fileType", "version", "groundStation", "mission", "geoFence", "rallyPoints"}
    assert doc["fileType"] == "Plan" and doc["version"] == 1
    m = doc["mission"]
    assert m["version"] == 2 and m["firmwareType"] in (3, 12) and m["vehicleType"] == 2
    assert isinstance(m["cruiseSpeed"], (int, float)) and isinstance(m["hoverSpeed"], (int, float))
    assert m["globalPlanAltitudeMode"] == 1
    home = m["plannedHomePosition"]
    assert len(home) == 3 and all(isinstance(x, float) for x in home)
    assert doc["geoFence"] == {"circles": [], "polygons": [], "version": 2}
    assert doc["rallyPoints"] == {"points": [], "version": 2}
    for k, it in enumerate(m["items"], start=1):
        assert it["type"] == "SimpleItem" and it["doJumpId"] == k and it["autoContinue"] is True
        assert isinstance(it["command"], int) and isinstance(it["frame"], int)
        assert len(it["params"]) == 7
        assert all(p is None or (isinstance(p, (int, float)) and np.isfinite(p)) for p in it["params"])
        coord = {"Altitude", "AltitudeMode", "AMSLAltAboveTerrain"}
        if it["command"] in (16, 22, 21):
            assert coord <= set(it) and it["AltitudeMode"] == 1 and it["frame"] == 3
            assert it["AMSLAltAboveTerrain"] is None and it["Altitude"] == it["params"][6]
            assert -90 <= it["params"][4] <= 90 and -180 <= it["params"][5] <= 180
        else:
            assert not (coord & set(it)), "items without a coordinate omit the Altitude keys"


def check_geojson(doc: dict) -> None:
    assert doc["type"] == "FeatureCollection"
    for f in doc["features"]:
        assert f["type"] == "Feature" and set(f) == {"type", "geometry", "properties"}
        g = f["geometry"]
        coords = g["coordinates"] if g["type"] == "Point" else None
        if g["type"] == "Point":
            pts = [coords]
        else:
            assert g["type"] in ("LineString", "MultiPoint")
            pts = g["coordinates"]
        for lon, lat, alt in pts:
            assert -180 <= lon <= 180 and -90 <= lat <= 90 and np.isfinite(alt)


# ---- tests ----------------------------------------------------------------------------------------
def test_geodesy_roundtrip():
    enu = np.array([[0, 0, 0], [100.0, -250.0, 80.0], [-3000, 5000, 10]])
    llh = enu_to_geodetic(enu, ORIGIN)
    back = geodetic_to_enu(llh[:, 0], llh[:, 1], llh[:, 2], ORIGIN)
    assert np.allclose(back, enu, atol=1e-6)
    assert llh[0, 0] == pytest.approx(ORIGIN["lat"]) and llh[0, 2] == pytest.approx(ORIGIN["alt"])
    # 0.001 deg of latitude is ~111 m north
    assert geodetic_to_enu(ORIGIN["lat"] + 0.001, ORIGIN["lon"], ORIGIN["alt"], ORIGIN)[1] == \
        pytest.approx(111.3, abs=0.3)


def test_sorties_split_at_battery_swaps():
    assert sorties(small_plan().routes[0]) == [(0, 5), (6, 10)]


def _golden(name: str, text: str) -> None:
    path = GOLDEN / name
    if os.environ.get("WTINSPECT_UPDATE_GOLDEN") == "1":
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    assert path.exists(), f"missing golden file {path} (set WTINSPECT_UPDATE_GOLDEN=1)"
    assert text == path.read_text(encoding="utf-8"), f"{name} differs from its golden file"


def test_wpl_and_qgc_plan_parse_strictly_and_match_golden():
    plan = small_plan()
    r = plan.routes[0]
    for s, (a, b) in enumerate(sorties(r), start=1):
        items, home = mission_items(plan, r, a, b)
        text = wpl_text(items, home)
        rows = parse_wpl(text)
        cmds = [row["command"] for row in rows[1:]]
        assert cmds[0] == 22 and cmds[-1] == 21 and 196 not in cmds
        photos = int(r.photo[a:b + 1].sum())
        assert cmds.count(203) == photos
        shoot = [row for row in rows if row["command"] == 203]
        assert all(row["params"][4] == 1 for row in shoot)  # p5 = 1 shoots
        assert rows[0]["params"][6] == pytest.approx(ORIGIN["alt"] + r.pos[a, 2], abs=1e-3)
        wp = [row for row in rows[1:] if row["command"] == 16]
        assert all(row["frame"] == 3 for row in wp)
        doc = qgc_plan_dict(items, home, 8.0, 2.0)
        check_qgc_plan(json.loads(json.dumps(doc, allow_nan=False)))
        assert [it["command"] for it in doc["mission"]["items"]] == cmds
        _golden(f"small_s{s}.waypoints", text)
        _golden(f"small_s{s}.plan", json.dumps(doc, indent=1) + "\n")
    gj = geojson_dict(plan)
    check_geojson(gj)
    _golden("small.geojson", json.dumps(gj, indent=1) + "\n")


def test_real_plan_exports_parse(tmp_path):
    from wtcli.plan.config import load_mission
    from wtcli.plan.mission import plan_mission

    root = Path(__file__).resolve().parents[1]
    plan = plan_mission(load_mission(root / "sample_images" / "turbines.yaml"))
    files = export_all(plan, tmp_path, stem="m")
    n_photos = 0
    for f in files:
        if f.suffix == ".waypoints":
            rows = parse_wpl(f.read_text())
            n_photos += sum(row["command"] == 203 for row in rows)
        elif f.suffix == ".plan":
            check_qgc_plan(json.loads(f.read_text()))
        else:
            check_geojson(json.loads(f.read_text()))
    assert n_photos == plan.summary["photos"]


def test_exports_need_a_site_origin(tmp_path):
    with pytest.raises(ConfigError, match="site.origin"):
        export_all(small_plan(origin=None), tmp_path)
