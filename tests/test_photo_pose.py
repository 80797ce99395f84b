"""The photo's own pose: EXIF GPS and DJI XMP read from JPEGs written here the way DJI cameras
write them (little-endian EXIF GPS IFD, an XMP packet with drone-dji:* attributes), turned into
the site ENU pose; on oblique renders it recovers the rotor azimuths where S_p does not."""

from __future__ import annotations

import math
import struct
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from wtcli.errors import ConfigError, InputError
from wtcli.geometry import Camera, Turbine
from wtcli.photo_pose import (PhotoMetadata, app1_segments, pose_from_metadata,
                              read_photo_metadata)
from wtcli.plan.geodesy import enu_to_geodetic, geodetic_to_enu

ORIGIN = {"lat": 53.5511, "lon": 9.9937, "alt": 12.0}


# ---- a DJI-style JPEG writer, independent of the reader -------------------------------------------
def _rational(x: float, den: int) -> tuple[int, int]:
    return int(round(x * den)), den


def exif_gps_app1(lat: float, lon: float, alt: float, endian: str = "<") -> bytes:
    """APP1 'Exif' payload: IFD0 with a GPSInfo pointer, then the GPS IFD (as DJI writes it)."""
    def dms(v):
        v = abs(v)
        d = int(v)
        m = int((v - d) * 60)
        s = (v - d - m / 60) * 3600
        return [_rational(d, 1), _rational(m, 1), _rational(s, 10000)]

    entries = [(0, 1, 4, bytes([2, 3, 0, 0])),                       # GPSVersionID
               (1, 2, 2, (b"N" if lat >= 0 else b"S") + b"\0\0\0"),   # GPSLatitudeRef
               (2, 5, 3, dms(lat)), (3, 2, 2, (b"E" if lon >= 0 else b"W") + b"\0\0\0"),
               (4, 5, 3, dms(lon)), (5, 1, 1, bytes([0 if alt >= 0 else 1, 0, 0, 0])),
               (6, 5, 1, [_rational(abs(alt), 1000)])]
    ifd0_off = 8
    gps_off = ifd0_off + 2 + 12 + 4
    data_off = gps_off + 2 + 12 * len(entries) + 4
    ifd0 = struct.pack(endian + "H", 1) + struct.pack(endian + "HHII", 0x8825, 4, 1, gps_off) \
        + struct.pack(endian + "I", 0)
    gps, blob = struct.pack(endian + "H", len(entries)), b""
    for tag, typ, cnt, val in entries:
        if typ == 5:
            raw = b"".join(struct.pack(endian + "II", a, b) for a, b in val)
            gps += struct.pack(endian + "HHII", tag, typ, cnt, data_off + len(blob))
            blob += raw
        else:
            gps += struct.pack(endian + "HHI", tag, typ, cnt) + val
    gps += struct.pack(endian + "I", 0)
    tiff = (b"II*\0" if endian == "<" else b"MM\0*") + struct.pack(endian + "I", ifd0_off)
    return b"Exif\0\0" + tiff + ifd0 + gps + blob


def dji_xmp_app1(**tags) -> bytes:
    attrs = "\n   ".join(f'drone-dji:{k}="{v}"' for k, v in tags.items())
    xml = ('<?xpacket begin="\ufeff" id="W5M0MpCehiHzreSzNTczkc9d"?>\n'
           '<x:xmpmeta xmlns:x="adobe:ns:meta/">\n'
           ' <rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">\n'
           '  <rdf:Description rdf:about="DJI Meta Data"\n'
           '   xmlns:tiff="http://ns.adobe.com/tiff/1.0/"\n'
           '   xmlns:drone-dji="http://www.dji.com/drone-dji/1.0/"\n'
           f'   tiff:Make="DJI"\n   {attrs}>\n'
           '  </rdf:Description>\n </rdf:RDF>\n</x:xmpmeta>\n<?xpacket end="w"?>')
    return b"http://ns.adobe.com/xap/1.0/\0" + xml.encode("utf-8")


def jpeg_with(image: np.ndarray, *app1: bytes) -> bytes:
    ok, buf = cv2.imencode(".jpg", image)
    assert ok
    data = buf.tobytes()
    segs = b"".join(b"\xff\xe1" + struct.pack(">H", len(p) + 2) + p for p in app1)
    return data[:2] + segs + data[2:]


def signed(v: float) -> str:
    return f"{v:+.2f}"


def dji_photo(path, image, lat, lon, abs_alt, rel_alt, yaw, pitch, roll=0.0, flight_yaw=None):
    path.write_bytes(jpeg_with(image, exif_gps_app1(lat, lon, abs_alt), dji_xmp_app1(
        AbsoluteAltitude=signed(abs_alt), RelativeAltitude=signed(rel_alt),
        GimbalRollDegree=signed(roll), GimbalYawDegree=signed(yaw), GimbalPitchDegree=signed(pitch),
        FlightRollDegree="+0.00", FlightYawDegree=signed(yaw if flight_yaw is None else flight_yaw),
        FlightPitchDegree="-1.20")))
    return path


# ---- reading ------------------------------------------------------------------------------------
def test_reads_exif_gps_and_dji_xmp_as_written(tmp_path):
    img = np.full((48, 64, 3), 128, np.uint8)
    p = dji_photo(tmp_path / "DJI_0001.JPG", img, 53.5532191, -9.9912345, 118.39, 60.1, -44.3,
                  -12.5, roll=1.5, flight_yaw=-45.1)
    m = read_photo_metadata(p)
    # seconds as rationals over 10000, as DJI writes them: 3e-8 deg, 3 mm
    assert m.lat == pytest.approx(53.5532191, abs=3e-8) and m.lon == pytest.approx(-9.9912345, abs=3e-8)
    assert m.gps_alt_m == pytest.approx(118.39, abs=1e-3)
    assert (m.absolute_alt_m, m.relative_alt_m) == (118.39, 60.1)
    assert (m.gimbal_yaw_deg, m.gimbal_pitch_deg, m.gimbal_roll_deg, m.flight_yaw_deg) == \
        (-44.3, -12.5, 1.5, -45.1)
    assert m.where["lat"] == "EXIF GPS" and m.where["gimbal_yaw_deg"] == "DJI XMP"
    assert m.has_pose
    # big-endian EXIF, southern/western hemisphere, below sea level
    p.write_bytes(jpeg_with(img, exif_gps_app1(-33.25, -70.5, -3.5, endian=">")))
    m = read_photo_metadata(p)
    assert (m.lat, m.lon) == (pytest.approx(-33.25), pytest.approx(-70.5))
    assert m.gps_alt_m == pytest.approx(-3.5) and not m.has_pose


def test_xmp_element_form_and_djis_longtitude_spelling(tmp_path):
    xml = ('<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF '
           'xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#"><rdf:Description '
           'xmlns:drone-dji="http://www.dji.com/drone-dji/1.0/" drone-dji:GpsLatitude="47.1" '
           'drone-dji:GpsLongtitude="8.2"><drone-dji:GimbalPitchDegree>-30.0'
           '</drone-dji:GimbalPitchDegree><drone-dji:FlightYawDegree>+120.5'
           '</drone-dji:FlightYawDegree><drone-dji:RelativeAltitude>+40.00'
           '</drone-dji:RelativeAltitude></rdf:Description></rdf:RDF></x:xmpmeta>')
    p = tmp_path / "a.jpg"
    p.write_bytes(jpeg_with(np.zeros((8, 8, 3), np.uint8),
                            b"http://ns.adobe.com/xap/1.0/\0" + xml.encode()))
    m = read_photo_metadata(p)
    assert (m.lat, m.lon, m.gimbal_pitch_deg, m.flight_yaw_deg, m.relative_alt_m) == \
        (47.1, 8.2, -30.0, 120.5, 40.0)
    assert m.gimbal_yaw_deg is None and m.has_pose and m.where["lat"] == "DJI XMP"


def test_untagged_and_non_jpeg_photos_and_corrupt_segments(tmp_path):
    img = np.zeros((8, 8, 3), np.uint8)
    png = tmp_path / "a.png"
    cv2.imwrite(str(png), img)
    assert read_photo_metadata(png) == PhotoMetadata()
    jpg = tmp_path / "b.jpg"
    cv2.imwrite(str(jpg), img)
    assert read_photo_metadata(jpg) == PhotoMetadata() and not PhotoMetadata().has_pose
    bad = tmp_path / "c.jpg"
    bad.write_bytes(b"\xff\xd8\xff\xe1\xff\xf0Exif\0\0")
    with pytest.raises(InputError, match="corrupt JPEG: segment at byte 2"):
        read_photo_metadata(bad)
    assert app1_segments(b"not a jpeg") == []


# ---- pose ---------------------------------------------------------------------------------------
def _metadata_of(cam: Camera, roll_deg: float, base=np.zeros(3)) -> PhotoMetadata:
    """What a DJI camera at ``cam`` would write (2 decimals, as DJI does)."""
    lat, lon, h = enu_to_geodetic(cam.position[None], ORIGIN)[0]
    f = cam.forward
    ground = enu_to_geodetic(np.asarray(base, float)[None], ORIGIN)[0][2]
    return PhotoMetadata(lat=float(lat), lon=float(lon), absolute_alt_m=round(float(h), 2),
                         relative_alt_m=round(float(h - ground), 2),
                         gimbal_yaw_deg=round(math.degrees(math.atan2(f[0], f[1])), 2),
                         gimbal_pitch_deg=round(math.degrees(math.asin(f[2])), 2),
                         gimbal_roll_deg=round(-roll_deg, 2), where={"lat": "EXIF GPS"})


def _circ_err(got, want) -> float:
    return max(min(abs((a - b + 180) % 360 - 180) for b in got) for a in want)


# oblique renders where the S_p assumption puts a blade more than 10 deg off
OBLIQUE_SEEDS = (0, 1, 2, 3, 4, 5)


def test_the_photos_pose_recovers_the_azimuths_of_oblique_renders(tmp_path):
    """Blade directions from the renderer's own projection (perfect segmentation), so the figure
    is the pose's alone: the metadata pose, written and read back through a JPEG, is within 1 deg
    of the truth where S_p is more than 10 deg off."""
    from wtcli.plan.zone import azimuths_from_pitch
    from wtcli.synth.render import render_sample

    for seed in OBLIQUE_SEEDS:
        s = render_sample(seed, 640, 480, view="oblique")
        tr = s.truth
        t = Turbine.from_dict(tr["turbine"])
        cam = Camera.from_dict(tr["camera"])
        meta = _metadata_of(cam, tr["roll_deg"])
        photo = dji_photo(tmp_path / f"DJI_{seed:04d}.JPG", s.image, meta.lat, meta.lon,
                          meta.absolute_alt_m, meta.relative_alt_m, meta.gimbal_yaw_deg,
                          meta.gimbal_pitch_deg, roll=meta.gimbal_roll_deg)
        read = read_photo_metadata(photo)
        pose = pose_from_metadata(read, t, ORIGIN, cam, photo.name)
        assert np.linalg.norm(pose.position - cam.position) < 0.05
        assert "GimbalYawDegree" in pose.description and "RelativeAltitude" in pose.description
        pitch = SimpleNamespace(image_size=(480, 640), hub_px=tr["hub_px"], blades=[
            SimpleNamespace(tip_px=b["tip_px"], phi_deg=b["phi_deg"]) for b in tr["blades"]])
        truth = t.azimuths_deg
        got = azimuths_from_pitch(t, pitch, cam, pose.camera_pose())
        assumed = azimuths_from_pitch(t, pitch, cam, None)
        assert _circ_err(got, truth) < 1.0, (seed, got, truth)
        assert _circ_err(assumed, truth) > 10.0, (seed, assumed, truth)


def test_absolute_altitude_is_used_without_a_relative_one():
    t = Turbine.with_rotor_azimuth(90, id="T1", base=(0, 0, 0), hub_height=80, rotor_diameter=90,
                                   yaw_deg=180)
    cam = Camera(640, 480, 16, 23.2)
    lat, lon, _ = enu_to_geodetic(np.array([[0.0, -150.0, 0.0]]), ORIGIN)[0]
    m = PhotoMetadata(lat=lat, lon=lon, absolute_alt_m=92.0, gimbal_yaw_deg=0.0,
                      gimbal_pitch_deg=0.0, where={"lat": "EXIF GPS"})
    pose = pose_from_metadata(m, t, ORIGIN, cam)
    want = geodetic_to_enu(lat, lon, 92.0, ORIGIN)
    assert np.allclose(pose.position, want, atol=1e-6) and pose.position[2] == pytest.approx(80, abs=0.01)
    assert "AbsoluteAltitude 92.00 m AMSL" in pose.description


@pytest.mark.parametrize("enu, yaw, pitch, match", [
    ((0.0, 0.5, 40.0), 180.0, 0.0, "inside turbine T1"),          # in the tower
    ((0.0, -2500.0, 80.0), 0.0, 0.0, r"2\.5 km from turbine T1's hub"),
    ((0.0, -150.0, 80.0), 180.0, 0.0, "looks 180 deg away from turbine T1's hub"),
    ((0.0, -150.0, 80.0), 0.0, 85.0, "looks 85 deg away"),
])
def test_refuses_a_pose_that_cannot_be_this_turbines_photo(enu, yaw, pitch, match):
    t = Turbine.with_rotor_azimuth(90, id="T1", base=(0, 0, 0), hub_height=80, rotor_diameter=90,
                                   yaw_deg=180)
    cam = Camera(640, 480, 16, 23.2)
    lat, lon, h = enu_to_geodetic(np.array([enu]), ORIGIN)[0]
    m = PhotoMetadata(lat=lat, lon=lon, relative_alt_m=h - ORIGIN["alt"], gimbal_yaw_deg=yaw,
                      gimbal_pitch_deg=pitch, where={"lat": "EXIF GPS"})
    with pytest.raises(ConfigError, match=match):
        pose_from_metadata(m, t, ORIGIN, cam, "DJI_0007.JPG")
    with pytest.raises(ConfigError, match="no site.origin"):
        pose_from_metadata(m, t, None, cam, "DJI_0007.JPG")


def test_camera_pose_of_photo_says_why_an_incomplete_pose_is_not_used(tmp_path):
    from wtcli.photo_pose import camera_pose_of_photo

    t = Turbine.with_rotor_azimuth(90, id="T1", base=(0, 0, 0), hub_height=80, rotor_diameter=90,
                                   yaw_deg=180)
    mission = SimpleNamespace(site_origin=ORIGIN, camera=Camera(640, 480, 16, 23.2))
    img = np.full((48, 64, 3), 90, np.uint8)
    p = tmp_path / "gps_only.jpg"
    p.write_bytes(jpeg_with(img, exif_gps_app1(53.55, 9.99, 40.0)))
    assert camera_pose_of_photo(p, t, mission) == \
        (None, "the photo's tags lack GimbalPitchDegree, a heading, so not its own pose")
    cv2.imwrite(str(tmp_path / "plain.jpg"), img)
    assert camera_pose_of_photo(tmp_path / "plain.jpg", t, mission) == (None, None)
    lat, lon, h = enu_to_geodetic(np.array([[0.0, -150.0, 80.0]]), ORIGIN)[0]
    p = dji_photo(tmp_path / "DJI_0002.JPG", img, lat, lon, h, h - ORIGIN["alt"], 0.0, 0.0)
    pose, how = camera_pose_of_photo(p, t, mission, "DJI_0002.JPG")
    assert np.allclose(pose.position, [0, -150, 80], atol=0.02)
    assert how.startswith("the photo's own pose (DJI XMP, EXIF GPS)")


def test_plan_uses_the_photos_own_pose_and_says_so(cli, tmp_path, monkeypatch):
    """`plan` on a DJI-tagged photo taken 55 deg off the rotor axis: the segmenter is stood in
    for by the true masks, so the figures are the pose's and the pitch stage's: within 2 deg with
    the photo's pose; from S_p the blades do not even look like a rotor (exit 5); --camera-pose
    still overrides the tags."""
    from wtcli.geometry.projection import instance_masks
    from wtcli.masks import Instances
    from wtcli.plan.config import load_mission
    from wtcli.plan_file import read_plan
    from wtcli.segment import infer

    yml = tmp_path / "site.yaml"
    yml.write_text(
        "site:\n  origin: {lat: 53.5511, lon: 9.9937, alt: 12.0}\n"
        "camera: {sensor_width_mm: 23.2, focal_mm: 16, width_px: 5456, height_px: 3632}\n"
        "mission: {min_side_coverage: 0.5}\n"  # the figures here are the azimuths, not coverage
        "turbines:\n  - {id: T1, position: [0, 0, 0], hub_height_m: 80, rotor_diameter_m: 90,\n"
        "     yaw_deg: 180, blade_azimuths_deg: [80, 200, 320]}\n")
    t = load_mission(yml).turbine("T1")
    heading = math.radians(180 + 55)  # the rotor faces south; the camera 55 deg round to the west
    pos = t.hub_center + 130 * np.array([math.sin(heading), math.cos(heading), 0.0]) + [0, 0, 12]
    cam = Camera(800, 600, 16, 23.2).looking_at(pos, t.hub_center)
    inst = instance_masks(t, cam)
    monkeypatch.setattr(infer, "segment_image", lambda image, **kw: Instances(
        np.array([lab for lab, _, _ in inst], dtype=object), np.array([m for _, _, m in inst])))
    meta = _metadata_of(cam, 0.0)
    img = np.full((600, 800, 3), 200, np.uint8)
    photo = dji_photo(tmp_path / "DJI_0042.JPG", img, meta.lat, meta.lon, meta.absolute_alt_m,
                      meta.relative_alt_m, meta.gimbal_yaw_deg, meta.gimbal_pitch_deg)
    plain = tmp_path / "plain.png"
    cv2.imwrite(str(plain), img)

    def run(*extra):
        out = tmp_path / "plan.json"
        r = cli("plan", yml, *extra, "--out", out)
        assert r.exit_code == 0, r.output
        return " ".join(r.output.split()), read_plan(out).turbine("T1").azimuths_deg

    said, got = run(f"T1={photo}")
    assert "back-projected from the photo's own pose (DJI XMP, EXIF GPS)" in said
    assert "GimbalYawDegree" in said
    assert _circ_err(got, t.azimuths_deg) < 2.0, got
    # The same blades back-projected from S_p come out 84, 217, 307 deg: not even a rotor.
    r = cli("plan", yml, f"T1={plain}", "--out", tmp_path / "sp.json")
    assert r.exit_code == 5 and "not spread like a 3-blade rotor" in " ".join(r.output.split())
    look = t.hub_center
    said, got = run(f"T1={photo}", "--camera-pose", ",".join(f"{v:.3f}" for v in [*pos, *look]))
    assert "the given camera pose" in said and _circ_err(got, t.azimuths_deg) < 2.0
    # A pitch JSON measured on the photo: plan finds the photo beside it and reads its tags.
    pj = tmp_path / "DJI_0042.pitch.json"
    r = cli("pitch", photo, "--out", pj)
    assert r.exit_code == 0, r.output
    said, got = run(f"T1={pj}")
    assert "the photo's own pose (DJI XMP, EXIF GPS)" in said and _circ_err(got, t.azimuths_deg) < 2.0
    photo.rename(tmp_path / "moved.jpg")  # the photo gone: S_p, as before
    r = cli("plan", yml, f"T1={pj}", "--out", tmp_path / "sp2.json")
    assert r.exit_code == 5 and "not spread like a 3-blade rotor" in " ".join(r.output.split())


def test_a_photo_stored_turned_does_not_give_its_own_pose(tmp_path):
    """segment reads a photo upright (its EXIF Orientation); the gimbal's angles are of the
    frame as stored, so plan does not back-project with them and says why."""
    from wtcli.photo_pose import camera_pose_of_photo, read_photo_metadata

    t = Turbine.with_rotor_azimuth(90, id="T1", base=(0, 0, 0), hub_height=80, rotor_diameter=90,
                                   yaw_deg=180)
    mission = SimpleNamespace(site_origin=ORIGIN, camera=Camera(640, 480, 16, 23.2))
    img = np.full((48, 64, 3), 90, np.uint8)
    lat, lon, h = enu_to_geodetic(np.array([[0.0, -150.0, 80.0]]), ORIGIN)[0]
    p = dji_photo(tmp_path / "DJI_0003.JPG", img, lat, lon, h, h - ORIGIN["alt"], 0.0, 0.0)
    upright = camera_pose_of_photo(p, t, mission)
    assert upright[0] is not None
    for orientation, used in ((1, True), (6, False), (3, False)):
        turned = b"Exif\0\0II*\0" + struct.pack("<IH", 8, 1) \
            + struct.pack("<HHIHH", 0x0112, 3, 1, orientation, 0) + struct.pack("<I", 0)
        data = p.read_bytes()
        q = tmp_path / f"o{orientation}.jpg"
        q.write_bytes(data[:2] + b"\xff\xe1" + struct.pack(">H", len(turned) + 2) + turned + data[2:])
        meta = read_photo_metadata(q)
        assert meta.orientation == orientation and "orientation" not in meta.where
        pose, how = camera_pose_of_photo(q, t, mission)
        assert (pose is not None) is used
        if used:
            assert how == upright[1]  # the Orientation tag is not named as a source of the pose
        else:
            assert f"EXIF Orientation {orientation}" in how and "--camera-pose" in how
    plain = tmp_path / "plain.jpg"  # an Orientation tag alone is no pose: nothing to say
    turned = b"Exif\0\0II*\0" + struct.pack("<IH", 8, 1) + struct.pack("<HHIHH", 0x0112, 3, 1, 1, 0) \
        + struct.pack("<I", 0)
    plain.write_bytes(jpeg_with(img, turned))
    assert camera_pose_of_photo(plain, t, mission) == (None, None)


def test_a_photo_turned_upright_keeps_the_cameras_angle_per_pixel():
    from wtcli.plan.zone import photo_camera

    cam = Camera(4000, 3000, 10.3, 13.2)
    land = photo_camera(cam, 1920, 1440, (0, -50, 80), (0, 0, 80))
    port = photo_camera(cam, 1440, 1920, (0, -50, 80), (0, 0, 80))
    assert land.fx == pytest.approx(cam.fx * 1920 / 4000) and land.sensor_width_mm == pytest.approx(13.2)
    assert port.fx == pytest.approx(land.fx)
