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
    files = export_all(plan, tmp_path, stem="m").written
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


# ---- exact WGS84 positions on a wide site ---------------------------------------------------------
def _textbook_enu_to_llh(enu: np.ndarray, origin: dict) -> np.ndarray:
    """ENU -> ECEF -> geodetic written independently of wtcli.plan.geodesy: the ECEF of the origin
    from the prime-vertical radius, the ENU rotation, then Heikkinen's closed form (Zhu 1993)."""
    a, f = 6378137.0, 1 / 298.257223563
    b = a * (1 - f)
    e2 = 1 - (b / a) ** 2
    ep2 = (a / b) ** 2 - 1
    la0, lo0, h0 = np.radians(origin["lat"]), np.radians(origin["lon"]), origin["alt"]
    n0 = a / np.sqrt(1 - e2 * np.sin(la0) ** 2)
    x0 = np.array([(n0 + h0) * np.cos(la0) * np.cos(lo0), (n0 + h0) * np.cos(la0) * np.sin(lo0),
                   (n0 * (1 - e2) + h0) * np.sin(la0)])
    out = []
    for e, n, u in enu:
        dx = -np.sin(lo0) * e - np.sin(la0) * np.cos(lo0) * n + np.cos(la0) * np.cos(lo0) * u
        dy = np.cos(lo0) * e - np.sin(la0) * np.sin(lo0) * n + np.cos(la0) * np.sin(lo0) * u
        dz = np.cos(la0) * n + np.sin(la0) * u
        x, y, z = x0 + [dx, dy, dz]
        p = np.hypot(x, y)
        F = 54 * b * b * z * z
        G = p * p + (1 - e2) * z * z - e2 * (a * a - b * b)
        c = e2 * e2 * F * p * p / G ** 3
        s = np.cbrt(1 + c + np.sqrt(c * c + 2 * c))
        P = F / (3 * (s + 1 / s + 1) ** 2 * G * G)
        Q = np.sqrt(1 + 2 * e2 * e2 * P)
        r0 = -P * e2 * p / (1 + Q) + np.sqrt(a * a / 2 * (1 + 1 / Q) - P * (1 - e2) * z * z
                                             / (Q * (1 + Q)) - P * p * p / 2)
        U = np.hypot(p - e2 * r0, z)
        V = np.sqrt((p - e2 * r0) ** 2 + (1 - e2) * z * z)
        z0 = b * b * z / (a * V)
        out.append([np.degrees(np.arctan((z + ep2 * z0) / p)), np.degrees(np.arctan2(y, x)),
                    U * (1 - b * b / (a * V))])
    return np.array(out)


def _metres_apart(llh1: np.ndarray, llh2: np.ndarray) -> np.ndarray:
    """Horizontal and vertical distances (m) between [lat, lon, h] rows, small offsets."""
    lat = np.radians(llh2[:, 0])
    dn = np.radians(llh1[:, 0] - llh2[:, 0]) * 6.3674e6
    de = np.radians(llh1[:, 1] - llh2[:, 1]) * 6.3781e6 * np.cos(lat)
    return np.stack([np.hypot(dn, de), np.abs(llh1[:, 2] - llh2[:, 2])], axis=1)


WIDE_ORIGIN = {"lat": 47.2, "lon": 8.3, "alt": 480.0}


def wide_plan() -> Plan:
    """One sortie over a 10 km site: launch 5.4 km out, waypoints up to 9.9 km from the origin."""
    p = small_plan(WIDE_ORIGIN)
    r = p.routes[0]
    launch = [3000.0, -4500.0, -2.3]
    pos = np.array([launch, [3000, -4500, 8], [-7000, 7000, 150], [-7000, 7002, 152],
                    [3000, -4500, 8], launch])
    n = len(pos)
    route = Route("UAV1", t=np.arange(n) * 600.0, pos=pos, speed=np.r_[0, 3.0, 12, 2, 12, 3],
                  yaw_deg=np.r_[0, 0, 315, 315, 0, 0], gimbal_pitch_deg=np.r_[0, 0, -20, -20, 0, 0],
                  photo=np.array([0, 0, 1, 1, 0, 0], bool), component=r.component[:n])
    return Plan(p.turbines, p.camera, [route], 3.0, 1.5, WIDE_ORIGIN, {})


def test_exports_agree_with_an_independent_wgs84_conversion_on_a_10_km_site(tmp_path):
    plan = wide_plan()
    r = plan.routes[0]
    truth = _textbook_enu_to_llh(r.pos, WIDE_ORIGIN)
    files = export_all(plan, tmp_path, stem="w").written
    rows = parse_wpl((tmp_path / "w_UAV1_s1.waypoints").read_text())
    home = np.array(rows[0]["params"][4:7])
    wp = np.array([row["params"][4:7] for row in rows[1:] if row["command"] in (22, 16, 21)])
    got = np.vstack([home, wp])
    got[1:, 2] += home[2]  # frame 3: relative to home -> AMSL
    want = truth[[0, 1, 2, 3, 4, 5]]
    assert got.shape == want.shape
    err = _metres_apart(got, want)
    assert err.max() < 0.1, err
    doc = json.loads((tmp_path / "w_UAV1_s1.plan").read_text())
    qh = np.array(doc["mission"]["plannedHomePosition"])
    q = np.array([it["params"][4:7] for it in doc["mission"]["items"] if it["command"] in (22, 16, 21)])
    q[:, 2] += qh[2]
    assert _metres_apart(np.vstack([qh, q]), want).max() < 0.1
    gj = json.loads((tmp_path / "w.geojson").read_text())
    assert "above mean sea level" in gj["altitude_reference"]
    line = next(f for f in gj["features"] if f["properties"]["kind"] == "route")
    g = np.array(line["geometry"]["coordinates"])[:, [1, 0, 2]]
    assert _metres_apart(g, truth).max() < 0.1
    assert len(files) == 3


def test_relative_altitude_is_the_height_difference_not_the_enu_z_difference():
    """Regression: a waypoint 5 km from home at ENU z 80 m used to be exported 80 m above home,
    but the ellipsoid curves away below the ENU plane by d^2/2R = 1.96 m, so the point is 81.96 m
    above home's height: the drone flew 1.96 m lower than planned."""
    plan = small_plan()
    r = plan.routes[0]
    r.pos[2] = [5000.0, 0.0, 80.0]
    r.pos[0] = r.pos[5] = [0.0, 0.0, 0.0]
    r.pos[1] = r.pos[4] = [0.0, 0.0, 10.0]
    items, home = mission_items(plan, r, 0, 5)
    wp = [it for it in items if it.command == 16]
    assert wp[0].params[6] == pytest.approx(80 + 5000 ** 2 / (2 * 6.38e6), abs=0.01)
    truth = _textbook_enu_to_llh(r.pos[2:3], ORIGIN)[0]
    assert wp[0].params[6] + home[2] == pytest.approx(truth[2], abs=0.01)


def test_a_site_wider_than_the_limit_is_refused_naming_the_key(tmp_path):
    plan = small_plan()
    plan.turbines[0] = Turbine.with_rotor_azimuth(90, id="T9", base=(10_500, 0, 0), hub_height=80,
                                                  rotor_diameter=90, yaw_deg=180)
    with pytest.raises(ConfigError, match=r"turbines\[0\] \(T9\)\.position: 10\.5 km from site\.origin"):
        export_all(plan, tmp_path)
    plan = wide_plan()
    plan.routes[0].pos[2] = [-8000, 8000, 150]
    with pytest.raises(ConfigError, match="UAV1 route point 2"):
        export_all(plan, tmp_path)
    assert not list(tmp_path.iterdir())


# ---- DJI WPML (.kmz) ------------------------------------------------------------------------------
KML = "{http://www.opengis.net/kml/2.2}"
WPML = "{http://www.dji.com/wpmz/1.0.2}"
TURN_STOP = "toPointAndStopWithDiscontinuityCurvature"  # straight in, stop at the point
TURN_PASS = "toPointAndPassWithContinuityCurvature"  # through the point without stopping
ACTION_PARAMS = {
    "gimbalRotate": ["gimbalHeadingYawBase", "gimbalRotateMode", "gimbalPitchRotateEnable",
                     "gimbalPitchRotateAngle", "gimbalRollRotateEnable", "gimbalRollRotateAngle",
                     "gimbalYawRotateEnable", "gimbalYawRotateAngle", "gimbalRotateTimeEnable",
                     "gimbalRotateTime", "payloadPositionIndex"],
    "rotateYaw": ["aircraftHeading", "aircraftPathMode"],
    "takePhoto": ["payloadPositionIndex", "fileSuffix", "useGlobalPayloadLensIndex"],
    "gimbalEvenlyRotate": ["gimbalPitchRotateAngle", "payloadPositionIndex"],
}


def _children(e, ns=WPML) -> list[str]:
    return [c.tag.replace(ns, "") for c in e]


def _text(e, tag: str, ns=WPML) -> str:
    c = e.find(ns + tag)
    assert c is not None and c.text is not None and c.text.strip(), f"missing {tag}"
    return c.text.strip()


def parse_wpml(text: str, template: bool) -> dict:
    """Strict reader of DJI WPML 1.0.2 (waylines.wpml, or template.kml with ``template``): every
    element the DJI reference marks required for these drones, in range, and nothing unknown."""
    import xml.etree.ElementTree as ET

    assert text.startswith('<?xml version="1.0" encoding="UTF-8"?>\n')
    root = ET.fromstring(text)
    assert root.tag == KML + "kml" and _children(root, KML) == ["Document"]
    doc = root.find(KML + "Document")
    mc = doc.find(WPML + "missionConfig")
    assert _children(mc) == ["flyToWaylineMode", "finishAction", "exitOnRCLost",
                             "executeRCLostAction", "takeOffSecurityHeight",
                             "globalTransitionalSpeed", "globalRTHHeight", "droneInfo", "payloadInfo"]
    assert _text(mc, "flyToWaylineMode") in ("safely", "pointToPoint")
    assert _text(mc, "finishAction") == "goHome"
    assert _text(mc, "exitOnRCLost") in ("goContinue", "executeLostAction")
    assert _text(mc, "executeRCLostAction") in ("goBack", "landing", "hover")
    assert 2 <= float(_text(mc, "takeOffSecurityHeight")) <= 1500
    assert 0 < float(_text(mc, "globalTransitionalSpeed")) <= 15
    di, pi = mc.find(WPML + "droneInfo"), mc.find(WPML + "payloadInfo")
    drone = (int(_text(di, "droneEnumValue")), int(_text(di, "droneSubEnumValue")))
    payload = int(_text(pi, "payloadEnumValue"))
    assert drone in ((60, 0), (89, 0), (67, 0), (67, 1)) and payload in (42, 43, 50, 52, 53)
    assert int(_text(pi, "payloadPositionIndex")) == 0
    folders = doc.findall(KML + "Folder")
    assert len(folders) == 1
    f = folders[0]
    if template:
        assert _text(doc, "author") == "wtinspect"
        assert _text(f, "templateType") == "waypoint" and _text(f, "templateId") == "0"
        cs = f.find(WPML + "waylineCoordinateSysParam")
        assert _text(cs, "coordinateMode") == "WGS84"
        assert _text(cs, "heightMode") == "relativeToStartPoint"
        assert _text(f, "gimbalPitchMode") == "usePointSetting"
    else:
        assert _text(f, "templateId") == "0" and _text(f, "waylineId") == "0"
        assert _text(f, "executeHeightMode") == "relativeToStartPoint"
    assert 0 < float(_text(f, "autoFlightSpeed")) <= 15
    wps, groups = [], set()
    for k, pm in enumerate(f.findall(KML + "Placemark")):
        lon, lat = (float(x) for x in _text(pm.find(KML + "Point"), "coordinates", KML).split(","))
        assert -90 <= lat <= 90 and -180 <= lon <= 180
        assert int(_text(pm, "index")) == k, "indices count up from 0 with no gap"
        if template:
            h = float(_text(pm, "height"))
            assert float(_text(pm, "ellipsoidHeight")) == h
            for key in ("useGlobalHeight", "useGlobalSpeed", "useGlobalHeadingParam",
                        "useGlobalTurnParam"):
                assert _text(pm, key) == "0"
            gimbal = float(_text(pm, "gimbalPitchAngle"))
        else:
            h, gimbal = float(_text(pm, "executeHeight")), None
        v = float(_text(pm, "waypointSpeed"))
        assert 0 < v <= 15
        hp = pm.find(WPML + "waypointHeadingParam")
        assert _text(hp, "waypointHeadingMode") == "smoothTransition"
        heading = float(int(_text(hp, "waypointHeadingAngle")))  # an integer in WPML
        assert -180 <= heading <= 180
        assert _text(hp, "waypointHeadingPathMode") == "followBadArc"
        tp = pm.find(WPML + "waypointTurnParam")
        mode = _text(tp, "waypointTurnMode")
        assert mode in (TURN_STOP, TURN_PASS)
        assert float(_text(tp, "waypointTurnDampingDist")) == 0  # only coordinateTurn uses it
        after = _children(pm)[_children(pm).index("waypointTurnParam") + 1:]
        # the continuity-curvature modes need useStraightLine; 1 keeps the checked straight legs
        assert (after[:1] == ["useStraightLine"]) == (mode == TURN_PASS)
        if mode == TURN_PASS:
            assert _text(pm, "useStraightLine") == "1"
        actions, along = [], None
        for g in pm.findall(WPML + "actionGroup"):
            gid = int(_text(g, "actionGroupId"))
            assert gid == len(groups), "action group ids count up from 0"
            groups.add(gid)
            trigger = _text(g.find(WPML + "actionTrigger"), "actionTriggerType")
            first, last = int(_text(g, "actionGroupStartIndex")), int(_text(g, "actionGroupEndIndex"))
            acts = []
            for a, act in enumerate(g.findall(WPML + "action")):
                assert int(_text(act, "actionId")) == a
                func = _text(act, "actionActuatorFunc")
                p = act.find(WPML + "actionActuatorFuncParam")
                assert _children(p) == ACTION_PARAMS[func], func
                acts.append((func, {c: _text(p, c) for c in ACTION_PARAMS[func]}))
            if trigger == "reachPoint":  # at this waypoint, one after the other
                assert first == last == k and _text(g, "actionGroupMode") == "sequence"
                assert "gimbalEvenlyRotate" not in [a for a, _ in acts]
                actions += acts
            else:  # along the leg to the next waypoint: only the gimbal, turned evenly
                assert trigger == "betweenAdjacentPoints" and (first, last) == (k, k + 1)
                assert _text(g, "actionGroupMode") == "parallel" and along is None
                assert [a for a, _ in acts] == ["gimbalEvenlyRotate"]
                along = float(acts[0][1]["gimbalPitchRotateAngle"])
        if mode == TURN_PASS:  # flown through: nothing that needs the aircraft standing
            assert not {"rotateYaw", "gimbalRotate"} & {a for a, _ in actions}
        for func, p in actions:
            if func == "rotateYaw":
                heading = float(p["aircraftHeading"])
                assert -180 <= heading <= 180
                assert p["aircraftPathMode"] in ("clockwise", "counterClockwise")
            if func == "gimbalRotate":
                assert p["gimbalRotateMode"] == "absoluteAngle" and p["gimbalPitchRotateEnable"] == "1"
        wps.append({"lat": lat, "lon": lon, "height": h, "speed": v, "heading": heading,
                    "stop": mode == TURN_STOP, "gimbal_along_next_leg": along,
                    "gimbal": gimbal, "actions": [a for a, _ in actions],
                    "params": dict((a, p) for a, p in actions)})
    assert wps, "a wayline has at least one waypoint"
    return {"drone": drone, "payload": payload, "waypoints": wps}


def _dji_plan() -> Plan:
    """small_plan with headings that are not whole degrees and a gimbal that moves mid-sortie."""
    plan = small_plan()
    r = plan.routes[0]
    r.yaw_deg[:] = [0, 10.0, 212.34, 212.34, 10.0, 0, 0, 5.0, 97.25, 350.0, 0]
    r.gimbal_pitch_deg[:] = [0, 0, -10, -12.5, 0, 0, 0, 0, -3.3, 0, 0]
    return plan


def _read_kmz(path) -> tuple[str, str]:
    import zipfile

    with zipfile.ZipFile(path) as z:
        assert sorted(z.namelist()) == ["wpmz/template.kml", "wpmz/waylines.wpml"]
        return (z.read("wpmz/template.kml").decode("utf-8"),
                z.read("wpmz/waylines.wpml").decode("utf-8"))


def _wrap(deg):
    return (np.asarray(deg, float) + 180) % 360 - 180


def test_dji_kmz_parses_back_to_the_plan_and_matches_golden(tmp_path):
    plan = _dji_plan()
    r = plan.routes[0]
    files = export_all(plan, tmp_path, stem="small", dji="m350-p1").written
    kmz = sorted(f for f in files if f.suffix == ".kmz")
    assert [f.name for f in kmz] == ["small_UAV1_s1.kmz", "small_UAV1_s2.kmz"]
    again = export_all(plan, tmp_path / "again", stem="small", dji="m350-p1").written
    assert kmz[0].read_bytes() == again[0].read_bytes(), "same plan, same bytes"
    truth = _textbook_enu_to_llh(r.pos, ORIGIN)
    for s, ((a, b), path) in enumerate(zip(sorties(r), kmz), start=1):
        template, waylines = _read_kmz(path)
        _golden(f"small_s{s}.template.kml", template)
        _golden(f"small_s{s}.waylines.wpml", waylines)
        t, w = parse_wpml(template, template=True), parse_wpml(waylines, template=False)
        assert t["drone"] == w["drone"] == (89, 0) and t["payload"] == w["payload"] == 50
        idx = list(range(a + 1, b))  # airborne points; take-off and landing are the drone's
        assert len(w["waypoints"]) == len(t["waypoints"]) == len(idx)
        for i, wp, tp in zip(idx, w["waypoints"], t["waypoints"]):
            got = np.array([[wp["lat"], wp["lon"], wp["height"] + truth[a, 2]]])
            assert _metres_apart(got, truth[i:i + 1]).max() < 0.01  # 1 cm
            assert (tp["lat"], tp["lon"], tp["height"]) == (wp["lat"], wp["lon"], wp["height"])
            # exact where it stops (rotateYaw); WPML's whole degree where it flies through
            assert abs(_wrap(wp["heading"] - r.yaw_deg[i])) <= (0.1 if wp["stop"] else 0.5)
            assert wp["speed"] == pytest.approx(r.speed[i + 1], abs=0.01)
            assert tp["gimbal"] == pytest.approx(r.gimbal_pitch_deg[i], abs=0.1)
            assert ("takePhoto" in wp["actions"]) == bool(r.photo[i])
            if r.photo[i]:
                assert wp["actions"][-1] == "takePhoto", "the photo is taken after turning"
                assert wp["params"]["takePhoto"]["fileSuffix"] == r.component[i].replace("/", "_")
        _check_gimbal_held(w["waypoints"], r.gimbal_pitch_deg[a + 1:b])


def _check_gimbal_held(wps: list[dict], pitch: np.ndarray) -> None:
    """The gimbal the aircraft holds at each waypoint, from its gimbal actions alone: turned at
    a stop, or evenly along the leg into a waypoint flown through; one action per change."""
    held, along = None, None
    for wp, p in zip(wps, pitch):
        if along is not None:
            assert not wp["stop"], "gimbalEvenlyRotate leads only to a waypoint flown through"
            held = along
        if "gimbalRotate" in wp["actions"]:
            assert wp["stop"]
            held = float(wp["params"]["gimbalRotate"]["gimbalPitchRotateAngle"])
        assert held == pytest.approx(p, abs=0.1)
        along = wp["gimbal_along_next_leg"]
    turns = sum(("gimbalRotate" in wp["actions"]) + (wp["gimbal_along_next_leg"] is not None)
                for wp in wps)
    assert turns == 1 + int(np.sum(np.diff(pitch) != 0))


def _pass_plan() -> Plan:
    """Take off, a straight photo pass of five stations (one a 10 deg bend, the heading not a
    whole degree), a right-angle corner into a second pass whose gimbal turns on its last leg, land."""
    t = Turbine.with_rotor_azimuth(90, id="T1", base=(0, 0, 0), hub_height=80, rotor_diameter=90,
                                   yaw_deg=180)
    launch = [60.0, -40.0, 0.0]
    bend = [30 + 2.5 * np.cos(np.radians(10)), -20 + 2.5 * np.sin(np.radians(10)), 60]
    pos = np.array([launch, [60, -40, 10], [25, -20, 60], [27.5, -20, 60], [30, -20, 60], bend,
                    [bend[0] + 2.5 * np.cos(np.radians(10)), bend[1] + 2.5 * np.sin(np.radians(10)), 60],
                    [bend[0] + 2.5 * np.cos(np.radians(10)), bend[1] + 5, 60],
                    [bend[0] + 2.5 * np.cos(np.radians(10)), bend[1] + 7.5, 60],
                    [bend[0] + 2.5 * np.cos(np.radians(10)), bend[1] + 10, 60], [60, -40, 10], launch])
    n = len(pos)
    photo = np.array([0, 0, 1, 1, 1, 1, 1, 1, 1, 1, 0, 0], bool)
    comp = ["launch", "launch"] + ["T1/blade1/leading_edge"] * 5 + ["T1/blade1/trailing_edge"] * 3 \
        + ["return", "return"]
    route = Route("UAV1", t=np.cumsum(np.r_[0, np.ones(n - 1) * 3.0]), pos=pos,
                  speed=np.r_[0, 3.0, 8.0, 2.7, 2.7, 2.7, 2.7, 2.7, 2.7, 2.7, 8.0, 3.0],
                  yaw_deg=np.r_[0, 0, 0, 12.34, 12.34, 12.34, 12.34, 102.5, 102.5, 102.5, 102.5, 102.5],
                  gimbal_pitch_deg=np.r_[0, 0, -5, -5, -5, -5, -5, -5, -20, -20, 0, 0],
                  photo=photo, component=np.array(comp, dtype=object))
    return Plan([t], Camera(5456, 3632, 16, 23.2), [route], 3.0, 1.5, ORIGIN, {})


def test_dji_kmz_flies_a_photo_pass_without_stopping(tmp_path):
    """The aircraft stops where the plan's timing stops it (corners.stops) and flies through the
    stations of a straight pass, photographing in flight: a stop at each photo would add about
    1 s per photo to what the plan says (16.8 min a turbine instead of 10)."""
    plan = _pass_plan()
    r = plan.routes[0]
    (path,) = [f for f in export_all(plan, tmp_path, stem="pass", dji="m350-p1").written
               if f.suffix == ".kmz"]
    template, waylines = _read_kmz(path)
    _golden("pass_s1.template.kml", template)
    _golden("pass_s1.waylines.wpml", waylines)
    t, w = parse_wpml(template, template=True), parse_wpml(waylines, template=False)
    stop = [wp["stop"] for wp in w["waypoints"]]
    assert stop == [wp["stop"] for wp in t["waypoints"]]
    # airborne 1..10: the climb's top (1) and the corner into the pass (2) stop; the pass (3..5,
    # with its 10 deg bend at 4) is flown through; the right-angle corner (6) stops; 7 and 8 are
    # flown through, the gimbal turning on the leg into 8; the pass's end (9) and the last
    # airborne point (10, the gimbal levelled there) stop.
    assert stop == [True, True, False, False, False, True, False, False, True, True]
    for i, wp in zip(range(1, 11), w["waypoints"]):
        assert ("takePhoto" in wp["actions"]) == bool(r.photo[i])
        assert ("rotateYaw" in wp["actions"]) == (wp["stop"] and abs(r.yaw_deg[i] % 1) > 0.05)
        assert abs(_wrap(wp["heading"] - r.yaw_deg[i])) <= (0.1 if wp["stop"] else 0.5)
    assert w["waypoints"][6]["gimbal_along_next_leg"] == -20  # on the leg 7 -> 8
    _check_gimbal_held(w["waypoints"], r.gimbal_pitch_deg[1:11])
    # The plan's own timing stops exactly there.
    from wtcli.plan.corners import stops
    assert list(stops(r.pos)[1:11] | np.isin(np.arange(1, 11), [1, 10])) == stop


def test_dji_kmz_for_every_aircraft_and_the_sample_site(tmp_path):
    from wtcli.plan.config import load_mission
    from wtcli.plan.dji_kmz import AIRCRAFT
    from wtcli.plan.mission import plan_mission

    plan = _dji_plan()
    for key, ac in AIRCRAFT.items():
        (path,) = [f for f in export_all(plan, tmp_path / key, dji=key).written
                   if f.suffix == ".kmz"][:1]
        w = parse_wpml(_read_kmz(path)[1], template=False)
        assert w["drone"] == (ac.drone_enum, ac.drone_sub_enum) and w["payload"] == ac.payload_enum
    root = Path(__file__).resolve().parents[1]
    mission = load_mission(root / "sample_images" / "turbines.yaml")
    real = plan_mission(mission)
    files = export_all(real, tmp_path / "real", stem="m", dji="m30t",
                       cruise=mission.fleet.cruise_speed_m_s,
                       hover=mission.fleet.inspection_speed_m_s).written
    photos = in_flight = 0
    for f in files:
        if f.suffix == ".kmz":
            for text, template in zip(_read_kmz(f), (True, False)):
                wps = parse_wpml(text, template)["waypoints"]
            photos += sum("takePhoto" in wp["actions"] for wp in wps)
            in_flight += sum("takePhoto" in wp["actions"] and not wp["stop"] for wp in wps)
    assert photos == real.summary["photos"]
    assert in_flight > 0.8 * photos, "photo passes are flown, not stop-and-shoot"


def test_dji_kmz_refuses_what_dji_waylines_cannot_fly(tmp_path):
    plan = _dji_plan()
    with pytest.raises(ConfigError, match="--dji-kmz: expected one of m300-p1"):
        export_all(plan, tmp_path, dji="phantom")
    plan.routes[0].speed[3] = 17.0
    with pytest.raises(ConfigError, match=r"UAV1 leg 2->3 is planned at 17 m/s.*\(0, 15\]"):
        export_all(plan, tmp_path, dji="m300-h20")
    assert not list(tmp_path.iterdir()), "nothing written when the DJI export is refused"


# ---- read back by the code ground stations use ----------------------------------------------------
def test_pymavlink_reads_every_waypoints_file_we_write(tmp_path):
    """pymavlink's mission loader (MAVProxy, many ground-station scripts) reads each .waypoints
    to the same commands, frames, parameters and positions as the plan's mission items."""
    mavwp = pytest.importorskip("pymavlink.mavwp", reason="pymavlink (test-only, requirements.lock) "
                                "is not installed in this environment")
    from wtcli.plan.config import load_mission
    from wtcli.plan.mission import plan_mission

    root = Path(__file__).resolve().parents[1]
    plans = {"small": small_plan(), "wide": wide_plan(),
             "sample": plan_mission(load_mission(root / "sample_images" / "turbines.yaml"))}
    n_files = 0
    for name, plan in plans.items():
        for r in plan.routes:
            for s, (a, b) in enumerate(sorties(r), start=1):
                items, home = mission_items(plan, r, a, b)
                path = tmp_path / f"{name}_{r.uav}_s{s}.waypoints"
                path.write_text(wpl_text(items, home))
                loader = mavwp.MAVWPLoader()
                assert loader.load(str(path)) == len(items) + 1
                h = loader.wp(0)
                assert (h.seq, h.frame, h.command, h.current) == (0, 0, 16, 1)
                assert (h.x, h.y, h.z) == pytest.approx(tuple(home), abs=1e-3)
                for k, it in enumerate(items, start=1):
                    m = loader.wp(k)
                    assert (m.seq, m.frame, m.command, m.autocontinue) == (k, it.frame, it.command, 1)
                    want = [0.0 if p is None else p for p in it.params]
                    got = [m.param1, m.param2, m.param3, m.param4, m.x, m.y, m.z]
                    assert got[:4] == pytest.approx(want[:4], abs=1e-3)  # 6 significant digits
                    assert got[4:6] == pytest.approx(want[4:6], abs=1e-7)  # ~1 cm
                    assert got[6] == pytest.approx(want[6], abs=1e-3)
                n_files += 1
    assert n_files >= 4


# ---- one export set per stem ----------------------------------------------------------------------
def _one_sortie_plan() -> Plan:
    """small_plan cut after its first landing: one sortie where small_plan has two."""
    p = small_plan()
    r = p.routes[0]
    k = 6
    route = Route(r.uav, t=r.t[:k], pos=r.pos[:k], speed=r.speed[:k], yaw_deg=r.yaw_deg[:k],
                  gimbal_pitch_deg=r.gimbal_pitch_deg[:k], photo=r.photo[:k],
                  component=r.component[:k])
    return Plan(p.turbines, p.camera, [route], 3.0, 1.5, ORIGIN, {})


def _snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (hidden ones too) and its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


def test_a_reexport_with_fewer_sorties_leaves_only_this_plans_files(tmp_path):
    """A plan of 1 sortie exported over one of 2 leaves no plan_UAV1_s2.* beside it (a sortie
    of another plan a pilot could fly). Other stems' exports and the user's files stay."""
    d = tmp_path / "exp"
    export_all(small_plan(), d, stem="plan", dji="m350-p1")
    export_all(small_plan(), d, stem="other")
    for name in ("notes.txt", "plan.json", "plan_UAV1_s2.txt", "plan_UAV1_s2.plan.bak"):
        (d / name).write_text("the user's\n")
    earlier = {"plan.geojson"} | {f"plan_UAV1_s{s}.{x}" for s in (1, 2)
                                  for x in ("plan", "waypoints", "kmz")}
    kept = {k: v for k, v in _snapshot(d).items() if k not in earlier}
    done = export_all(_one_sortie_plan(), d, stem="plan")
    assert sorted(p.name for p in done.written) == ["plan.geojson", "plan_UAV1_s1.plan",
                                                     "plan_UAV1_s1.waypoints"]
    assert sorted(p.name for p in done.removed) == [
        "plan_UAV1_s1.kmz", "plan_UAV1_s2.kmz", "plan_UAV1_s2.plan", "plan_UAV1_s2.waypoints"]
    assert sorted(p.name for p in done.replaced) == sorted(p.name for p in done.written)
    after = _snapshot(d)
    assert sorted(k for k in after if k not in kept) == sorted(p.name for p in done.written)
    assert {k: after[k] for k in kept} == kept, "other stems' exports and user files untouched"
    assert parse_wpl((d / "plan_UAV1_s1.waypoints").read_text())[-1]["command"] == 21
    fresh = export_all(_one_sortie_plan(), tmp_path / "fresh", stem="plan")
    assert not fresh.replaced and not fresh.removed
    assert _snapshot(tmp_path / "fresh") == {p.name: after[p.name] for p in done.written}


@pytest.mark.parametrize("failure", ["full disk", "ctrl-c"])
def test_an_export_that_fails_part_way_leaves_the_earlier_set_whole(tmp_path, monkeypatch, failure):
    """A disk filling (or Ctrl-C) part-way through a re-export changes nothing in the folder:
    no sortie files of two plans side by side, no staging folder left."""
    import wtcli.plan.exports as exports
    from wtcli.errors import OutputError

    d = tmp_path / "exp"
    export_all(small_plan(), d, stem="plan", dji="m350-p1")
    (d / "notes.txt").write_text("the user's\n")
    before = _snapshot(d)
    real, calls = exports._stage, []

    def stage(tmp, final, data):
        calls.append(final.name)
        if len(calls) == 3:
            if failure == "ctrl-c":
                raise KeyboardInterrupt
            real(tmp.parent / "gone" / tmp.name, final, data)  # a real OSError from the write
        real(tmp, final, data)

    monkeypatch.setattr(exports, "_stage", stage)
    with pytest.raises(KeyboardInterrupt if failure == "ctrl-c" else OutputError) as e:
        export_all(_one_sortie_plan(), d, stem="plan", dji="m30")
    if failure == "full disk":
        assert str(e.value).startswith(f"{d / calls[2]}: cannot write ("), "names the file"
    assert _snapshot(d) == before, "the earlier set whole, no staging folder left"


def test_files_another_stem_may_own_are_left_to_it(tmp_path):
    """UAV ids may hold "_", so plan_UAV1_UAV1_s1.plan could be stem plan's (UAV "UAV1_UAV1")
    or stem plan_UAV1's (UAV "UAV1"): the other stem's map (its .geojson) says which."""
    d = tmp_path
    export_all(small_plan(), d, stem="plan_UAV1")
    theirs = _snapshot(d)
    export_all(small_plan(), d, stem="plan")
    done = export_all(_one_sortie_plan(), d, stem="plan")
    assert sorted(p.name for p in done.removed) == ["plan_UAV1_s2.plan", "plan_UAV1_s2.waypoints"]
    assert {k: v for k, v in _snapshot(d).items() if k in theirs} == theirs
    # The other way round: site's map has no UAV "north_UAV1", so those files are site_north's.
    export_all(small_plan(), d, stem="site_north")
    export_all(small_plan(), d, stem="site")
    done = export_all(_one_sortie_plan(), d, stem="site_north")
    assert sorted(p.name for p in done.removed) == ["site_north_UAV1_s2.plan",
                                                    "site_north_UAV1_s2.waypoints"]
    assert (d / "site_UAV1_s2.plan").is_file()


def test_a_folder_in_the_way_is_refused_before_the_earlier_set_is_touched(tmp_path):
    from wtcli.errors import OutputError

    export_all(small_plan(), tmp_path, stem="plan")
    (tmp_path / "plan_UAV1_s2.plan").unlink()
    (tmp_path / "plan_UAV1_s2.plan").mkdir()
    before = _snapshot(tmp_path)
    with pytest.raises(OutputError, match=r"s2\.plan: cannot write \(a folder is in the way\)"):
        export_all(small_plan(), tmp_path, stem="plan")
    assert _snapshot(tmp_path) == before


def test_a_uav_id_that_is_not_a_file_name_is_refused(tmp_path):
    import dataclasses

    p = small_plan()
    p = dataclasses.replace(p, routes=[dataclasses.replace(p.routes[0], uav="../UAV1")])
    with pytest.raises(ConfigError, match=r"fleet.uavs: '../UAV1' cannot be part of a file name"):
        export_all(p, tmp_path / "exp")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("theirs", [
    '{"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": null, '
    '"properties": {"name": "site boundary"}}]}',
    '{"type": "FeatureCollection", "features": []}', "not json at all", ""])
def test_a_users_own_geojson_under_the_maps_name_is_not_replaced(tmp_path, theirs):
    """STEM.geojson is the export's map; a user's GeoJSON of that name (a site boundary) is
    refused, exit 3 naming it, and nothing is written; an earlier export's map is replaced."""
    from wtcli.errors import OutputError

    (tmp_path / "plan.geojson").write_text(theirs)
    with pytest.raises(OutputError, match=r"plan\.geojson: is not the map of an earlier wtinspect"):
        export_all(small_plan(), tmp_path, stem="plan")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan.geojson"]
    assert (tmp_path / "plan.geojson").read_text() == theirs
    (tmp_path / "plan.geojson").unlink()
    export_all(small_plan(), tmp_path, stem="plan")
    done = export_all(_one_sortie_plan(), tmp_path, stem="plan")
    assert tmp_path / "plan.geojson" in done.replaced
