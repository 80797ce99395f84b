"""pitch: θ (eq. 7 and principal axis), classes, φ hub -> tip, overlay and CLI, on blade masks
built in code and on turbines rendered through the one geometry."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from wtcli.contours import find_contours
from wtcli.errors import InputError, PerceptionError
from wtcli.geometry import Camera, Turbine
from wtcli.geometry.projection import instance_masks
from wtcli.masks import Instances, write_instances
from wtcli.pitch import (ACUTE, HORIZONTAL, PITCH_SCHEMA, VERTICAL, BladePitch, classify_theta,
                         draw_pitch_overlay, measure_pitch, normalize_theta, pitch_from_instances,
                         read_pitch, rect_eq7)


# ---- synthetic masks -----------------------------------------------------------------------------
def blade_polygon(hub, phi_deg, length, root_half, tip_half, start=0.0):
    """A tapered blade from ``start`` px off the hub to ``length``, pointing at φ (y up)."""
    r = math.radians(phi_deg)
    u = np.array([math.cos(r), -math.sin(r)])  # image coordinates, y down
    n = np.array([-u[1], u[0]])
    hub = np.asarray(hub, float)
    p0, p1 = hub + start * u, hub + length * u
    return np.array([p0 + root_half * n, p1 + tip_half * n, p1 - tip_half * n,
                     p0 - root_half * n])


def fill(poly, h, w):
    m = np.zeros((h, w), np.uint8)
    cv2.fillPoly(m, [np.round(np.asarray(poly) * 16).astype(np.int32)], 1, cv2.LINE_8, shift=4)
    return m.astype(bool)


def make_blade_mask(h, w, phi_deg, thickness=14.0, length=None, hub=None, taper=0.3, start=12.0):
    hub = (w / 2, h / 2) if hub is None else hub
    length = 0.45 * min(h, w) if length is None else length
    return fill(blade_polygon(hub, phi_deg, length, thickness / 2, taper * thickness / 2, start),
                h, w)


def rotor(h, w, phis, thickness=14.0, hub=None, nacelle=True, **kw):
    hub = (w / 2, h / 2) if hub is None else hub
    masks = [make_blade_mask(h, w, p, thickness, hub=hub, **kw) for p in phis]
    labels = ["blade"] * len(phis)
    if nacelle:
        m = np.zeros((h, w), np.uint8)
        cv2.circle(m, tuple(int(round(v)) for v in hub), 14, 1, -1)
        masks.append(m.astype(bool))
        labels.append("nacelle")
    return Instances(np.array(labels, object), np.stack(masks))


def err(a, b, period):
    d = abs(a - b) % period
    return min(d, period - d)


# ---- classes -------------------------------------------------------------------------------------
EPS = 1e-6


@pytest.mark.parametrize("theta, cls", [
    (0, HORIZONTAL), (EPS, HORIZONTAL), (30 - EPS, HORIZONTAL), (30, HORIZONTAL),
    (30 + EPS, ACUTE), (45, ACUTE), (60 - EPS, ACUTE), (60, ACUTE),
    (60 + EPS, VERTICAL), (90, VERTICAL), (120 - EPS, VERTICAL),
    (120, ACUTE), (120 + EPS, ACUTE), (150 - EPS, ACUTE),
    (150, HORIZONTAL), (150 + EPS, HORIZONTAL), (180 - EPS, HORIZONTAL),
    (180, HORIZONTAL), (-10, HORIZONTAL), (405, ACUTE), (270, VERTICAL),
    (30 + 1e-8, HORIZONTAL),  # below the file's 6 decimals: classified as written, 30.0
    (179.9999999, HORIZONTAL),
])
def test_class_boundaries_exactly_as_design(theta, cls):
    assert classify_theta(theta) == cls


def test_normalize_theta_wraps_and_rounds():
    assert normalize_theta(180) == 0.0
    assert normalize_theta(179.99999999) == 0.0
    assert normalize_theta(-30) == 150.0
    assert normalize_theta(359.5) == 179.5
    with pytest.raises(ValueError, match="finite"):
        classify_theta(float("nan"))


# ---- eq. 7 ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("theta", [0, 0.5, 1, 44.9, 45, 45.1, 89, 89.5, 90, 90.5, 91, 134.9, 135,
                                   135.1, 179, 179.5])
def test_eq7_on_a_rectangle_ignores_minarearect_angle_convention(theta):
    poly = blade_polygon((200, 200), theta, 170, 8, 8, start=-170)  # a plain rectangle
    rect = rect_eq7(poly)
    assert err(rect.angle_deg, theta, 180) < 1e-3
    assert rect.length == pytest.approx(340, abs=0.01) and rect.width == pytest.approx(16, abs=0.01)
    assert rect.top[1] <= rect.bottom[1]  # top = smaller image y
    assert 0 <= rect.angle_deg < 180


def test_eq7_uses_box_points_not_the_returned_angle():
    # Whatever range cv2.minAreaRect reports its angle in, the returned θ is ours.
    poly = blade_polygon((100, 100), 100, 80, 5, 5, start=-80)
    (_, _), (_, _), a = cv2.minAreaRect(poly.astype(np.float32))
    assert a != pytest.approx(100) and err(rect_eq7(poly).angle_deg, 100, 180) < 1e-3


# ---- angles over the whole circle -------------------------------------------------------------
def test_single_blade_every_degree_theta_and_phi():
    """One tapered blade (no nacelle) at φ = 0..359°: θ, class and φ (the wider end is the hub)."""
    h = w = 240
    for phi in range(360):
        inst = Instances(np.array(["blade"], object), make_blade_mask(h, w, phi, 12, 100)[None])
        res = pitch_from_instances(inst, expected_blades=1)
        b, = res.blades
        assert res.hub_source == "blade_taper"
        assert err(b.theta_deg, phi % 180, 180) < 0.5, phi
        assert err(b.phi_deg, phi, 360) < 0.5, phi
        theta_true = phi % 180
        if min(abs(theta_true - x) for x in (0, 30, 60, 120, 150, 180)) > 0.5:
            assert b.theta_class == classify_theta(theta_true), phi


def test_three_blade_rotor_every_degree():
    h, w = 300, 320
    for az in range(0, 360):
        phis = [az, az + 120, az + 240]
        inst = rotor(h, w, phis, 12, length=130)
        res = pitch_from_instances(inst)
        assert res.hub_source == "nacelle"
        assert np.hypot(res.hub_px[0] - w / 2, res.hub_px[1] - h / 2) < 1.0
        for b in res.blades:
            want = phis[b.source_index] % 360
            assert err(b.phi_deg, want, 360) < 0.5, (az, b)
            assert err(b.theta_deg, want % 180, 180) < 0.5


def test_without_nacelle_the_blade_axes_give_the_hub():
    inst = rotor(300, 300, [20, 140, 260], 12, nacelle=False, hub=(140, 160))
    res = pitch_from_instances(inst)
    assert res.hub_source == "blade_axes"
    assert np.hypot(res.hub_px[0] - 140, res.hub_px[1] - 160) < 1.0
    assert sorted(round(p) for p in res.phis) == [20, 140, 260]


@pytest.mark.parametrize("thickness, tol", [(2.0, 1.0), (5.0, 0.5), (30.0, 0.5), (60.0, 0.7)])
def test_thin_and_thick_blades(thickness, tol):
    for az in range(0, 120, 7):
        phis = [az + 0.3, az + 120.3, az + 240.3]
        inst = rotor(400, 400, phis, thickness, length=170, start=20, taper=0.5)
        res = pitch_from_instances(inst, area_threshold=20)
        for b in res.blades:
            assert err(b.phi_deg, phis[b.source_index], 360) < tol, (thickness, az, b.phi_deg)


def test_one_pixel_lines_still_measure():
    m = np.zeros((3, 200, 200), np.uint8)
    want = []
    for k, phi in enumerate([10, 130, 250]):
        r = math.radians(phi)
        a = (100 + round(8 * math.cos(r)), 100 - round(8 * math.sin(r)))
        b = (100 + round(90 * math.cos(r)), 100 - round(90 * math.sin(r)))
        cv2.line(m[k], a, b, 1, 1)
        want.append(math.degrees(math.atan2(a[1] - b[1], b[0] - a[0])) % 360)
    res = pitch_from_instances(Instances(np.array(["blade"] * 3, object), m > 0), 20)
    for got, w in zip(res.phis, want):
        assert err(got, w, 360) < 0.5


def test_jagged_and_noisy_masks():
    rng = np.random.default_rng(3)
    h = w = 400
    for az in (5.0, 47.0, 88.0):
        phis = [az, az + 120, az + 240]
        inst = rotor(h, w, phis, 18, length=170, start=20)
        masks = inst.masks.copy()
        for k in range(3):
            edge = cv2.morphologyEx(masks[k].astype(np.uint8), cv2.MORPH_GRADIENT,
                                    np.ones((3, 3), np.uint8)) > 0
            flip = edge & (rng.random((h, w)) < 0.5)  # ragged boundary
            masks[k] ^= flip
            specks = rng.random((h, w)) < 0.0005  # salt noise far from the blade
            masks[k] |= cv2.dilate(specks.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
            masks[k][200:205, 5:9] = False
        noisy = Instances(inst.labels, masks)
        res = pitch_from_instances(noisy, area_threshold=50)
        assert res.contours.dropped > 10  # the specks were filtered by eq. 6
        for b in res.blades:
            assert err(b.phi_deg, phis[b.source_index], 360) < 0.6


@pytest.mark.parametrize("hub, tol", [((140, 100), 0.5), ((60, 50), 1.5)])
def test_blades_cut_by_the_image_border(hub, tol):
    # All three blades run out of the frame; near the corner one keeps a short stub (about
    # 5x as long as wide) whose slanted cut tilts its principal axis by about 1.3°.
    h, w = 240, 320
    phis = [15, 135, 255]
    inst = rotor(h, w, phis, 14, hub=hub, length=300)
    res = pitch_from_instances(inst, area_threshold=50)
    for b in res.blades:
        assert err(b.phi_deg, phis[b.source_index], 360) < tol
    assert res.image_size == (h, w)


def test_a_stub_cut_by_the_frame_follows_the_hub():
    # The upper blade shows only ~22 px of its root: no axis of its own (elongation < 3).
    h = w = 300
    inst = rotor(h, w, [80, 200, 320], 14, hub=(150, 30), length=200, start=8)
    res = pitch_from_instances(inst)
    stub = next(b for b in res.blades if b.source_index == 0)
    assert stub.elongation < 3 and stub.theta_method == "hub_to_centroid"
    assert err(stub.phi_deg, 80, 360) < 6
    assert all(b.theta_method == "principal_axis" for b in res.blades if b is not stub)


@pytest.mark.parametrize("gap", [0, 1, 2])
def test_a_stub_just_short_of_the_frame_is_still_cut_by_it(gap):
    # The upper blade's stub, narrower at the hub than at the frame (the nacelle's mask took
    # its root's edges) and stopping ``gap`` px short of the edge as masks often do, is still
    # this rotor's blade, not a far turbine's blade pointing at the hub (dev render 7 000 092).
    h = w = 300
    inst = rotor(h, w, [80, 200, 320], 14, hub=(150, 40), length=200, start=8)
    inst.masks[0] = fill([(149, 32), (153, 32), (168, 0), (146, 0)], h, w)
    inst.masks[0][:gap] = False
    res = pitch_from_instances(inst, expected_blades=None)
    assert sorted(b.source_index for b in res.blades) == [0, 1, 2]
    assert err(next(b for b in res.blades if b.source_index == 0).phi_deg, 80, 360) < 12


# ---- rendered turbines (the one geometry) -----------------------------------------------------------
@pytest.mark.parametrize("azimuth, yaw, side", [(0, 0, 0), (33, 120, 0), (90, 250, 0), (61, 10, 15),
                                                 (178, 300, -12)])
def test_rendered_turbine_matches_camera_image_angles(azimuth, yaw, side):
    t = Turbine.with_rotor_azimuth(azimuth, id="t", base=(0, 0, 0), hub_height=90,
                                   rotor_diameter=110, yaw_deg=yaw)
    a = math.radians(side)
    view = np.array([math.cos(a) * t.axis[0] - math.sin(a) * t.axis[1],
                     math.sin(a) * t.axis[0] + math.cos(a) * t.axis[1], 0.0])
    cam = Camera(800, 600, 20, 23.5).looking_at(t.hub_center + view * 150, t.hub_center)
    parts = instance_masks(t, cam)
    inst = Instances(np.array([p[0] for p in parts], object), np.stack([p[2] for p in parts]))
    res = pitch_from_instances(inst)
    tips = t.blade_tips()
    for b in res.blades:
        k = parts[b.source_index][1]
        phi = cam.image_angle_deg(t.hub_center, tips[k])
        assert err(b.phi_deg, phi, 360) < 0.3
        assert err(b.theta_eq7_deg, phi % 180, 180) < 3.0  # minAreaRect tilts on the taper
    hub_uv = cam.project(t.hub_center[None])[0][0]
    assert np.hypot(*(np.asarray(res.hub_px) - hub_uv)) < 3.0


# ---- blade counts and bad input ----------------------------------------------------------------------
def test_blade_counts_are_clear_errors():
    h = w = 240
    named = {"file_name": "x.png"}
    for n in (1, 2, 4):
        phis = [k * 360 / n + 10 for k in range(n)]
        cs = find_contours(rotor(h, w, phis, 10, length=100), 50, image=named)
        with pytest.raises(PerceptionError, match=f"found {n} blades? in x.png, expected 3"):
            measure_pitch(cs, 3)
        for expected in (None, 0, n):
            res = measure_pitch(cs, expected)
            assert len(res) == n
            for b in res.blades:
                assert err(b.phi_deg, phis[b.source_index], 360) < 0.5
    no_blades = find_contours(rotor(h, w, [], nacelle=True), 50, image=named)
    with pytest.raises(PerceptionError, match="no blade found in x.png"):
        measure_pitch(no_blades)


@pytest.mark.parametrize("with_nacelles", [True, False])
def test_the_main_rotor_is_picked_among_several_turbines(with_nacelles):
    """A photo with far turbines behind the inspected one (as the sample renders have): the
    rotor whose blades cover the most pixels is measured, the others are listed, not counted."""
    h, w = 400, 500
    main = rotor(h, w, [20, 140, 260], 14, hub=(300, 220), length=150, nacelle=with_nacelles)
    far = rotor(h, w, [70, 190, 310], 5, hub=(80, 80), length=55, nacelle=with_nacelles, start=6)
    stray = make_blade_mask(h, w, 45, 6, length=40, hub=(450, 360), start=0)
    inst = Instances(np.concatenate([main.labels, far.labels, ["blade"]]),
                     np.concatenate([main.masks, far.masks, stray[None]]))
    res = pitch_from_instances(inst)
    assert sorted(round(p) for p in res.phis) == [20, 140, 260]
    n_main = len(main)
    assert sorted(res.other_rotor_blades) == [n_main, n_main + 1, n_main + 2, len(inst) - 1]
    assert np.hypot(res.hub_px[0] - 300, res.hub_px[1] - 220) < 1.5
    # A fourth blade on the main rotor is still four blades.
    extra = make_blade_mask(h, w, 80, 14, length=150, hub=(300, 220))
    four = Instances(np.concatenate([inst.labels, ["blade"]]), np.concatenate([inst.masks, extra[None]]))
    with pytest.raises(PerceptionError, match=r"found 4 blades in .*besides 4 blade\(s\) of other"):
        pitch_from_instances(four)


def test_a_blade_read_twice_counts_once():
    """The tower's edge beside the blade pointing down, read as a blade too (held-out render
    9 000 040): four detections on the hub, two in one slot. The rotor's three evenly spaced
    blades are measured, the weaker double is left out like another rotor's blade. A fourth
    blade between the slots stays a count error (see above)."""
    h = w = 400
    main = rotor(h, w, [30, 150, 270], 14, length=170)
    double = make_blade_mask(h, w, 262, 5, length=150, start=20)
    inst = Instances(np.concatenate([main.labels, ["blade"]]), np.concatenate([main.masks, double[None]]),
                     np.array([1.0, 1.0, 0.99, 1.0, 0.8]))
    res = pitch_from_instances(inst)
    assert sorted(round(p) for p in res.phis) == [30, 150, 270]
    assert res.other_rotor_blades == (4,)
    loose = Instances(inst.labels, inst.masks, np.array([1.0, 1.0, 0.99, 1.0, 0.8]))
    loose.masks[4] = make_blade_mask(h, w, 210, 5, length=150, start=20)  # between two slots
    with pytest.raises(PerceptionError, match="found 4 blades"):
        pitch_from_instances(loose)


def test_a_far_rotor_right_behind_the_hub():
    """Its blades meet at the same image point: told apart by length when clearly shorter."""
    h = w = 400
    main = rotor(h, w, [10, 130, 250], 12, length=170, nacelle=True)
    far = rotor(h, w, [60, 180, 300], 6, length=110, nacelle=False)
    inst = Instances(np.concatenate([main.labels, far.labels]),
                     np.concatenate([main.masks, far.masks]))
    res = pitch_from_instances(inst)
    assert sorted(round(p) for p in res.phis) == [10, 130, 250]
    assert sorted(res.other_rotor_blades) == [4, 5, 6]
    with pytest.raises(PerceptionError, match="found 6 blades"):  # any count: all six
        measure_pitch(find_contours(inst, 20), 5)
    same = rotor(h, w, [60, 180, 300], 12, length=160, nacelle=False)  # not clearly shorter
    inst = Instances(np.concatenate([main.labels, same.labels]),
                     np.concatenate([main.masks, same.masks]))
    with pytest.raises(PerceptionError, match="found 6 blades"):
        pitch_from_instances(inst)


def test_any_count_still_trims_a_far_rotor_right_behind_the_hub():
    """With any count accepted (how plan reads a photo first), a rotor has 3 blades unless told
    otherwise: a far rotor's clearly shorter blades on the same hub are still left out."""
    h = w = 400
    main = rotor(h, w, [10, 130, 250], 12, length=170, nacelle=True)
    far = rotor(h, w, [60, 180, 300], 6, length=110, nacelle=False)
    inst = Instances(np.concatenate([main.labels, far.labels]),
                     np.concatenate([main.masks, far.masks]))
    res = pitch_from_instances(inst, expected_blades=None)
    assert sorted(round(p) for p in res.phis) == [10, 130, 250]
    res = pitch_from_instances(inst, expected_blades=None, rotor_blades=6)  # a 6-blade rotor
    assert len(res.blades) == 6


def test_a_tower_read_as_a_blade_under_a_close_up_hub():
    """A close-up's tower, read as a blade (dev render 7 000 240): it meets the hub like a blade
    but widens away from it, so it is left out when the hub has one blade too many. A real
    blade tapers to its tip and stays."""
    h = w = 400
    main = rotor(h, w, [90, 210, 330], 14, hub=(200, 150), length=140, nacelle=True)
    tower = make_blade_mask(h, w, 90, 40, length=235, hub=(200, 400), taper=0.45, start=0)
    inst = Instances(np.concatenate([main.labels, ["blade"]]), np.concatenate([main.masks, tower[None]]))
    res = pitch_from_instances(inst, expected_blades=None)
    assert sorted(round(p) for p in res.phis) == [90, 210, 330]
    assert res.other_rotor_blades == (4,)
    blade = make_blade_mask(h, w, 270, 14, length=140, hub=(200, 150))  # a fourth, tapering one
    inst = Instances(np.concatenate([main.labels, ["blade"]]), np.concatenate([main.masks, blade[None]]))
    with pytest.raises(PerceptionError, match="found 4 blades"):
        pitch_from_instances(inst)


def test_hub_out_of_frame_beats_a_far_rotor():
    """A close-up with the inspected hub above the frame (dev render 7 000 184): its
    blades, cut by the frame at their roots, outweigh a small far rotor in full view, and are
    the ones measured. A far blade that only reaches the frame with its tip is not one of them."""
    h, w = 400, 500
    # The hub is so far above that the blades' axes cross beyond reach of their visible ends.
    main = rotor(h, w, [240, 300], 20, hub=(250, -200), length=450, nacelle=False)
    far = rotor(h, w, [90, 210, 330], 4, hub=(420, 300), length=50, nacelle=True)
    tip_cut = make_blade_mask(h, w, 90, 5, length=70, hub=(90, 60), start=4)  # reaches y = 0
    inst = Instances(np.concatenate([main.labels, far.labels, ["blade"]]),
                     np.concatenate([main.masks, far.masks, tip_cut[None]]))
    res = pitch_from_instances(inst, expected_blades=None)
    assert sorted(round(p) for p in res.phis) == [240, 300]
    assert sorted(res.other_rotor_blades) == [2, 3, 4, 6]
    # A long dark streak read as a blade (the tower's shadow, render 7 000 328), cut by the frame
    # at its wide end, is no close-up blade when it is not far longer than the rotor's.
    full = rotor(h, w, [30, 150, 270], 10, hub=(250, 120), length=110, nacelle=True)
    shadow = make_blade_mask(h, w, 70, 24, length=300, hub=(180, 490), taper=0.5, start=0)
    inst = Instances(np.concatenate([full.labels, ["blade"]]), np.concatenate([full.masks, shadow[None]]))
    res = pitch_from_instances(inst, expected_blades=None)
    assert sorted(round(p) for p in res.phis) == [30, 150, 270]
    # Without the close-up blades the far rotor is all there is, and it is measured.
    alone = Instances(np.concatenate([far.labels, ["blade"]]), np.concatenate([far.masks, tip_cut[None]]))
    assert sorted(round(p) for p in pitch_from_instances(alone, expected_blades=None).phis) == [90, 210, 330]


def test_a_far_nacelle_never_turns_the_blades_around():
    h = w = 400
    main = rotor(h, w, [10, 130, 250], 12, length=150, nacelle=False)
    far = np.zeros((h, w), np.uint8)
    cv2.circle(far, (355, 170), 6, 1, -1)  # just beyond the tip of the 10° blade
    inst = Instances(np.concatenate([main.labels, ["nacelle"]]),
                     np.concatenate([main.masks, far[None] > 0]))
    res = pitch_from_instances(inst)
    assert res.hub_source == "blade_axes"
    assert sorted(round(p) for p in res.phis) == [10, 130, 250]
    one = Instances(np.array(["blade", "nacelle"], object), np.stack([main.masks[0], far > 0]))
    res = pitch_from_instances(one, expected_blades=1)
    assert res.hub_source == "blade_taper" and round(res.blades[0].phi_deg) == 10


def test_two_opposite_blades_without_nacelle_use_their_common_end():
    cs = find_contours(rotor(240, 240, [30, 210], 12, length=100, nacelle=False), 50)
    res = measure_pitch(cs, 2)
    assert res.hub_source == "common_end"
    assert sorted(round(p) for p in res.phis) == [30, 210]


def test_blade_pitch_checks_itself():
    cs = find_contours(rotor(240, 240, [10, 130, 250], 12, length=100), 50)
    b = measure_pitch(cs).blades[0]
    kw = dict(b.__dict__)
    with pytest.raises(ValueError, match="expected class"):
        BladePitch(**{**kw, "theta_class": VERTICAL})
    with pytest.raises(ValueError, match="phi_deg"):
        BladePitch(**{**kw, "phi_deg": 360.0})
    with pytest.raises(ValueError, match="θ \\+ 180"):
        BladePitch(**{**kw, "phi_deg": (b.theta_deg + 90) % 360})


# ---- overlay -------------------------------------------------------------------------------------------
def test_overlay_draws_on_photo_and_on_masks():
    inst = rotor(240, 320, [10, 130, 250], 12, length=100)
    res = pitch_from_instances(inst)
    photo = np.full((240, 320, 3), 90, np.uint8)
    out = draw_pitch_overlay(photo, res)
    assert out.shape == photo.shape and (out != photo).any() and (photo == 90).all()
    canvas = draw_pitch_overlay(None, res)
    assert canvas.shape == (240, 320, 3) and canvas.any()
    with pytest.raises(ValueError, match="expected an image of 320x240"):
        draw_pitch_overlay(np.zeros((10, 10, 3), np.uint8), res)


# ---- CLI -------------------------------------------------------------------------------------------
def write_rotor_instances(path, rotors, size=(240, 320)):
    h, w = size
    images = [{"id": i + 1, "file_name": f"r{i}.png", "width": w, "height": h}
              for i in range(len(rotors))]
    return write_instances(path, images, [rotor(h, w, p, 12, length=100) for p in rotors])


def test_cli_demo_chain(cli, tmp_path):
    inst = write_rotor_instances(tmp_path / "in" / "instances.json", [[10, 130, 250]])
    photo = np.full((240, 320, 3), 120, np.uint8)
    cv2.imwrite(str(tmp_path / "in" / "r0.png"), photo)
    out = tmp_path / "out"
    r = cli("contours", inst, "--out", out / "contours.json")
    assert r.exit_code == 0, r.stderr
    r = cli("pitch", out / "contours.json", "--out", out / "pitch.json", "--overlay-dir",
            out / "overlays")
    assert r.exit_code == 0, r.stderr
    doc = json.loads((out / "pitch.json").read_text())
    assert doc["schema"] == PITCH_SCHEMA and doc["schema_version"] == 3
    img, = doc["images"]
    assert img["error"] is None and img["n_blades"] == 3
    assert [round(b["phi_deg"]) for b in img["blades"]] == [10, 130, 250]
    assert [b["theta_class"] for b in img["blades"]] == [HORIZONTAL, ACUTE, VERTICAL]
    ov = cv2.imread(img["overlay"])
    assert ov.shape == (240, 320, 3)
    assert (ov == 120).mean() > 0.5  # drawn on the photo found next to the instances JSON
    (res, err_, _), = read_pitch(out / "pitch.json")
    assert err_ is None and len(res) == 3


def test_cli_json_stdout_is_clean(cli, tmp_path):
    inst = write_rotor_instances(tmp_path / "instances.json", [[10, 130, 250]])
    r = cli("pitch", inst, "--json")
    assert r.exit_code == 0
    doc = json.loads(r.stdout)
    assert doc["schema"] == PITCH_SCHEMA and doc["images"][0]["blades"][0]["theta_class"]


def test_cli_mask_pngs_binary_and_label(cli, tmp_path):
    inst = rotor(240, 320, [20, 140, 260], 12, length=100)
    for k in range(3):
        cv2.imwrite(str(tmp_path / f"blade_{k}.png"), inst.masks[k].astype(np.uint8) * 255)
    cv2.imwrite(str(tmp_path / "nacelle.png"), inst.masks[3].astype(np.uint8) * 255)
    files = [tmp_path / f"blade_{k}.png" for k in range(3)] + [tmp_path / "nacelle.png"]
    r = cli("pitch", *files, "--json", "--overlay-dir", tmp_path / "ov")
    assert r.exit_code == 0, r.stderr
    img, = json.loads(r.stdout)["images"]
    assert img["hub_source"] == "nacelle"
    assert sorted(round(b["phi_deg"]) for b in img["blades"]) == [20, 140, 260]
    label = np.zeros((240, 320), np.uint8)
    for k in range(3):
        label[inst.masks[k]] = k + 1
    cv2.imwrite(str(tmp_path / "labels.png"), label)
    r = cli("pitch", tmp_path / "labels.png", "--json")
    assert r.exit_code == 0, r.stderr
    img, = json.loads(r.stdout)["images"]
    assert img["hub_source"] == "blade_axes" and img["n_blades"] == 3


def test_cli_batch_partial_failure(cli, tmp_path):
    inst = write_rotor_instances(tmp_path / "instances.json",
                                 [[10, 130, 250], [0, 90, 180, 270], [40, 160, 280]])
    r = cli("pitch", inst, "--out", tmp_path / "pitch.json", "--json")
    assert r.exit_code == 9
    doc = json.loads(r.stdout)
    errs = [i["error"] for i in doc["images"]]
    assert errs[0] is None and errs[2] is None
    assert "found 4 blades in r1.png, expected 3" in errs[1]
    assert "1 of 3 images failed" in r.stderr and "Traceback" not in r.stderr
    assert cli("pitch", inst, "--blades", "0", "--json").exit_code == 0


def one_line_error(r, code, text):
    assert r.exit_code == code, (r.exit_code, r.stdout, r.stderr)
    assert text in r.stderr and r.stderr.strip().count("\n") == 0 and "Traceback" not in r.stderr


def test_cli_bad_inputs(cli, tmp_path):
    four = write_rotor_instances(tmp_path / "four.json", [[0, 90, 180, 270]])
    one_line_error(cli("pitch", four), 5, "found 4 blades")
    two = write_rotor_instances(tmp_path / "two.json", [[0, 180]])
    one_line_error(cli("pitch", two), 5, "found 2 blades")
    empty = np.zeros((50, 50), np.uint8)
    cv2.imwrite(str(tmp_path / "empty.png"), empty)
    one_line_error(cli("pitch", tmp_path / "empty.png"), 5, "no mask pixels in empty.png")
    tiny = empty.copy()
    tiny[5:8, 5:8] = 255
    cv2.imwrite(str(tmp_path / "tiny.png"), tiny)
    one_line_error(cli("pitch", tmp_path / "tiny.png"), 5, "no contour above the area threshold")
    tower = np.zeros((50, 50), np.uint8)
    tower[5:45, 20:30] = 255
    cv2.imwrite(str(tmp_path / "tower.png"), tower)
    one_line_error(cli("pitch", tmp_path / "tower.png"), 5, "no blade found in tower.png")
    (tmp_path / "broken.png").write_bytes(b"\x89PNG broken")
    one_line_error(cli("pitch", tmp_path / "broken.png"), 3, "cannot read the image")
    (tmp_path / "photo.jpg").write_bytes(b"")
    colour = np.zeros((40, 40, 3), np.uint8)
    colour[:, :20] = (200, 120, 40)
    cv2.imwrite(str(tmp_path / "photo.png"), colour)
    from wtcli.chain import photo_input
    try:  # the segment stage may already take photos here
        photo_input(tmp_path / "photo.png", 20)
    except InputError:
        one_line_error(cli("pitch", tmp_path / "photo.jpg"), 3, "run `wtinspect segment`")
        one_line_error(cli("pitch", tmp_path / "photo.png"), 3, "run `wtinspect segment`")
    except Exception:  # noqa: BLE001 - a segmenting photo_input may fail on this tiny image
        pass
    one_line_error(cli("pitch", tmp_path / "photo.png", tmp_path / "tower.png"), 3,
                   "a photo among mask files")
    (tmp_path / "plan.json").write_text('{"schema": "wtinspect.plan", "schema_version": 1}')
    one_line_error(cli("pitch", tmp_path / "plan.json"), 3, "wtinspect.instances")
    (tmp_path / "c.json").write_text('{"schema": "wtinspect.contours", "schema_version": 7}')
    one_line_error(cli("pitch", tmp_path / "c.json"), 3, "schema_version 7")
    (tmp_path / "c2.json").write_text('{"schema": "wtinspect.contours", "schema_version": 1, '
                                      '"images": [{"image_size": [5, 5]}]}')
    one_line_error(cli("pitch", tmp_path / "c2.json"), 3, "missing key")
    one_line_error(cli("pitch", tmp_path / "missing.json"), 3, "file not found")
    ok = write_rotor_instances(tmp_path / "ok.json", [[10, 130, 250]])
    cv2.imwrite(str(tmp_path / "wrong_size.png"), np.zeros((10, 10, 3), np.uint8))
    one_line_error(cli("pitch", ok, "--overlay-dir", tmp_path / "ov", "--image",
                       tmp_path / "wrong_size.png"), 3, "does not match the masks")


def test_cli_contours_file_threshold_can_rise_not_fall(cli, tmp_path):
    inst = write_rotor_instances(tmp_path / "instances.json", [[10, 130, 250]])
    assert cli("contours", inst, "--area-threshold", "50", "--out", tmp_path / "c.json").exit_code == 0
    r = cli("pitch", tmp_path / "c.json", "--area-threshold", "10")
    one_line_error(r, 4, "filtered at 50 px")
    r = cli("pitch", tmp_path / "c.json", "--area-threshold", "100", "--json")
    assert r.exit_code == 0 and json.loads(r.stdout)["images"][0]["area_threshold"] == 100
    one_line_error(cli("pitch", tmp_path / "c.json", "--area-threshold", "1e6"), 5,
                   "no contour above the area threshold")


# ---- rotor completion: a low-score blade admitted when the rotor is one short ----------------------
def scored(inst, scores):
    return Instances(inst.labels, inst.masks, np.asarray(scores, float))


def with_blades(inst, masks, scores):
    """``inst`` with extra blade masks (and their scores) appended."""
    return Instances(np.concatenate([inst.labels, ["blade"] * len(masks)]),
                     np.concatenate([inst.masks, np.stack(masks)]),
                     np.concatenate([inst.scores, scores]))


H, W = 300, 400
HUB = (200.0, 150.0)


def two_and_candidate(phi, score=0.3, nacelle=True, **kw):
    """Blades at 20 and 140 deg (scores 0.9, 0.8), a nacelle, and a candidate blade at ``phi``."""
    two = scored(rotor(H, W, [20, 140], 12, hub=HUB, length=120, nacelle=nacelle),
                 [0.9, 0.8] + ([0.95] if nacelle else []))
    kw = {"thickness": 12, "length": 120, "hub": HUB, **kw}
    return with_blades(two, [make_blade_mask(H, W, phi, **kw)], [score])


@pytest.mark.parametrize("nacelle", [True, False])
def test_a_low_score_blade_in_the_free_slot_completes_the_rotor(nacelle):
    inst = two_and_candidate(255, nacelle=nacelle)
    cand = len(inst) - 1
    res = pitch_from_instances(inst)  # expected 3, threshold 0.5, floor 0.2
    assert len(res) == 3 and res.score_threshold == 0.5 and res.candidate_floor == 0.2
    assert [b.admitted_low_score for b in res.blades] == [b.source_index == cand for b in res.blades]
    adm, = res.admitted
    assert adm.source_index == cand and adm.score == 0.3 and err(adm.phi_deg, 255, 360) < 0.5
    assert np.hypot(res.hub_px[0] - HUB[0], res.hub_px[1] - HUB[1]) < 3
    d = res.to_dict()
    assert [b["admitted_low_score"] for b in d["blades"]] == [False, False, True]
    # The same instances without completion: two blades, as before.
    with pytest.raises(PerceptionError, match="found 2 blades"):
        pitch_from_instances(inst, candidate_floor=None)
    assert len(pitch_from_instances(inst, expected_blades=None, candidate_floor=None)) == 2
    # No threshold: every instance counts, as it did before completion existed.
    res = pitch_from_instances(inst, score_threshold=None)
    assert len(res) == 3 and not res.admitted and res.score_threshold is None


@pytest.mark.parametrize("why, kw", [
    ("wrong direction", {"phi": 200}),  # 55 deg off the free slot at 260
    ("duplicates blade 1", {"phi": 22, "thickness": 8}),  # inside the blade at 20 deg
    ("off the hub", {"phi": 260, "hub": (200 + 60 * math.sin(math.radians(260)),
                                         150 + 60 * math.cos(math.radians(260)))}),
    ("root away from the hub", {"phi": 260, "start": 100, "length": 200}),
    ("below the floor", {"phi": 260, "score": 0.15}),
    ("too short", {"phi": 260, "length": 22, "start": 2}),  # < 1/4 of the blades
])
def test_a_low_score_blade_that_does_not_fit_is_not_admitted(why, kw):
    kw = dict(kw)
    phi = kw.pop("phi")
    inst = two_and_candidate(phi, **kw)
    res = pitch_from_instances(inst, expected_blades=None)
    assert len(res) == 2 and not res.admitted, why
    with pytest.raises(PerceptionError, match="found 2 blades"):
        pitch_from_instances(inst)


def test_nothing_is_admitted_when_the_confident_blades_are_enough():
    three = scored(rotor(H, W, [20, 140, 260], 12, hub=HUB, length=120), [0.9, 0.8, 0.7, 0.9])
    inst = with_blades(three, [make_blade_mask(H, W, 80, 12, hub=HUB, length=120)], [0.45])
    res = pitch_from_instances(inst)
    assert len(res) == 3 and not res.admitted
    assert sorted(round(p) for p in res.phis) == [20, 140, 260]


def test_best_scored_first_and_at_most_the_number_missing():
    two = two_and_candidate(258, score=0.3)
    inst = with_blades(two, [make_blade_mask(H, W, 262, 10, hub=HUB, length=110, start=30)],
                       [0.4])
    res = pitch_from_instances(inst, expected_blades=None)
    adm, = res.admitted
    assert adm.score == 0.4 and len(res) == 3


def test_a_four_blade_rotor_is_completed_to_its_count():
    three = scored(rotor(H, W, [10, 100, 190], 12, hub=HUB, length=120), [0.9, 0.9, 0.8, 0.9])
    inst = with_blades(three, [make_blade_mask(H, W, 282, 12, hub=HUB, length=120)], [0.25])
    assert len(pitch_from_instances(inst, expected_blades=None)) == 3  # default rotor: 3
    res = pitch_from_instances(inst, expected_blades=4)
    assert len(res) == 4 and res.admitted[0].score == 0.25
    res = pitch_from_instances(inst, expected_blades=None, rotor_blades=4)
    assert len(res) == 4


def test_the_counted_blades_must_be_spaced_like_the_rotor():
    """Blades 90 deg apart are not two of three: no slot is free for a candidate."""
    two = scored(rotor(H, W, [20, 110], 12, hub=HUB, length=120), [0.9, 0.8, 0.95])
    inst = with_blades(two, [make_blade_mask(H, W, 245, 12, hub=HUB, length=120)], [0.4])
    assert not pitch_from_instances(inst, expected_blades=None).admitted


def test_cli_records_admitted_blades_and_reads_version_1(cli, tmp_path):
    inst = two_and_candidate(255)
    path = write_instances(tmp_path / "instances.json",
                           [{"id": 1, "file_name": "r.png", "width": W, "height": H}], [inst])
    r = cli("pitch", path, "--score-threshold", "0.5", "--out", tmp_path / "p.json")
    assert r.exit_code == 0, r.stderr
    assert "blade 3 (score 0.30) admitted below the score threshold 0.5" in r.stderr
    doc = json.loads((tmp_path / "p.json").read_text())
    assert doc["schema_version"] == 3 and doc["score_threshold"] == 0.5
    img, = doc["images"]
    assert [b["admitted_low_score"] for b in img["blades"]] == [False, False, True]
    assert img["score_threshold"] == 0.5 and img["candidate_floor"] == 0.2
    (res, _, _), = read_pitch(tmp_path / "p.json")
    assert [b.admitted_low_score for b in res.blades] == [False, False, True]
    # A file's instances all count unless --score-threshold is given (as before).
    r = cli("pitch", path, "--json")
    assert r.exit_code == 0 and "admitted" not in r.stderr
    assert not any(b["admitted_low_score"] for b in json.loads(r.stdout)["images"][0]["blades"])
    # Completion off: the candidate floor at the threshold.
    r = cli("pitch", path, "--score-threshold", "0.5", "--candidate-floor", "0.5")
    assert r.exit_code == 5 and "found 2 blades" in r.stderr
    # A version 1 file (no flags, no thresholds) still loads.
    for b in img["blades"]:
        del b["admitted_low_score"]
    del img["score_threshold"], img["candidate_floor"]
    doc.update(schema_version=1, images=[img])
    del doc["score_threshold"], doc["candidate_floor"]
    (tmp_path / "v1.json").write_text(json.dumps(doc))
    (res, _, _), = read_pitch(tmp_path / "v1.json")
    assert len(res) == 3 and not res.admitted and res.score_threshold is None


def test_a_candidate_mostly_inside_a_counted_blade_is_not_admitted():
    from wtcli.pitch import admit_low_score_blades

    inst = two_and_candidate(255)
    fat = make_blade_mask(H, W, 255, 30, hub=HUB, length=130, taper=1.0)
    cs = find_contours(with_blades(inst, [fat], [0.9]), 20)
    res = pitch_from_instances(inst, expected_blades=None)
    measured = [b for b in res.blades if not b.admitted_low_score]
    blades, cand, fat_c = list(cs.instances[:2]), cs.instances[3], cs.instances[4]
    hub = np.asarray(res.hub_px)
    assert [c for c, _ in admit_low_score_blades([cand], blades, measured, hub, 3)] == [cand]
    assert admit_low_score_blades([cand], blades + [fat_c], measured, hub, 3) == []


# ---- the chain for one photo ----------------------------------------------------------------------
def test_photo_to_pitch_counts_and_the_one_short_rotor(tmp_path, monkeypatch):
    """``wtcli.chain.photo_to_pitch`` (segmenter stood in by known masks): the photo's record and
    contours come through; a rotor one blade short is a count error unless ``one_short_ok``;
    a blade scoring below 0.5 is not counted unless it completes the rotor."""
    from wtcli.chain import photo_to_pitch
    from wtcli.segment import infer

    h, w = 240, 320
    cv2.imwrite(str(tmp_path / "p.jpg"), np.full((h, w, 3), 128, np.uint8))
    two = rotor(h, w, [90, 210])
    monkeypatch.setattr(infer, "segment_image", lambda image, **kw: two)
    found = photo_to_pitch(tmp_path / "p.jpg", 3)
    assert found.result is None and "found 2 blades" in found.error
    assert found.input.image["file_name"] == "p.jpg" and found.input.image["width"] == w
    assert found.input.background_candidates == (tmp_path / "p.jpg",)
    short = photo_to_pitch(tmp_path / "p.jpg", 3, one_short_ok=True)
    assert short.error is None and sorted(round(b.phi_deg) for b in short.result.blades) == [90, 210]
    # Two blades of a 2-blade rotor is right; one short of it is not "one short" (n < 3).
    assert photo_to_pitch(tmp_path / "p.jpg", 2).error is None
    one = rotor(h, w, [90])
    monkeypatch.setattr(infer, "segment_image", lambda image, **kw: one)
    assert "found 1 blade" in photo_to_pitch(tmp_path / "p.jpg", 2, one_short_ok=True).error

    low = rotor(h, w, [90, 210, 330])
    low = Instances(low.labels, low.masks, np.array([0.9, 0.9, 0.3, 0.9]))
    monkeypatch.setattr(infer, "segment_image", lambda image, **kw: low)
    res = photo_to_pitch(tmp_path / "p.jpg", 3).result
    assert len(res.blades) == 3 and [b.admitted_low_score for b in res.blades] == [False, False, True]
    no_floor = photo_to_pitch(tmp_path / "p.jpg", 3, candidate_floor=None)
    assert "found 2 blades" in no_floor.error


def test_overlay_finds_the_photo_segment_read(cli, tmp_path, monkeypatch):
    """A contours JSON made from ``segment``'s instances JSON (in another folder than the
    photos) draws its overlay on the photo at the ``path`` segment recorded."""
    from wtcli.pitch.inputs import load_pitch_input
    from wtcli.pitch.overlay import overlay_background
    from wtcli.segment.batch import read_image

    monkeypatch.chdir(tmp_path)
    (tmp_path / "photos").mkdir()
    (tmp_path / "seg").mkdir()
    photo = np.full((120, 160, 3), 200, np.uint8)
    cv2.imwrite(str(tmp_path / "photos" / "a.png"), photo)
    img = {"id": 1, "file_name": "a.png", "path": "photos/a.png", "width": 160, "height": 120}
    write_instances(tmp_path / "seg" / "instances.json", [img], [rotor(120, 160, [90, 210, 330])])
    assert cli("contours", "seg/instances.json", "--out", "contours.json").exit_code == 0
    (inp,) = load_pitch_input(["contours.json"])
    bg, note = overlay_background(inp, None, read_image)
    assert note == "" and bg is not None and bg.shape == photo.shape and (bg == 200).all()
    assert cli("pitch", "contours.json", "--overlay-dir", "ov").exit_code == 0
    drawn = cv2.imread("ov/a_pitch.png")
    assert (drawn == 200).all(axis=2).mean() > 0.3  # the photo's grey; the canvas has none


# ---- overlay names, overlay background, photos the segmenter refuses ------------------------------
def test_overlay_names_are_one_file_per_image():
    """Folders kept, the extension where names would meet (without case, as on macOS/Windows),
    ~2 after names still alike (as segment's outputs); nothing outside --overlay-dir."""
    from wtcli.pitch import overlay_names

    names = overlay_names([{"file_name": f} for f in (
        "site1/IMG_0001.JPG", "site2/IMG_0001.JPG", "dup.jpg", "dup.png", "A.jpg", "a.png",
        "x.jpg", "x.jpg", "../up.jpg", "/abs/q.jpg", "one.jpg", "dup.jpg.png", "b.jpg",
        "B.JPG")] + [{"id": 7}])
    assert names == [
        "site1/IMG_0001_pitch.png", "site2/IMG_0001_pitch.png", "dup.jpg_pitch.png",
        "dup.png_pitch.png", "A.jpg_pitch.png", "a.png_pitch.png", "x.jpg_pitch.png",
        "x.jpg~2_pitch.png", "up_pitch.png", "q_pitch.png", "one_pitch.png",
        "dup.jpg.png_pitch.png", "b.jpg~2_pitch.png", "B.JPG_pitch.png", "image7_pitch.png"]
    assert len({n.casefold() for n in names}) == len(names)
    # Decided from the whole set: the same names in another order get the same files.
    recs = [{"file_name": f} for f in ("dup.png", "Site/a.jpg", "dup.jpg", "site/A.tif",
                                        "c.jpg", "C.jpg")]
    assert overlay_names(recs[::-1]) == overlay_names(recs)[::-1]
    assert overlay_names(recs)[1] == "Site/a.jpg_pitch.png"


def test_overlay_names_near_the_limit_are_cut_to_fit_and_stay_apart():
    """A photo named within `_pitch.png` of the 255-byte limit (segment wrote its masks) gets an
    overlay name cut to fit, a hash of its path after the cut, so two such names stay apart;
    multi-byte characters are cut whole."""
    from wtcli.pitch import overlay_names

    long_a, long_b = "site/" + "a" * 246 + "1.jpg", "site/" + "a" * 246 + "2.jpg"
    wide = "é" * 125 + ".jpg"  # 250 bytes
    names = overlay_names([{"file_name": f} for f in (long_a, long_b, wide, "short.jpg")])
    assert names[3] == "short_pitch.png"
    for n in names[:3]:
        last = n.rpartition("/")[2]
        assert len(last.encode()) <= 255 and last.endswith("_pitch.png"), n
        last.encode().decode("utf-8")
    assert names[0] != names[1] and names[0].startswith("site/aaaa")
    assert names[2].startswith("é" * 100)


def test_cli_overlays_of_photos_with_one_name_do_not_overwrite_each_other(cli, tmp_path):
    """A ``segment -r`` batch of site1/IMG_0001.JPG and site2/IMG_0001.JPG, and dup.jpg beside
    dup.png: four overlays, each drawn on its own photo."""
    names = ["site1/IMG_0001.JPG", "site2/IMG_0001.JPG", "dup.jpg", "dup.png"]
    h, w = 240, 320
    for k, name in enumerate(names):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        # PNG bytes under every name (read_image goes by the bytes): each grey comes back exact.
        _, png = cv2.imencode(".png", np.full((h, w, 3), 40 + 40 * k, np.uint8))
        (tmp_path / name).write_bytes(png.tobytes())
    images = [{"id": k + 1, "file_name": n, "width": w, "height": h} for k, n in enumerate(names)]
    write_instances(tmp_path / "instances.json", images,
                    [rotor(h, w, [10, 130, 250], 12, length=100)] * len(names))
    r = cli("pitch", tmp_path / "instances.json", "--overlay-dir", tmp_path / "ov", "--json")
    assert r.exit_code == 0, r.stderr
    overlays = [i["overlay"] for i in json.loads(r.stdout)["images"]]
    ov = tmp_path / "ov"
    assert overlays == [str(ov / "site1" / "IMG_0001_pitch.png"),
                        str(ov / "site2" / "IMG_0001_pitch.png"),
                        str(ov / "dup.jpg_pitch.png"), str(ov / "dup.png_pitch.png")]
    for k, path in enumerate(overlays):
        grey = 40 + 40 * k
        assert (cv2.imread(path) == grey).all(axis=2).mean() > 0.5, path  # its own photo


def test_overlay_background_is_read_as_segment_reads_it(cli, tmp_path):
    """The overlay's photo comes from ``read_image``, as segment's masks did: 16-bit scaled as
    there (65280 is 254 there, 255 through cv2.imread's own conversion), from a candidate and
    from --image; an unreadable --image names the file, an unreadable candidate is a note."""
    from wtcli.pitch.inputs import load_pitch_input
    from wtcli.pitch.overlay import overlay_background
    from wtcli.segment.batch import read_image

    h, w = 120, 160
    cv2.imwrite(str(tmp_path / "a.png"), np.full((h, w, 3), 65280, np.uint16))
    write_instances(tmp_path / "instances.json", [{"id": 1, "file_name": "a.png", "width": w,
                                                   "height": h}], [rotor(h, w, [90, 210, 330])])
    (inp,) = load_pitch_input([tmp_path / "instances.json"])
    want = read_image(tmp_path / "a.png")
    for explicit in (None, tmp_path / "a.png"):
        bg, note = overlay_background(inp, explicit, read_image)
        assert note == "" and bg.dtype == np.uint8 and np.array_equal(bg, want)
    r = cli("pitch", tmp_path / "instances.json", "--overlay-dir", tmp_path / "ov")
    assert r.exit_code == 0, r.stderr
    assert (cv2.imread(str(tmp_path / "ov" / "a_pitch.png")) == 254).all(axis=2).mean() > 0.3
    (tmp_path / "bad.png").write_bytes(b"\x89PNG not really")
    with pytest.raises(InputError, match=r"bad\.png: not a readable image"):
        overlay_background(inp, tmp_path / "bad.png", read_image)
    (tmp_path / "a.png").write_bytes(b"\x89PNG not really")
    bg, note = overlay_background(inp, None, read_image)
    assert bg is None and note.endswith("a.png: unreadable or not 160x120; overlay drawn on the "
                                        "masks")


def _segmenter_checks_only(monkeypatch):
    """The torch segmenter stood in for by its own size checks (post.working_image), which
    refuse a photo before the network runs; what it would find is a rotor."""
    from wtcli.segment import infer, post

    def segment_image(image, **kw):
        post.working_image(image, 0.5, None)
        return rotor(*image.shape[:2], [90, 210, 330])

    monkeypatch.setattr(infer, "segment_image", segment_image)


@pytest.mark.parametrize("size, why", [((1, 1), "image is too small (1x1)"),
                                       ((9, 2000), "image is too narrow (2000x9)")])
def test_a_photo_the_segmenter_refuses_is_named_and_exit_3(cli, tmp_path, monkeypatch, size, why):
    """As ``segment`` says it: the file named once, exit 3 (not "no mask pixels", exit 5, nor a
    cv2.error, exit 1), through ``photo_to_pitch`` and the command."""
    from wtcli.chain import photo_to_pitch

    _segmenter_checks_only(monkeypatch)
    for name in ("tiny.jpg", "tiny.png"):  # a colour PNG is a photo too
        photo = tmp_path / name
        cv2.imwrite(str(photo), np.full(size + (3,), (30, 90, 200), np.uint8))
        with pytest.raises(InputError) as e:
            photo_to_pitch(photo)
        assert str(e.value).startswith(f"{photo}: {why}") and str(e.value).count(str(photo)) == 1
        one_line_error(cli("pitch", photo), 3, f"{photo}: {why}")


def test_a_broken_link_to_a_photo_says_so(cli, tmp_path, monkeypatch):
    from wtcli.chain import photo_to_pitch

    _segmenter_checks_only(monkeypatch)
    (tmp_path / "gone.jpg").symlink_to(tmp_path / "missing.jpg")
    with pytest.raises(InputError, match="gone.jpg: broken symbolic link"):
        photo_to_pitch(tmp_path / "gone.jpg")
    one_line_error(cli("pitch", tmp_path / "gone.jpg"), 3, "gone.jpg: broken symbolic link")


def test_pitch_notes_are_one_line_in_a_log(cli, tmp_path):
    """stderr not a terminal (a log): a note longer than the console's 80 columns stays one line."""
    deep = tmp_path / ("a_long_folder_name_" * 8)
    deep.mkdir()
    inst = write_rotor_instances(deep / "instances.json", [[10, 130, 250]])
    cv2.imwrite(str(deep / "r0.png"), np.zeros((10, 10, 3), np.uint8))  # not the masks' size
    r = cli("pitch", inst, "--overlay-dir", deep / "ov")
    assert r.exit_code == 0, r.stderr
    notes = [line for line in r.stderr.splitlines() if line.startswith("note:")]
    assert len(notes) == 1 and notes[0].endswith("not 320x240; overlay drawn on the masks")
    summary = [line for line in r.stderr.splitlines() if line.startswith("pitch of")]
    assert summary == [f"pitch of 1/1 image(s) -> {deep / 'ov'}"]


def test_overlay_of_a_thin_strip_draws(tmp_path):
    """The overlay resizes nothing: a 9 x 2000 or 1 x 300 image draws at its own size."""
    for h, w in ((9, 2000), (2000, 9), (1, 300)):
        m = np.zeros((h, w), bool)
        if h < w:
            m[max(0, h // 2 - 1):h // 2 + 2, 5:w - 5] = True
        else:
            m[5:h - 5, w // 2 - 1:w // 2 + 2] = True
        res = measure_pitch(find_contours(Instances(np.array(["blade"], object), m[None]), 0),
                            None)
        for bg in (None, np.full((h, w, 3), 100, np.uint8)):
            assert draw_pitch_overlay(bg, res).shape == (h, w, 3)
