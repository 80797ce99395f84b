"""What `fly` checks on the plan it is given and reports about the flight: non-finite and out-of-
range numbers refused before flying, the planned path re-checked against the turbine model
(collisions refused, clearance breaches reported, every one with its kind and time), the
tracking margin against the 99.9th-percentile deviation, and sorties that eat into the battery
reserve.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from wtcli.errors import InputError, PlanError
from wtcli.fly.flight import fly_plan, plan_violations
from wtcli.fly.scenario import default_scenario
from wtcli.plan_file import Plan, write_plan
from tests.test_fly import CAM, QUIET, blade_pass_plan, line_plan, route_through, turbine


def through_the_tower_plan() -> Plan:
    """A level line at 20 m that passes straight through the tower (an edited plan)."""
    pts = np.array([[-30.0, 0.0, 20.0], [-10.0, 0.0, 20.0], [0.0, 0.0, 20.0], [10.0, 0.0, 20.0],
                    [30.0, 0.0, 20.0]])
    return Plan([turbine()], CAM, [route_through(pts, 2.0)], safe_distance_m=3.0,
                target_gsd_mm=1.5)


def test_nan_and_infinite_plan_numbers_are_refused_before_flying_as_input_errors(tmp_path, cli):
    good = tmp_path / "plan.json"
    write_plan(good, line_plan())
    text = good.read_text()
    doc = json.loads(text)
    bad_safe = tmp_path / "nan_safe.json"
    bad_safe.write_text(text.replace(f'"safe_distance_m": {doc["safe_distance_m"]}',
                                     '"safe_distance_m": NaN'))
    d2 = json.loads(text)
    d2["turbines"][0]["hub_height"] = 1e300
    bad_hub = tmp_path / "huge_hub.json"
    bad_hub.write_text(json.dumps(d2))
    d3 = json.loads(text)
    d3["routes"][0]["waypoints"][1]["pos"][2] = "Infinity"
    bad_wp = tmp_path / "inf_wp.json"
    bad_wp.write_text(json.dumps(d3).replace('"Infinity"', "Infinity"))
    for path, what in ((bad_safe, "NaN"), (bad_hub, "hub_height"), (bad_wp, "Infinity")):
        res = cli("fly", path, "--scenario", "tiny", "--out", tmp_path / "r.json")
        assert res.exit_code == 3, (path.name, res.exit_code, res.stderr)
        assert path.name in res.stderr and what in res.stderr
        assert len(res.stderr.strip().splitlines()) == 1
        assert not (tmp_path / "r.json").exists()  # refused before flying


def test_a_plan_through_the_tower_is_a_collision_refused_before_flying(tmp_path, cli):
    plan = through_the_tower_plan()
    v = plan_violations(plan)
    kinds = [x.kind for x in v]
    assert "collision" in kinds and "clearance" in kinds  # approach, inside, leave
    hit = next(x for x in v if x.kind == "collision")
    assert hit.what == "T1/tower" and hit.worst_m == 0.0
    # The tower is hit around x = 0, reached after 30 m at 2 m/s.
    assert 13.0 < hit.t_start < 15.0 < hit.t_end < 17.0
    with pytest.raises(PlanError, match=r"collision with T1/tower at t=1[34]\.\d-1[56]\.\d s"):
        fly_plan(plan, default_scenario())
    path = tmp_path / "plan.json"
    write_plan(path, plan)
    res = cli("fly", path, "--scenario", "tiny", "--out", tmp_path / "r.json")
    assert res.exit_code == 6, res.stderr
    assert "collision with T1/tower" in res.stderr and "clearance 0.0" not in res.stderr
    assert not (tmp_path / "r.json").exists()


def test_every_clearance_breach_of_the_plan_and_the_flight_is_reported_with_kind_and_time(tmp_path,
                                                                                          cli):
    # Two separate passes at 2 m from the blade (safe distance 3 m): two episodes each.
    one = blade_pass_plan(distance=2.0).routes[0]
    back = one.pos[::-1] + np.array([0.0, 6.0, 0.0])  # away from the blade, then a second pass
    pts = np.concatenate([one.pos, back, one.pos])
    plan = replace(blade_pass_plan(distance=2.0), routes=[route_through(pts, 1.5)])
    pre = plan_violations(plan)
    assert [v.kind for v in pre] == ["clearance", "clearance"]
    assert pre[0].t_end < pre[1].t_start
    rep = fly_plan(plan, default_scenario(**QUIET))
    assert len(rep.preflight) == 2
    warned = rep.warnings()
    assert sum(w.startswith("plan: clearance") for w in warned) == 2
    flown = [w for w in warned if w.startswith("automated: clearance")]
    assert len(flown) == len(rep.automated.violations) >= 2
    path = tmp_path / "plan.json"
    write_plan(path, plan)
    res = cli("fly", path, "--scenario", "tiny", "--out", tmp_path / "r.json")
    assert res.exit_code == 0, res.stderr
    assert res.stderr.count("warning: plan: clearance") == 2
    assert res.stderr.count("warning: automated: clearance") >= 2
    doc = json.loads((tmp_path / "r.json").read_text())
    assert [v["kind"] for v in doc["preflight"]["violations"]] == ["clearance", "clearance"]
    for v in doc["preflight"]["violations"]:
        assert v["t_start_s"] <= v["t_end_s"] and v["what"] == "T1/blade1"
    res = cli("fly", path, "--scenario", "tiny", "--fail-on-violation")
    assert res.exit_code == 8 and "clearance" in res.stderr


def test_a_plan_from_the_planner_has_no_preflight_violation():
    # A pass outside the safe distance (what the planner writes).
    assert plan_violations(blade_pass_plan(distance=5.5)) == []


def test_deviation_beyond_the_tracking_margin_is_a_warning():
    plan = line_plan()
    scn = default_scenario(wind={"speed_ms": 12, "reference_height_m": 50})
    tight = replace(plan, summary={"tracking_margin_m": 0.001})
    loose = replace(plan, summary={"tracking_margin_m": 50.0})
    a = fly_plan(tight, scn).automated
    assert a.to_dict()["deviation_m"]["within_margin"] is False
    assert any("tracking_margin_m" in w for w in a.warnings())
    b = fly_plan(loose, scn).automated
    assert b.to_dict()["deviation_m"]["within_margin"] is True
    assert not any("tracking_margin_m" in w for w in b.warnings())
    assert a.deviation_p999 == pytest.approx(np.percentile(a.deviation, 99.9))
    assert fly_plan(plan, scn).automated.to_dict()["deviation_m"]["within_margin"] is None


def test_a_sortie_that_eats_into_the_reserve_is_reported_and_warned():
    plan = line_plan()  # about 40 s of flight
    scn = default_scenario()
    short = replace(plan, summary={"battery_minutes": 0.8, "battery_reserve_minutes": 0.5})
    ample = replace(plan, summary={"battery_minutes": 30.0, "battery_reserve_minutes": 5.0})
    a = fly_plan(short, scn).automated
    s = a.to_dict()["battery"]["sorties_flown"]
    assert len(s) == 1 and s[0]["reserve_intact"] is False and s[0]["time_s"] > 18.0
    assert any("ate into the battery reserve" in w for w in a.warnings())
    assert any("battery reserve was eaten" in n for n in a.notes)
    b = fly_plan(ample, scn).automated
    assert b.to_dict()["battery"]["sorties_flown"][0]["reserve_intact"] is True
    assert not any("reserve" in w for w in b.warnings())


def test_plan_summary_numbers_fly_reads_are_checked(tmp_path, cli):
    path = tmp_path / "plan.json"
    write_plan(path, replace(line_plan(), summary={"battery_minutes": -3}))
    res = cli("fly", path, "--scenario", "tiny")
    assert res.exit_code == 3 and "battery_minutes" in res.stderr


def test_legs_and_sorties_beyond_the_vehicle_are_refused_before_flying():
    import time
    from wtcli.errors import InputError
    scn = default_scenario(**QUIET)
    # One waypoint moved 100 km by hand: the leg into it would take 6667 s at 15 m/s.
    plan = line_plan()
    r = plan.routes[0]
    pos = np.array(r.pos, float)
    pos[3, 0] += 1e5
    moved = replace(plan, routes=[replace(r, pos=pos)])
    t0 = time.perf_counter()
    with pytest.raises(InputError, match=r"edited\.json: routes\[0\]\.waypoints\[3\] is 100\d+ m"):
        fly_plan(moved, scn, plan_source="edited.json")
    assert time.perf_counter() - t0 < 5.0  # refused up front, not after minutes of flying
    # Timed consistently (15 m/s) but 120 km in one sortie: 133 min against the battery's 45.
    far = line_plan(length=120_000.0, speed=15.0, step=2_000.0)
    with pytest.raises(InputError, match=r"sortie of at least 133 min"):
        fly_plan(far, scn, plan_source="far.json")
    # The same line at its own 120 m flies.
    assert fly_plan(line_plan(), scn).automated.photos >= 0


def test_a_margin_below_the_documented_one_for_the_positioning_is_a_plan_warning():
    from wtcli.fly.flight import DOCUMENTED_MARGIN_M
    plan = line_plan()
    need = DOCUMENTED_MARGIN_M["gnss"]
    gnss = default_scenario(positioning={"mode": "gnss"})
    thin = fly_plan(replace(plan, summary={"tracking_margin_m": need - 0.5}), gnss)
    said = [w for w in thin.warnings() if w.startswith("plan: tracking_margin_m")]
    assert len(said) == 1 and f"{need:g} m documented for gnss" in said[0], said
    wide = fly_plan(replace(plan, summary={"tracking_margin_m": need}), gnss)
    assert not any(w.startswith("plan: tracking_margin_m") for w in wide.warnings())
    # RTK that may lose its fix near the tower is held to RTK float's margin.
    float_need = DOCUMENTED_MARGIN_M["rtk_float"]
    rtk = default_scenario(positioning={"mode": "rtk_fixed", "rtk_degrades_near_tower": True})
    rep = fly_plan(replace(plan, summary={"tracking_margin_m": float_need - 0.1}), rtk)
    assert any(f"documented for rtk_float" in w for w in rep.warnings())


def test_wind_above_the_documented_limit_at_hub_height_is_a_warning():
    from wtcli.fly.flight import SAFE_HUB_WIND_MS, hub_wind_ms
    plan = line_plan()
    hub = max(t.hub_height for t in plan.turbines)
    # The limit is on the mean at the hub: 7 m/s at 10 m grows with the power law to the hub.
    scn = default_scenario(wind={"speed_ms": 7.0, "reference_height_m": 10.0, "shear_exponent": 0.2})
    assert hub_wind_ms(scn, plan.turbines) == pytest.approx(7.0 * (hub / 10.0) ** 0.2)
    for v, warned in ((SAFE_HUB_WIND_MS, False), (12.0, True)):
        scn = default_scenario(wind={"speed_ms": v, "reference_height_m": hub})
        said = [w for w in fly_plan(plan, scn).warnings() if w.startswith("wind:")]
        assert (len(said) == 1) is warned, (v, said)
        if warned:
            assert "12.0 m/s mean at hub height" in said[0] and "do not fly" in said[0]


def _shifted(plan: Plan, dz: float) -> Plan:
    """``plan`` moved up by ``dz`` metres: turbines, waypoints and the stated launch point."""
    summary = dict(plan.summary)
    if "launch" in summary:
        summary["launch"] = [summary["launch"][0], summary["launch"][1], summary["launch"][2] + dz]
    return replace(plan, turbines=[replace(t, base=(t.base[0], t.base[1], t.base[2] + dz))
                                   for t in plan.turbines],
                   routes=[replace(r, pos=np.asarray(r.pos, float) + [0.0, 0.0, dz])
                           for r in plan.routes], summary=summary)


def test_a_launch_point_at_a_real_height_lands_on_flat_ground_like_one_at_zero():
    """A plan whose tower base and launch point stand 40 m up (``wtinspect site`` writes real
    heights) flown on a flat scenario: the ground is level with them, so its battery swaps are
    landings and it flies the sorties of the same plan at z = 0 (the drone used to count as
    landed only within 0.5 m of z = 0: one sortie over the whole flight, reported as eating into
    the reserve, and the pre-flight check summed all sorties into one)."""
    from wtcli.fly.flight import check_feasible, make_ground
    from wtcli.geometry import Turbine
    from wtcli.plan.config import Fleet, Mission, Settings
    from wtcli.plan.mission import plan_mission

    t = Turbine.with_rotor_azimuth(90, id="T1", base=(0.0, 0.0, 40.0), hub_height=30.0,
                                   rotor_diameter=24.0, yaw_deg=180.0)
    high = plan_mission(Mission((t,), CAM, fleet=Fleet(battery_minutes=3.0, battery_reserve_minutes=0.5,
                                                       wind_margin=0.0,
                                                       battery_swap_s=20.0),
                                settings=Settings(min_side_coverage=0.0, inspect_tower=False,
                                                  inspect_nacelle=False)))
    assert high.routes[0].pos[0][2] == pytest.approx(40.0) and high.summary["per_uav"]["UAV1"]["sorties"] == 3
    low = _shifted(high, -40.0)
    scn = default_scenario(wind={"speed_ms": 4.0, "reference_height_m": 30.0}, seed=3)
    a, b = (fly_plan(p, scn).automated for p in (high, low))
    sa, sb = a.sorties_flown(), b.sorties_flown()
    assert len(sa) == len(sb) == 3
    for x, y in zip(sa, sb):
        assert x["time_s"] == pytest.approx(y["time_s"], abs=0.05)
        assert x["energy_wh"] == pytest.approx(y["energy_wh"], rel=1e-3)  # the same wind heights
        assert x["reserve_intact"] is y["reserve_intact"] is True
    assert not any("reserve" in w for w in a.warnings())
    assert a.to_dict()["min_height_above_ground_m"] == pytest.approx(
        b.to_dict()["min_height_above_ground_m"], abs=0.05)
    # The pre-flight check splits the plan into the same sorties: each within twice a small
    # battery's hover endurance (6 Wh at 730 W: 59 s), all three together (90 s) not.
    small = default_scenario(vehicle={"battery_wh": 6.0})
    for p in (high, low):
        check_feasible(p, small, make_ground(p, small), "plan.json")
    # ... and a sortie beyond a smaller battery is named alike at both heights.
    tiny = default_scenario(vehicle={"battery_wh": 3.0})
    msgs = []
    for p in (high, low):
        with pytest.raises(InputError, match=r"a sortie of at least") as e:
            check_feasible(p, tiny, make_ground(p, tiny), "plan.json")
        msgs.append(str(e.value))
    assert msgs[0] == msgs[1] and "waypoints[0] to" not in msgs[0]


def test_flat_ground_is_the_planners_ground_where_bases_stand_at_different_heights():
    """Flat terrain: the height of the nearest turbine base or launch point, the ground the
    planner keeps its minimum altitude above (``Site.ground_z``); a route that starts in the
    air (built by hand) is no launch point."""
    from wtcli.fly.flight import make_ground
    from wtcli.plan.clearance import Site

    ts = [turbine(id="T1", base=(0.0, 0.0, 14.9)), turbine(id="T2", base=(300.0, 0.0, 6.6)),
          turbine(id="T3", base=(600.0, 50.0, 0.4))]
    launch = np.array([-40.0, 90.0, 12.0])
    r = route_through([launch, launch + [0, 0, 10], [650.0, 60.0, 60.0]], component="launch")
    plan = Plan(ts, CAM, [r], safe_distance_m=3.0, target_gsd_mm=1.5)
    pts = np.random.default_rng(0).uniform([-200, -200, 0], [800, 300, 100], (2000, 3))
    ground = make_ground(plan, default_scenario())
    assert np.array_equal(ground.height(pts), Site(ts, launch=launch).ground_z(pts))
    in_air = Plan(ts, CAM, [route_through([[-40.0, 90.0, 50.0], [650.0, 60.0, 60.0]])], 3.0, 1.5)
    assert np.array_equal(make_ground(in_air, default_scenario()).height(pts),
                          Site(ts).ground_z(pts))
