"""The gap search (``wtcli/plan/paths.py: gap_views``, ``gap_plan``) and the property suite's
checks (``benchmarks/plan_property.py``): what the search's shortcuts must not change, and a
refusal the search used to make where safe views exist."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from wtcli.errors import PlanError
from wtcli.geometry import Turbine
from wtcli.plan.clearance import Site
from wtcli.plan.config import mission_from_dict
from wtcli.plan.mission import pass_params, plan_mission
from wtcli.plan.paths import _clear_along_rays

ROOT = Path(__file__).resolve().parents[1]


def _property_module():
    spec = importlib.util.spec_from_file_location("plan_property", ROOT / "benchmarks" / "plan_property.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_walking_the_rays_gives_the_clearance_test_of_every_candidate():
    """The gap search measures the clearance of only some candidates on each ray (those a
    failed one does not prove inside): the answer must be the full test's, candidate by
    candidate, around a turbine's root where most candidates fail."""
    t = Turbine.with_rotor_azimuth(0.0, id="T1", base=(0, 0, 0), hub_height=40.0,
                                   rotor_diameter=40.0, yaw_deg=180.0)
    m = mission_from_dict({"turbines": [{"id": "T1", "position": [0, 0, 0], "hub_height_m": 40,
                                         "rotor_diameter_m": 40, "yaw_deg": 180}]}, where="x")
    site = Site([t], uncertainty=[0.5])
    pp = pass_params(m)[0]
    rng = np.random.default_rng(0)
    R = np.linspace(pp.min_standoff, 9.0, 12)
    S = t.hub_center + rng.normal(0, 3.0, (400, 1, 3))  # ray origins round the hub and roots
    U = rng.normal(size=(400, 1, 3))
    U /= np.linalg.norm(U, axis=2, keepdims=True)
    C = S + R[None, :, None] * U
    walked = _clear_along_rays(site, C, R, pp)
    full = (site.clearance(C.reshape(-1, 3), pp.required) >= pp.required) \
        & site.above_ground(C.reshape(-1, 3), pp.min_altitude)
    assert 0.05 < full.mean() < 0.95  # both answers occur
    np.testing.assert_array_equal(walked.reshape(-1), full)


def test_a_trailing_edge_with_safe_views_left_is_planned_not_refused():
    """Property site 20's T3 (108 m rotor, a blade straight down in front of a 4.1 m tower,
    gimbal up to +37 deg, safe distance 4.94 m): its trailing edge read 89.3 % and was refused
    (exit 6) while a brute-force search over views (random directions within the incidence
    limit, at distances up to the GSD's reach, clear of every part, in sight) reaches 93 %. The
    rounds for a short side now search more of what is left one sample at a time."""
    d = {"fleet": {"uavs": 1, "battery_minutes": 40, "gimbal_pitch_max_deg": 37.23351358342694},
         "mission": {"safe_distance_m": 4.940981045979093, "tracking_margin_m": 0.14305357223721643,
                     "target_gsd_mm": 2.479355584120168},
         "turbines": [{"id": "T3", "position": [0.0, 0.0, 14.04885673170191],
                       "hub_height_m": 94.62139059261514, "rotor_diameter_m": 107.94584058680546,
                       "blades": 2, "yaw_deg": 168.27312875242615,
                       "blade_pitch_deg": 68.91381421031778, "blade_azimuths_deg": [270.0, 90.0],
                       "tower": {"base_radius_m": 4.135712258330633,
                                 "top_radius_m": 2.9102574474473304}}]}
    m = mission_from_dict(d, where="site.yaml")
    try:
        plan = plan_mission(m, workers=1)
    except PlanError as e:
        pytest.fail(f"refused: {e}")
    sides = plan.summary["predicted_coverage"]["T3"]["by_blade_side"]
    assert min(v for s in sides.values() for v in s.values()) >= m.settings.min_side_coverage


def test_the_property_suite_checks_against_the_turbine_grown_by_its_uncertainty():
    """``grown_turbine`` is the "true" turbine of tests/test_turbine_geometry.py: every surface
    within u outside the model's, so a plan that keeps the safe distance from it keeps it from
    any turbine the uncertainty allows."""
    pp = _property_module()
    t = Turbine.with_rotor_azimuth(30.0, id="T1", base=(0, 0, 0), hub_height=60.0,
                                   rotor_diameter=60.0, yaw_deg=90.0)
    g = pp.grown_turbine(t, 0.5)
    f = np.linspace(0, 1, 501)
    A, B = t.blade_semi_axes(f)
    Ag, Bg = g.blade_semi_axes(f)
    assert (Ag - A).max() <= 0.5 and (Bg - B).max() <= 0.5 and (Ag - A).min() >= 0.45
    assert g.hub_radius == pytest.approx(t.hub_radius + 0.49)
    assert pp.grown_turbine(t, 0.0) is t
    # A point 0.3 m off the modelled tower is clear of the model and inside the grown one.
    p = np.array([[t.tower_base_radius + 0.3, 0.0, 1.0]])
    assert 0.25 < pp.independent_min_clearance([t], p, 5.0) < 0.35
    assert pp.independent_min_clearance([g], p, 5.0) == 0.0
