"""The one geometry: turbine model and camera model, checked against known answers."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from wtcli.geometry import BLADE_SIDES, Camera, Turbine
from wtcli.geometry.projection import instance_masks, part_id_map


def make_turbine(az=90.0, yaw=0.0, **kw):
    base = dict(id="T1", base=(0, 0, 0), hub_height=80, rotor_diameter=90, yaw_deg=yaw)
    base.update(kw)
    return Turbine.with_rotor_azimuth(az, **base)


def front_camera(t, dist=110.0, w=640, h=480):
    return Camera(w, h, 16, 23.2).looking_at(t.hub_center + t.axis * dist, t.hub_center)


@pytest.mark.parametrize("yaw", [0, 37, 90, 200, 359])
@pytest.mark.parametrize("az", [0, 45, 90, 181, 300])
def test_front_view_image_angle_equals_rotor_azimuth(yaw, az):
    t = make_turbine(az, yaw)
    cam = front_camera(t)
    for k in range(3):
        got = cam.image_angle_deg(t.hub_center, t.blade_tips()[k])
        want = (az + 120 * k) % 360
        assert abs((got - want + 180) % 360 - 180) < 1e-6


def test_tips_at_rotor_radius_and_axis_points_to_heading():
    t = make_turbine(yaw=90)
    assert np.allclose(t.axis, [1, 0, 0])
    assert np.allclose(np.linalg.norm(t.blade_tips() - t.hub_center, axis=1), 45)


def test_clearance_known_answers():
    t = make_turbine()
    # 10 m in front of the tower base's surface, on the ground.
    p = t.base_xyz + np.array([t.tower_base_radius + 10, 0, 0.0])
    assert t.clearance(p)[0] == pytest.approx(10, abs=1e-6)
    # Above the hub along z, beyond the upright blade's tip.
    p = t.blade_tips()[0] + np.array([0, 0, 7.0])
    assert t.clearance(p)[0] == pytest.approx(7, abs=1e-6)
    # Inside the nacelle.
    assert t.clearance(t.nacelle_center)[0] == 0


def test_clearance_never_exceeds_distance_to_dense_surface():
    """Safety: the model's clearance is a lower bound of the true distance to the surface."""
    rng = np.random.default_rng(1)
    for trial in range(4):
        t = make_turbine(az=rng.uniform(0, 360), yaw=rng.uniform(0, 360),
                         blade_pitch_deg=rng.uniform(0, 90))
        dense = t.surface_samples(0.15)
        P = t.hub_center + rng.normal(size=(400, 3)) * rng.uniform(3, 30)
        c = t.clearance(P)
        d = np.array([np.linalg.norm(dense.points - p, axis=1).min() for p in P])
        inside = c == 0
        assert (c[~inside] <= d[~inside] + 1e-6).all()
        # ... and not pessimistic by more than the sampling resolution away from the junctions.
        assert np.median(d[~inside] - c[~inside]) < 0.1


def test_offset_along_normal_gives_that_clearance_on_blades():
    t = make_turbine(az=20, yaw=45)
    s = t.surface_samples(0.5, parts="blades")
    s = s[s.span > 0.1]
    own = t.clearance_by_part(s.points + 3.0 * s.normals)[np.arange(len(s)), s.blade]
    assert own.min() > 2.95 and own.max() <= 3.0 + 1e-9


def test_segment_clearance_is_a_lower_bound():
    t = make_turbine()
    a = t.hub_center + t.axis * 30 + np.array([-60, 0, 0])
    b = t.hub_center + t.axis * 2 + np.array([60, 0, 0])
    lb = t.segment_clearance(a[None], b[None], step=0.5)[0]
    dense = np.linspace(a, b, 5000)
    assert lb <= t.clearance(dense).min() + 1e-9
    assert lb > t.clearance(dense).min() - 0.3


def test_surface_samples_labels():
    t = make_turbine()
    s = t.surface_samples(0.5)
    blades = s[s.blade >= 0]
    assert set(np.unique(blades.side)) == set(range(len(BLADE_SIDES)))
    assert np.allclose(np.linalg.norm(s.normals, axis=1), 1)
    # Leading-edge normals of a feathered blade face the front.
    le = blades[blades.side == 0]
    assert (le.normals @ t.axis).mean() > 0.8
    area = s.area[s.blade == 0].sum()
    assert 100 < area < 1000  # a 45 m blade has a few hundred m^2 of surface


def test_blade_root_inside_the_nacelle_is_not_surface():
    """The nacelle's front face sits less than a root semi-chord behind the rotor plane, so the
    root's trailing edge runs into the nacelle box: those points are inside the turbine, not on
    its outer surface, and are not sampled. Everywhere else the blade is sampled as before."""
    t = make_turbine(az=30, yaw=20)
    front = t.overhang - 0.6 * t.nacelle_length  # hub centre -> nacelle front face, along the axis
    assert 0 < front < t.blade_root_chord / 2  # the premise: the root crosses the front face
    k = 0
    d, c, _ = t.blade_frame(k)
    te_root = t.hub_center + t.hub_radius * d - (t.blade_root_chord / 2) * c  # outside the hub
    assert t.clearance_by_part(te_root)[0, t.part_names().index("nacelle")] == 0  # inside
    s = t.surface_samples(0.25, parts="blades")
    others = t.clearance_by_part(s.points)
    own = others[np.arange(len(s)), s.blade]
    others[np.arange(len(s)), s.blade] = np.inf
    assert (others.min(axis=1) > 0).all()  # no sample inside another part
    assert (own < 1e-6).all()  # and every one on its own blade
    # Only the root loses samples: the trailing edge just beyond the nacelle is still there,
    # and against the same blade on a longer overhang (no contact) only a few % of area is gone.
    te_idx = (s.blade == k) & (s.side == BLADE_SIDES.index("trailing_edge"))
    assert 0 < others[te_idx].min() < 0.3
    free = make_turbine(az=30, yaw=20, overhang=10.0).surface_samples(0.25, parts="blades")
    free_area = free.area[(free.blade == k) & (free.side == BLADE_SIDES.index("trailing_edge"))].sum()
    assert 0.93 * free_area < s.area[te_idx].sum() < 0.99 * free_area


def test_camera_projection_roundtrip_and_gsd():
    cam = Camera(5456, 3632, 16, 23.2).looking_at(np.array([0, -10, 50.0]), np.array([0, 0, 50.0]))
    assert cam.gsd_mm(10) == pytest.approx(2.657, abs=1e-3)  # formats.md example
    assert cam.distance_for_gsd(cam.gsd_mm(7.5)) == pytest.approx(7.5)
    P = np.array([[1.0, 5, 52], [-3, 20, 47]])
    uv, z = cam.project(P)
    back = cam.rays(uv)
    assert np.allclose(back, (P - cam.position) / np.linalg.norm(P - cam.position, axis=1)[:, None])
    assert (z > 0).all()


def test_roll_turns_the_image_clockwise():
    t = make_turbine(az=0)
    cam = front_camera(t)
    rolled = Camera(640, 480, 16, 23.2).looking_at(cam.position, t.hub_center, roll_deg=10)
    a0 = cam.image_angle_deg(t.hub_center, t.blade_tips()[0])
    a1 = rolled.image_angle_deg(t.hub_center, t.blade_tips()[0])
    assert (a0 - a1) % 360 == pytest.approx(10, abs=1e-6)


def test_masks_show_each_part_with_occlusion():
    t = make_turbine(az=270 - 120)  # one blade straight down, in front of the tower
    cam = front_camera(t)
    inst = instance_masks(t, cam)
    labels = [l for l, _, _ in inst]
    assert labels.count("blade") == 3 and "tower" in labels and "nacelle" in labels
    ids = part_id_map(t, cam)
    # Just below the hub, the down blade hides the tower.
    uv, _ = cam.project(t.hub_center - np.array([0, 0, 15.0]) + t.axis * 0.0)
    u, v = np.round(uv[0]).astype(int)
    assert ids[v, u] == 1  # blade 2 (index 1) points down: 150 + 120 = 270


def test_coverage_counts_only_the_side_facing_the_camera():
    from wtcli.geometry.coverage import measure_coverage, turbine_coverage

    t = make_turbine(az=90, yaw=0)  # blade 1 straight up, leading edge faces the front (+y)
    cam = Camera(4000, 3000, 16, 23.2)
    d = cam.distance_for_gsd(1.0)
    s = t.surface_samples(0.5, parts="blades")
    # Photos every 1 m up blade 1 from the front at the 1 mm/px distance.
    zs = np.arange(t.hub_center[2], t.blade_tips()[0][2] + 2, 1.0)
    pos = np.array([[t.hub_center[0], t.hub_center[1] + d, z] for z in zs])
    R = np.array([Camera.rotation_from_yaw_pitch(180, 0) for _ in zs])  # looking south
    cov = measure_coverage(s, cam, pos, R, target_gsd_mm=1.0)
    # the wide root's flanks leave the 3 m high frame: the converged figure is ~90.7 %
    sides = turbine_coverage(t, cam, pos, R, 1.0, 0.5, parts="blades").by_blade_side()["blade1"]
    assert sides["leading_edge"] > 0.9
    sides = cov.by_blade_side()["blade1"]
    assert sides["trailing_edge"] == 0.0
    assert cov.by_blade_side()["blade2"]["leading_edge"] == 0.0
    # Twice the distance: too coarse, nothing counts.
    far = measure_coverage(s, cam, pos + np.array([0, d, 0]), R, target_gsd_mm=1.0)
    assert far.covered.sum() == 0


def test_capped_clearance_is_exact_below_the_cap_and_a_lower_bound_above():
    rng = np.random.default_rng(5)
    t = make_turbine(az=rng.uniform(0, 360), yaw=rng.uniform(0, 360))
    P = t.hub_center + rng.normal(size=(3000, 3)) * 40
    full, capped = t.clearance(P), t.clearance(P, cap=8.0)
    below = capped < 8.0
    assert below.any() and (~below).any()
    assert np.allclose(capped[below], full[below])
    assert (capped[~below] <= full[~below] + 1e-9).all()


def _bisection_ellipse_distance(u, v, A, B):
    """The 60-step bisection ``_ellipse_distance`` used before (reference for the test below)."""
    u, v = np.abs(u), np.abs(v)
    A = np.broadcast_to(A, u.shape).astype(float)
    B = np.broadcast_to(B, u.shape).astype(float)
    outside = (u / A) ** 2 + (v / B) ** 2 > 1.0
    lo = np.zeros_like(u)
    hi = np.sqrt((A * u) ** 2 + (B * v) ** 2) + 1e-12
    for _ in range(60):
        t = 0.5 * (lo + hi)
        pos = (A * u / (t + A * A)) ** 2 + (B * v / (t + B * B)) ** 2 - 1.0 > 0
        lo, hi = np.where(pos, t, lo), np.where(pos, hi, t)
    t = 0.5 * (lo + hi)
    x, y = A * A * u / (t + A * A), B * B * v / (t + B * B)
    return np.where(outside, np.hypot(u - x, v - y), 0.0)


_coord = st.floats(-300.0, 300.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(pts=st.lists(st.tuples(_coord, _coord), min_size=1, max_size=50),
       a=st.floats(0.05, 5.0), ratio=st.floats(0.1, 1.0))
def test_ellipse_distance_never_above_the_bisection_it_replaced(pts, a, ratio):
    """Safety: the Newton solve of the blade-section distance is never larger than the old
    60-step bisection (beyond float rounding, 1e-12 relative), nor the true distance (dense
    boundary points), and as accurate (within 1e-9 m)."""
    from wtcli.geometry.turbine import _ellipse_distance

    P = np.array(pts)
    # Points near the surface too, where the solve is hardest.
    ang = np.arctan2(P[:, 1], P[:, 0])
    near = np.stack([a * np.cos(ang), a * ratio * np.sin(ang)], 1) * (1 + 1e-3 * np.tanh(P[:, :1]))
    P = np.vstack([P, near])
    A = np.full(len(P), a)
    B = A * ratio
    new = _ellipse_distance(P[:, 0], P[:, 1], A, B)
    old = _bisection_ellipse_distance(P[:, 0], P[:, 1], A, B)
    assert (new <= old + 1e-12 * np.maximum(1.0, old)).all()
    assert (new >= old - 1e-9).all()
    th = np.linspace(0, 2 * np.pi, 20001)
    edge = np.stack([a * np.cos(th), a * ratio * np.sin(th)], 1)
    dense = np.linalg.norm(P[:, None] - edge[None], axis=2).min(axis=1)
    assert (new <= dense + 1e-9).all()


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31), blades=st.integers(1, 4), pitch=st.floats(0.0, 90.0),
       sizes=st.lists(st.floats(0.5, 1.8), min_size=9, max_size=9),
       cap=st.sampled_from([None, 0.3, 1.0, 6.0, 60.0]))
def test_compiled_clearance_is_the_reference_model(seed, blades, pitch, sizes, cap):
    """Safety: ``Turbine.clearance`` (compiled, clearance_kernel) gives the reference model's
    values (``clearance_by_part``, numpy) below the cap, to rounding, and at least the cap where
    the reference does: on random turbines with unusual part sizes and blade counts, points
    near every part, inside parts and far away."""
    rng = np.random.default_rng(seed)
    R = float(rng.uniform(30, 80))
    names = ("tower_base_radius", "tower_top_radius", "nacelle_length", "nacelle_width",
             "nacelle_height", "hub_radius", "blade_root_chord", "blade_max_chord",
             "blade_tip_chord")
    base = {"tower_base_radius": 0.03 * R, "tower_top_radius": 0.02 * R, "nacelle_length": 0.25 * R,
            "nacelle_width": 0.09 * R, "nacelle_height": 0.09 * R, "hub_radius": 0.05 * R,
            "blade_root_chord": 0.055 * R, "blade_max_chord": 0.075 * R, "blade_tip_chord": 0.015 * R}
    kw = {k: base[k] * f for k, f in zip(names, sizes)}
    t = Turbine(id="T", base=tuple(rng.uniform(-100, 100, 3)), hub_height=R + float(rng.uniform(5, 40)),
                rotor_diameter=2 * R, yaw_deg=float(rng.uniform(0, 360)),
                azimuths_deg=tuple(float(a) for a in rng.uniform(0, 360, blades)),
                blade_pitch_deg=pitch, **kw)
    P = np.vstack([t.hub_center + rng.normal(size=(300, 3)) * rng.uniform(0.5, 1.2 * R),
                   t.blade_tips() + rng.normal(size=(blades, 3)),
                   t.base_xyz + rng.uniform(-1, 1, (50, 3)) * [3, 3, t.hub_height],
                   t.nacelle_center + rng.normal(size=(20, 3))])
    ref = t.clearance_by_part(P, cap).min(axis=1)
    got = t.clearance(P, cap)
    c = np.inf if cap is None else cap
    low = (ref < c) | (got < c)
    assert np.allclose(got[low], ref[low], rtol=0, atol=1e-9)
    assert (got[~low] >= c).all() and (ref[~low] >= c).all()
    assert (got == 0).any() or (ref > 0).all()  # inside a part reads 0 in both


def test_compiled_clearance_of_a_nan_point_is_nan():
    """A NaN point never reads as a safe distance."""
    t = make_turbine(az=10.0, yaw=30.0)
    got = t.clearance(np.array([[np.nan, 0.0, 50.0], [0.0, 0.0, 500.0], [0.0, np.nan, np.nan]]))
    assert np.isnan(got[0]) and np.isnan(got[2]) and got[1] > 100.0


def test_a_tower_wider_at_the_top_is_still_bounded_from_below():
    """turbines.yaml allows a tower top wider than its base; the tower's cheap bound used the
    base radius alone and read 1.5 m for a point inside the top (found by the test above)."""
    t = make_turbine(az=0.0, yaw=0.0, tower_base_radius=1.0, tower_top_radius=3.0)
    p = t.base_xyz + [2.5, 0.0, t.tower_height - 1.0]  # inside the frustum near its top
    assert t.clearance(p[None])[0] == 0.0
    assert t.clearance(p[None], cap=6.0)[0] == 0.0
    assert t.clearance_by_part(p[None], cap=1.0)[0, t.part_names().index("tower")] == 0.0


def test_a_pickled_turbine_gives_the_kernels_the_same_types():
    """The planner's workers get turbines by pickle. Their cached frame arrays must come back
    read-only like the original's, or numba compiles a second version of every kernel in each
    worker (seconds, on a machine's first plan): the cache is not pickled, but rebuilt."""
    import pickle

    t = Turbine.with_rotor_azimuth(10.0, id="T", base=(0.0, 0.0, 0.0), hub_height=80.0,
                                   rotor_diameter=90.0, yaw_deg=0.0)
    P = t.hub_center + np.array([[0.0, -5.0, 0.0], [0.0, 0.0, -70.0]])
    want = t.clearance(P)
    u = pickle.loads(pickle.dumps(t))
    assert u == t and not u._cache
    np.testing.assert_array_equal(u.clearance(P), want)
    assert all(not a.flags.writeable for a in u._cache["kernel_params"])


def test_warm_up_calls_every_kernel():
    from wtcli.geometry import clearance_kernel, coverage_kernel
    from wtcli.plan import clearance_site_kernel
    from wtcli.warmup import warm_up

    assert warm_up() >= 0
    for k in (clearance_kernel.clearance, clearance_kernel.trace, coverage_kernel.near_pairs,
              clearance_site_kernel.clearance, clearance_site_kernel.near, clearance_site_kernel.segment_clearance,
              clearance_site_kernel.stretches, clearance_site_kernel.ground_index):
        assert k.signatures, k


def test_clearance_kernel_compiles_where_numba_cannot_cache(monkeypatch):
    """A read-only install without a writable cache folder: numba refuses cache=True at
    decoration; the kernel module then compiles without caching and gives the same values."""
    import importlib

    import numba

    from wtcli.geometry import clearance_kernel

    real = numba.njit

    def no_cache(*a, **kw):
        if kw.get("cache"):
            raise RuntimeError("cannot cache function: no locator available")
        return real(*a, **kw)

    t = make_turbine(az=20.0, yaw=50.0)
    P = t.hub_center + np.random.default_rng(3).normal(size=(200, 3)) * 30
    want = t.clearance(P, cap=6.0)
    monkeypatch.setattr(numba, "njit", no_cache)
    fresh = importlib.reload(clearance_kernel)
    try:
        vec, sc, frames = t._kernel_params()
        assert np.array_equal(fresh.clearance(np.ascontiguousarray(P), vec, sc, frames, 6.0), want)
    finally:
        monkeypatch.setattr(numba, "njit", real)
        importlib.reload(clearance_kernel)
