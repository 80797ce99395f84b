"""Coverage counts a sample only if no part of the turbine stands between it and the camera."""

import numpy as np
import pytest

from wtcli.geometry import BLADE_SIDES, Camera, SurfaceSamples, Turbine, look_at_rotation
from wtcli.geometry.coverage import measure_coverage

CAM = Camera(5456, 3632, 16, 23.2)
TE = BLADE_SIDES.index("trailing_edge")
LE = BLADE_SIDES.index("leading_edge")


def make_turbine(az=90.0, yaw=0.0, **kw):
    base = dict(id="T1", base=(0, 0, 0), hub_height=80, rotor_diameter=90, yaw_deg=yaw)
    base.update(kw)
    return Turbine.with_rotor_azimuth(az, **base)


def pick(samples: SurfaceSamples, blade: int, side: int, span: float, normal) -> SurfaceSamples:
    """The one sample of ``blade``'s ``side`` nearest span fraction ``span`` whose normal is
    closest to ``normal``."""
    sel = np.nonzero((samples.blade == blade) & (samples.side == side))[0]
    near = sel[np.abs(samples.span[sel] - span) <= np.abs(samples.span[sel] - span).min() + 1e-9]
    i = near[np.argmax(samples.normals[near] @ np.asarray(normal, float))]
    return samples[[i]]


def covered_from(sample: SurfaceSamples, eye: np.ndarray, gsd_mm: float = 8.0) -> bool:
    """Whether one photo from ``eye`` aimed at the sample covers it (GSD limit ``gsd_mm``)."""
    R = look_at_rotation(eye, sample.points[0])
    return bool(measure_coverage(sample, CAM, eye[None], R[None], gsd_mm).covered[0])


def incidence_deg(sample: SurfaceSamples, eye: np.ndarray) -> float:
    to_eye = eye - sample.points[0]
    return float(np.degrees(np.arccos(np.clip(sample.normals[0] @ to_eye / np.linalg.norm(to_eye), -1, 1))))


def test_blade_behind_the_tower_is_not_covered_from_the_tower_side():
    # Rotor faces north (+y), blade 1 points straight down in front of the tower: its trailing
    # edge faces the tower (south).
    t = make_turbine(az=270.0, yaw=0.0)  # 8 mm/px GSD limit below: photos from up to 31 m
    # a trailing-edge sample facing 40 deg off south, so that a view along its normal passes
    # beside the tower (the edge line itself faces the tower squarely)
    s = pick(t.surface_samples(0.5, "blades"), 0, TE, 0.4, [0.64, -0.77, 0.0])
    x = s.points[0]
    n = s.normals[0] * [1.0, 1.0, 0.0]
    behind = x + np.array([0.0, -25.0, 0.0])  # due south: across the tower's axis (x = y = 0)
    aside = x + 25.0 * n / np.linalg.norm(n)  # along the sample's own normal, beside the tower
    # The set-up: both views pass the in-frame, GSD and incidence tests; the tower stands on
    # the first line and not on the second.
    assert incidence_deg(s, behind) < 45.0 and incidence_deg(s, aside) < 5.0
    tower = t.part_names().index("tower")
    assert t.clearance_by_part(np.array([[x[0], 0.0, x[2]]]))[0, tower] == 0
    f = np.linspace(0, 1, 500)[:, None]
    assert t.clearance_by_part(aside + f * (x - aside))[:, tower].min() > 1.0

    assert not covered_from(s, behind)
    assert covered_from(s, aside)
    both = measure_coverage(s, CAM, np.array([behind, aside]),
                            np.array([look_at_rotation(e, x) for e in (behind, aside)]), 8.0)
    assert both.covered[0]
    # The finest GSD is the clear photo's, not the closer-to-normal hidden one's.
    assert both.best_gsd_mm[0] == pytest.approx(CAM.gsd_mm(25.0))


def test_root_hidden_by_the_hub_is_not_covered():
    # A hub well above the default size (3.5 m, default 2.25 m) leaves no doubt which lines it
    # blocks; blade 1 horizontal, its leading edge facing the front (+y).
    t = make_turbine(az=0.0, yaw=0.0, hub_radius=3.5)
    s = t.surface_samples(0.5, "blades")
    root = s.span[s.blade == 0].min()
    x_s = pick(s, 0, LE, root, t.axis)
    x, d = x_s.points[0], t.blade_direction(0)
    a = np.radians(50.0)
    toward_hub = x + 12.0 * (np.cos(a) * t.axis - np.sin(a) * d)  # 50 deg off the normal, inboard
    outboard = x + 12.0 * (np.cos(a) * t.axis + np.sin(a) * d)  # the mirror view, outboard
    assert incidence_deg(x_s, toward_hub) < 55.0 and incidence_deg(x_s, outboard) < 55.0
    assert t.clearance(np.array([toward_hub, outboard])).min() > 3.0
    # The inboard line runs through the hub sphere.
    f = np.linspace(0, 1, 200)[:, None]
    line = toward_hub + f * (x - toward_hub)
    assert t.clearance_by_part(line)[:, t.part_names().index("hub")].min() == 0.0

    assert not covered_from(x_s, toward_hub)
    assert covered_from(x_s, outboard)


@pytest.mark.parametrize("off_normal_deg", [0.0, 30.0, 55.0])
@pytest.mark.parametrize("side", ["leading_edge", "pressure_side", "trailing_edge", "suction_side"])
def test_a_blade_face_is_not_hidden_by_its_own_surface(side, off_normal_deg):
    """Seen at the planner's 1.5 mm/px standoff, head-on or obliquely (incidence up to 55 deg,
    tilted along the span), a sample on any side of an upright blade stays covered: the end of
    the sight line at the sample is not taken for an obstacle."""
    t = make_turbine(az=90.0, yaw=30.0)
    d = t.blade_direction(0)
    s = t.surface_samples(0.5, "blades")
    for span in (0.1, 0.5, 0.9):
        i = pick(s, 0, BLADE_SIDES.index(side), span, np.zeros(3))
        n = i.normals[0]
        # Tilt the view along the span, away from the hub, so no other part is in the way.
        a = np.radians(off_normal_deg)
        eye = i.points[0] + CAM.distance_for_gsd(1.5) * (np.cos(a) * n + np.sin(a) * d)
        assert covered_from(i, eye, gsd_mm=1.5), (side, span, off_normal_deg)


def test_line_of_sight_through_a_thin_blade_tip_is_blocked():
    """Sphere tracing never steps over a part, however thin: a line through the 95 % span
    section (a few centimetres thick) is blocked, the same line 0.5 m past the tip is not.
    The blade is given a slender tip (chord 0.015 R, 18 % thick), thinner than the defaults."""
    t = make_turbine(az=0.0, yaw=0.0, blade_tip_chord=0.675, blade_tip_thickness_ratio=0.18)
    d, c, n = t.blade_frame(0)
    x = t.hub_center + 0.95 * t.tip_radius * d
    a, b = t.blade_semi_axes((0.95 * t.tip_radius - t.blade_root_offset)
                             / (t.tip_radius - t.blade_root_offset))
    assert b < 0.1  # the section really is thin
    eyes = np.array([x - 10 * n, x - 10 * n + (0.05 * t.tip_radius + 0.5) * d])
    ends = np.array([x + 10 * n, x + 10 * n + (0.05 * t.tip_radius + 0.5) * d])
    assert t.line_of_sight(eyes, ends).tolist() == [False, True]


@pytest.mark.parametrize("max_steps", [64, 3])
def test_line_of_sight_is_the_sphere_trace_of_the_reference_model(max_steps):
    """The compiled trace (clearance_kernel.trace) against the same sphere trace written out in
    numpy on the reference model (clearance_by_part): rays past, through and along the
    turbine, from the surface, with few steps so that the finishing samples are tried too."""
    from wtcli.geometry.turbine import segment_lower_bound

    rng = np.random.default_rng(max_steps)
    t = make_turbine(az=float(rng.uniform(0, 120)), yaw=float(rng.uniform(0, 360)))
    S = t.surface_samples(1.0)
    k = rng.integers(0, len(S), 400)
    targets = S.points[k]
    eyes = np.r_[targets[:200] + S.normals[k[:200]] * rng.uniform(0.05, 20, (200, 1))
                 + rng.normal(0, 3, (200, 3)),
                 targets[200:] + rng.normal(0, 15, (200, 3))]
    eyes[:20] = targets[:20] + 0.02 * S.normals[k[:20]]  # grazing: along the surface
    got = t.line_of_sight(eyes, targets, max_steps=max_steps)

    def dist(X):
        return t.clearance_by_part(X, cap=1.0).min(axis=1)

    ray = targets - eyes
    stop = np.linalg.norm(ray, axis=1)
    ray /= stop[:, None]
    stop -= 0.05
    want, live, tt = np.ones(len(eyes), bool), np.nonzero(stop > 0)[0], np.zeros(len(eyes))
    for _ in range(max_steps):
        c = dist(eyes[live] + tt[live, None] * ray[live])
        want[live[c < 0.01]] = False
        tt[live] += c
        live = live[(c >= 0.01) & (tt[live] < stop[live])]
    lb = segment_lower_bound(dist, eyes[live] + tt[live, None] * ray[live],
                             eyes[live] + stop[live, None] * ray[live], 0.01)
    want[live[lb < 0.005]] = False
    assert 50 < want.sum() < 350  # both answers occur
    if max_steps == 3:
        assert len(live) > 20  # the finishing samples decide some
    assert np.array_equal(got, want)


def test_line_of_sight_checks_its_input():
    t = make_turbine()
    with pytest.raises(ValueError, match="same shape"):
        t.line_of_sight(np.zeros((2, 3)), np.zeros((3, 3)))


def test_coverage_needs_samples_that_know_their_turbine():
    t = make_turbine()
    s = t.surface_samples(2.0, "blades")
    bare = SurfaceSamples(s.points, s.normals, s.area, s.part, s.blade, s.side, s.span)
    with pytest.raises(ValueError, match="occlusion"):
        measure_coverage(bare, CAM, np.zeros((1, 3)), np.eye(3)[None], 1.5)
    assert s[s.blade == 0].turbine is t  # selecting samples keeps the turbine


@pytest.mark.parametrize("seed", range(4))
def test_the_pair_search_finds_every_pair_a_full_search_finds(seed):
    """measure_coverage's cubes-and-cone cull (coverage._near_pairs) drops no (sample, photo) pair
    that the per-pair tests pass: against every pair tested, for cameras of any field of view
    near the surface, aimed anywhere (at it, past it, away)."""
    from wtcli.geometry.coverage import _near_pairs, imaged

    rng = np.random.default_rng(seed)
    t = make_turbine(az=float(rng.uniform(0, 120)), yaw=float(rng.uniform(0, 360)))
    s = t.surface_samples(1.0)
    cam = Camera(int(rng.integers(800, 5456)), int(rng.integers(600, 3632)), float(rng.uniform(8, 35)), 23.2)
    max_dist = float(rng.uniform(3, 12))
    anchors = s.points[rng.integers(0, len(s), 300)]
    pos = anchors + rng.normal(0, max_dist, (300, 3))
    R = np.stack([look_at_rotation(p, a + rng.normal(0, 0.6 * max_dist, 3))
                  for p, a in zip(pos, anchors)])
    got = _near_pairs(s.points, s.normals, pos, R, cam, max_dist, 60.0, 0.02)
    rel = s.points[None, :, :] - pos[:, None, :]
    ok = imaged(rel, np.broadcast_to(s.normals, rel.shape), R[:, None], cam, max_dist, 60.0, 0.02)
    p, i = np.nonzero(ok)
    assert len(p) > 100  # the cases do see the surface
    assert sorted(zip(got[0].tolist(), got[1].tolist())) == sorted(zip(i.tolist(), p.tolist()))
    # Photo-major (measure_coverage's tie order), with each pair's GSD.
    assert (np.diff(got[1]) >= 0).all()
    np.testing.assert_array_equal(got[2], cam.gsd_mm(np.linalg.norm(s.points[got[0]] - pos[got[1]], axis=1)))
