"""plan: zone/S_p (eq. 1-3), blade angles -> 3D, trajectories, safety, coverage, CLI, bad input."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from wtcli.errors import ConfigError, PlanError
from wtcli.geometry import Camera, Turbine
from wtcli.plan.config import Fleet, Mission, Settings, load_mission, mission_from_dict
from wtcli.plan.mission import plan_mission
from wtcli.plan.paths import yaw_pitch
from wtcli.plan.zone import (azimuths_from_image_directions, azimuths_from_pitch,
                             default_photo_camera, initial_point, zone)
from wtcli.plan_file import read_plan

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_images" / "turbines.yaml"
CAM = Camera(5456, 3632, 16, 23.2)


def make_turbine(az=90.0, yaw=0.0, tid="T1", base=(0, 0, 0), **kw):
    args = dict(id=tid, base=base, hub_height=80, rotor_diameter=90, yaw_deg=yaw)
    args.update(kw)
    return Turbine.with_rotor_azimuth(az, **args)


def assert_safe(plan, safe):
    """Independent check with the one turbine model: every waypoint and leg, every turbine."""
    for r in plan.routes:
        for t in plan.turbines:
            assert t.clearance(r.pos).min() >= safe
            assert t.segment_clearance(r.pos[:-1], r.pos[1:], step=0.5).min() >= safe


# ---- eq. 1-3 and back-projection ------------------------------------------------------------------
def test_zone_and_initial_point_known_answer():
    t = make_turbine(az=90, yaw=90)  # rotor faces east: the paper's +x
    z = zone(t)
    assert np.allclose(z.center, t.hub_center)  # evenly spaced tips average to the hub
    assert z.radius == pytest.approx(45.0)
    assert np.allclose(initial_point(t, z), t.hub_center + [45.0, 0, 0])  # S_p = (x+R, y, z)
    tips = np.array([[0, 0, 100.0], [0, 10, 60], [0, -10, 60]])  # measured tips (eq. 2 input)
    z2 = zone(t, tips)
    assert np.allclose(z2.center, [0, 0, 220 / 3])
    assert z2.radius == pytest.approx(max(np.linalg.norm(tips - z2.center, axis=1)))
    assert z2.contains(z2.center[None])[0]


@pytest.mark.parametrize("yaw", [0, 133, 270])
@pytest.mark.parametrize("az", [10, 95, 260])
def test_front_photo_angles_back_project_to_azimuths(yaw, az):
    t = make_turbine(az=az, yaw=yaw)
    cam = default_photo_camera(t, Camera(1280, 960, 16, 23.2))
    hub_uv, _ = cam.project(t.hub_center[None])
    phis = [cam.image_angle_deg(t.hub_center, tip) for tip in t.blade_tips()]
    got = azimuths_from_image_directions(t, cam, hub_uv[0], phis, [200, 200, 200])
    for g, w in zip(got, t.azimuths_deg):
        assert abs((g - w + 180) % 360 - 180) < 1e-3


def test_oblique_photo_back_projection_matches_ground_truth():
    """Sample renders are taken off-axis (with roll): the image angle φ is not the rotor azimuth,
    the back-projection through the photo's camera is."""
    gt = json.loads((ROOT / "sample_images" / "ground_truth.json").read_text())["images"]
    checked = 0
    for rec in gt.values():
        t = Turbine.from_dict(rec["turbine"])
        c = rec["camera"]
        cam = Camera(c["width_px"], c["height_px"], c["focal_mm"], c["sensor_width_mm"],
                     np.array(c["position"]), np.array(c["R"]))
        blades = [b for b in rec["blades"] if b["visible"]]
        if len(blades) < 3:
            continue
        lengths = [math.dist(b["tip_px"], rec["hub_px"]) for b in blades]
        got = azimuths_from_image_directions(t, cam, rec["hub_px"], [b["phi_deg"] for b in blades],
                                             lengths)
        naive_err, err = 0.0, 0.0
        for g, b in zip(got, blades):
            want = b["rotor_azimuth_deg"]
            err = max(err, abs((g - want + 180) % 360 - 180))
            naive_err = max(naive_err, abs((b["phi_deg"] - want + 180) % 360 - 180))
        assert err < 0.5, (err, naive_err)
        checked += 1
    assert checked >= 1


def test_azimuths_from_pitch_result_of_rendered_masks():
    from wtcli.geometry.projection import instance_masks
    from wtcli.masks import Instances
    from wtcli.pitch import pitch_from_instances

    t = make_turbine(az=33, yaw=220)
    cam = default_photo_camera(t, Camera(800, 600, 16, 23.2))
    inst = instance_masks(t, cam)
    res = pitch_from_instances(Instances(np.array([l for l, _, _ in inst], dtype=object),
                                         np.array([m for _, _, m in inst])), expected_blades=3)
    got = sorted(azimuths_from_pitch(t, res, CAM))
    for g, w in zip(got, sorted(t.azimuths_deg)):
        assert abs((g - w + 180) % 360 - 180) < 2.0


def test_yaw_pitch_is_what_the_camera_uses():
    for fwd in ([0, 1, 0], [1, 0, 0], [0.3, -0.2, -0.9], [-0.5, 0.5, 0.7]):
        f = np.array(fwd, float) / np.linalg.norm(fwd)
        R = Camera.rotation_from_yaw_pitch(*yaw_pitch(f))
        assert np.allclose(R[2], f, atol=1e-9)


# ---- planning ---------------------------------------------------------------------------------------
def side_coverage(plan, tid="T1"):
    return plan.summary["predicted_coverage"][tid]["by_blade_side"]


@pytest.mark.parametrize("az, yaw", [(270, 0), (257, 60)])
def test_blade_down_in_front_of_the_tower_covers_every_side(az, yaw):
    """Blade 1 straight down (and 13 deg off it): its trailing edge faces the tower, the gap is
    narrower than twice the clearance. Oblique passes plus extra views reach every side above
    the default min_side_coverage 0.9 (the trailing edge straight down reads ~92 % on the
    converged figure: the part facing the tower squarely is seen only beyond 60 deg)."""
    t = make_turbine(az=az, yaw=yaw)
    plan = plan_mission(Mission((t,), CAM))  # default min_side_coverage 0.9: not refused
    assert_safe(plan, 3.0)
    sides = side_coverage(plan)
    assert min(v for d in sides.values() for v in d.values()) >= 0.9, sides
    assert min(v for b, d in sides.items() if b != "blade1" for v in d.values()) >= 0.98, sides
    r = plan.routes[0]
    assert r.photo[r.component == "T1/blade1/trailing_edge"].sum() > 10


def test_horizontal_blade_covers_every_side_and_the_rest_stays_near_full():
    """Blade 1 horizontal and blade 3 at 240 deg (down-left) keep a patch of trailing edge at the
    root (2.7 and 3.1 % of that side on the converged figure; without a coverage floor no extra
    round of gap views goes after it: test_root_trailing_edge_miss_is_the_root_patch)."""
    t = make_turbine(az=0, yaw=0)
    plan = plan_mission(Mission((t,), CAM, settings=Settings(min_side_coverage=0.95)))
    assert_safe(plan, 3.0)
    sides = side_coverage(plan)
    assert min(sides["blade1"].values()) >= 0.96, sides["blade1"]
    assert min(sides["blade2"].values()) >= 0.96, sides["blade2"]
    assert min(sides["blade3"].values()) >= 0.96, sides["blade3"]
    assert plan.summary["predicted_coverage"]["T1"]["blade_average"] >= 0.995
    # Asking for more than the geometry allows is refused, naming the side and what blocks it.
    with pytest.raises(PlanError, match=r"blade\d trailing_edge: predicted coverage .* < "
                                        r"min_side_coverage 99.95%.*turn the rotor"):
        plan_mission(Mission((t,), CAM, settings=Settings(min_side_coverage=0.9995)))


def test_root_trailing_edge_miss_is_the_root_patch():
    """What the horizontal-blade plan misses (min_side_coverage 0: no extra rounds of gap views)
    is a patch of trailing edge within 5 m of the root, under 3.5 % of each side (the photos
    moved onto the arcs of rounded corners shift which extra views the search picks: 4.7 m on
    this turbine; 3 m with every corner a stop). On the converged figure a
    brute-force search (every direction within 59 deg of the normal, every distance within 2 %
    of the GSD, keeping safe distance + margin) finds safe, clear views of parts of it: the gap
    search's cap of views per blade stops short of them (docs/plan.md, Known limits)."""
    from wtcli.geometry.coverage import turbine_coverage
    from wtcli.plan.mission import _photos_of, pass_params

    t = make_turbine(az=0, yaw=0)
    m = Mission((t,), CAM, settings=Settings(min_side_coverage=0.0))
    plan = plan_mission(m)
    pp, gsd, _ = pass_params(m)
    pos, rot = _photos_of(t, plan.routes)
    cov = turbine_coverage(t, CAM, pos, rot, gsd, m.settings.coverage_spacing_m, 60.0, "blades")
    missed = cov.samples[~cov.covered]
    assert len(missed) >= 1
    assert (missed.span < 0.11).all()  # at the root: the trailing edge, and slivers where
    # the other sides enter the hub, which get no extra views once a side is predicted
    # above 99.5 % (mission.GAP_SIDE_BELOW)
    for b, sides in cov.by_blade_side().items():
        assert sides["trailing_edge"] >= 0.96, (b, sides)
        assert min(v for k, v in sides.items() if k != "trailing_edge") > 0.995, (b, sides)


@pytest.mark.slow
def test_worst_side_over_random_single_turbines():
    """16 random stops, yaws and sizes at the default settings (benchmarks/plan_coverage.py is
    the longer run), judged on the converged figure: every plan has each side at least
    min_side_coverage 0.9 and the worst side 95 % or more on average (96.8 % measured: the
    trailing edge's root patch at the nacelle); a turbine whose trailing edge the views cannot
    bring to 0.9 is refused naming the side (1 of the 16, at most 2 allowed)."""
    rng = np.random.default_rng(5)
    worst, refused = [], []
    for _ in range(16):
        D = float(rng.choice([90.0, 120.0, 150.0]))
        t = make_turbine(az=float(rng.uniform(0, 120)), yaw=float(rng.uniform(0, 360)),
                         hub_height=D / 2 + float(rng.uniform(15, 45)), rotor_diameter=D)
        try:
            plan = plan_mission(Mission((t,), CAM))
        except PlanError as e:
            assert "predicted coverage" in str(e) and "min_side_coverage 90%" in str(e), e
            refused.append(str(e))
            continue
        assert not any(plan.summary["violations"].values())
        worst.append(plan.summary["predicted_coverage"]["T1"]["min_side"])
    worst = np.array(worst)
    assert len(refused) <= 2, refused
    assert worst.min() >= 0.9, worst
    assert worst.mean() >= 0.95, worst


def test_trailing_edge_facing_the_tower_is_flown_round_not_refused():
    """A blade down-left in front of the tower at 6.5 m clearance: its trailing-edge pass has
    stations missing in the middle and the leg between them passes between blade and tower.
    It used to be refused ("no safe way between two trailing_edge stations"); now the pass goes
    round the blade on its free side."""
    t = make_turbine(az=10, yaw=98, hub_height=102, rotor_diameter=94)
    m = Mission((t,), CAM, settings=Settings(safe_distance_m=5.5, tracking_margin_m=1.0,
                                             target_gsd_mm=2.1, min_side_coverage=0.0))
    plan = plan_mission(m)
    assert_safe(plan, 5.5)
    assert plan.summary["predicted_coverage"]["T1"]["min_side"] >= 0.7


def test_single_turbine_plan_is_safe_covers_and_is_well_formed():
    t = make_turbine(az=80, yaw=60)
    m = Mission((t,), CAM)
    plan = plan_mission(m)
    s = plan.summary
    assert s["min_clearance_m"] >= m.settings.safe_distance_m
    assert not any(s["violations"].values())
    assert_safe(plan, m.settings.safe_distance_m)
    cov = s["predicted_coverage"]["T1"]
    assert cov["blade_average"] >= 0.98
    assert cov["min_side"] >= m.settings.min_side_coverage
    r = plan.routes[0]
    assert np.allclose(r.pos[0], r.pos[-1])  # take off and land at the launch point
    assert r.component[0] == "launch" and r.component[-1] == "return"
    assert (np.diff(r.t) >= 0).all() and r.photo.sum() == s["photos"]
    comps = set(r.component)
    for k in (1, 2, 3):
        for side in ("leading_edge", "trailing_edge", "pressure_side", "suction_side"):
            assert f"T1/blade{k}/{side}" in comps
    assert {"T1/tower", "T1/nacelle", "T1/overview", "transit"} <= comps
    for key in ("total_length_m", "total_time_s", "photos", "min_clearance_m", "per_uav",
                "per_component", "predicted_coverage"):
        assert key in s
    assert s["per_component"]["T1/blade1/leading_edge"]["photos"] > 10


def test_standoff_is_raised_to_the_safe_distance_and_gsd_reported():
    t = make_turbine(az=50)
    m = Mission((t,), CAM, settings=Settings(target_gsd_mm=1.0, min_side_coverage=0.0))
    plan = plan_mission(m)
    s = plan.summary
    assert s["standoff_m"] >= m.settings.required_clearance_m
    assert s["achieved_gsd_mm"] > 1.0 and plan.target_gsd_mm > 1.0
    with pytest.raises(PlanError, match="target_gsd_mm"):
        plan_mission(Mission((t,), CAM, settings=Settings(target_gsd_mm=1.0, allow_coarser_gsd=False)))


def test_fixed_y_baseline_is_reported_not_refused():
    t = make_turbine(az=30, yaw=0)  # a real stop far from a Y
    m = Mission((t,), CAM, settings=Settings(min_side_coverage=0.0))
    adaptive = plan_mission(m)
    fixed = plan_mission(m, pattern="fixed-y")
    assert fixed.turbines[0].azimuths_deg == t.azimuths_deg  # judged against the real rotor
    assert fixed.summary["pattern"] == "fixed-y"
    a = adaptive.summary["predicted_coverage"]["T1"]["blade_average"]
    f = fixed.summary["predicted_coverage"]["T1"]["blade_average"]
    assert f < a - 0.2
    with pytest.raises(PlanError):
        plan_mission(m, pattern="fixed-y", enforce_safety=True)


def test_azimuth_override_and_several_uavs_balance():
    ts = tuple(make_turbine(az=40 * i, yaw=15 * i, tid=f"T{i + 1}", base=(300.0 * i, 50.0 * (i % 2), 0))
               for i in range(4))
    m = Mission(ts, CAM, fleet=Fleet(uavs=("A", "B"), launch=(450.0, -150.0, 0.0)),
                settings=Settings(inspect_tower=False, inspect_nacelle=False, min_side_coverage=0.0))
    plan = plan_mission(m, azimuths={"T1": [90, 210, 330]})
    assert plan.turbine("T1").azimuths_deg == (90.0, 210.0, 330.0)
    per = plan.summary["per_uav"]
    assert sorted(sum((per[u]["turbines"] for u in per), [])) == ["T1", "T2", "T3", "T4"]
    times = [per[u]["time_s"] for u in ("A", "B")]
    assert max(times) < 1.6 * min(times)
    assert_safe(plan, 3.0)


def test_battery_limit_inserts_swaps_or_refuses():
    t = make_turbine(az=70)
    m = Mission((t,), CAM, fleet=Fleet(battery_minutes=9, battery_reserve_minutes=2),
                settings=Settings(min_side_coverage=0.0))
    plan = plan_mission(m)
    r = plan.routes[0]
    assert r.summary["battery_swaps"] >= 1
    at_launch = np.linalg.norm(r.pos - r.pos[0], axis=1) < 1e-6
    assert at_launch.sum() >= 3  # landed mid-mission to swap
    legs = np.split(np.arange(len(r)), np.nonzero(at_launch)[0])
    for idx in legs:
        if len(idx) > 1:
            assert r.t[idx[-1]] - r.t[idx[0]] <= 7 * 60 + 1e-6
    with pytest.raises(PlanError, match="battery"):
        plan_mission(Mission((t,), CAM, fleet=Fleet(battery_minutes=3, battery_reserve_minutes=1)))


def test_sorties_leave_the_wind_margin_and_the_reserve():
    """A sortie is planned to at most (battery - reserve) / (1 + wind_margin): flown that much
    longer in wind it still lands with the reserve. Without the margin the same battery flies
    fewer, fuller sorties; a component that fits the battery only without it is refused."""
    t = make_turbine(az=70)
    settings = Settings(min_side_coverage=0.0)
    plans = {m: plan_mission(Mission((t,), CAM, settings=settings,
                                     fleet=Fleet(battery_minutes=9, battery_reserve_minutes=2,
                                                 wind_margin=m)))
             for m in (0.0, 0.3)}
    for m, plan in plans.items():
        (r,) = plan.routes
        times = _sortie_times(r)
        assert max(times) <= 7 * 60 / (1 + m) + 1e-6
        assert plan.summary["wind_margin"] == m
    assert plans[0.3].routes[0].summary["sorties"] > plans[0.0].routes[0].summary["sorties"]
    # the longest component alone: fits 7 min, not 7 / 2 min
    longest = max(_sortie_times(plans[0.0].routes[0]))
    battery = 2 + 1.02 * longest / 60
    assert plan_mission(Mission((t,), CAM, settings=settings, fleet=Fleet(
        battery_minutes=battery, battery_reserve_minutes=2, wind_margin=0.0)))
    with pytest.raises(PlanError, match=r"wind_margin 1\b.*raise battery_minutes"):
        plan_mission(Mission((t,), CAM, settings=settings, fleet=Fleet(
            battery_minutes=battery / 2 + 1, battery_reserve_minutes=2, wind_margin=1.0)))
    with pytest.raises(ValueError, match="wind_margin"):
        Fleet(wind_margin=-0.1)


def test_launch_point_too_close_is_refused():
    t = make_turbine()
    with pytest.raises(PlanError, match="launch point"):
        plan_mission(Mission((t,), CAM, fleet=Fleet(launch=(1.0, 1.0, 0.0))))


@pytest.mark.parametrize("seed", range(3))
def test_property_clearance_quick(seed):
    _property_cases(seed, 6)


@pytest.mark.slow
def test_property_clearance_200():
    """200 random turbines, azimuths, yaws, sizes and fleets (about 4 min on 2 cores); the
    1000-case run is benchmarks/plan_property.py. A refusal (PlanError) is a legitimate answer
    and never unsafe, but it must stay rare."""
    refused = _property_cases(1000, 200)
    assert refused <= 0.15 * 200, f"{refused} of 200 random sites refused"


def _property_cases(seed: int, n: int) -> int:
    rng = np.random.default_rng(seed)
    refused = 0
    for _ in range(n):
        case = random_case(rng, gimbal=True)
        try:
            plan = plan_mission(case)
        except PlanError:
            refused += 1
            continue
        assert_safe(plan, case.settings.safe_distance_m)
        up = case.fleet.gimbal_pitch_max_deg
        assert all(r.gimbal_pitch_deg.max() <= up + 1e-9 for r in plan.routes)
    return refused


def random_case(rng: np.random.Generator, gimbal: bool = False) -> Mission:
    """A random site: 1-3 turbines (radius 20-75 m, any yaw and stop angle), 1-3 UAVs; with
    ``gimbal``, a third of them with a gimbal that looks up at most 20-60 deg (drawn last, so
    the site is the same either way)."""
    n = int(rng.integers(1, 4))
    ts = []
    for i in range(n):
        R = float(rng.uniform(20, 75))
        ts.append(Turbine.with_rotor_azimuth(
            float(rng.uniform(0, 360)), blades=(3, 2, 4, 1)[i % 4], id=f"T{i + 1}",
            base=(float(i * rng.uniform(2.5, 4) * 2 * R), float(rng.uniform(-50, 50)),
                  float(rng.uniform(0, 20))),
            hub_height=float(rng.uniform(R + 10, R + 60)), rotor_diameter=2 * R,
            yaw_deg=float(rng.uniform(0, 360)), blade_pitch_deg=float(rng.choice([90.0, rng.uniform(60, 90)]))))
    uavs = tuple(f"U{k}" for k in range(int(rng.integers(1, 4))))
    settings = Settings(safe_distance_m=float(rng.uniform(2.5, 6)),
                        tracking_margin_m=float(rng.uniform(0, 1.5)),
                        target_gsd_mm=float(rng.uniform(1.2, 2.5)),
                        min_side_coverage=0.0, coverage_spacing_m=2.0)
    up = float(rng.choice([90.0, 90.0, rng.uniform(20, 60)])) if gimbal else 90.0
    return Mission(tuple(ts), CAM, fleet=Fleet(uavs=uavs, gimbal_pitch_max_deg=up), settings=settings)


# ---- the site's culled clearance ---------------------------------------------------------------------
def _odd_site(rng: np.random.Generator, n: int):
    """n turbines a few hundred metres apart, boxes overlapping; every third with odd part sizes
    (a wide chord, a tiny nacelle and hub, a thick tower); one to four blades (the compiled site
    query stacks turbines of different blade counts)."""
    from wtcli.plan.clearance import Site

    ts = []
    for i in range(n):
        R = float(rng.uniform(20, 60))
        odd = (dict(blade_max_chord=0.2 * R, nacelle_length=1.0, hub_radius=1.0, tower_base_radius=5.0)
               if i % 3 == 2 else {})
        ts.append(Turbine.with_rotor_azimuth(
            float(rng.uniform(0, 360)), blades=(3, 2, 4, 1)[i % 4], id=f"T{i + 1}",
            base=(float(rng.uniform(-250, 250)), float(rng.uniform(-250, 250)), float(rng.uniform(0, 20))),
            hub_height=float(rng.uniform(R + 5, R + 50)), rotor_diameter=2 * R,
            yaw_deg=float(rng.uniform(0, 360)), blade_pitch_deg=float(rng.uniform(60, 90)), **odd))
    return Site(ts, launch=np.array([-300.0, -300.0, 0.0]))


def _probe_points(site, rng: np.random.Generator, cap: float | None, m: int) -> np.ndarray:
    """Random points, points near the rotors, and points exactly on the borders: corners and
    faces of every culling box (grown by the horizon, and the part boxes by the cap's cull
    distance) and the grid's cell borders."""
    P = [rng.uniform(site.lo.min(axis=0) - 30, site.hi.max(axis=0) + 30, (m, 3))]
    P += [t.hub_center + rng.normal(0, 0.6 * t.tip_radius, (m // 4, 3)) for t in site.turbines]
    g = site.horizon if cap is None else site.cull_distance(cap)
    boxes = list(zip(site.lo, site.hi)) + list(zip((site.part_lo - g).reshape(-1, 3),
                                                   (site.part_hi + g).reshape(-1, 3)))
    for lo, hi in boxes:
        P.append(np.array([[(lo, hi)[(c >> a) & 1][a] for a in range(3)] for c in range(8)]))
        face = rng.uniform(lo, hi, (6, 3))
        face[np.arange(6), np.arange(6) % 3] = np.r_[lo, hi]
        P.append(face)
    k = np.arange(int(site._shape.max()) + 2)
    edge = rng.uniform(site.lo.min(axis=0), site.hi.max(axis=0), (len(k), 3))
    edge[:, 0] = site._origin[0] + k * site._cell
    edge2 = edge.copy()
    edge2[:, :2] = site._origin + k[:, None] * site._cell
    return np.vstack(P + [edge, edge2])


def _every_turbine(site, P: np.ndarray, cap: float | None) -> np.ndarray:
    """The model's clearance to every turbine, no culling, capped at the horizon."""
    c = site.horizon if cap is None else cap
    return np.minimum.reduce([t.clearance(P, cap=c) for t in site.turbines] + [np.full(len(P), site.horizon)])


def _check_site(site, rng: np.random.Generator, m: int) -> None:
    from wtcli.geometry.turbine import segment_lower_bound
    from wtcli.plan.clearance import enclosing_box, part_boxes

    for t in site.turbines:  # the boxes hold the whole turbine (its surface, hence the solid)
        S = t.surface_samples(1.0).points
        lo, hi = enclosing_box(t)
        assert ((S >= lo) & (S <= hi)).all()
        plo, phi = part_boxes(t)
        assert ((S[:, None] >= plo) & (S[:, None] <= phi)).all(axis=2).any(axis=1).all()
    for cap in (None, 4.5):
        P = _probe_points(site, rng, cap, m)
        # The grid finds exactly the points each grown box holds.
        for idx, lo, hi in zip(site.near(P), site.lo, site.hi):
            assert np.array_equal(idx, np.nonzero(((P >= lo) & (P <= hi)).all(axis=1))[0])
        got, ref = site.clearance(P, cap), _every_turbine(site, P, cap)
        exact_below = site.horizon * site._taper_min if cap is None else cap
        low = ref < exact_below
        assert np.array_equal(got[low], ref[low]), "exact below the cap"
        assert (got[~low] >= min(exact_below, site.horizon) - 1e-12).all()
        assert (got <= site.horizon).all()
        if cap is None:  # the culled turbines' model distance is only dropped, never lowered
            assert (got >= ref).all()
        # A lower bound of the true distance: never more than the distance to a surface point.
        Q = P[rng.choice(len(P), 300, replace=False)]
        surface = np.vstack([t.surface_samples(1.0).points for t in site.turbines])
        nearest = np.array([np.linalg.norm(surface - q, axis=1).min() for q in Q])
        assert (site.clearance(Q, cap) <= nearest + 1e-9).all()
        # Legs: only the samples inside a box are evaluated, with the same result as all of them.
        Q0 = P[rng.permutation(len(P))[:400]]
        Q1 = Q0 + rng.normal(0, 1, Q0.shape) * rng.choice([0.0, 0.3, 4.0, 60.0, 500.0], (len(Q0), 1))
        Q1[::5, 1:] = Q0[::5, 1:]  # along x only, from a border
        legs = site.segment_clearance(Q0, Q1, 0.5, cap)
        assert np.array_equal(legs, segment_lower_bound(lambda X: site.clearance(X, cap), Q0, Q1, 0.5))
    for x in P[::40]:  # the nearest part, searched nearest box first, is the whole site's
        best = ("nothing", np.inf)
        for t in site.turbines:
            c = t.clearance_by_part(x[None])[0]
            if c.min() < best[1]:
                best = (f"{t.id} {t.part_names()[int(np.argmin(c))]}", float(c.min()))
        assert site.nearest_part(x) == best


def test_site_culled_clearance_is_exact_below_the_cap_and_a_lower_bound():
    rng = np.random.default_rng(5)
    for n in (1, 3, 7):
        _check_site(_odd_site(rng, n), rng, 600)


@pytest.mark.slow
def test_site_culled_clearance_many_sites():
    rng = np.random.default_rng(6)
    for _ in range(25):
        _check_site(_odd_site(rng, int(rng.integers(1, 12))), rng, 2000)


# ---- turbines.yaml --------------------------------------------------------------------------------------
def test_sample_yaml_loads_and_converts_lat_lon(tmp_path):
    m = load_mission(SAMPLE)
    assert [t.id for t in m.turbines] == ["T1", "T2"]
    assert m.site_origin["lat"] == pytest.approx(53.5511)
    assert m.turbine("T1").azimuths_deg == (80.0, 200.0, 320.0)
    d = {"site": {"origin": {"lat": 50.0, "lon": 8.0, "alt": 100}},
         "turbines": [{"id": "A", "lat": 50.001, "lon": 8.0, "alt": 100, "hub_height_m": 80,
                       "rotor_diameter_m": 90, "yaw_deg": 0}]}
    m2 = mission_from_dict(d)
    assert m2.turbine("A").base[1] == pytest.approx(111.2, abs=0.5)  # 0.001 deg of latitude


@pytest.mark.parametrize("patch, message", [
    ({"mission": {"safe_distnce_m": 3}}, "did you mean 'safe_distance_m'"),
    ({"mission": {"safe_distance_m": -1}}, r"mission.safe_distance_m: expected a number in \[0.5, 100\], got -1"),
    ({"fleet": {"uavs": 0}}, "fleet.uavs: expected a count in"),
    ({"turbines": []}, "expected a non-empty list"),
    ({"turbines": [{"id": "X", "position": [0, 0, 0], "hub_height_m": 80, "rotor_diameter_m": 90,
                    "yaw_deg": 400}]}, r"turbines\[0\].yaw_deg: expected a number in \[0, 360\], got 400"),
    ({"turbines": [{"id": "X", "position": [0, 0, 0], "hub_height_m": 40, "rotor_diameter_m": 90,
                    "yaw_deg": 0}]}, "hub_height"),
    ({"turbines": [{"id": "X", "lat": 1, "lon": 2, "hub_height_m": 80, "rotor_diameter_m": 90,
                    "yaw_deg": 0}]}, "needs site.origin"),
    ({"turbines": [{"id": "X", "position": [0, 0, 0], "hub_height_m": 80, "rotor_diameter_m": 90,
                    "yaw_deg": 0, "blade_azimuths_deg": [1, 2]}]}, "expected a list of 3 angles"),
    ({"turbines": [{"id": "X", "position": [0, 0, 0], "hub_hieght_m": 80}]}, "did you mean 'hub_height_m'"),
    ({"fleet": {"gimbal_pitch_max_deg": 120}}, r"fleet.gimbal_pitch_max_deg: expected a number in \[0, 90\], got 120"),
    ({"fleet": {"gimbal_pitch_min_deg": 10}}, r"fleet.gimbal_pitch_min_deg: expected a number in \[-90, 0\]"),
    ({"fleet": {"gimbal_pitch_max": 30}}, "did you mean 'gimbal_pitch_max_deg'"),
    ({"fleet": {"uavs": ["A", "../../etc/x"]}}, r"fleet.uavs\[1\]: expected an id .* got '../../etc/x'"),
    ({"fleet": {"uavs": [".."]}}, r"fleet.uavs\[0\]: expected an id"),
    ({"fleet": {"wind_margin": -0.1}}, r"fleet.wind_margin: expected a number in \[0, 1\], got -0.1"),
    ({"fleet": {"wind_margin": float("nan")}}, r"fleet.wind_margin: expected a number"),
])
def test_bad_yaml_names_key_value_and_range(patch, message):
    base = {"turbines": [{"id": "T1", "position": [0, 0, 0], "hub_height_m": 80,
                          "rotor_diameter_m": 90, "yaw_deg": 0}]}
    base.update(patch)
    with pytest.raises(ConfigError, match=message):
        mission_from_dict(base, where="t.yaml")


def test_measured_tips_set_zone_and_azimuths():
    t = make_turbine(az=64, yaw=123)
    d = {"turbines": [{"id": "T1", "position": [0, 0, 0], "hub_height_m": 80, "rotor_diameter_m": 90,
                       "yaw_deg": 123, "blade_tips": t.blade_tips().tolist()}]}
    m = mission_from_dict(d)
    assert m.extra("T1").azimuth_source == "tips"
    assert np.allclose(sorted(m.turbine("T1").azimuths_deg), sorted(t.azimuths_deg), atol=1e-6)


# ---- CLI ---------------------------------------------------------------------------------------------------
def test_cli_plan_sample_writes_plan_exports_and_picture(cli, tmp_path):
    out = tmp_path / "plan.json"
    r = cli("plan", SAMPLE, "--out", out, "--export-dir", tmp_path / "exp", "--picture",
            tmp_path / "plan.png")
    assert r.exit_code == 0, r.output
    plan = read_plan(out)
    assert len(plan.turbines) == 2 and plan.site_origin
    assert (tmp_path / "plan.png").stat().st_size > 1000
    assert sorted(p.suffix for p in (tmp_path / "exp").iterdir()).count(".waypoints") >= 1


def test_cli_plan_for_an_underslung_gimbal_says_so_and_exports_within_it(cli, tmp_path):
    y = tmp_path / "t.yaml"
    y.write_text(SAMPLE.read_text().replace("  battery_reserve_minutes: 5\n",
                                            "  battery_reserve_minutes: 5\n  gimbal_pitch_max_deg: 30\n"))
    r = cli("plan", y, "--out", tmp_path / "p.json", "--export-dir", tmp_path / "exp")
    assert r.exit_code == 0, r.output
    assert "gimbal pitch within [-90, +30] deg" in r.output
    plan = read_plan(tmp_path / "p.json")
    assert max(float(rt.gimbal_pitch_deg.max()) for rt in plan.routes) <= 30.0
    # MAVLink DO_MOUNT_CONTROL (205): p1 is the gimbal pitch the UAV is told to take.
    rows = [ln.split("\t") for f in (tmp_path / "exp").glob("*.waypoints")
            for ln in f.read_text().splitlines()[1:]]
    pitches = [float(c[4]) for c in rows if c[3] == "205"]
    assert pitches and max(pitches) <= 30.0


def test_cli_reexport_replaces_the_earlier_set_and_says_so(cli, tmp_path):
    """A plan of 3 sorties (18 min battery), then the sample's plan of 2 into the same folder:
    only the second plan's files are left, and stderr says what was replaced and removed."""
    y = tmp_path / "short.yaml"
    y.write_text(SAMPLE.read_text().replace("battery_minutes: 30", "battery_minutes: 18"))
    exp = tmp_path / "exp"
    exp.mkdir()
    (exp / "notes.txt").write_text("the user's\n")
    r = cli("plan", y, "--out", tmp_path / "plan.json", "--export-dir", exp, "--dji-kmz", "m30")
    assert r.exit_code == 0, r.output
    first = sorted(p.name for p in exp.iterdir())
    assert "plan_UAV1_s3.kmz" in first
    r = cli("plan", SAMPLE, "--out", tmp_path / "plan.json", "--export-dir", exp)
    assert r.exit_code == 0, r.output
    names = sorted(p.name for p in exp.iterdir())
    assert names == ["notes.txt", "plan.geojson", "plan_UAV1_s1.plan", "plan_UAV1_s1.waypoints",
                     "plan_UAV1_s2.plan", "plan_UAV1_s2.waypoints"]
    line, = [ln for ln in r.stderr.splitlines() if ln.startswith("exports:")]
    assert line == (f"exports: 5 file(s) -> {exp} (replaced the earlier export of plan: "
                    f"{len(first) - 1} file(s); removed 5 this plan has not: plan_UAV1_s1.kmz, "
                    "plan_UAV1_s2.kmz, plan_UAV1_s3.kmz and 2 more)")


def test_cli_a_failed_export_leaves_the_earlier_plan_with_its_export(cli, tmp_path):
    """The plan JSON is written only once the export is staged: an export refused part-way (a
    folder in the way of one sortie file) leaves the earlier plan.json and its set together,
    not the new plan beside the earlier plan's sorties."""
    y = tmp_path / "short.yaml"
    y.write_text(SAMPLE.read_text().replace("battery_minutes: 30", "battery_minutes: 18"))
    exp, out = tmp_path / "exp", tmp_path / "plan.json"
    r = cli("plan", y, "--out", out, "--export-dir", exp)
    assert r.exit_code == 0, r.output
    (exp / "plan_UAV1_s1.plan").unlink()
    (exp / "plan_UAV1_s1.plan").mkdir()  # in the way of the new plan's first sortie
    before = {p.name: p.read_bytes() for p in [out, *exp.iterdir()] if p.is_file()}
    r = cli("plan", SAMPLE, "--out", out, "--export-dir", exp)
    assert r.exit_code == 3, r.output
    assert "plan_UAV1_s1.plan: cannot write (a folder is in the way)" in r.stderr
    after = {p.name: p.read_bytes() for p in [out, *exp.iterdir()] if p.is_file()}
    assert after == before, "the earlier plan.json and its export, as they were"
    assert len(read_plan(out).routes[0].pos) > 0


def test_cli_export_removes_the_staging_folder_a_killed_run_left(cli, tmp_path):
    """A SIGKILL mid-export leaves its hidden staging folder: the next export into the folder
    removes it when its owner is a dead process of this host, and keeps a live or foreign one."""
    import os
    import signal
    import socket
    import subprocess
    import sys

    from wtcli.plan.exports import OWNER_FILE, STAGING_PREFIX

    exp = tmp_path / "exp"
    exp.mkdir()
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        owners = {"dead": None, "live": (socket.gethostname(), os.getpid()),
                  "foreign": ("another-host.example", 1), "unowned": None}
        child.send_signal(signal.SIGKILL)
        child.wait()
        owners["dead"] = (socket.gethostname(), child.pid)
        for name, owner in owners.items():
            d = exp / f"{STAGING_PREFIX}{name}"
            d.mkdir()
            (d / "plan_UAV1_s1.plan").write_text("half\n")
            if owner:
                (d / OWNER_FILE).write_text(f"{owner[0]}\n{owner[1]}\n")
    finally:
        child.kill()
    r = cli("plan", SAMPLE, "--out", tmp_path / "plan.json", "--export-dir", exp)
    assert r.exit_code == 0, r.output
    left = sorted(p.name for p in exp.iterdir() if p.name.startswith(STAGING_PREFIX))
    assert left == [f"{STAGING_PREFIX}{n}" for n in ("foreign", "live", "unowned")]
    assert f"exports: removed {exp / (STAGING_PREFIX + 'dead')}, a staging folder a killed run left" \
        in r.stderr


def test_cli_a_users_geojson_under_the_maps_name_is_refused_before_planning(cli, tmp_path):
    exp = tmp_path / "exp"
    exp.mkdir()
    (exp / "plan.geojson").write_text('{"type": "FeatureCollection", "features": []}')
    r = cli("plan", SAMPLE, "--out", tmp_path / "plan.json", "--export-dir", exp)
    assert r.exit_code == 3, r.output
    assert f"{exp / 'plan.geojson'}: is not the map of an earlier wtinspect export" in r.stderr
    assert "blade azimuths" not in r.stderr and not (tmp_path / "plan.json").exists()
    assert sorted(p.name for p in exp.iterdir()) == ["plan.geojson"]


def test_cli_export_names_over_the_limit_are_refused_before_planning(cli, tmp_path):
    out = tmp_path / ("p" * 240 + ".json")
    r = cli("plan", SAMPLE, "--out", out, "--export-dir", tmp_path / "exp")
    assert r.exit_code == 3, r.output
    assert "_UAV1_s999.waypoints: the export's file names would be over the 255-byte limit" in r.stderr
    assert "blade azimuths" not in r.stderr and not out.exists()


def test_cli_json_is_one_document(cli):
    r = cli("plan", SAMPLE, "--json")
    assert r.exit_code == 0
    doc = json.loads(r.stdout)
    assert doc["schema"] == "wtinspect.plan" and doc["summary"]["photos"] > 0


def _pitch_image(t, cam=None):
    """A pitch-JSON image record of turbine ``t`` photographed from S_p (ground-truth masks)."""
    from wtcli.geometry.projection import instance_masks
    from wtcli.masks import Instances
    from wtcli.pitch import pitch_from_instances

    cam = cam or default_photo_camera(t, Camera(800, 600, 16, 23.2))
    inst = instance_masks(t, cam)
    res = pitch_from_instances(Instances(np.array([l for l, _, _ in inst], dtype=object),
                                         np.array([x for _, _, x in inst])), expected_blades=3)
    return {**res.to_dict(), "error": None}


def test_cli_pitch_json_input_sets_azimuths(cli, tmp_path):
    import dataclasses

    from wtcli.jsonio import document, write_json
    from wtcli.pitch import PITCH_SCHEMA, PITCH_VERSION

    m = load_mission(SAMPLE)
    t = m.turbine("T2")
    img = _pitch_image(t)
    pj = tmp_path / "t2_pitch.json"
    write_json(pj, document(PITCH_SCHEMA, PITCH_VERSION, {"images": [img]}))
    out = tmp_path / "plan.json"
    r = cli("plan", SAMPLE, f"T2={pj}", "--out", out)
    assert r.exit_code == 0, r.output
    got = sorted(read_plan(out).turbine("T2").azimuths_deg)
    for g, w in zip(got, sorted(t.azimuths_deg)):
        assert abs((g - w + 180) % 360 - 180) < 2.0
    sources = {tid: z["azimuth_source"] for tid, z in read_plan(out).summary["turbines"].items()}
    assert sources == {"T1": "yaml", "T2": "photo"}  # was "yaml" for the photo's turbine too

    def rotated(deg):
        return dataclasses.replace(t, azimuths_deg=tuple(a + deg for a in t.azimuths_deg))

    # Two photos of one rotor are combined: 3 deg either side of the truth average back to it.
    two = tmp_path / "two.json"
    write_json(two, document(PITCH_SCHEMA, PITCH_VERSION,
                             {"images": [_pitch_image(rotated(3.0)), _pitch_image(rotated(-3.0))]}))
    r = cli("plan", SAMPLE, f"T2={two}", "--out", tmp_path / "p2.json")
    assert r.exit_code == 0, r.output
    assert "2 images" in r.output and "averaged" in r.output
    got = sorted(read_plan(tmp_path / "p2.json").turbine("T2").azimuths_deg)
    for g, w in zip(got, sorted(t.azimuths_deg)):
        assert abs((g - w + 180) % 360 - 180) < 1.0
    # ... but photos of a rotor that turned 20 deg between them are refused, naming both.
    moved = tmp_path / "moved.json"
    write_json(moved, document(PITCH_SCHEMA, PITCH_VERSION,
                               {"images": [img, _pitch_image(rotated(20.0))]}))
    r = cli("plan", SAMPLE, f"T2={moved}", "--out", tmp_path / "p3.json")
    assert r.exit_code == 5 and "disagree by" in r.output, r.output
    assert not (tmp_path / "p3.json").exists()


def test_cli_bad_inputs_exit_codes(cli, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("turbines:\n  - id: T1\n    positon: [0, 0, 0]\n")
    r = cli("plan", bad)
    assert r.exit_code == 4 and "did you mean 'position'" in r.output
    assert cli("plan", tmp_path / "missing.yaml").exit_code == 3  # missing input file
    assert cli("plan", SAMPLE, "--pattern", "spiral").exit_code == 4
    assert cli("plan", SAMPLE, "T1=" + str(tmp_path / "nope.json")).exit_code == 3
    tight = tmp_path / "tight.yaml"
    tight.write_text(SAMPLE.read_text().replace("battery_minutes: 30", "battery_minutes: 6"))
    r = cli("plan", tight)
    assert r.exit_code == 6 and "battery" in r.output


def test_worker_processes_give_the_same_plan():
    ts = tuple(make_turbine(az=25 * i, yaw=40 * i, tid=f"T{i + 1}", base=(250.0 * i, 0, 0))
               for i in range(2))
    m = Mission(ts, CAM, settings=Settings(inspect_tower=False, min_side_coverage=0.0))
    seen: dict[int, list] = {1: [], 2: []}
    a, b = (plan_mission(m, workers=w, progress=lambda *x, w=w: seen[w].append(x)) for w in (1, 2))
    assert np.array_equal(a.routes[0].pos, b.routes[0].pos)
    assert a.summary["predicted_coverage"] == b.summary["predicted_coverage"]
    # The progress reports: every stage in order, each counted from 0 to its total, one by one.
    from wtcli.plan.mission import STAGES

    assert seen[1] == seen[2]
    assert [st for st, done, _ in seen[1] if done == 0] == list(STAGES)
    for st in STAGES:
        counts = [(done, total) for s_, done, total in seen[1] if s_ == st]
        total = counts[0][1]
        assert counts == [(i, total) for i in range(total + 1)]
    assert dict((st, total) for st, _, total in seen[1])["turbines"] == 2
    # One process holds one turbine's coverage memos at a time (a site's worth: 2.9 GB at 100).
    assert not [k for t in m.turbines for k in t._cache
                if isinstance(k, tuple) and k and k[0] == "coverage_cells"]


def test_every_turbine_short_of_coverage_is_named_at_once():
    """A site is planned once: the refusal names the first turbine short of min_side_coverage
    with its why, and every other one short, not one per run of the whole site."""
    ts = tuple(make_turbine(az=25 * i, yaw=40 * i, tid=f"T{i + 1}", base=(250.0 * i, 0, 0))
               for i in range(3))
    m = Mission(ts, CAM, settings=Settings(inspect_tower=False, min_side_coverage=0.9999))
    with pytest.raises(PlanError) as e:
        plan_mission(m, workers=1)
    said = str(e.value)
    assert said.startswith("turbine T1 blade") and "< min_side_coverage 99.99%" in said
    assert said.endswith("(2 more turbine(s) short too: T2, T3)")


def test_a_turbine_too_far_from_the_launch_point_says_so():
    """On a wide site the battery is spent flying out and back: the refusal says how much of
    the sortie that is and to launch nearer, not only to raise the battery."""
    ts = (make_turbine(az=0, tid="T1", base=(0.0, 0, 0)),
          make_turbine(az=0, tid="T2", base=(5200.0, 0, 0)))
    m = Mission(ts, CAM, settings=Settings(inspect_tower=False, min_side_coverage=0.0))
    with pytest.raises(PlanError, match=r"T2 \S+ takes [0-9.]+ min from take-off to landing, more "
                       r"than one battery allows \(.*\); [0-9.]+ min of it is the flight to and "
                       r"from the launch point 5\.[0-9] km away: launch nearer \(fleet\.launch\)"):
        plan_mission(m, workers=1)


def test_photo_azimuths_not_spread_like_a_rotor_are_refused():
    """A merged or missed blade must never become a plan around blades that are not there."""
    from wtcli.errors import PerceptionError
    from wtcli.plan.angles import check_rotor_spacing

    check_rotor_spacing([16.7, 135.4, 252.5], "ok")
    check_rotor_spacing([350.0, 112.0, 228.0], "ok")  # wraps around 0
    with pytest.raises(PerceptionError, match="not spread like a 3-blade rotor"):
        check_rotor_spacing([134.4, 135.1, 11.8], "photo.jpg: turbine T1")
    with pytest.raises(PerceptionError, match="2-blade"):
        check_rotor_spacing([10.0, 100.0], "x")


def test_combine_azimuths_wraps_and_matches_blades():
    from wtcli.errors import PerceptionError
    from wtcli.plan.angles import combine_azimuths

    # Blade order differs and angles straddle 0/360: matched by nearest angle, averaged on the circle.
    got = combine_azimuths([[358.0, 118.0, 238.0], [242.0, 2.0, 122.0]], ["a", "b"], "T1")
    assert np.allclose(got, [0.0, 120.0, 240.0])
    assert combine_azimuths([[10.0, 130.0, 250.0]], ["a"], "T1") == [10.0, 130.0, 250.0]
    with pytest.raises(PerceptionError, match="a and c disagree by 12.0 deg"):
        combine_azimuths([[10.0, 130.0, 250.0], [11.0, 131.0, 251.0], [22.0, 142.0, 262.0]],
                         ["a", "b", "c"], "T1")


def test_complete_rotor_infers_the_missing_blade_or_refuses():
    from wtcli.errors import PerceptionError
    from wtcli.plan.angles import complete_rotor

    az, inferred = complete_rotor([10.0, 130.0], 3, "x")
    assert inferred == pytest.approx(250.0) and az[:2] == [10.0, 130.0]
    _, inferred = complete_rotor([355.0, 233.0], 3, "x")  # wraps; 2 deg off even, split evenly
    assert inferred == pytest.approx(114.0)
    _, inferred = complete_rotor([0.0, 90.0, 180.0], 4, "x")
    assert inferred == pytest.approx(270.0)
    with pytest.raises(PerceptionError, match="not spaced like blades of a 3-blade rotor"):
        complete_rotor([10.0, 80.0], 3, "photo.jpg: turbine T1")  # 70 deg apart: no rotor
    with pytest.raises(PerceptionError, match="not spaced"):
        complete_rotor([10.0, 14.0], 3, "x")  # one blade twice, same slot
    with pytest.raises(ValueError):
        complete_rotor([10.0], 3, "x")


def test_cli_photo_missing_one_blade_plans_with_the_inferred_blade(cli, tmp_path):
    """A pitch result with one blade of three (say the segmenter missed one) still plans: the
    third blade is where the other two leave room, and the output says it was inferred."""
    from wtcli.jsonio import document, write_json
    from wtcli.pitch import PITCH_SCHEMA, PITCH_VERSION

    m = load_mission(SAMPLE)
    t = m.turbine("T2")
    img = _pitch_image(t)
    for drop in range(3):
        short = {**img, "blades": [b for i, b in enumerate(img["blades"]) if i != drop],
                 "n_blades": 2}
        pj = tmp_path / f"short{drop}.json"
        write_json(pj, document(PITCH_SCHEMA, PITCH_VERSION, {"images": [short]}))
        out = tmp_path / f"plan{drop}.json"
        r = cli("plan", SAMPLE, f"T2={pj}", "--out", out)
        assert r.exit_code == 0, r.output
        said = " ".join(r.output.split())  # the console wraps long lines
        assert "2 of 3 blades found" in said and "inferred from the rotor's even spacing" in said
        got = sorted(read_plan(out).turbine("T2").azimuths_deg)
        for g, w in zip(got, sorted(t.azimuths_deg)):
            assert abs((g - w + 180) % 360 - 180) < 2.0
    # One blade of three is not enough to infer two.
    one = {**img, "blades": img["blades"][:1], "n_blades": 1}
    write_json(tmp_path / "one.json", document(PITCH_SCHEMA, PITCH_VERSION, {"images": [one]}))
    r = cli("plan", SAMPLE, f"T2={tmp_path / 'one.json'}", "--out", tmp_path / "p1.json")
    assert r.exit_code == 5 and "found 1 blade(s)" in r.output
    assert not (tmp_path / "p1.json").exists()


def test_cli_photo_with_a_blade_missed_by_the_segmenter_still_plans(cli, tmp_path, monkeypatch):
    """The photo path (segment -> contours -> pitch inside plan) keeps a result one blade short
    for the rotor completion; the segmenter is stood in for by the true masks less one blade."""
    import cv2

    from wtcli.geometry.projection import instance_masks
    from wtcli.masks import Instances
    from wtcli.segment import infer

    m = load_mission(SAMPLE)
    t = m.turbine("T2")
    cam = default_photo_camera(t, Camera(800, 600, 16, 23.2))
    inst = instance_masks(t, cam)
    keep = [i for i, (label, _, _) in enumerate(inst) if label != "blade"] + \
        [i for i, (label, _, _) in enumerate(inst) if label == "blade"][1:]
    short = Instances(np.array([inst[i][0] for i in keep], dtype=object),
                      np.array([inst[i][2] for i in keep]))
    monkeypatch.setattr(infer, "segment_image", lambda image, **kw: short)
    photo = tmp_path / "t2.png"
    cv2.imwrite(str(photo), np.full((600, 800, 3), 200, np.uint8))
    r = cli("plan", SAMPLE, f"T2={photo}", "--out", tmp_path / "plan.json")
    assert r.exit_code == 0, r.output
    assert "2 of 3 blades found" in " ".join(r.output.split())
    got = sorted(read_plan(tmp_path / "plan.json").turbine("T2").azimuths_deg)
    for g, w in zip(got, sorted(t.azimuths_deg)):
        assert abs((g - w + 180) % 360 - 180) < 2.0


@pytest.mark.parametrize("layout", ["grid", "cluster_and_far_launch", "duplicates"])
def test_site_ground_z_is_the_nearest_base_as_by_comparing_all(layout):
    """Site.ground_z finds the nearest ground point through a grid of cells; it must pick the
    same point as comparing every one (the first of equally near ones), wherever the query is."""
    from wtcli.plan.clearance import Site

    rng = np.random.default_rng(3)
    if layout == "grid":
        xy = [(400.0 * (i % 6), 400.0 * (i // 6)) for i in range(30)]
    elif layout == "cluster_and_far_launch":
        xy = [tuple(rng.uniform(-300, 300, 2)) for _ in range(25)]
    else:  # bases on top of each other and on cell edges: ties
        xy = [(100.0 * (i % 5), 100.0 * (i // 5 % 3)) for i in range(30)]
    ts = [make_turbine(tid=f"T{i}", base=(x, y, float(rng.uniform(0, 30)))) for i, (x, y) in enumerate(xy)]
    site = Site(ts, launch=np.array([5000.0, -2000.0, 7.0]))
    lo, hi = site.ground_points[:, :2].min(axis=0) - 800, site.ground_points[:, :2].max(axis=0) + 800
    P = np.c_[rng.uniform(lo, hi, (4000, 2)), rng.uniform(0, 200, 4000)]
    P = np.r_[P, site.ground_points + [0, 0, 50], [[5000.0, -2000.0, 60.0], [-1e5, 3e4, 10.0]],
              np.c_[np.round(P[:200, :2] / 50) * 50, P[:200, 2]],  # on cell edges, far away
              [[np.nan, 0.0, 10.0], [0.0, np.inf, 10.0]]]  # what argmin makes of those: the first
    d = np.linalg.norm(P[:, None, :2] - site.ground_points[None, :, :2], axis=2)
    want = site.ground_points[np.argmin(d, axis=1), 2]
    assert np.array_equal(site.ground_z(P), want)


# ---- legs over uneven ground ----------------------------------------------------------------------
def _hilly_site():
    """Three turbines in a row, the middle one's base 40 m higher: a straight leg between the
    low ones, or back to the launch point, runs into the high base's ground."""
    return tuple(make_turbine(az=30.0 * i, tid=f"T{i + 1}", base=(400.0 * i, 0.0, 40.0 * (i == 1)))
                 for i in range(3))


def test_a_point_tucked_under_the_nacelle_is_connected_along_a_direction_no_escape_names(
        monkeypatch):
    """The top of a tower column (16 mm lens, 5 m out) between the tower, the nacelle and a
    blade root, 4.0 m from the nearest part, and S_p 69 m in front of the hub: none of the
    escape directions (radial, away from the tower, the axis, the blades, up) leads out, one
    of the lattice's does; the plan of this turbine was refused for it."""
    from wtcli.plan import paths
    from wtcli.plan.clearance import Site

    t = Turbine.with_rotor_azimuth(63.40235471669334, id="T1", base=(0, 0, 0),
                                   hub_height=116.74420547730556,
                                   rotor_diameter=137.36167373937914, yaw_deg=112.63757669885429)
    site = Site([t], launch=np.array([77.2, -32.2, 0.0]), uncertainty=[0.5])
    p = np.array([6.175115552527011, 3.1957396014914816, 108.77573044296336])
    q = np.array([73.84879860405789, -30.79712828863798, 116.74420547730556])
    vias = paths.connect(site, p, q, 3.75, ground=5.0)
    assert vias, vias
    chain = np.array([p, *vias, q])
    for a, b in zip(chain[:-1], chain[1:]):  # every 5 cm, against the site's own distance
        X = a + (b - a) * np.linspace(0, 1, int(np.linalg.norm(b - a) / 0.05) + 2)[:, None]
        assert site.clearance(X).min() >= 3.75 - 0.05, (a, b)
        assert X[:, 2].min() >= 5.0
    monkeypatch.setattr(paths, "LATTICE", [])
    assert paths.connect(site, p, q, 3.75, ground=5.0) is None


def test_legs_above_ground_sees_a_leg_cross_higher_ground():
    from wtcli.plan.clearance import Site

    site = Site(_hilly_site(), launch=np.array([-150.0, 0.0, 0.0]))
    p0 = np.array([[0.0, 30.0, 6.0], [0.0, 30.0, 50.0], [0.0, 30.0, 6.0]])
    p1 = np.array([[800.0, 30.0, 6.0], [800.0, 30.0, 50.0], [150.0, 30.0, 6.0]])
    assert site.legs_above_ground(p0, p1, 5.0).tolist() == [False, True, True]
    flat = Site(tuple(make_turbine(tid=f"T{i}", base=(400.0 * i, 0, 0)) for i in range(3)))
    assert flat.legs_above_ground(p0, p1, 5.0).tolist() == [True, True, True]
    assert not flat.legs_above_ground(p0[:1], p1[:1], 7.0)[0]  # the ends are too low


def test_plan_over_uneven_ground_keeps_every_leg_above_it():
    ts = _hilly_site()
    launch = np.array([-150.0, 0.0, 0.0])
    m = Mission(ts, CAM, fleet=Fleet(launch=tuple(launch)),
                settings=Settings(inspect_tower=False, inspect_nacelle=False, min_side_coverage=0.0))
    plan = plan_mission(m)
    assert plan.summary["violations"]["ground_violations"] == 0
    # Independently: the nearest base or launch point's height, every 0.5 m of every leg.
    G = np.array([t.base for t in ts] + [launch], float)
    for r in plan.routes:
        at_launch = np.linalg.norm(r.pos[:, :2] - launch[:2], axis=1) < 0.5
        for i in np.nonzero(~at_launch[:-1] & ~at_launch[1:])[0]:
            n = int(np.ceil(np.linalg.norm(r.pos[i + 1] - r.pos[i]) / 0.5)) + 1
            X = r.pos[i] + (r.pos[i + 1] - r.pos[i]) * np.linspace(0, 1, n)[:, None]
            g = G[np.argmin(np.linalg.norm(X[:, None, :2] - G[None, :, :2], axis=2), axis=1), 2]
            assert (X[:, 2] >= g + m.settings.min_altitude_m - 1e-6).all(), (r.uav, i, r.component[i + 1])
    assert_safe(plan, m.settings.safe_distance_m)
    for r in plan.routes:  # every leg in the air moves: no two waypoints at one place at 0 m/s
        still = np.nonzero(np.linalg.norm(np.diff(r.pos, axis=0), axis=1) <= 1e-6)[0]
        assert all((r.component[i], r.component[i + 1]) == ("return", "launch") for i in still), \
            (r.uav, still)  # only a battery swap stands still, on the ground


def test_a_detour_holding_a_via_at_a_legs_end_adds_no_leg_of_no_length():
    from wtcli.plan.mission import distinct_vias

    p, q = np.array([0.0, 0.0, 24.9]), np.array([-34.4, 91.0, 24.9])
    vias = [np.array([0.0, 0.0, 24.9]), np.array([-10.0, 50.0, 40.0]),
            np.array([-10.0, 50.0, 40.0]), q.copy()]
    got = distinct_vias(vias, p, q)
    assert len(got) == 1 and np.allclose(got[0], [-10.0, 50.0, 40.0])
    assert distinct_vias([], p, q) == []


def test_cli_photo_with_a_low_score_blade_admits_it_and_says_so(cli, tmp_path, monkeypatch):
    """The segmenter scores one blade 0.3 (below segment's 0.5): pitch's rotor completion
    admits it inside plan's photo path, the console names it, and the azimuths are the truth."""
    import cv2

    from wtcli.geometry.projection import instance_masks
    from wtcli.masks import Instances
    from wtcli.segment import infer

    m = load_mission(SAMPLE)
    t = m.turbine("T2")
    cam = default_photo_camera(t, Camera(800, 600, 16, 23.2))
    inst = instance_masks(t, cam)
    first_blade = next(i for i, (label, _, _) in enumerate(inst) if label == "blade")
    scores = np.array([0.3 if i == first_blade else 0.95 for i in range(len(inst))])
    low = Instances(np.array([x[0] for x in inst], dtype=object), np.array([x[2] for x in inst]),
                    scores)
    monkeypatch.setattr(infer, "segment_image", lambda image, **kw: low)
    photo = tmp_path / "t2.png"
    cv2.imwrite(str(photo), np.full((600, 800, 3), 200, np.uint8))
    r = cli("plan", SAMPLE, f"T2={photo}", "--out", tmp_path / "plan.json")
    assert r.exit_code == 0, r.output
    out = " ".join(r.output.split())
    assert "detected at score 0.30, below 0.5, and admitted to complete the rotor" in out
    assert "inferred from the rotor's even spacing" not in out
    got = sorted(read_plan(tmp_path / "plan.json").turbine("T2").azimuths_deg)
    for g, w in zip(got, sorted(t.azimuths_deg)):
        assert abs((g - w + 180) % 360 - 180) < 2.0


def test_unreachable_root_station_is_dropped_and_coverage_decides():
    """A property case (seed 10190: 6 m required clearance, the trailing edge's root stations
    wedged between the blade and the nacelle) used to refuse the whole mission for one leg. Now
    the station is left out with a note naming the blocker: the plan is safe, and with a
    coverage floor the refusal says which side, how much, and what blocks it."""
    import dataclasses

    case = random_case(np.random.default_rng(10190))
    plan = plan_mission(case)
    assert_safe(plan, case.settings.safe_distance_m)
    assert any("blocked by T1 nacelle" in n and "dropped" in n for n in plan.summary["notes"])
    strict = dataclasses.replace(case, settings=dataclasses.replace(case.settings, min_side_coverage=1.0))
    with pytest.raises(PlanError, match=r"trailing_edge: predicted coverage .*blocked by T1 nacelle"):
        plan_mission(strict)


def test_legs_above_ground_is_exact_against_dense_sampling():
    """The leg test works out, per leg, the stretch over each base's flat ground (the nearest
    base's region, convex) instead of sampling; it must agree with samples every 5 cm."""
    from wtcli.plan.clearance import Site

    rng = np.random.default_rng(3)
    for n in (3, 20):
        ts = [make_turbine(tid=f"T{i}", base=(float(rng.uniform(0, 500)), float(rng.uniform(0, 500)),
                                              float(rng.uniform(0, 40)))) for i in range(n)]
        site = Site(ts, launch=np.array([-50.0, -50.0, 0.0]))
        p0 = np.c_[rng.uniform(-80, 580, (100, 2)), rng.uniform(0, 60, 100)]
        p1 = np.c_[rng.uniform(-80, 580, (100, 2)), rng.uniform(0, 60, 100)]
        got = site.legs_above_ground(p0, p1, 5.0)
        for i in range(len(p0)):
            m = int(np.ceil(np.linalg.norm(p1[i] - p0[i]) / 0.05)) + 1
            X = p0[i] + (p1[i] - p0[i]) * np.linspace(0, 1, m)[:, None]
            assert got[i] == bool((X[:, 2] >= site.ground_z(X) + 5.0 - 1e-6).all()), i
        assert 10 < got.sum() < 90  # both answers occur


def _assert_chain_clear(ts, launch, chain, need: float, ground: float) -> None:
    """Every 5 cm of every leg of ``chain``: ``need`` from every turbine and ``ground`` above
    the nearest base or launch point's height."""
    G = np.array([t.base for t in ts] + [launch], float)
    for a, b in zip(chain[:-1], chain[1:]):
        X = a + (b - a) * np.linspace(0, 1, int(np.linalg.norm(b - a) / 0.05) + 2)[:, None]
        g = G[np.argmin(np.linalg.norm(X[:, None, :2] - G[None, :, :2], axis=2), axis=1), 2]
        assert (X[:, 2] >= g + ground - 1e-6).all()
        assert min(t.clearance(X).min() for t in ts) >= need


def _stepped_row():
    """A row down a slope: T3 on ground 16 m above the launch point, T2 in line between them
    (from the property suite, seed 10 335)."""
    return (make_turbine(az=10.0, yaw=288.8, tid="T1", base=(0.0, -33.0, 2.3), hub_height=48.3,
                         rotor_diameter=49.2),
            make_turbine(az=0.0, yaw=195.8, tid="T2", base=(273.9, -10.3, 5.4), hub_height=88.3,
                         rotor_diameter=88.6),
            make_turbine(az=40.0, yaw=185.2, tid="T3", base=(530.5, -14.5, 18.4), hub_height=67.0,
                         rotor_diameter=96.4))


def test_return_from_higher_ground_past_a_turbine_holds_its_height():
    """From the foot of T3's tower back to the launch point: the straight leg hits T2's tower,
    and a detour that descends on the way dips below T3's ground before leaving it. The way
    found must clear both, checked densely (was refused: 'no safe ... path back')."""
    from wtcli.plan.paths import connect
    from wtcli.plan.clearance import Site

    ts = _stepped_row()
    launch = np.array([-56.8, -13.6, 2.3])
    site = Site(ts, launch=launch)
    p, q = np.array([540.16, -12.26, 23.92]), launch + (0.0, 0.0, 10.0)
    vias = connect(site, p, q, 4.55, ground=5.0)
    assert vias is not None
    _assert_chain_clear(ts, launch, np.array([p] + list(vias) + [q]), 4.55, 5.0)


def test_return_over_a_higher_base_between_two_lower_ones_climbs_over_its_ground():
    """From the foot of T3's tower (5.5 m above its ground) back to the launch point, over T2's
    base 6-9 m higher than both ends: a chain held at the ends' height stays too low over T2's
    ground (property suite, seed 10 394: was refused)."""
    from wtcli.plan.paths import connect
    from wtcli.plan.clearance import Site

    ts = (make_turbine(az=0.0, yaw=342.3, tid="T1", base=(0.0, -8.3, 1.9), hub_height=117.0,
                       rotor_diameter=145.0),
          make_turbine(az=0.0, yaw=125.4, tid="T2", base=(454.7, 48.2, 10.6), hub_height=107.7,
                       rotor_diameter=117.4),
          make_turbine(az=0.0, yaw=191.9, tid="T3", base=(692.1, 30.8, 4.6), hub_height=105.4,
                       rotor_diameter=100.0))
    launch = np.array([-26.57, 75.01, 1.92])
    site = Site(ts, launch=launch)
    p, q = np.array([700.66, 31.68, 10.15]), launch + (0.0, 0.0, 10.0)
    vias = connect(site, p, q, 5.46, ground=5.0)
    assert vias is not None
    _assert_chain_clear(ts, launch, np.array([p] + list(vias) + [q]), 5.46, 5.0)


def test_long_leg_goes_round_a_tower_in_line_where_it_stands():
    """A 1 km transit with a tower 300 m along it: the detour bends at the tower (1.3 m longer,
    within 40 m of it), not 7 m sideways over the whole length (14 m longer, as the search from
    the middle and the ends found)."""
    from wtcli.plan.paths import connect
    from wtcli.plan.clearance import Site

    t = make_turbine(az=0.0, yaw=90.0, base=(300.0, 0.0, 0.0))
    site = Site((t,), launch=np.array([0.0, -100.0, 0.0]))
    p, q = np.array([0.0, 0.0, 30.0]), np.array([1000.0, 0.0, 30.0])
    chain = np.array([p] + connect(site, p, q, 4.55, ground=5.0) + [q])
    assert np.linalg.norm(np.diff(chain, axis=0), axis=1).sum() < 1000.0 + 2.0
    assert (np.abs(chain[1:-1, 0] - 300.0) < 40.0).all()  # every bend at the tower
    assert t.segment_clearance(chain[:-1], chain[1:], step=0.05).min() >= 4.55


def test_long_leg_blocked_at_both_ends_is_detoured_at_each():
    """A 2 km transit with a tower in line 150 m from each end: two blocked stretches, each
    detoured on its own (short searches), straight in between; safe at every 5 cm."""
    from wtcli.plan.paths import connect
    from wtcli.plan.clearance import Site

    ts = (make_turbine(az=0.0, yaw=90.0, base=(150.0, 0.0, 0.0)),
          make_turbine(az=0.0, yaw=90.0, base=(1850.0, 0.0, 0.0), tid="T2"))
    launch = np.array([0.0, -100.0, 0.0])
    site = Site(ts, launch=launch)
    p, q = np.array([0.0, 0.0, 30.0]), np.array([2000.0, 0.0, 30.0])
    runs = site.blocked_stretches(p, q, 4.55, 0.5, 4.8, gap=60.0)
    assert len(runs) == 2
    assert all(abs(0.5 * (a + b) * 2000.0 - x) < 10.0 for (a, b), x in zip(runs, (150.0, 1850.0)))
    chain = np.array([p] + connect(site, p, q, 4.55, ground=5.0) + [q])
    assert (np.minimum(np.abs(chain[1:-1, 0] - 150.0), np.abs(chain[1:-1, 0] - 1850.0)) < 70.0).all()
    assert np.linalg.norm(np.diff(chain, axis=0), axis=1).sum() < 2000.0 + 4.0
    _assert_chain_clear(ts, launch, chain, 4.55, 5.0)


# ---- gimbal limits -----------------------------------------------------------------------------------
def _gimbal_mission(azimuths, up_deg, min_side=0.9):
    t = Turbine(id="T1", base=(0, 0, 0), hub_height=80, rotor_diameter=90, yaw_deg=180,
                azimuths_deg=azimuths)
    return Mission((t,), CAM, fleet=Fleet(gimbal_pitch_max_deg=up_deg),
                   settings=Settings(min_side_coverage=min_side))


def test_gimbal_that_looks_up_30_deg_is_never_asked_for_more():
    """An under-slung gimbal stops near +30 deg. The side of a blade below the hub that faces
    down is seen head-on only from below, looking up 70 deg (blade at 200 deg): the planner must
    see it obliquely instead, every photo aimed within the gimbal's reach, and still cover it."""
    from wtcli.plan.mission import _chunks, pass_params
    from wtcli.plan.clearance import Site

    m = _gimbal_mission((80.0, 200.0, 320.0), 30.0)
    pp, gsd, _ = pass_params(m)
    assert pp.pitch_range == (-90.0, 30.0)
    t = m.turbines[0]
    chunks = _chunks((t, Site([t]), pp, m, "adaptive", gsd))
    aims = np.array([w.fwd for c in chunks for w in c.wps if w.photo])
    up = np.degrees(np.arcsin(aims[:, 2] / np.linalg.norm(aims, axis=1)))
    assert up.max() <= 30.0 + 1e-6
    free = _chunks((t, Site([t]), pass_params(_gimbal_mission((80.0, 200.0, 320.0), 90.0))[0],
                    _gimbal_mission((80.0, 200.0, 320.0), 90.0), "adaptive", gsd))
    assert max(np.degrees(np.arcsin(w.fwd[2])) for c in free for w in c.wps if w.photo) > 60
    plan = plan_mission(m)
    assert plan.summary["gimbal_pitch_range_deg"] == [-90.0, 30.0]
    assert all(r.gimbal_pitch_deg.max() <= 30.0 + 1e-9 for r in plan.routes)
    assert plan.summary["predicted_coverage"]["T1"]["min_side"] >= 0.9
    assert_safe(plan, m.settings.safe_distance_m)


def test_horizontal_blade_face_down_is_refused_naming_the_gimbal():
    """A horizontal blade's downward face is seen within 60 deg of incidence only by a camera
    looking up at least ~30 deg: a gimbal that stops at +20 sees about half of it, and the
    refusal says why (at +30 the oblique passes reach 98 %, measured 2026-11-30)."""
    with pytest.raises(PlanError, match=r"blade1 pressure_side: predicted coverage .*gimbal's "
                                        r"pitch range \[-90, \+20\] deg.*turn the rotor"):
        plan_mission(_gimbal_mission((0.0, 120.0, 240.0), 20.0))


def test_site_clearance_of_a_nan_point_is_nan():
    """A NaN point never reads as clear (it falls outside the grid, and read the cull
    distance, 60 m, before)."""
    from wtcli.plan.clearance import Site

    site = Site([make_turbine(tid="T1")])
    got = site.clearance(np.array([[np.nan, 0.0, 80.0], [0.0, 0.0, 500.0]]))
    assert np.isnan(got[0]) and got[1] == site.horizon
    assert np.isnan(Site([]).clearance(np.array([[0.0, np.nan, 1.0]]))).all()


def test_site_queries_far_outside_the_grid():
    """Points and legs far beyond every turbine (infinite, or beyond an integer's range in grid
    cells) read the horizon, as any point outside the grid; their ground is the first base's
    (np.argmin's answer), and a photo taken there sees nothing."""
    from wtcli.geometry.coverage import measure_coverage
    from wtcli.plan.clearance import Site

    ts = [make_turbine(tid=f"T{i}", base=(300.0 * i, 0.0, float(i))) for i in range(20)]
    site = Site(ts)
    far = np.array([[1e300, 0.0, 80.0], [-1e300, 5.0, 80.0], [np.inf, 0.0, 80.0], [0.0, -np.inf, 80.0]])
    assert (site.clearance(far) == site.horizon).all()
    assert (site.clearance(far, 5.0) == site.cull_distance(5.0)).all()
    legs = site.segment_clearance(far[:2], far[:2] + 1.0, 0.5, 5.0)  # finite legs only
    assert (legs >= site.cull_distance(5.0) - 0.5).all()
    assert (site.ground_z(far) == ts[0].base[2]).all()
    s = ts[0].surface_samples(2.0)
    cov = measure_coverage(s, CAM, far, np.repeat(np.eye(3)[None], len(far), 0), 2.0)
    assert not cov.covered.any()


# ---- a tower wider than the nacelle's standoff ------------------------------------------------------
def _wide_tower_mission(radius: float) -> Mission:
    """The failing case of a property run: a wide tower reaches into the nacelle's nominal
    standoff, the gimbal stops at -60 deg (no top views), safe distance 5.36 m."""
    t = make_turbine(az=90.0, tower_base_radius=radius, tower_top_radius=radius)
    return Mission((t,), CAM, fleet=Fleet(gimbal_pitch_max_deg=30, gimbal_pitch_min_deg=-60),
                   settings=Settings(safe_distance_m=5.36, min_side_coverage=0.0,
                                     coverage_spacing_m=2.0))


def test_wide_tower_backs_the_nacelle_stations_off_instead_of_crashing():
    plan = plan_mission(_wide_tower_mission(5.0))
    assert plan.summary["per_component"]["T1/nacelle"]["photos"] > 0
    assert_safe(plan, 5.36)


def test_nacelle_with_no_possible_station_is_refused_by_name():
    with pytest.raises(PlanError, match=r"T1 nacelle: no photo station .* mission.inspect_nacelle: false"):
        plan_mission(_wide_tower_mission(8.0))


# ---- one source of defaults ------------------------------------------------------------------------
def _doc_defaults(section: str) -> dict[str, str]:
    """key -> the default column of a table in docs/turbines-yaml.md (## `section`)."""
    text = (ROOT / "docs" / "turbines-yaml.md").read_text(encoding="utf-8")
    body = text.split(f"## `{section}`", 1)[1].split("\n## ", 1)[0]
    out = {}
    for line in body.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) >= 3 and cells[0].startswith("`"):
            out[cells[0].strip("`")] = cells[2]
    return out


def _as_value(text: str):
    t = text.replace("\u2212", "-")
    if t in ("true", "false"):
        return t == "true"
    return float(t)


@pytest.mark.parametrize("section,cls", [("fleet", Fleet), ("mission", Settings)])
def test_docs_yaml_and_dataclasses_agree_on_every_default(section, cls):
    import dataclasses

    from wtcli.plan.config import default_dict

    yaml_d = default_dict()[section]
    docs = _doc_defaults(section)
    fields = {f.name: f.default for f in dataclasses.fields(cls)}
    assert set(docs) == set(yaml_d), "every key has a row in the docs' table and a packaged default"
    for key, value in yaml_d.items():
        if key == "uavs":
            assert fields[key] == tuple(f"UAV{k + 1}" for k in range(value)) and docs[key] == str(value)
            continue
        if key == "launch":
            assert value is None and fields[key] is None and "in front of" in docs[key]
            continue
        assert fields[key] == value, f"{section}.{key}: dataclass {fields[key]!r}, YAML {value!r}"
        assert _as_value(docs[key]) == value, f"{section}.{key}: docs {docs[key]!r}, YAML {value!r}"


def test_camera_defaults_in_docs_match_the_packaged_yaml():
    from wtcli.plan.config import default_dict

    docs = _doc_defaults("camera")
    assert {k: _as_value(v) for k, v in docs.items()} == default_dict()["camera"]


def test_a_mission_built_in_code_plans_like_a_yaml_that_leaves_keys_out():
    d = {"turbines": [{"id": "T1", "position": [0, 0, 0], "hub_height_m": 80,
                       "rotor_diameter_m": 90, "yaw_deg": 0}]}
    m = mission_from_dict(d)
    assert m.settings == Settings() and m.fleet == Fleet()


def test_clearance_to_parts_is_the_sites_clearance_with_the_part_named():
    from wtcli.plan.clearance import HORIZON_M, Site, clearance_to_parts

    rng = np.random.default_rng(3)
    ts = [make_turbine(az=10.0, tid="T1"), make_turbine(az=70.0, yaw=40.0, tid="T2", base=(250, 0, 0))]
    P = np.vstack([t.hub_center + rng.normal(0, 30, (200, 3)) for t in ts]
                  + [np.array([[5000.0, 0.0, 50.0]])])
    d, part = clearance_to_parts(ts, P)
    assert np.allclose(d, Site(ts).clearance(P), atol=1e-9)
    for i in rng.choice(len(P) - 1, 25, replace=False):
        name, dist = Site(ts).nearest_part(P[i])
        assert part[i] == name.replace(" ", "/") and abs(min(dist, HORIZON_M) - d[i]) < 1e-9
    assert d[-1] == HORIZON_M and part[-1] == ""


def _sortie_times(route) -> list[float]:
    """Independent of the planner's bookkeeping: take-off to landing, between ground stops at
    the launch point."""
    g = [i for i in range(len(route)) if np.allclose(route.pos[i], route.pos[0])]
    return [float(route.t[b] - route.t[a]) for a, b in zip(g, g[1:]) if b > a + 1]


def test_every_sortie_keeps_the_battery_reserve_with_detoured_transits():
    """The failing case of a property run: a return leg detoured round a turbine made the
    second sortie 7 s longer than battery minus reserve (its estimate flew straight)."""
    case = random_case(np.random.default_rng(10034), gimbal=True)
    plan = plan_mission(case)
    fl = case.fleet
    limit = 60 * (fl.battery_minutes - fl.battery_reserve_minutes) / (1 + fl.wind_margin)
    times = [x for r in plan.routes for x in _sortie_times(r)]
    assert len(times) >= 2 and max(times) <= limit + 1e-6
    assert max(r.summary["longest_sortie_s"] for r in plan.routes) == pytest.approx(max(times))


def test_sorties_are_balanced_with_the_same_battery_changes():
    """A route that needs two batteries is split where both sorties are about as long, not with
    the first filled to the brim: the reserve is then left for wind. On the sample site the
    first sortie was 23.1 of 25 usable minutes and the second under 5; flown in paper-s2's
    10 m/s wind the first ate into the reserve."""
    mission = load_mission(SAMPLE)
    plan = plan_mission(mission)
    (route,) = plan.routes
    times = _sortie_times(route)
    assert len(times) == 2 == route.summary["sorties"]
    assert max(times) <= 0.6 * sum(times)
    assert route.summary["longest_sortie_s"] == pytest.approx(max(times))
    usable = mission.fleet.usable_battery_s
    assert max(times) < 0.7 * usable


# ---- the property suite, small ---------------------------------------------------------------------
def _plan_property():
    import importlib.util

    spec = importlib.util.spec_from_file_location("plan_property",
                                                  ROOT / "benchmarks" / "plan_property.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_independent_distance_is_never_below_the_models_lower_bound():
    """The property suite's own distance (closed forms and elliptic sections) against the
    model's, which promises a lower bound: the two must agree within the model's slack."""
    pp = _plan_property()
    t = make_turbine(az=33.0, yaw=20.0, blades=5, tower_base_radius=4.0)
    rng = np.random.default_rng(7)
    Q = t.hub_center + rng.normal(0, 15, (200, 3))
    model = t.clearance(Q)
    indep = np.array([pp.independent_min_clearance([t], Q[i:i + 1], 20.0) for i in range(len(Q))])
    near = model < 15.0
    assert (model[near] <= indep[near] + 1e-6).all()
    assert np.median(indep[near] - model[near]) < 0.05  # a close bound, not a loose one


def test_the_suites_leg_samples_reach_every_part():
    """Legs are sampled only within a sphere round each turbine: every surface point of the
    suite's turbines (low hubs, blades straight up included) lies inside it."""
    pp = _plan_property()
    for seed in range(8):
        try:
            m = mission_from_dict(pp.random_site(np.random.default_rng(seed)))
        except ConfigError:  # a blade that would cut into its tower: refused, nothing to fly
            continue
        for t in m.turbines:
            c, r = pp.enclosing_sphere(t)
            assert np.linalg.norm(t.surface_samples(1.0).points - c, axis=1).max() <= r


@pytest.mark.parametrize("seed", [4, 1])
def test_random_sites_plan_or_refuse_in_one_line_safely(seed):
    """A few sites of benchmarks/plan_property.py (1 000 of them there): planned ones are
    checked with the independent distance, the sorties and the coverage at half spacing."""
    r = _plan_property().one(seed)
    assert "crash" not in r, r.get("trace")
    if "refused" in r:
        assert r["one_line"] and r["exit"] in (4, 6)
        return
    assert not r["clearance_violation"] and not r["battery_overrun"]
    assert r["min_side_fine"] >= r["min_side_coverage"]


def test_a_sortie_the_timing_finds_over_the_limit_is_planned_again():
    """Site 406 of the property suite: the battery decisions estimated UAV3's sortie inside the
    limit, the timed route took 2.4 s more (18.29 min against 18.25) and the plan was refused;
    planned again under a limit shrunk by the overrun, it keeps the limit."""
    r = _plan_property().one(406, coverage=False)
    assert "refused" not in r and "crash" not in r, r
    assert not r["battery_overrun"] and r["longest_sortie_s"] <= r["sortie_limit_s"]
    assert not r["clearance_violation"]


# ---- site sanity -----------------------------------------------------------------------------------
def _site(*turbines, **top):
    base = {"id": "T1", "position": [0, 0, 0], "hub_height_m": 80, "rotor_diameter_m": 90,
            "yaw_deg": 0}
    return {"turbines": [{**base, **t} for t in turbines], **top}


@pytest.mark.parametrize("entry,key", [
    ({"position": [1e12, 1e12, 0]}, r"turbines\[0\]\.position: expected a point within 50 km"),
    ({"position": [0, 0, 2e4]}, r"turbines\[0\]\.position: expected a point within 50 km"),
    ({"blade_azimuths_deg": [90, 90, 210]}, r"turbines\[0\]\.blade_azimuths_deg: expected blades spread like a rotor"),
])
def test_absurd_turbine_is_refused_naming_the_key(entry, key):
    with pytest.raises(ConfigError, match=key):
        mission_from_dict(_site(entry))


def test_far_lat_lon_is_refused_naming_it():
    d = _site({"position": None, "lat": 10.0, "lon": 10.0}, site={"origin": {"lat": 53.5, "lon": 10.0}})
    with pytest.raises(ConfigError, match=r"turbines\[0\]\.lat/lon: expected a point within 50 km"):
        mission_from_dict(d)


def test_turbines_on_top_of_each_other_are_refused_naming_both():
    with pytest.raises(ConfigError, match=r"turbines\[1\]\.position: turbine 'T2' stands 0\.0 m from 'T1'"):
        mission_from_dict(_site({}, {"id": "T2"}))
    with pytest.raises(ConfigError, match=r"turbines\[2\]\.position: turbine 'T3' stands 60\.0 m from 'T2'"):
        mission_from_dict(_site({}, {"id": "T2", "position": [300, 0, 0]},
                                {"id": "T3", "position": [360, 0, 0]}))
    m = mission_from_dict(_site({}, {"id": "T2", "position": [91, 0, 0]}))  # rotors just apart
    assert len(m.turbines) == 2


def test_a_turbine_whose_blade_would_cut_into_its_tower_is_refused():
    """Property site 25's T1: a 5.3 m tower, its hub 5.27 m ahead of the tower axis. Its one
    blade pointed down and passed into the tower; the plan then rested on a blade that is not
    there. Refused at any stopped azimuth: the rotor could not turn past the tower either."""
    wide = {"hub_height_m": 42.0, "rotor_diameter_m": 63.8, "blades": 1, "blade_pitch_deg": 89.7,
            "tower": {"base_radius_m": 5.3, "top_radius_m": 5.12}, "overhang_m": 5.27}
    for az in ([270.0], [90.0]):
        with pytest.raises(ConfigError, match=r"turbines\[0\]: a blade pointing down would pass "
                           r"1\.\d\d m into the tower .*overhang_m"):
            mission_from_dict(_site({**wide, "blade_azimuths_deg": az}))
    # Given the overhang such a tower needs, it plans as any other.
    t = mission_from_dict(_site({**wide, "overhang_m": 7.5})).turbines[0]
    assert t.overhang == 7.5
    # The packaged proportions clear their own tower, small rotors on tall towers included.
    for d, hub in ((5, 250), (10, 80), (60, 250), (90, 80), (300, 160)):
        mission_from_dict(_site({"rotor_diameter_m": d, "hub_height_m": hub}))
    # Datasheet turbines without the shaft tilt and cone the model lacks: NREL 5 MW (Jonkman et
    # al. 2009, NREL/TP-500-38060) and DTU 10 MW (Bak et al. 2013) clear their towers.
    for hub, d, rb, rt, over, root, mx, at in ((90.0, 126.0, 3.0, 1.935, 5.0, 3.542, 4.652, 0.23),
                                              (119.0, 178.3, 4.15, 2.75, 7.1, 5.38, 6.2, 0.22)):
        mission_from_dict(_site({"hub_height_m": hub, "rotor_diameter_m": d, "overhang_m": over,
                                 "tower": {"base_radius_m": rb, "top_radius_m": rt},
                                 "blade": {"root_chord_m": root, "max_chord_m": mx,
                                           "max_chord_span_fraction": at}}))


def test_a_rotor_a_little_uneven_is_accepted():
    m = mission_from_dict(_site({"blade_azimuths_deg": [90, 215, 330]}))
    assert m.turbines[0].azimuths_deg == (90.0, 215.0, 330.0)


def test_trailing_edge_coverage_converges_as_the_sampling_refines():
    """The failing case of issue 40: a blade straight down in front of the tower, whose trailing
    edge faces it. The plan's figure is the converged one (``turbine_coverage``) and holds
    within 0.5 points at half the sampling (tests/test_coverage.py has the finer checks)."""
    from wtcli.geometry.coverage import turbine_coverage
    from wtcli.plan.mission import _photos_of

    plan = plan_mission(Mission((make_turbine(az=270.0),), CAM, settings=Settings(min_side_coverage=0.0)))
    t = plan.turbines[0]
    pos, rot = _photos_of(t, plan.routes)
    figs = []
    for sp in (0.5, 0.25):
        cov = turbine_coverage(t, CAM, pos, rot, plan.target_gsd_mm, sp, 60.0, "blades")
        figs.append(cov.by_blade_side()["blade1"]["trailing_edge"])
    said = plan.summary["predicted_coverage"]["T1"]["by_blade_side"]["blade1"]["trailing_edge"]
    assert said == pytest.approx(figs[0])
    assert abs(figs[0] - figs[1]) < 0.005 and figs[0] < 0.99


def test_every_blade_side_has_its_middle_line_sampled():
    t = make_turbine(az=10.0)
    smp = t.surface_samples(0.5, "blades")
    d, c, n = t.blade_frame(0)
    for side, axis in enumerate((c, n, -c, -n)):
        m = (smp.blade == 0) & (smp.side == side)
        assert (smp.normals[m] @ axis).max() > 1 - 1e-9  # a sample whose normal is the side's own


def test_cli_photo_without_a_turbine_on_a_site_of_two_is_a_usage_error(cli, tmp_path):
    """The sample site has two turbines: a photo or pitch JSON that names none is a command
    line that does not say enough (exit 2, with the fix), not a missing file (exit 3)."""
    from wtcli.jsonio import document, write_json
    from wtcli.pitch import PITCH_SCHEMA, PITCH_VERSION

    pj = tmp_path / "pitch.json"
    write_json(pj, document(PITCH_SCHEMA, PITCH_VERSION,
                            {"images": [_pitch_image(load_mission(SAMPLE).turbine("T2"))]}))
    r = cli("plan", SAMPLE, pj)
    assert r.exit_code == 2, r.output
    assert "which turbine is this? prefix it with the turbine id (T1=" in r.output
    assert cli("plan", SAMPLE, f"T2={pj}").exit_code == 0


def test_blade_chords_from_the_yaml_reach_the_model_and_its_clearance():
    wide = mission_from_dict(_site({"blade": {"root_chord_m": 3.0, "max_chord_m": 5.5,
                                              "tip_chord_m": 0.8}})).turbines[0]
    plain = mission_from_dict(_site({})).turbines[0]
    assert (wide.blade_root_chord, wide.blade_max_chord, wide.blade_tip_chord) == (3.0, 5.5, 0.8)
    d, c, n = wide.blade_frame(0)
    s = wide.blade_root_offset + 0.2 * (wide.tip_radius - wide.blade_root_offset)
    p = wide.hub_center + s * d + 4.0 * c  # 4 m out along the chord at the widest section
    assert wide.clearance(p[None])[0] == pytest.approx(4.0 - 5.5 / 2, abs=0.05)
    assert plain.clearance(p[None])[0] > wide.clearance(p[None])[0] + 0.5
    with pytest.raises(ConfigError, match=r"turbines\[0\]\.blade: unknown key 'max_chord'"):
        mission_from_dict(_site({"blade": {"max_chord": 5.5}}))


# ---- the tower's columns ------------------------------------------------------------------------
P1_35 = Camera(8192, 5460, 35, 35.9)  # the default camera (Zenmuse P1, DL 35 mm)


@pytest.mark.parametrize("cam, want", [(P1_35, 4), (CAM, 5)])
def test_tower_columns_see_the_girth_and_one_fewer_does_not(cam, want):
    """The count from the geometry, checked by the coverage measure itself on a band of the
    tower near its base: every column count's level views from the plan's standoff."""
    from wtcli.geometry.coverage import measure_coverage
    from wtcli.plan.mission import pass_params
    from wtcli.plan.paths import _camera_rotations, tower_columns, tower_standoff
    t = make_turbine(hub_height=98, rotor_diameter=150)
    pp, gsd, _ = pass_params(Mission((t,), cam, settings=Settings()))
    n = tower_columns(t.tower_base_radius, pp)
    assert n == want
    samples = t.surface_samples(0.25, "structure")
    z = 6.0  # the lowest level a column's level views reach (min_altitude 5 m + 0.5)
    band = (samples.part == t.part_names().index("tower")) & (np.abs(samples.points[:, 2] - z) < 0.5)
    assert band.sum() > 50

    def seen(columns: int, phase: float, standoff: float = pp.standoff) -> float:
        a = phase + 2 * np.pi * np.arange(columns) / columns
        u = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)
        pos = t.base_xyz + (t.tower_radius_at(np.array([z]))[0] + standoff) * u + [0, 0, z]
        cov = measure_coverage(samples, cam, pos, _camera_rotations(-u), gsd, 60.0)
        return cov.fraction(band)

    for phase in (0.0, 0.3, 1.1):
        assert seen(n, phase) > 0.999
    assert seen(n - 1, 0.0) < 0.97
    # the columns fly out as far as they still see the girth (a looser blur limit): farther
    # than the blades' standoff, within the GSD's distance, and still seeing all of it
    e = tower_standoff(t.tower_base_radius, pp, n)
    assert pp.standoff <= e <= pp.max_standoff
    for phase in (0.0, 0.3, 1.1):
        assert seen(n, phase, e) > 0.999
    if e + 0.25 <= pp.max_standoff:  # stopped by the girth, not the GSD: a metre farther
        assert seen(n, 0.0, e + 1.0) < 0.999  # (beyond the planning margins) it is not seen


@pytest.mark.parametrize("horizontal", [False, True])
def test_a_face_a_little_taller_than_the_frame_is_tiled_quicker_to_fly_and_all_seen(horizontal):
    """A nacelle face a few decimetres taller than the frame's usable height, flown in rows
    along it, takes two rows 1.2 m apart, the aircraft stopping at every row's end. A side is
    flown as one straight line instead, the camera aimed at either row in turn (one photo more,
    no stop); the top with the frame turned (fewer photos). Every point is seen either way, by
    coverage's own test. (The top's view is tipped 1 deg to fix the camera's yaw: its stations
    are set back along it, or the frame's far edge moves 0.2 m off the face.)"""
    from wtcli.plan.corners import stops
    from wtcli.plan.mission import pass_params
    from wtcli.plan.paths import FACE_BORDER, _camera_rotations, _face_rows, _face_tiling
    t = make_turbine(hub_height=98, rotor_diameter=150)
    pp, gsd, _ = pass_params(Mission((t,), P1_35, settings=Settings()))
    fw, fh = P1_35.footprint_m(pp.standoff)
    hu, hv = 8.3, 0.5 * (1 - FACE_BORDER) * fh + 0.4  # 16.6 m long, 0.8 m taller than a row sees
    c = np.array([0.0, 0.0, 100.0])
    if horizontal:  # the top face: rows along x, the view tipped towards y (frame along x)
        nrm, u, v, tilt = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), \
            np.array([0, 1.0, 0])
    else:  # a side: rows along x, across z
        nrm, u, v, tilt = np.array([0, 1.0, 0]), np.array([1.0, 0, 0]), np.array([0, 0, 1.0]), None
    rows = _face_rows(c, nrm, u, v, hu, hv, pp, tilt)
    tiled = _face_tiling(c, nrm, u, v, hu, hv, pp, tilt)
    n_rows, n_tiled = (sum(len(r[0]) for r in x) for x in (rows, tiled))
    stops_rows, stops_tiled = (int(stops(np.vstack([r[0] for r in x]))[1:-1].sum())
                               for x in (rows, tiled))
    assert len(rows) == 2 and stops_rows >= 1
    if horizontal:
        assert n_tiled < n_rows, (n_rows, n_tiled)
    else:
        assert len(tiled) == 1 and stops_tiled == 0 and n_tiled == n_rows + 1, (n_tiled, stops_tiled)
        pitch = np.degrees(np.arcsin(tiled[0][1][:, 2]))
        assert (np.abs(pitch) > 1.0).all() and (np.sign(pitch[1:]) != np.sign(pitch[:-1])).all()
    # every point of the face, 10 cm apart, in some photo: frame less 2 %, the GSD's distance,
    # incidence within 60 deg (the coverage measure's test, line of sight aside: a flat face)
    a, b = np.meshgrid(np.linspace(-hu, hu, 171), np.linspace(-hv, hv, 1 + int(20 * hv)))
    X = c + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
    pos = np.vstack([r[0] for r in tiled])
    rot = _camera_rotations(np.vstack([r[1] for r in tiled]))  # as the route records them
    from wtcli.geometry.coverage import imaged
    seen = imaged(X[:, None] - pos[None], np.broadcast_to(nrm, (len(X), 1, 3)), rot[None],
                  P1_35, P1_35.distance_for_gsd(1.05 * gsd), 60.0, 0.02).any(axis=1)
    assert seen.all(), (~seen).sum()


@pytest.mark.parametrize("cam", [P1_35, CAM])
@pytest.mark.parametrize("hub, rotor", [(60, 80), (98, 150), (120, 170)])
def test_tower_columns_fly_less_than_a_helix_at_the_same_standoff(cam, hub, rotor):
    """Columns or a helix, by time (both are flown at the same blur limit, so by length): a
    helix round the tower at the columns' standoff climbs by one footprint height less the
    rows' overlap per turn; the columns climb the tower once each. Over the turbines' range,
    with either camera, the helix is at least twice as long."""
    from wtcli.plan.mission import pass_params
    from wtcli.plan.paths import FACE_ROW_LAP, tower_columns, tower_standoff
    t = make_turbine(hub_height=hub, rotor_diameter=rotor)
    pp, _, _ = pass_params(Mission((t,), cam, settings=Settings()))
    r = t.tower_base_radius
    n = tower_columns(r, pp)
    e = tower_standoff(r, pp, n)
    height = t.hub_height - pp.min_altitude
    columns = n * height
    helix = height / ((1 - FACE_ROW_LAP) * cam.footprint_m(e)[1]) * 2 * np.pi * (r + e)
    assert helix > 2 * columns, (n, e, columns, helix)


@pytest.mark.parametrize("cam, columns", [(P1_35, 4), (CAM, 5)])
def test_an_even_tower_is_climbed_on_the_way_up_and_ends_at_the_bottom(cam, columns):
    """Four columns flown from the top would end at the top, a descent without photos before
    the landing: one is flown bottom -> top before the overview photo instead. Five end at the
    bottom as they are, all after the nacelle."""
    t = make_turbine(hub_height=98, rotor_diameter=150)
    plan = plan_mission(Mission((t,), cam, settings=Settings(min_side_coverage=0.0)))
    r = plan.routes[0]
    comp = [str(c) for c in r.component]
    tower = [i for i, c in enumerate(comp) if c == "T1/tower" and r.photo[i]]
    overview = comp.index("T1/overview")
    climb = [i for i in tower if i < overview]
    rest = [i for i in tower if i > overview]
    if columns % 2 == 0:
        z = r.pos[climb, 2]
        assert len(climb) > 10 and (np.diff(z) > 0).all()  # upwards, photo after photo
        assert z[0] < 8.0 and z[-1] > 0.9 * t.hub_height - 10.0
        # straight from the take-off: through at most the via a metre out from the foot view
        # (its slow leg, FOOT_VIA_M)
        k = climb[0] - 1
        if comp[k] == "T1/tower":
            assert not r.photo[k] and np.linalg.norm(r.pos[k] - r.pos[climb[0]]) < 1.01
            k -= 1
        assert comp[k] in ("launch", "transit")
    else:
        assert not climb
    assert r.pos[rest[-1], 2] < 8.0  # the last column ends at the bottom
    assert set(comp[rest[-1] + 1:]) <= {"T1/tower", "return"}  # then home
    assert_safe(plan, 3.0)


@pytest.mark.parametrize("cam", [P1_35, CAM])
@pytest.mark.parametrize("side", [1.0, -1.0])
def test_the_tower_ends_by_the_landing(cam, side):
    """The columns after the climb go round the tower the way whose last column ends on the
    landing's side: with the landing off to either side of the climbing column, the last
    station flips with it, and the way home from it is straight."""
    from wtcli.plan.clearance import Site
    from wtcli.plan.mission import pass_params
    from wtcli.plan.paths import LEG_STEP, tower_chunk
    t = make_turbine(az=90.0, hub_height=98, rotor_diameter=150)  # no blade down the tower
    pp, _, _ = pass_params(Mission((t,), cam, settings=Settings()))
    site = Site([t])
    front = t.base_xyz + 80.0 * t.axis + [0, 0, 98.0]
    across = np.cross([0.0, 0.0, 1.0], t.axis)
    land = t.base_xyz + 90.0 * side * across + [0, 0, 10.0]
    chunks = tower_chunk(t, site, pp, start_near=t.nacelle_center + [0, 0, 15.0],
                         climb_toward=front, end_toward=land)
    last = chunks[-1].wps[-1].pos
    assert (last - t.base_xyz)[:2] @ (land - t.base_xyz)[:2] > 0, (last, land)
    assert site.segment_clearance(last[None], land[None], LEG_STEP, pp.required)[0] \
        >= pp.leg_required


def test_tower_columns_stay_within_what_the_yaml_allows_for_a_narrow_camera():
    """A camera whose frame sees a sliver of the tower asks for many columns, at most 16
    (mission.tower_columns' bound); the usual cameras ask for 4-6."""
    from wtcli.plan.mission import pass_params
    from wtcli.plan.paths import tower_columns
    t = make_turbine(hub_height=98, rotor_diameter=150)
    narrow = Camera(64, 48, 2000, 35.9)  # a 2 m lens on 64 px: 0.6 deg across
    pp = pass_params(Mission((t,), narrow, settings=Settings()))[0]
    assert tower_columns(t.tower_base_radius, pp) == 16
    pp = pass_params(Mission((t,), P1_35, settings=Settings()))[0]
    assert tower_columns(t.tower_base_radius, pp) == 4


def test_unit_order_is_the_shortest_of_every_order_and_direction():
    """The nacelle's faces: the dynamic programme against trying every order and direction."""
    import itertools

    from wtcli.plan.paths import _unit_order
    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 5):
        for _ in range(5):
            cost = rng.uniform(0, 50, (2 * n, 2 * n))
            first = rng.uniform(0, 50, 2 * n)

            def total(plan):
                nodes = [(2 * i + f, 2 * i + 1 - f) for i, f in plan]
                return first[nodes[0][0]] + sum(cost[a[1], b[0]] for a, b in zip(nodes, nodes[1:]))

            best = min(total(list(zip(order, flips)))
                       for order in itertools.permutations(range(n))
                       for flips in itertools.product((0, 1), repeat=n))
            got = _unit_order(cost, first)
            assert sorted(i for i, _ in got) == list(range(n))
            assert total(got) == pytest.approx(best)


def _plan_segmenter_checks_only(monkeypatch, inst=None):
    """The torch segmenter stood in for by its own size checks (post.working_image), then
    ``inst``: a photo it refuses is refused before any network runs."""
    from wtcli.segment import infer, post

    def segment_image(image, **kw):
        post.working_image(image, 0.5, None)
        return inst

    monkeypatch.setattr(infer, "segment_image", segment_image)


@pytest.mark.parametrize("size, why", [((1, 1), "image is too small (1x1)"),
                                       ((9, 2000), "image is too narrow (2000x9)")])
def test_cli_plan_names_a_photo_the_segmenter_refuses(cli, tmp_path, monkeypatch, size, why):
    import cv2

    _plan_segmenter_checks_only(monkeypatch)
    photo = tmp_path / "tiny.jpg"
    cv2.imwrite(str(photo), np.full(size + (3,), (30, 90, 200), np.uint8))
    r = cli("plan", SAMPLE, f"T1={photo}")
    assert r.exit_code == 3, r.output
    assert r.stderr == f"error: {photo}: {why}" + r.stderr.split(why, 1)[1]
    assert r.stderr.count("\n") == 1 and r.stderr.count(str(photo)) == 1


def test_cli_plan_lines_on_stderr_are_one_line_in_a_log(cli, tmp_path, monkeypatch):
    """stderr not a terminal (a log): "T2: blade azimuths ... from PHOTO" and "plan -> OUT"
    stay one line each however long the path (the console's 80 columns would wrap them)."""
    import cv2

    from wtcli.geometry.projection import instance_masks
    from wtcli.masks import Instances

    t = load_mission(SAMPLE).turbine("T2")
    inst = instance_masks(t, default_photo_camera(t, Camera(800, 600, 16, 23.2)))
    _plan_segmenter_checks_only(monkeypatch, Instances(np.array([i[0] for i in inst], dtype=object),
                                                       np.array([i[2] for i in inst])))
    deep = tmp_path / ("a_long_folder_name_" * 6)
    deep.mkdir()
    photo = deep / "t2.png"
    cv2.imwrite(str(photo), np.full((600, 800, 3), 200, np.uint8))
    r = cli("plan", SAMPLE, f"T2={photo}", "--out", deep / "plan.json")
    assert r.exit_code == 0, r.output
    lines = r.stderr.splitlines()
    assert any(line.startswith("T2: blade azimuths ") and f"from {photo}" in line
               for line in lines), lines
    assert f"plan -> {deep / 'plan.json'}" in lines


def test_cli_plan_says_a_dangling_photo_link_is_one(cli, tmp_path):
    (tmp_path / "gone.jpg").symlink_to(tmp_path / "missing.jpg")
    r = cli("plan", SAMPLE, f"T1={tmp_path / 'gone.jpg'}")
    assert r.exit_code == 3 and "gone.jpg: broken symbolic link" in r.stderr
    (tmp_path / "gone.json").symlink_to(tmp_path / "missing.json")  # a pitch JSON, and contours
    r = cli("plan", SAMPLE, f"T1={tmp_path / 'gone.json'}")
    assert r.exit_code == 3 and "gone.json: broken symbolic link" in r.stderr
    r = cli("contours", tmp_path / "gone.json")
    assert r.exit_code == 3 and "gone.json: broken symbolic link" in r.stderr


def test_exports_without_an_origin_and_an_odd_picture_are_refused_before_planning(cli, tmp_path):
    import yaml

    doc = yaml.safe_load(SAMPLE.read_text())
    doc.get("site", {}).pop("origin", None)
    y = tmp_path / "noorigin.yaml"
    y.write_text(yaml.safe_dump(doc))
    r = cli("plan", y, "--export-dir", tmp_path / "ex")
    assert r.exit_code == 4 and f"{y}: --export-dir writes lat/lon" in r.stderr
    assert "plan ->" not in r.stderr and not (tmp_path / "ex").exists()
    r = cli("plan", SAMPLE, "--picture", tmp_path / "p.gif")
    assert r.exit_code == 2 and "expected a .png or .jpg" in r.stderr


def test_the_picture_is_encoded_as_its_name_says(cli, tmp_path):
    r = cli("plan", SAMPLE, "--picture", tmp_path / "p.jpg")
    assert r.exit_code == 0, r.stderr
    assert (tmp_path / "p.jpg").read_bytes()[:2] == b"\xff\xd8"
