"""Property tests (hypothesis) of pitch on random rotors and random shapes."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from wtcli.contours import find_contours
from wtcli.errors import PerceptionError
from wtcli.jsonio import dumps
from wtcli.masks import Instances
from wtcli.pitch import PitchResult, classify_theta, measure_pitch, normalize_theta

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def err(a, b, period):
    d = abs(a - b) % period
    return min(d, period - d)


def blade(h, w, hub, phi, length, thick, taper, start):
    r = math.radians(phi)
    u = np.array([math.cos(r), -math.sin(r)])
    n = np.array([-u[1], u[0]])
    p0, p1 = np.asarray(hub) + start * u, np.asarray(hub) + length * u
    poly = np.array([p0 + thick / 2 * n, p1 + taper * thick / 2 * n, p1 - taper * thick / 2 * n,
                     p0 - thick / 2 * n])
    m = np.zeros((h, w), np.uint8)
    cv2.fillPoly(m, [np.round(poly * 16).astype(np.int32)], 1, cv2.LINE_8, shift=4)
    return m.astype(bool)


def valid(res: PitchResult) -> None:
    for b in res.blades:
        assert 0 <= b.theta_deg < 180 and 0 <= b.theta_eq7_deg < 180 and 0 <= b.phi_deg < 360
        assert b.theta_class == classify_theta(b.theta_deg)
        assert err(b.phi_deg % 180, b.theta_deg, 180) < 1e-4
    doc = json.loads(dumps(res.to_dict()))  # no NaN, plain JSON
    back = PitchResult.from_dict(doc)
    assert [b.theta_class for b in back.blades] == res.classes


@SETTINGS
@given(theta=st.floats(-1e4, 1e4, allow_nan=False), k=st.integers(-3, 3))
def test_classes_are_periodic_and_mirror_symmetric(theta, k):
    t = normalize_theta(theta)
    assert classify_theta(t) == classify_theta(t + 180 * k)
    assert classify_theta(t) == classify_theta((180 - t) % 180)


@SETTINGS
@given(az=st.floats(0, 360), n=st.integers(2, 5), thick=st.floats(4, 30),
       taper=st.floats(0.1, 1.0), length=st.floats(70, 140),
       hx=st.floats(-40, 40), hy=st.floats(-30, 30), nacelle=st.booleans())
# Found by CI: thin blades that do not taper lost to the "wide tip" rule (all four
# dropped, or one of five), since pixel noise made a tip look wider.
@example(az=67.0, n=4, thick=4.0, taper=1.0, length=74.0, hx=0.0, hy=0.0, nacelle=True)
@example(az=67.0, n=4, thick=4.0, taper=1.0, length=74.0, hx=0.0, hy=0.0, nacelle=False)
@example(az=1.0, n=5, thick=5.0, taper=1.0, length=73.0, hx=0.0, hy=0.0, nacelle=False)
# Found by CI: one of four such blades, 15 % wider at the tip by pixel noise (less
# than a pixel on average), was taken for the tower.
@example(az=12.0, n=4, thick=4.0, taper=1.0, length=70.0, hx=1.75, hy=0.0, nacelle=False)
def test_random_rotors_give_their_angles(az, n, thick, taper, length, hx, hy, nacelle):
    h, w = 320, 360
    hub = (w / 2 + hx, h / 2 + hy)
    phis = [(az + k * 360 / n) % 360 for k in range(n)]
    masks = [blade(h, w, hub, p, length, thick, taper, 0.12 * length) for p in phis]
    labels = ["blade"] * n
    if nacelle:
        m = np.zeros((h, w), np.uint8)
        cv2.circle(m, (round(hub[0]), round(hub[1])), 12, 1, -1)
        masks.append(m.astype(bool))
        labels.append("nacelle")
    inst = Instances(np.array(labels, object), np.stack(masks))
    res = measure_pitch(find_contours(inst, 30), expected_blades=0)
    valid(res)
    assert len(res) == n
    # Pixels quantise the blade's ends and edges: about a pixel across its visible length.
    tol = 0.2 + math.degrees(math.atan(1.2 / (0.88 * length))) + (0 if thick / length < 0.3 else 1)
    for b in res.blades:
        assert err(b.phi_deg, phis[b.source_index], 360) < tol


@SETTINGS
@given(seed=st.integers(0, 10_000), n=st.integers(1, 4))
def test_random_shapes_never_crash_and_stay_in_range(seed, n):
    """Arbitrary blobs labelled blade: a valid result or a PerceptionError, nothing else."""
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(20, 200)), int(rng.integers(20, 200))
    masks = []
    for _ in range(n):
        m = np.zeros((h, w), np.uint8)
        k = int(rng.integers(3, 9))
        poly = np.stack([rng.integers(-10, w + 10, k), rng.integers(-10, h + 10, k)], 1)
        cv2.fillPoly(m, [poly.astype(np.int32)], 1)
        if rng.random() < 0.3:
            m |= (rng.random((h, w)) < 0.05).astype(np.uint8)
        masks.append(m.astype(bool))
    inst = Instances(np.array(["blade"] * n, object), np.stack(masks))
    try:
        res = measure_pitch(find_contours(inst, float(rng.choice([0, 5, 50]))), expected_blades=0)
    except PerceptionError:
        return
    valid(res)


@SETTINGS
@given(az=st.floats(0, 120), thick=st.floats(4, 20), quarter=st.integers(1, 3))
def test_rotating_the_mask_by_90_degrees_adds_90_degrees(az, thick, quarter):
    """np.rot90 is an exact pixel rotation (counter-clockwise as displayed)."""
    h = w = 301
    phis = [az, az + 120, az + 240]
    masks = np.stack([blade(h, w, (150, 150), p, 130, thick, 0.3, 15) for p in phis])
    inst = Instances(np.array(["blade"] * 3, object), masks)
    rot = Instances(inst.labels, np.rot90(masks, quarter, axes=(1, 2)).copy())
    a = measure_pitch(find_contours(inst, 30))
    b = measure_pitch(find_contours(rot, 30))
    for x, y in zip(a.blades, b.blades):
        assert err(y.phi_deg, x.phi_deg + 90 * quarter, 360) < 1e-3
        assert err(y.theta_deg, x.theta_deg + 90 * quarter, 180) < 1e-3


@SETTINGS
@given(az=st.floats(0, 120), thick=st.floats(4, 20))
def test_mirroring_the_mask_mirrors_the_angles(az, thick):
    h = w = 301
    phis = [az, az + 120, az + 240]
    masks = np.stack([blade(h, w, (150, 150), p, 130, thick, 0.3, 15) for p in phis])
    a = measure_pitch(find_contours(Instances(np.array(["blade"] * 3, object), masks), 30))
    b = measure_pitch(find_contours(Instances(np.array(["blade"] * 3, object),
                                              masks[:, :, ::-1].copy()), 30))
    for x, y in zip(a.blades, b.blades):
        assert err(y.theta_deg, 180 - x.theta_deg, 180) < 1e-3
        assert err(y.phi_deg, 180 - x.phi_deg, 360) < 1e-3
