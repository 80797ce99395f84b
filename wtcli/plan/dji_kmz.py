"""DJI WPML waypoint missions (``.kmz``) for DJI Pilot 2 and FlightHub 2, one per UAV sortie.

The archive holds ``wpmz/template.kml`` (the editable template) and ``wpmz/waylines.wpml`` (what
the aircraft executes), following DJI's published WPML 1.0.2 reference (DJI Cloud API docs:
"DJI WPML", template.kml / waylines.wpml / common elements). Only the standard library writes it.

Heights: ``executeHeightMode`` is ``relativeToStartPoint``: every ``executeHeight`` is the
waypoint's exact WGS84 height minus the launch point's (the same figure as the MAVLink frame-3
altitude, see ``wtcli.plan.exports``). The drone must take off from the planned launch point.
``WGS84`` (ellipsoid) heights would need the geoid undulation at the site, which is not known
offline: ``site.origin.alt`` is above mean sea level, and EGM96 and the ellipsoid differ by up to
±100 m. docs/plan.md ("DJI WPML") explains the trap.

Each waypoint is one plan waypoint between take-off and landing, flown where the plan's timing
says (``wtcli.plan.corners``): through it on straight segments
(``toPointAndPassWithContinuityCurvature``, ``useStraightLine`` 1: a photo pass is flown without
stopping, the photos taken in flight) or stopping at it
(``toPointAndStopWithDiscontinuityCurvature``: sharper corners, the first and last waypoint).
Legs stay the straight segments the clearance was checked on. ``waypointSpeed`` = the planned
speed of the leg leaving it, heading ``smoothTransition`` to the plan's heading (an integer in
WPML) plus, where the aircraft stops, a ``rotateYaw`` action to the exact heading where the two
differ (a waypoint flown through keeps the whole degree, within 0.5 deg of the plan's), the
gimbal pitch where it changes
(``gimbalRotate`` at a stop; ``gimbalEvenlyRotate`` along the leg into a waypoint flown through),
then ``takePhoto`` at photo waypoints (file suffix = the component photographed). Finish: go home.
"""

from __future__ import annotations

import io
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass

import numpy as np

from wtcli.errors import ConfigError
from wtcli.plan.corners import stops
from wtcli.plan.geodesy import enu_to_geodetic
from wtcli.plan_file import Plan, Route

KML_NS = "http://www.opengis.net/kml/2.2"
WPML_NS = "http://www.dji.com/wpmz/1.0.2"
# DJI's waylines accept waypoint and transitional speeds up to 15 m/s.
MAX_WAYLINE_SPEED_M_S = 15.0
HEIGHT_MODE = "relativeToStartPoint"
TURN_STOP = "toPointAndStopWithDiscontinuityCurvature"  # straight in, stop at the point
TURN_PASS = "toPointAndPassWithContinuityCurvature"  # fly through the point (straight segments)
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)  # fixed, so the same plan gives the same bytes


@dataclass(frozen=True)
class Aircraft:
    name: str
    drone_enum: int
    drone_sub_enum: int
    payload_enum: int
    image_format: str  # the lens the photos are stored from (wpml:imageFormat)


# droneEnumValue / payloadEnumValue from DJI's Cloud API product tables; P1 (50) is the value
# DJI Pilot 2 writes for the Zenmuse P1 (it is absent from the Cloud API's payload table).
AIRCRAFT = {
    "m300-p1": Aircraft("Matrice 300 RTK + Zenmuse P1", 60, 0, 50, "visible"),
    "m300-h20": Aircraft("Matrice 300 RTK + Zenmuse H20", 60, 0, 42, "zoom"),
    "m350-p1": Aircraft("Matrice 350 RTK + Zenmuse P1", 89, 0, 50, "visible"),
    "m350-h20": Aircraft("Matrice 350 RTK + Zenmuse H20", 89, 0, 42, "zoom"),
    "m30": Aircraft("Matrice 30", 67, 0, 52, "wide"),
    "m30t": Aircraft("Matrice 30T", 67, 1, 53, "wide"),
}


@dataclass(frozen=True)
class Waypoint:
    """One WPML waypoint as the aircraft flies it."""

    lat: float
    lon: float
    height: float  # m above the launch point (relativeToStartPoint)
    speed: float  # m/s on the leg leaving this waypoint
    heading: float  # aircraft heading, deg in [-180, 180] (0 north, 90 east)
    gimbal_pitch: float  # deg, 0 level, -90 down
    photo: bool
    component: str
    stop: bool = True  # the aircraft stops here (else it flies through, on straight segments)


def _heading180(deg: float) -> float:
    h = (float(deg) + 180.0) % 360.0 - 180.0
    return 180.0 if h == -180.0 else h


def aircraft(key: str) -> Aircraft:
    if key not in AIRCRAFT:
        raise ConfigError(f"--dji-kmz: expected one of {', '.join(AIRCRAFT)}, got {key!r}")
    return AIRCRAFT[key]


def sortie_waypoints(plan: Plan, route: Route, first: int, last: int) -> list[Waypoint]:
    """The airborne waypoints of one sortie (the route's points strictly between take-off at
    ``first`` and landing at ``last``), positions exact WGS84, heights above the launch point."""
    if not plan.site_origin:
        raise ConfigError("exports to lat/lon need site.origin (lat, lon, alt) in turbines.yaml")
    llh = enu_to_geodetic(route.pos[first:last + 1], plan.site_origin)
    rel = llh[:, 2] - llh[0, 2]
    halt = stops(route.pos)
    halt[[first + 1, last - 1]] = True  # the wayline starts and ends standing
    out = []
    for i in range(first + 1, last):
        j = i - first
        v = float(route.speed[i + 1])
        if np.linalg.norm(route.pos[i + 1] - route.pos[i]) < 1e-6:
            raise ConfigError(f"fleet: {route.uav} leg {i}->{i + 1} has no length (two waypoints "
                              "at one place, a plan edited by hand?); DJI waylines need every "
                              "leg to move")
        if not 0.0 < v <= MAX_WAYLINE_SPEED_M_S:
            raise ConfigError(
                f"fleet: {route.uav} leg {i}->{i + 1} is planned at {v:g} m/s; DJI waylines fly "
                f"(0, {MAX_WAYLINE_SPEED_M_S:g}] m/s: lower fleet.cruise_speed_m_s / "
                "max_speed_m_s for a DJI export")
        out.append(Waypoint(float(llh[j, 0]), float(llh[j, 1]), float(rel[j]), v,
                            _heading180(route.yaw_deg[i]), float(route.gimbal_pitch_deg[i]),
                            bool(route.photo[i]), str(route.component[i]), bool(halt[i])))
    return out


# ---- XML -----------------------------------------------------------------------------------------
ET.register_namespace("", KML_NS)
ET.register_namespace("wpml", WPML_NS)


def _k(tag: str) -> str:
    return f"{{{KML_NS}}}{tag}"


def _w(tag: str) -> str:
    return f"{{{WPML_NS}}}{tag}"


def _num(x: float, nd: int) -> str:
    s = f"{float(x):.{nd}f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _sub(parent: ET.Element, tag: str, text=None) -> ET.Element:
    e = ET.SubElement(parent, _w(tag))
    if text is not None:
        e.text = str(text)
    return e


def _mission_config(parent: ET.Element, wps: list[Waypoint], ac: Aircraft, cruise: float) -> None:
    mc = _sub(parent, "missionConfig")
    _sub(mc, "flyToWaylineMode", "safely")
    _sub(mc, "finishAction", "goHome")
    # A lost link continues the planned (clearance-checked) path, then goes home from above the
    # launch point; a return from an arbitrary point near a rotor is not checked.
    _sub(mc, "exitOnRCLost", "goContinue")
    _sub(mc, "executeRCLostAction", "hover")
    _sub(mc, "takeOffSecurityHeight", _num(np.clip(wps[0].height, 2.0, 1500.0), 3))
    _sub(mc, "globalTransitionalSpeed", _num(min(cruise, MAX_WAYLINE_SPEED_M_S), 2))
    _sub(mc, "globalRTHHeight", _num(np.clip(wps[-1].height, 20.0, 1500.0), 3))
    di = _sub(mc, "droneInfo")
    _sub(di, "droneEnumValue", ac.drone_enum)
    _sub(di, "droneSubEnumValue", ac.drone_sub_enum)
    pi = _sub(mc, "payloadInfo")
    _sub(pi, "payloadEnumValue", ac.payload_enum)
    _sub(pi, "payloadSubEnumValue", 0)
    _sub(pi, "payloadPositionIndex", 0)


def _heading_param(parent: ET.Element, wp: Waypoint) -> None:
    hp = _sub(parent, "waypointHeadingParam")
    _sub(hp, "waypointHeadingMode", "smoothTransition")
    _sub(hp, "waypointHeadingAngle", int(round(wp.heading)))
    _sub(hp, "waypointHeadingPathMode", "followBadArc")  # WPML's name for the shortest turn


def _turn_param(parent: ET.Element, wp: Waypoint) -> None:
    tp = _sub(parent, "waypointTurnParam")
    _sub(tp, "waypointTurnMode", TURN_STOP if wp.stop else TURN_PASS)
    _sub(tp, "waypointTurnDampingDist", 0)
    if not wp.stop:  # required with the continuity-curvature modes: 1 = straight segments
        _sub(parent, "useStraightLine", 1)


def _pitch_changes(a: Waypoint | None, b: Waypoint) -> bool:
    return a is None or round(b.gimbal_pitch, 1) != round(a.gimbal_pitch, 1)


def _actions(parent: ET.Element, k: int, wp: Waypoint, prev: Waypoint | None,
             nxt: Waypoint | None, group_id: int) -> int:
    """The action groups of waypoint ``k``; how many. At the waypoint (``reachPoint``): where it
    stops, the gimbal's and the exact heading's turns; the photo. Along the leg to a next
    waypoint flown through (``betweenAdjacentPoints``): the gimbal turned evenly, so the aircraft
    need not stop for it."""
    acts: list[tuple[str, list[tuple[str, object]]]] = []
    if wp.stop and _pitch_changes(prev, wp):
        acts.append(("gimbalRotate", [
            ("gimbalHeadingYawBase", "north"), ("gimbalRotateMode", "absoluteAngle"),
            ("gimbalPitchRotateEnable", 1), ("gimbalPitchRotateAngle", _num(wp.gimbal_pitch, 2)),
            ("gimbalRollRotateEnable", 0), ("gimbalRollRotateAngle", 0),
            ("gimbalYawRotateEnable", 0), ("gimbalYawRotateAngle", 0),
            ("gimbalRotateTimeEnable", 0), ("gimbalRotateTime", 0), ("payloadPositionIndex", 0)]))
    if wp.stop and abs(wp.heading - round(wp.heading)) > 0.05:
        turn = _heading180(wp.heading - (prev.heading if prev else wp.heading))
        acts.append(("rotateYaw", [("aircraftHeading", _num(wp.heading, 2)),
                                   ("aircraftPathMode",
                                    "clockwise" if turn >= 0 else "counterClockwise")]))
    if wp.photo:
        acts.append(("takePhoto", [("payloadPositionIndex", 0),
                                   ("fileSuffix", wp.component.replace("/", "_")),
                                   ("useGlobalPayloadLensIndex", 1)]))
    n = 0
    if acts:
        _group(parent, group_id, k, k, "sequence", "reachPoint", acts)
        n += 1
    if nxt is not None and not nxt.stop and _pitch_changes(wp, nxt):
        _group(parent, group_id + n, k, k + 1, "parallel", "betweenAdjacentPoints",
               [("gimbalEvenlyRotate", [("gimbalPitchRotateAngle", _num(nxt.gimbal_pitch, 2)),
                                        ("payloadPositionIndex", 0)])])
        n += 1
    return n


def _group(parent: ET.Element, group_id: int, first: int, last: int, mode: str, trigger: str,
           acts: list[tuple[str, list[tuple[str, object]]]]) -> None:
    g = _sub(parent, "actionGroup")
    _sub(g, "actionGroupId", group_id)
    _sub(g, "actionGroupStartIndex", first)
    _sub(g, "actionGroupEndIndex", last)
    _sub(g, "actionGroupMode", mode)
    _sub(_sub(g, "actionTrigger"), "actionTriggerType", trigger)
    for a, (func, params) in enumerate(acts):
        act = _sub(g, "action")
        _sub(act, "actionId", a)
        _sub(act, "actionActuatorFunc", func)
        p = _sub(act, "actionActuatorFuncParam")
        for name, value in params:
            _sub(p, name, value)


def _placemark(folder: ET.Element, k: int, wp: Waypoint) -> ET.Element:
    pm = ET.SubElement(folder, _k("Placemark"))
    pt = ET.SubElement(pm, _k("Point"))
    ET.SubElement(pt, _k("coordinates")).text = f"{wp.lon:.9f},{wp.lat:.9f}"
    _sub(pm, "index", k)
    return pm


def _to_text(root: ET.Element) -> str:
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def waylines_wpml(wps: list[Waypoint], ac: Aircraft, cruise: float, inspection: float) -> str:
    root = ET.Element(_k("kml"))
    doc = ET.SubElement(root, _k("Document"))
    _mission_config(doc, wps, ac, cruise)
    folder = ET.SubElement(doc, _k("Folder"))
    _sub(folder, "templateId", 0)
    _sub(folder, "executeHeightMode", HEIGHT_MODE)
    _sub(folder, "waylineId", 0)
    _sub(folder, "autoFlightSpeed", _num(min(inspection, MAX_WAYLINE_SPEED_M_S), 2))
    gid = 0
    for k, wp in enumerate(wps):
        pm = _placemark(folder, k, wp)
        _sub(pm, "executeHeight", _num(wp.height, 3))
        _sub(pm, "waypointSpeed", _num(wp.speed, 2))
        _heading_param(pm, wp)
        _turn_param(pm, wp)
        gid += _actions(pm, k, wp, wps[k - 1] if k else None,
                        wps[k + 1] if k + 1 < len(wps) else None, gid)
    return _to_text(root)


def template_kml(wps: list[Waypoint], ac: Aircraft, cruise: float, inspection: float) -> str:
    root = ET.Element(_k("kml"))
    doc = ET.SubElement(root, _k("Document"))
    _sub(doc, "author", "wtinspect")
    _mission_config(doc, wps, ac, cruise)
    folder = ET.SubElement(doc, _k("Folder"))
    _sub(folder, "templateType", "waypoint")
    _sub(folder, "templateId", 0)
    cs = _sub(folder, "waylineCoordinateSysParam")
    _sub(cs, "coordinateMode", "WGS84")
    _sub(cs, "heightMode", HEIGHT_MODE)
    _sub(cs, "positioningType", "GPS")
    _sub(folder, "autoFlightSpeed", _num(min(inspection, MAX_WAYLINE_SPEED_M_S), 2))
    _sub(folder, "gimbalPitchMode", "usePointSetting")
    _sub(folder, "globalWaypointTurnMode", TURN_STOP)
    pp = _sub(folder, "payloadParam")
    _sub(pp, "payloadPositionIndex", 0)
    _sub(pp, "imageFormat", ac.image_format)
    gid = 0
    for k, wp in enumerate(wps):
        pm = _placemark(folder, k, wp)
        # In relativeToStartPoint mode the height above the launch point is the one used; the
        # ellipsoid height is unknown offline, so both carry the same figure.
        _sub(pm, "ellipsoidHeight", _num(wp.height, 3))
        _sub(pm, "height", _num(wp.height, 3))
        _sub(pm, "useGlobalHeight", 0)
        _sub(pm, "useGlobalSpeed", 0)
        _sub(pm, "waypointSpeed", _num(wp.speed, 2))
        _sub(pm, "useGlobalHeadingParam", 0)
        _heading_param(pm, wp)
        _sub(pm, "useGlobalTurnParam", 0)
        _turn_param(pm, wp)
        _sub(pm, "gimbalPitchAngle", _num(wp.gimbal_pitch, 2))
        gid += _actions(pm, k, wp, wps[k - 1] if k else None,
                        wps[k + 1] if k + 1 < len(wps) else None, gid)
    return _to_text(root)


def kmz_bytes(wps: list[Waypoint], ac: Aircraft, cruise: float, inspection: float) -> bytes:
    """The ``.kmz`` archive: ``wpmz/template.kml`` and ``wpmz/waylines.wpml``."""
    if not wps:
        raise ConfigError("a DJI wayline needs at least one airborne waypoint")
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, text in (("wpmz/template.kml", template_kml(wps, ac, cruise, inspection)),
                           ("wpmz/waylines.wpml", waylines_wpml(wps, ac, cruise, inspection))):
            info = zipfile.ZipInfo(name, date_time=_ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            z.writestr(info, text.encode("utf-8"))
    return buf.getvalue()
