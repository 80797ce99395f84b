"""The flight simulator: determinism, tracking, wind rejection, safety checks, failure modes, CLI.

Plans are built in code (a straight line, a pass along an upright blade) so these tests only
depend on the plan file's types, not on the planner.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from wtcli.errors import ConfigError, SimulationError
from wtcli.fly.flight import fly_plan, path_deviation, turbine_clearance
from wtcli.fly.scenario import default_scenario, load_scenario, shipped_scenarios
from wtcli.fly.navigation import make_navigation
from wtcli.fly.sim import fly, make_controller, make_reference
from wtcli.fly.wind import dryden_params, dryden_series, gust_series, make_wind
from wtcli.geometry import Camera, Turbine
from wtcli.plan_file import Plan, Route, write_plan

CAM = Camera(5456, 3632, 16, 23.2)


def turbine(**kw) -> Turbine:
    base = dict(id="T1", base=(0, 0, 0), hub_height=60, rotor_diameter=60, yaw_deg=0)
    base.update(kw)
    return Turbine.with_rotor_azimuth(90, **base)  # blade 1 straight up, rotor facing north


def route_through(points, speed=2.0, yaw=180.0, pitch=0.0, photo=None, component="T1/blade1",
                  uav="UAV1") -> Route:
    pts = np.asarray(points, float)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    t = np.r_[0.0, np.cumsum(seg / speed)]
    m = len(pts)
    return Route(uav=uav, t=t, pos=pts, speed=np.full(m, speed), yaw_deg=np.full(m, yaw),
                 gimbal_pitch_deg=np.full(m, pitch),
                 photo=np.zeros(m, bool) if photo is None else np.asarray(photo, bool),
                 component=np.full(m, component, dtype=object))


def line_plan(length=120.0, z=50.0, y=60.0, speed=3.0, step=10.0) -> Plan:
    """A straight east-west line well away from the turbine (no photos of interest)."""
    x = np.arange(-length / 2, length / 2 + 1e-9, step)
    pts = np.stack([x, np.full_like(x, y), np.full_like(x, z)], 1)
    return Plan([turbine()], CAM, [route_through(pts, speed)], safe_distance_m=3.0,
                target_gsd_mm=1.5)


def blade_pass_plan(distance=5.5, speed=1.5, safe=3.0) -> Plan:
    """Up the front of the upright blade at ``distance`` from its axis, photos every 2 m."""
    t = turbine()
    hub = t.hub_center
    z = np.arange(hub[2] + 4, hub[2] + t.tip_radius, 2.0)
    y = hub[1] + distance
    pts = np.stack([np.full_like(z, hub[0]), np.full_like(z, y), z], 1)
    return Plan([t], CAM, [route_through(pts, speed, photo=np.ones(len(z), bool),
                                         component="T1/blade1/leading_edge")],
                safe_distance_m=safe, target_gsd_mm=1.5)


QUIET = dict(vehicle={"position_noise_m": 0.0, "velocity_noise_ms": 0.0}, positioning={"mode": "ideal"})


# ---- scenario ----------------------------------------------------------------------------------

def test_shipped_scenarios_load_and_name_their_missions():
    shipped = shipped_scenarios()
    assert {"paper-s1", "paper-s2", "paper-s3", "paper-s4", "tiny"} <= set(shipped)
    for name, path in shipped.items():
        s = load_scenario(path)
        assert s.mission is not None and s.mission.exists(), name
        if name.startswith("paper-"):
            assert s.paper["manual"]["time_min"] > s.paper["automated"]["time_min"]
    s2 = load_scenario(shipped["paper-s2"])
    assert s2.terrain.kind == "hilly" and 8 <= s2.wind.speed_ms <= 12


def test_scenario_unknown_key_gets_a_hint(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("wind:\n  sped_ms: 3\n")
    with pytest.raises(ConfigError, match=r"did you mean 'speed_ms'"):
        load_scenario(p)


def test_scenario_value_out_of_range_names_key_and_range(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("vehicle:\n  max_tilt_deg: 80\n")
    with pytest.raises(ConfigError, match=r"vehicle.max_tilt_deg: expected a number in \[5, 60\]"):
        load_scenario(p)
    p.write_text("terrain: {kind: hily}\n")
    with pytest.raises(ConfigError, match="did you mean 'hilly'"):
        load_scenario(p)


# ---- wind --------------------------------------------------------------------------------------

def test_dryden_series_has_the_model_variance_and_is_seeded():
    scn = default_scenario(wind={"speed_ms": 10, "reference_height_m": 100,
                                 "turbulence": {"intensity": "moderate"}})
    p = dryden_params(scn.wind, 100.0)
    # MIL-HDBK-1797 low altitude: sigma_w = 0.1 W20 (moderate: 30 kt), sigma_u = sigma_w / k^0.4.
    assert p.sigma_w == pytest.approx(0.1 * 30 * 0.514444, rel=1e-6)
    h = 100 / 0.3048
    assert p.sigma_u == pytest.approx(p.sigma_w / (0.177 + 0.000823 * h) ** 0.4, rel=1e-6)
    assert p.L_w == pytest.approx(100.0)
    a = dryden_series(p, 400_000, 0.05, np.random.default_rng(3))
    b = dryden_series(p, 400_000, 0.05, np.random.default_rng(3))
    assert np.array_equal(a, b)
    assert a.std(0) == pytest.approx([p.sigma_u, p.sigma_v, p.sigma_w], rel=0.15)


def test_one_minus_cosine_gust_peaks_at_its_amplitude():
    scn = default_scenario(wind={"gusts": {"rate_per_min": 1, "amplitude_ms": 3, "duration_s": 4}})
    g, gusts = gust_series(scn.wind, 60_000, 0.01, np.random.default_rng(0))
    assert gusts and g.min() >= 0
    t0 = gusts[0][0]
    assert gusts[1][0] > t0 + 4  # the first gust stands alone
    k0 = int(math.ceil(t0 / 0.01))
    assert g[k0 + 200] == pytest.approx(3.0, abs=1e-3)  # peak in the middle
    assert g[k0] < 0.01 and g[k0 + 400] < 0.01  # 1-cosine: zero at both ends


# ---- flying ------------------------------------------------------------------------------------

def test_same_seed_same_flight_other_seed_other_flight():
    plan = blade_pass_plan()
    scn = default_scenario(wind={"speed_ms": 8, "reference_height_m": 60,
                                 "turbulence": {"intensity": "moderate"},
                                 "gusts": {"rate_per_min": 2, "amplitude_ms": 2}})
    a = fly_plan(plan, scn).automated
    b = fly_plan(plan, scn).automated
    c = fly_plan(plan, scn.with_seed(1)).automated
    assert np.array_equal(a.uavs[0].track.pos, b.uavs[0].track.pos)
    assert a.to_dict() == b.to_dict()
    pa, pc = a.uavs[0].track.pos, c.uavs[0].track.pos  # the set-point's wait differs: so may the length
    m = min(len(pa), len(pc))
    assert not np.allclose(pa[:m], pc[:m])


def test_straight_line_without_wind_tracks_within_centimetres():
    rep = fly_plan(line_plan(), default_scenario(**QUIET))
    f = rep.automated
    # The rigid body lags its set-point where the speed changes (attitude and rotor lag).
    assert f.deviation.max() < 0.06
    assert f.deviation.mean() < 0.005
    assert f.path_length_m == pytest.approx(120.0, abs=0.5)
    # The kinematic model realises each commanded acceleration at once: no lag at all.
    kin = fly_plan(line_plan(), default_scenario(**{**QUIET, "vehicle": {
        **QUIET["vehicle"], "model": "kinematic"}}))
    assert kin.automated.deviation.max() < 1e-6


def test_pid_beats_feedforward_in_steady_wind():
    scn = default_scenario(wind={"speed_ms": 8, "reference_height_m": 50, "direction_deg": 0,
                                 "turbulence": {"model": "none"}}, **QUIET)
    seen = []
    rep = fly_plan(line_plan(), scn, baselines=True, progress=lambda *x: seen.append(x))
    pid, ff = rep.automated, rep.flights["no_compensation"]
    assert pid.deviation.mean() < 0.15
    assert ff.deviation.mean() > 10 * pid.deviation.mean()
    assert ff.deviation.mean() > 2.0
    # One progress stage per flight kind flown, counting its route and then its measurement.
    kinds = [k for k, done, _ in seen if done == 0]
    assert kinds == list(rep.flights) and kinds[:2] == ["automated", "no_compensation"]
    assert [x for x in seen if x[0] == "automated"] == [("automated", i, 2) for i in range(3)]


def test_strong_turbulent_wind_blade_pass_stays_close_and_covers_the_blade():
    plan = blade_pass_plan()
    scn = default_scenario(wind={"speed_ms": 10, "reference_height_m": 60, "direction_deg": 180,
                                 "turbulence": {"intensity": "moderate"},
                                 "gusts": {"rate_per_min": 2, "amplitude_ms": 2}})
    f = fly_plan(plan, scn).automated
    assert f.deviation.mean() < 0.5
    assert f.min_clearance_m > plan.safe_distance_m and not f.violations
    le = f.coverage["T1"].by_blade_side()["blade1"]["leading_edge"]
    assert le > 0.9  # the pass looks straight at blade 1's leading edge (feathered: faces front)


def test_gimbal_stops_at_the_vehicles_limit_and_the_report_says_so():
    """A plan made for a gimbal that looks up 60 deg, flown by one that stops at +30: the photos
    are taken at +30 and the report counts the photos that asked for more."""
    route = blade_pass_plan().routes[0]
    plan = blade_pass_plan()
    plan.routes[0] = route_through(route.pos, 1.5, pitch=60.0, photo=route.photo,
                                   component="T1/blade1/leading_edge")
    free = fly_plan(plan, default_scenario(**QUIET)).automated
    assert free.uavs[0].photo_pitch_deg.min() > 55 and not any("gimbal" in n for n in free.notes)
    limited = fly_plan(plan, default_scenario(vehicle={**QUIET["vehicle"],
                                                        "gimbal_pitch_max_deg": 30.0})).automated
    assert limited.uavs[0].photo_pitch_deg.max() <= 30.0 + 1e-9
    n = int(route.photo.sum())
    assert any(f"{n} of {n} photos ask the gimbal for pitch beyond the vehicle's [-90, +30] deg "
               "(up to +60)" in note for note in limited.notes)


def test_clearance_violation_is_detected_when_forced():
    plan = blade_pass_plan(distance=2.0, safe=3.0)  # planned inside the safe distance
    f = fly_plan(plan, default_scenario(**QUIET)).automated
    assert f.violations and f.violations[0].kind == "clearance"
    assert f.violations[0].worst_m < 3.0 and f.violations[0].what == "T1/blade1"
    assert f.min_clearance_m == pytest.approx(f.violations[0].worst_m)


def test_clearance_is_the_projects_one_clearance_and_matches_the_turbine_model():
    from wtcli.plan.clearance import HORIZON_M, clearance_to_parts

    t = turbine()
    rng = np.random.default_rng(0)
    P = t.hub_center + rng.normal(size=(500, 3)) * 40
    c, part = turbine_clearance([t], P)
    c_ref, part_ref = clearance_to_parts([t], P)
    assert np.array_equal(c, c_ref) and list(part) == list(part_ref)
    near = c < 30  # exact near the turbine, capped (a lower bound) far away
    assert np.allclose(c[near], t.clearance(P[near])) and (c <= t.clearance(P) + 1e-9).all()
    assert c.max() <= HORIZON_M


def test_path_deviation_of_known_offsets():
    path = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0]], float)
    pos = np.array([[5, 1, 0], [11, 5, 0], [10, 12, 0]], float)
    d = path_deviation(path, np.array([0, 1, 1]), pos)
    assert d == pytest.approx([1, 1, 2])


def test_wind_beyond_the_vehicle_fails_loudly():
    scn = default_scenario(wind={"speed_ms": 40, "reference_height_m": 50,
                                 "turbulence": {"model": "none"}})
    with pytest.raises(SimulationError, match="diverged"):
        fly_plan(line_plan(), scn)


def test_non_finite_state_fails_loudly_not_nan():
    plan = line_plan()
    scn = default_scenario()
    r = plan.routes[0]
    ref = make_reference(r.t, r.pos, r.yaw_deg, r.gimbal_pitch_deg, 0.02, 0.3)
    wind = make_wind(scn.wind, 1.0, len(ref.t) * 2, 0.01, 50, np.random.default_rng(0))
    extra = wind.extra.copy()
    extra[1000:] = np.nan
    from dataclasses import replace
    with pytest.raises(SimulationError, match="diverged"):
        fly(ref, scn, replace(wind, extra=extra), np.zeros(len(ref.t)),
            make_controller("pid", ref, scn),
            make_navigation("ideal", len(ref.t), 0.02, np.random.default_rng(0), 0.02, 0.05))


def test_manual_pilot_is_slower_and_less_precise():
    plan = blade_pass_plan()
    scn = default_scenario(wind={"speed_ms": 5, "reference_height_m": 60})
    rep = fly_plan(plan, scn, baselines=True)
    auto, man = rep.automated, rep.flights["manual"]
    assert man.time_s > 2 * auto.time_s
    assert man.deviation.mean() > 3 * auto.deviation.mean()
    assert man.photos == auto.photos


def test_report_json_is_clean_and_has_the_schema(tmp_path, cli):
    plan_path = tmp_path / "plan.json"
    write_plan(plan_path, blade_pass_plan())
    scn = tmp_path / "s.yaml"
    scn.write_text("wind: {speed_ms: 6, reference_height_m: 60}\nbaselines: {fixed_pattern: false}\n")
    res = cli("fly", plan_path, "--scenario", scn, "--json", "--baselines",
              "--pictures", tmp_path / "pics", "--out", tmp_path / "r.json")
    assert res.exit_code == 0, res.stderr
    doc = json.loads(res.stdout)
    assert doc["schema"] == "wtinspect.flight" and doc["schema_version"] == 1
    assert set(doc["flights"]) == {"automated", "no_compensation", "manual"}
    a = doc["flights"]["automated"]
    for key in ("time_s", "path_length_m", "deviation_m", "clearance", "coverage", "photos",
                "battery"):
        assert key in a
    assert json.loads((tmp_path / "r.json").read_text()) == doc
    assert "NaN" not in res.stdout and "Infinity" not in res.stdout
    for name in ("path.png", "deviation.png", "coverage.png"):
        assert (tmp_path / "pics" / name).stat().st_size > 1000


def test_cli_fail_on_violation_exits_8(tmp_path, cli):
    plan_path = tmp_path / "plan.json"
    write_plan(plan_path, blade_pass_plan(distance=2.0))
    res = cli("fly", plan_path, "--scenario", "tiny", "--fail-on-violation")
    assert res.exit_code == 8
    assert "clearance" in res.stderr
    res = cli("fly", plan_path, "--scenario", "tiny")
    assert res.exit_code == 0


def test_cli_needs_a_scenario(cli, tmp_path):
    res = cli("fly")
    assert res.exit_code == 2
    res = cli("fly", "--scenario", tmp_path / "missing.yaml")
    assert res.exit_code == 3  # a missing input file (docs/exit-codes.md)
    res = cli("fly", "--scenario", "no-such-scenario")  # neither a file nor a shipped name
    assert res.exit_code == 4 and "no-such-scenario" in res.stderr


@pytest.mark.slow
def test_twenty_minute_flight_in_turbulence_stays_on_its_path():
    # A 20-minute pass pattern: up and down a 60 m line at 1 m/s, with photos (the case
    # benchmarks/fly_speed.py times; speed is a benchmark figure, not a test).
    z = np.r_[np.linspace(10, 70, 31), np.linspace(70, 10, 31)[1:]]
    pts = np.stack([np.zeros_like(z), np.full_like(z, 40.0), z], 1)
    pts = np.concatenate([pts] * 10)
    plan = Plan([turbine()], CAM, [route_through(pts, 1.0, photo=np.ones(len(pts), bool))], 3.0, 1.5)
    assert plan.routes[0].duration_s >= 1200 - 60
    scn = default_scenario(wind={"speed_ms": 10, "reference_height_m": 60,
                                 "turbulence": {"intensity": "moderate"}})
    auto = fly_plan(plan, scn).automated
    assert auto.time_s >= plan.routes[0].duration_s - 1.0
    assert len(auto.deviation) >= 50 * 1140  # one record per 50 Hz control step, all flight long
    assert auto.deviation.max() < 1.0 and not auto.violations


@pytest.mark.slow
def test_paper_strong_wind_scenario_meets_the_done_criteria():
    """paper-s2 (8-12 m/s, turbulence, gusts, hills): mean deviation <= 0.5 m, no violation,
    measured coverage >= 97 %; the manual pilot is slower and strays more."""
    pytest.importorskip("wtcli.plan.mission")
    from wtcli.fly.run import paper_table

    (row,) = paper_table(names=("paper-s2",))
    auto = row.report.automated
    assert auto.deviation.mean() <= 0.5
    assert not auto.violations and auto.min_clearance_m >= auto.safe_distance_m
    assert auto.coverage_average >= 0.97
    assert row.ours["manual"]["time_min"] > row.ours["automated"]["time_min"]
    assert row.ours["manual"]["deviation_m"] > 5 * row.ours["automated"]["deviation_m"]


def test_set_point_follows_the_path_and_slows_for_corners():
    pts = np.array([[0, 0, 20], [30, 0, 20], [30, 30, 20], [0, 30, 20]], float)
    r = route_through(pts, speed=5.0)
    ref = make_reference(r.t, r.pos, r.yaw_deg, r.gimbal_pitch_deg, 0.02, 0.3, accel=2.5,
                         corner_m=0.05)
    seg = np.clip(np.floor(ref.wp_index).astype(int), 0, len(pts) - 2)
    assert path_deviation(pts, seg, ref.pos).max() < 0.05
    speed = np.linalg.norm(ref.vel, axis=1)
    assert speed.max() == pytest.approx(5.0, abs=0.05)
    at_corner = ref.reach_step([1, 2])
    assert (speed[at_corner] < 1.0).all()  # a 90-degree corner is taken slowly
    acc = np.linalg.norm(np.diff(ref.vel, axis=0) / 0.02, axis=1)
    assert acc.max() < 9.81 * math.tan(math.radians(30))  # within what the vehicle can do


def test_plan_speed_and_hover_at_the_end_of_a_leg():
    """A leg whose planned time exceeds its length / speed ends in a hover (a battery swap)."""
    pts = np.array([[0, 0, 20], [20, 0, 20], [20, 0, 0.0]], float)
    r = Route("UAV1", np.array([0.0, 10.0, 200.0]), pts, np.array([0.0, 2.0, 2.0]),
              np.zeros(3), np.zeros(3), np.zeros(3, bool), np.array(["a", "b", "launch"], object))
    ref = make_reference(r.t, r.pos, r.yaw_deg, r.gimbal_pitch_deg, 0.02, 0.0, accel=2.5,
                         speed=r.speed)
    k = ref.reach_step([2])[0]
    assert ref.t[k] < 30  # down at 2 m/s, not spread over the 190 s
    assert ref.t[ref.end_index - 1] == pytest.approx(200, abs=2)  # + time to speed up, slow down


def test_a_planned_route_is_flown_in_its_planned_time():
    """The planner times each leg with its speed changes and corners; the set-point flies the
    commanded speeds with the same ones, so they are not counted twice (a pass of short photo
    legs took ~10 % longer than planned when the plan's speed was a leg's average)."""
    from wtcli.plan.mission import ACCEL_M_S2, CORNER_M, _flown_leg_times

    ang = np.radians(np.arange(0, 181, 6.0))  # a half ring of photo legs, then a straight return
    pts = np.c_[20 * np.cos(ang), 20 * np.sin(ang), np.full(len(ang), 30.0)]
    pts = np.vstack([pts, [[-20.0, -40.0, 30.0]]])
    v = np.r_[np.full(len(ang) - 1, 2.5), 8.0]
    dt = _flown_leg_times(pts, v, 3.0)
    r = Route("UAV1", np.r_[0.0, np.cumsum(dt)], pts, np.r_[0.0, v], np.zeros(len(pts)),
              np.zeros(len(pts)), np.zeros(len(pts), bool), np.array(["a"] * len(pts), object))
    ref = make_reference(r.t, r.pos, r.yaw_deg, r.gimbal_pitch_deg, 0.02, 0.0, accel=ACCEL_M_S2,
                         corner_m=CORNER_M, speed=r.speed, settle_s=0.0)
    assert dt.sum() > (np.linalg.norm(np.diff(pts, axis=0), axis=1) / v).sum() + 2  # they cost time
    assert ref.t[ref.end_index - 1] == pytest.approx(r.t[-1], abs=0.05)


def test_the_planners_route_is_its_set_points_time():
    """A whole planned inspection (passes, rings, camera turns, transits): fly's set-point, with
    the default vehicle's yaw and gimbal rates, takes the time the plan's battery decisions
    rest on (they differed by 10 % when the plan's speed was a leg's average speed and camera
    turns were not timed)."""
    from wtcli.plan.config import Mission, Settings
    from wtcli.plan.mission import plan_mission

    plan = plan_mission(Mission((Turbine("T1", (0.0, 0.0, 0.0), 60.0, 60.0, 180.0, (80.0, 200.0, 320.0)),),
                                CAM, settings=Settings(min_side_coverage=0.0)))
    scn = default_scenario()
    c, v = scn.control, scn.vehicle
    r = plan.routes[0]
    ref = make_reference(r.t, r.pos, r.yaw_deg, r.gimbal_pitch_deg, 1.0 / c.control_hz,
                         c.reference_smoothing_s, c.reference_accel_ms2, c.corner_deviation_m,
                         speed=r.speed, yaw_rate=v.yaw_rate_deg_s, pitch_rate=v.gimbal_rate_deg_s,
                         settle_s=0.0)
    assert ref.t[ref.end_index - 1] == pytest.approx(r.t[-1], rel=0.005)


def test_manual_route_hovers_per_photo_and_keeps_the_geometry():
    from wtcli.fly.pilot import manual_route

    plan = blade_pass_plan()
    r = plan.routes[0]
    scn = default_scenario()
    m, _ = manual_route(r, scn.manual_pilot)
    assert m.photo.sum() == r.photo.sum()
    assert m.length_m == pytest.approx(r.length_m)
    hover = scn.manual_pilot.hover_per_photo_s * r.photo.sum()
    assert m.duration_s >= r.duration_s / scn.manual_pilot.speed_factor + hover - 1e-6


def test_low_transit_over_hills_is_a_violation():
    t = turbine()
    pts = np.array([[-400, 200, 0.5], [-400, 200, 12], [400, 200, 12], [400, 200, 0.5]], float)
    r = route_through(pts, speed=8.0, component="transit")
    plan = Plan([t], CAM, [r], 3.0, 1.5)
    scn = default_scenario(terrain={"kind": "hilly", "amplitude_m": 40, "wavelength_m": 300,
                                    "min_transit_agl_m": 20}, **QUIET)
    f = fly_plan(plan, scn).automated
    kinds = {v.kind for v in f.violations}
    assert kinds & {"ground", "transit_altitude"}
    flat = fly_plan(plan, default_scenario(terrain={"min_transit_agl_m": 10}, **QUIET)).automated
    assert not flat.violations


def _corner_in_a_headwind_gust(leash_m: float, gust_ms: float = 10.0):
    """A right-angle corner at 6 m/s with a headwind gust in the 4.5 s before it, flown with and
    without the set-point waiting for the vehicle. Returns (path deviation, reference flown)."""
    from dataclasses import replace
    P = np.array([[0, 0, 50], [60, 0, 50], [60, 60, 50]], float)
    scn = default_scenario(wind={"speed_ms": 0.0, "turbulence": {"model": "none"}, "wake": False},
                           positioning={"mode": "ideal"}, control={"leash_m": leash_m},
                           vehicle={"position_noise_m": 0.0, "velocity_noise_ms": 0.0})
    ref = make_reference(np.array([0.0, 10.0, 20.0]), P, np.zeros(3), np.zeros(3), 0.02, 0.3,
                         settle_s=40.0)
    n, sub = len(ref.t), scn.substeps
    wind = make_wind(scn.wind, 1.0, n * sub, 0.02 / sub, 50, np.random.default_rng(0))
    t = np.arange(n * sub) * 0.02 / sub
    extra = np.zeros((n * sub, 3))
    extra[(t > 6.0) & (t < 10.5), 0] = -gust_ms
    nav = make_navigation("ideal", n, 0.02, np.random.default_rng(0), 0.0, 0.0)
    track = fly(ref, scn, replace(wind, extra=extra), np.zeros(n), make_controller("pid", ref, scn),
                nav)
    flown = ref.retimed(track.progress, 0.02) if track.progress is not None else ref
    seg = np.floor(flown.wp_index[:len(track.pos)]).astype(int)
    return path_deviation(P, seg, track.pos), flown, ref


def test_set_point_waits_for_the_vehicle_so_a_gust_does_not_cut_the_corner():
    free, _, ref = _corner_in_a_headwind_gust(0.0)
    held, flown, _ = _corner_in_a_headwind_gust(2.0)
    # Without the leash the set-point turns the corner while the gust holds the vehicle back and
    # the vehicle cuts across (0.74 m); held back, it turns nearer where the path does (0.36 m).
    assert free.max() > 0.5
    assert held.max() < 0.4 and held.max() < 0.55 * free.max()
    assert flown.end_index > ref.end_index + 50  # the set-point waited (> 1 s)
    # Retimed reference: starts and ends where the route does, never runs backwards.
    assert np.allclose(flown.pos[0], ref.pos[0]) and np.allclose(flown.pos[-1], ref.pos[-1])
    assert np.all(np.diff(flown.wp_index) >= -1e-12)
