"""Where a photo was taken from, as the photo itself says: EXIF GPS and DJI's XMP tags, read from
the JPEG's APP1 segments by a small reader of our own (no dependency), turned into the camera
pose (``CameraPose``, site ENU metres) that back-projects the photo's blade angles. docs/photo-pose.md

DJI drones write, in an XMP packet (namespace ``http://www.dji.com/drone-dji/1.0/``), attributes
such as ``drone-dji:GimbalYawDegree="-44.30"`` (compass, clockwise from north),
``GimbalPitchDegree`` (0 level, -90 straight down), ``GimbalRollDegree`` (positive: the image's
right side down), ``FlightYawDegree``, ``AbsoluteAltitude`` (m above mean sea level) and
``RelativeAltitude`` (m above the take-off point); latitude/longitude are in the EXIF GPS IFD (and
``drone-dji:GpsLatitude``/``GpsLongitude``, or DJI's ``GpsLongtitude``, on some models).

Height: ``RelativeAltitude`` above the turbine's tower base (the drone took off at the tower's
ground level) when present, else ``AbsoluteAltitude`` or EXIF ``GPSAltitude`` through
``site.origin.alt`` (above mean sea level). The heading is the gimbal's yaw, else the aircraft's.
"""

from __future__ import annotations

import math
import re
import struct
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wtcli.errors import ConfigError, InputError

DJI_NS = "http://www.dji.com/drone-dji/1.0/"
XMP_HEADER = b"http://ns.adobe.com/xap/1.0/\x00"
EXIF_HEADER = b"Exif\x00\x00"
# A pose farther than this from the hub is not an overview photo of this turbine.
MAX_DISTANCE_M = 2000.0
# Nearer than this to the turbine's surfaces counts as inside it (no drone takes a photo there).
MIN_CLEARANCE_M = 0.5

_DJI_FIELDS = {"GimbalYawDegree": "gimbal_yaw_deg", "GimbalPitchDegree": "gimbal_pitch_deg",
               "GimbalRollDegree": "gimbal_roll_deg", "FlightYawDegree": "flight_yaw_deg",
               "AbsoluteAltitude": "absolute_alt_m", "RelativeAltitude": "relative_alt_m",
               "GpsLatitude": "xmp_lat", "GpsLongitude": "xmp_lon", "GpsLongtitude": "xmp_lon"}


@dataclass(frozen=True)
class PhotoMetadata:
    """The pose-related tags of one photo; None where the photo does not carry the tag."""

    lat: float | None = None
    lon: float | None = None
    gps_alt_m: float | None = None  # EXIF GPSAltitude, m above sea level
    absolute_alt_m: float | None = None
    relative_alt_m: float | None = None
    gimbal_yaw_deg: float | None = None
    gimbal_pitch_deg: float | None = None
    gimbal_roll_deg: float | None = None
    flight_yaw_deg: float | None = None
    orientation: int | None = None  # EXIF Orientation: 1 upright; 2-8 turned or mirrored to show
    where: dict = field(default_factory=dict)  # field -> "EXIF GPS" / "DJI XMP"

    @property
    def has_position(self) -> bool:
        return self.lat is not None and self.lon is not None

    @property
    def has_pose(self) -> bool:
        return (self.has_position and self.gimbal_pitch_deg is not None
                and (self.gimbal_yaw_deg is not None or self.flight_yaw_deg is not None)
                and (self.relative_alt_m is not None or self.absolute_alt_m is not None
                     or self.gps_alt_m is not None))


# ---- JPEG / EXIF / XMP ---------------------------------------------------------------------------
def app1_segments(data: bytes, name: str = "photo") -> list[bytes]:
    """Payloads of the APP1 segments of a JPEG, in file order (up to the image data)."""
    if data[:2] != b"\xff\xd8":
        return []
    out, i, n = [], 2, len(data)
    while i + 4 <= n:
        if data[i] != 0xFF:
            raise InputError(f"{name}: corrupt JPEG: expected a marker at byte {i}")
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0xD9, 0xDA):  # end of image / start of scan: no more metadata
            break
        if 0xD0 <= marker <= 0xD7 or marker == 0x01:
            i += 2
            continue
        (length,) = struct.unpack(">H", data[i + 2:i + 4])
        if length < 2 or i + 2 + length > n:
            raise InputError(f"{name}: corrupt JPEG: segment at byte {i} runs past the file")
        if marker == 0xE1:
            out.append(data[i + 4:i + 2 + length])
        i += 2 + length
    return out


def _exif_gps(tiff: bytes) -> dict:
    """lat, lon, gps_alt_m from the GPS IFD of a TIFF/EXIF block, and the Orientation tag of
    its first IFD as ``orientation`` (each absent when the block does not carry it)."""
    if len(tiff) < 8 or tiff[:2] not in (b"II", b"MM"):
        return {}
    e = "<" if tiff[:2] == b"II" else ">"

    def ifd(off: int) -> dict[int, tuple[int, int, bytes, int]]:
        if off + 2 > len(tiff):
            return {}
        (count,) = struct.unpack(e + "H", tiff[off:off + 2])
        tags = {}
        for k in range(count):
            p = off + 2 + 12 * k
            if p + 12 > len(tiff):
                break
            tag, typ, cnt = struct.unpack(e + "HHI", tiff[p:p + 8])
            tags[tag] = (typ, cnt, tiff[p + 8:p + 12], p + 8)
        return tags

    sizes = {1: 1, 2: 1, 3: 2, 4: 4, 5: 8, 7: 1, 9: 4, 10: 8}

    def value(entry) -> list:
        typ, cnt, raw, _ = entry
        size = sizes.get(typ, 1) * cnt
        if size > 4:
            (off,) = struct.unpack(e + "I", raw)
            raw = tiff[off:off + size]
            if len(raw) < size:
                return []
        if typ == 5:
            vals = struct.unpack(e + "II" * cnt, raw[:8 * cnt])
            return [a / b if b else float("nan") for a, b in zip(vals[::2], vals[1::2])]
        if typ == 2:
            return [raw[:cnt].split(b"\x00")[0].decode("ascii", "replace")]
        if typ in (1, 7):
            return list(raw[:cnt])
        if typ == 3:
            return list(struct.unpack(e + "H" * cnt, raw[:2 * cnt]))
        if typ == 4:
            return list(struct.unpack(e + "I" * cnt, raw[:4 * cnt]))
        return []

    (first,) = struct.unpack(e + "I", tiff[4:8])
    ifd0 = ifd(first)
    out = {}
    turned = value(ifd0[0x0112]) if 0x0112 in ifd0 else []
    if turned and 1 <= turned[0] <= 8:
        out["orientation"] = int(turned[0])
    if 0x8825 not in ifd0:
        return out
    gps_off = value(ifd0[0x8825])
    if not gps_off:
        return out
    g = ifd(int(gps_off[0]))

    def dms(tag_ref: int, tag: int, neg: str) -> float | None:
        if tag not in g:
            return None
        v = value(g[tag])
        if len(v) != 3 or not all(map(math.isfinite, v)):
            return None
        ref = value(g[tag_ref])[0] if tag_ref in g and value(g[tag_ref]) else ""
        d = v[0] + v[1] / 60.0 + v[2] / 3600.0
        return -d if str(ref).strip().upper() == neg else d

    lat, lon = dms(1, 2, "S"), dms(3, 4, "W")
    if lat is not None and lon is not None:
        out.update(lat=lat, lon=lon)
    if 6 in g:
        alt = value(g[6])
        below = 5 in g and value(g[5])[:1] == [1]
        if alt and math.isfinite(alt[0]):
            out["gps_alt_m"] = -alt[0] if below else alt[0]
    return out


def _number(text: str | None) -> float | None:
    if text is None:
        return None
    try:
        v = float(str(text).strip())
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def _dji_xmp(packet: bytes) -> dict:
    """DJI's drone-dji:* values from an XMP packet, as attributes or as elements."""
    text = packet.decode("utf-8", "replace")
    out = {}
    try:
        root = ET.fromstring(text[text.index("<x:xmpmeta"):text.rindex("</x:xmpmeta>") + 12]
                             if "<x:xmpmeta" in text else text)
        for el in root.iter():
            for k, v in el.attrib.items():
                if k.startswith("{" + DJI_NS + "}") and k[len(DJI_NS) + 2:] in _DJI_FIELDS:
                    out[_DJI_FIELDS[k[len(DJI_NS) + 2:]]] = _number(v)
            if el.tag.startswith("{" + DJI_NS + "}") and el.tag[len(DJI_NS) + 2:] in _DJI_FIELDS:
                out[_DJI_FIELDS[el.tag[len(DJI_NS) + 2:]]] = _number(el.text)
    except (ET.ParseError, ValueError):
        # A packet that is not well-formed XML: DJI's attribute form, read textually.
        for name, key in _DJI_FIELDS.items():
            m = re.search(rf'drone-dji:{name}\s*=\s*"([^"]*)"', text)
            if m:
                out[key] = _number(m.group(1))
    return {k: v for k, v in out.items() if v is not None}


def read_photo_metadata(path: str | Path) -> PhotoMetadata:
    """The pose tags of a JPEG (an empty PhotoMetadata for other images or untagged photos)."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            data = f.read(2)
            if data != b"\xff\xd8":
                return PhotoMetadata()
            data += f.read()
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.__class__.__name__}: {e})") from None
    vals, where = {}, {}
    for seg in app1_segments(data, str(path)):
        if seg.startswith(EXIF_HEADER):
            got = _exif_gps(seg[len(EXIF_HEADER):])
            src = "EXIF GPS"
        elif seg.startswith(XMP_HEADER):
            got = _dji_xmp(seg[len(XMP_HEADER):])
            src = "DJI XMP"
        else:
            continue
        for k, v in got.items():
            vals.setdefault(k, v)
            where.setdefault(k, src)
    for k in ("lat", "lon"):  # EXIF first; DJI's XMP copy where a photo has no EXIF GPS
        if k not in vals and f"xmp_{k}" in vals:
            vals[k], where[k] = vals[f"xmp_{k}"], "DJI XMP"
    vals.pop("xmp_lat", None)
    vals.pop("xmp_lon", None)
    where.pop("orientation", None)  # not a pose tag: never named as a pose's source
    where.pop("xmp_lat", None)
    where.pop("xmp_lon", None)
    if "lat" in vals and not (-90 <= vals["lat"] <= 90 and -180 <= vals.get("lon", 0) <= 180):
        raise InputError(f"{path}: GPS position {vals.get('lat')}, {vals.get('lon')} is not a "
                         "latitude/longitude")
    return PhotoMetadata(**vals, where=where)


# ---- pose ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PhotoPose:
    position: np.ndarray  # ENU m
    direction: np.ndarray  # unit vector the camera looks along
    roll_deg: float  # counter-clockwise as the operator sees it (CameraPose's convention)
    description: str  # what was read from where, for the user

    def camera_pose(self):
        from wtcli.plan.config import CameraPose

        p = tuple(float(v) for v in self.position)
        return CameraPose(p, tuple(float(v) for v in self.position + 100.0 * self.direction),
                          self.roll_deg)


def pose_from_metadata(meta: PhotoMetadata, turbine, origin: dict | None, camera,
                       name: str = "photo") -> PhotoPose:
    """The camera pose in the site's ENU frame; ConfigError (exit 4) when the pose cannot be
    this turbine's photo: inside the turbine, more than MAX_DISTANCE_M from its hub, or looking
    away from it (the rotor not in the frame of ``camera``'s field of view)."""
    from wtcli.plan.geodesy import geodetic_to_enu

    if not meta.has_pose:
        raise ValueError("expected metadata with a position, height, gimbal pitch and a heading")
    if origin is None:
        raise ConfigError(f"{name}: the photo says where it was taken (lat/lon), but "
                          "turbines.yaml has no site.origin to place it in the site; add "
                          "site.origin or give --camera-pose")
    base = np.asarray(turbine.base_xyz, float)
    if meta.relative_alt_m is not None:
        e = geodetic_to_enu(meta.lat, meta.lon, origin["alt"], origin)
        ground = geodetic_to_enu(*_llh_below(base, origin), origin)  # the base's height
        pos = np.array([e[0], e[1], float(e[2] - ground[2] + base[2] + meta.relative_alt_m)])
        height = (f"RelativeAltitude {meta.relative_alt_m:+.2f} m above the tower base "
                  "(take-off at its ground level)")
    else:
        alt = meta.absolute_alt_m if meta.absolute_alt_m is not None else meta.gps_alt_m
        key = "AbsoluteAltitude" if meta.absolute_alt_m is not None else "EXIF GPSAltitude"
        pos = np.asarray(geodetic_to_enu(meta.lat, meta.lon, alt, origin), float)
        height = f"{key} {alt:.2f} m AMSL (through site.origin.alt)"
    if meta.gimbal_yaw_deg is not None:
        yaw, yaw_src = meta.gimbal_yaw_deg, "GimbalYawDegree"
    else:
        yaw, yaw_src = meta.flight_yaw_deg, "FlightYawDegree (no gimbal yaw: gimbal taken as aligned)"
    pitch = meta.gimbal_pitch_deg
    y, p = math.radians(yaw), math.radians(pitch)
    direction = np.array([math.sin(y) * math.cos(p), math.cos(y) * math.cos(p), math.sin(p)])
    roll = -(meta.gimbal_roll_deg or 0.0)

    hub = np.asarray(turbine.hub_center, float)
    to_hub = hub - pos
    dist = float(np.linalg.norm(to_hub))
    where = f"{name}: the pose its metadata gives"
    if dist > MAX_DISTANCE_M:
        raise ConfigError(f"{where} is {dist / 1000:.1f} km from turbine {turbine.id}'s hub (limit "
                          f"{MAX_DISTANCE_M / 1000:g} km): a photo of another turbine, or a wrong "
                          "site.origin or turbine position? give --camera-pose to override")
    if pos[2] < base[2] - 1.0 or float(turbine.clearance(pos[None])[0]) < MIN_CLEARANCE_M:
        raise ConfigError(f"{where} puts the camera inside turbine {turbine.id} (at "
                          f"{pos[0]:.1f}, {pos[1]:.1f}, {pos[2]:.1f} m ENU): check the turbine's "
                          "position in turbines.yaml, or give --camera-pose to override")
    half_diag = math.degrees(math.atan(math.hypot(camera.width_px, camera.height_px) / 2
                                       / camera.fx))
    rotor = math.degrees(math.asin(min(1.0, turbine.rotor_diameter / 2 / max(dist, 1e-9))))
    off = math.degrees(math.acos(float(np.clip(direction @ to_hub / dist, -1.0, 1.0))))
    if off > half_diag + rotor:
        raise ConfigError(f"{where} looks {off:.0f} deg away from turbine {turbine.id}'s hub (the "
                          f"rotor spans {half_diag + rotor:.0f} deg of the frame's half-diagonal): "
                          "a photo of something else, or a wrong heading? give --camera-pose to "
                          "override")
    srcs = sorted(set(meta.where.values()))
    desc = (f"the photo's own pose ({', '.join(srcs)}): {meta.lat:.7f}, {meta.lon:.7f}, {height}; "
            f"heading {yaw:.1f} deg from {yaw_src}, gimbal pitch {pitch:.1f} deg, roll "
            f"{meta.gimbal_roll_deg or 0.0:.1f} deg; {dist:.0f} m from the hub")
    return PhotoPose(pos, direction, roll, desc)


def _llh_below(base: np.ndarray, origin: dict) -> tuple[float, float, float]:
    """lat, lon and the origin's altitude under an ENU point (its ground at the origin's height)."""
    from wtcli.plan.geodesy import enu_to_geodetic

    lat, lon, _ = enu_to_geodetic(np.asarray(base, float)[None], origin)[0]
    return float(lat), float(lon), float(origin["alt"])


def camera_pose_of_photo(path: str | Path, turbine, mission, name: str | None = None):
    """(CameraPose, what was read) from a photo's own tags for ``plan``'s back-projection, or
    (None, why not) when it carries an incomplete pose, or (None, None) when it carries none."""
    meta = read_photo_metadata(path)
    name = name or str(path)
    if meta.orientation not in (None, 1) and (meta.has_pose or meta.gimbal_pitch_deg is not None):
        # segment reads the photo upright, as a viewer shows it; the gimbal's angles are of the
        # frame as stored, and which way the camera was turned is not known from the tag alone.
        return None, (f"the photo is stored turned (EXIF Orientation {meta.orientation}) and read "
                      "upright, so its gimbal angles do not give the upright frame's pose; give "
                      "--camera-pose")
    if meta.has_pose:
        pp = pose_from_metadata(meta, turbine, mission.site_origin, mission.camera, name)
        return pp.camera_pose(), pp.description
    if meta == PhotoMetadata(orientation=meta.orientation):
        return None, None
    need = {"a position": meta.has_position, "GimbalPitchDegree": meta.gimbal_pitch_deg is not None,
            "a heading": meta.gimbal_yaw_deg is not None or meta.flight_yaw_deg is not None,
            "a height": any(v is not None for v in (meta.relative_alt_m, meta.absolute_alt_m,
                                                    meta.gps_alt_m))}
    return None, ("the photo's tags lack " + ", ".join(k for k, ok in need.items() if not ok)
                  + ", so not its own pose")


def photo_beside(pitch_json: str | Path, image_name: str | None) -> Path | None:
    """The photo a pitch JSON was measured on, where it is still found: next to the JSON, or at
    the name it records (relative to the working folder). None when neither exists."""
    if not image_name:
        return None
    pitch_json = Path(pitch_json)
    for cand in (pitch_json.parent / Path(str(image_name)).name, Path(str(image_name))):
        if cand.is_file():
            return cand
    return None
