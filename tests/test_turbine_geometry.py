"""The turbine dimensions the clearance rests on, and the geometry uncertainty kept on top of the
safe distance (docs/turbines-yaml.md, "Turbine geometry the clearance rests on").

The central test builds a "true" turbine whose every surface lies up to the uncertainty outside
the modelled one (thicker, wider blades, a bigger hub and tower, the nacelle further forward),
plans on the model, and measures the plan against the true turbine.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from wtcli.errors import ConfigError
from wtcli.geometry import Turbine
from wtcli.plan.mission import plan_mission
from wtcli.plan.clearance import Site, clearance_to_parts
from wtcli.plan.config import Settings, load_mission, mission_from_dict


def _site(uncertainty: float | None = None, **turbine) -> dict:
    t = {"id": "T1", "position": [0.0, 0.0, 0.0], "hub_height_m": 60, "rotor_diameter_m": 60,
         "yaw_deg": 90, "blade_azimuths_deg": [90, 210, 330], **turbine}
    d = {"fleet": {"launch": {"position": [50.0, -10.0, 0.0]}, "battery_minutes": 60},
         "mission": {"inspect_tower": False}, "turbines": [t]}
    if uncertainty is not None:
        d["mission"]["geometry_uncertainty_m"] = uncertainty
    return d


def true_turbine(t: Turbine, u: float) -> Turbine:
    """A turbine whose surfaces lie outside ``t``'s by up to ``u``: blade semi-axes (chord/2 and
    thickness/2) each grown by at most u (the grown ellipse's points are the model's plus a
    vector (a cos, b sin) no longer than u), hub and tower radii + u, the nacelle box moved u
    forward, towards the rotor. The thickness knots give B + g only at the knots (between them
    the product of two straight lines bulges): g is the largest that keeps B within u."""
    g = 0.98 * u
    f = np.linspace(0, 1, 2001)
    B = t.blade_semi_axes(f)[1]

    def grown(gt: float) -> Turbine:
        ratio = lambda r, c: min(1.0, (r * c + 2 * gt) / (c + 2 * g))  # noqa: E731
        return replace(
            t, blade_root_chord=t.blade_root_chord + 2 * g,
            blade_max_chord=t.blade_max_chord + 2 * g, blade_tip_chord=t.blade_tip_chord + 2 * g,
            blade_root_thickness_ratio=ratio(t.blade_root_thickness_ratio, t.blade_root_chord),
            blade_max_chord_thickness_ratio=ratio(t.blade_max_chord_thickness_ratio, t.blade_max_chord),
            blade_tip_thickness_ratio=ratio(t.blade_tip_thickness_ratio, t.blade_tip_chord),
            hub_radius=t.hub_radius + g, tower_base_radius=t.tower_base_radius + g,
            tower_top_radius=t.tower_top_radius + g, nacelle_ahead=t.nacelle_ahead + g)

    lo, hi = 0.0, g
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if (grown(mid).blade_semi_axes(f)[1] - B).max() <= g:
            lo = mid
        else:
            hi = mid
    return grown(lo)


def _path_points(plan, step: float = 0.1) -> np.ndarray:
    """Every waypoint and points every ``step`` m along every leg of the plan."""
    out = []
    for r in plan.routes:
        p0, p1 = r.pos[:-1], r.pos[1:]
        n = np.maximum(1, np.ceil(np.linalg.norm(p1 - p0, axis=1) / step).astype(int))
        for a, b, k in zip(p0, p1, n):
            out.append(a + (b - a) * (np.arange(k + 1) / k)[:, None])
    return np.concatenate(out)


def test_the_true_turbine_lies_within_the_uncertainty_and_outside_the_model():
    t = load_mission_dict(_site()).turbines[0]
    u = 0.5
    tt = true_turbine(t, u)
    f = np.linspace(0, 1, 2001)
    A, B = t.blade_semi_axes(f)
    At, Bt = tt.blade_semi_axes(f)
    assert (At - A).max() <= u and (Bt - B).max() <= u
    assert (At - A).min() >= 0.9 * u and (Bt - B).min() >= 0.3 * u
    # Points on the true surface are at most u from the modelled turbine.
    s = tt.surface_samples(0.5)
    assert t.clearance(s.points).max() <= u + 1e-6
    assert t.clearance(s.points).max() >= 0.9 * u


@pytest.mark.parametrize("u", [0.5])
def test_a_plan_keeps_its_clearance_from_a_turbine_that_differs_by_the_uncertainty(u):
    """Planned on the model with geometry_uncertainty_m = u, the path (waypoints and every leg,
    sampled every 0.1 m) keeps the planner's clearance (safe distance + tracking margin, legs
    less half the sampling step) from the true turbine; planned with 0, it does not."""
    mission = load_mission_dict(_site(u))
    t = mission.turbines[0]
    s = mission.settings
    legs_keep = s.safe_distance_m + s.tracking_margin_m - 0.25
    truth = [true_turbine(t, u)]
    plan = plan_mission(mission)
    assert plan.summary["turbines"][t.id]["geometry_uncertainty_m"] == u
    d, part = clearance_to_parts(truth, _path_points(plan))
    assert d.min() >= legs_keep - 1e-6, (d.min(), part[np.argmin(d)])
    assert d.min() >= s.safe_distance_m
    # The same plan measured against the model keeps the uncertainty more.
    assert clearance_to_parts([t], _path_points(plan))[0].min() >= legs_keep + u - 1e-6

    bare = plan_mission(load_mission_dict(_site(0.0)))
    assert clearance_to_parts(truth, _path_points(bare))[0].min() < legs_keep


def test_site_measures_to_the_model_grown_by_each_turbines_uncertainty():
    t = load_mission_dict(_site()).turbines[0]
    t2 = replace(t, id="T2", base=(400.0, 0.0, 0.0))
    P = np.array([t.hub_center + t.axis * 9.0, t2.hub_center + t2.axis * 9.0,
                  t.base_xyz + np.array([0.0, 0.0, 30.0]) + t.right * 8.0])
    bare = Site([t, t2]).clearance(P)
    grown = Site([t, t2], uncertainty=[0.5, 2.0]).clearance(P)
    np.testing.assert_allclose(grown, np.maximum(bare - [0.5, 2.0, 0.5], 0.0), atol=1e-9)
    # Capped queries agree below the cap, and legs are bounded the same way.
    np.testing.assert_allclose(Site([t, t2], uncertainty=[0.5, 2.0]).clearance(P, cap=20.0),
                               grown, atol=1e-9)
    seg = Site([t, t2], uncertainty=2.0).segment_clearance(P[:1], P[1:2])
    assert seg[0] <= grown[0] - 1.5 + 1e-9
    name, dist = Site([t, t2], uncertainty=[0.5, 2.0]).nearest_part(P[1])
    assert name.startswith("T2") and dist == pytest.approx(grown[1])
    with pytest.raises(ValueError, match="uncertainties"):
        Site([t], uncertainty=-1.0)


def test_geometry_uncertainty_defaults_and_per_turbine_override():
    assert Settings().geometry_uncertainty_m >= 0.5
    m = load_mission_dict(_site())
    assert m.geometry_uncertainty("T1") == Settings().geometry_uncertainty_m
    m = load_mission_dict(_site(1.5, geometry_uncertainty_m=0.2))
    assert m.geometry_uncertainty("T1") == 0.2 and m.settings.geometry_uncertainty_m == 1.5


def test_every_dimension_key_reaches_the_model():
    m = load_mission_dict(_site(
        nacelle={"length_m": 12, "width_m": 4, "height_m": 4.2, "ahead_m": -2.5, "above_hub_m": -0.6},
        blade={"root_chord_m": 3.5, "max_chord_m": 4.6, "tip_chord_m": 1.2,
               "max_chord_span_fraction": 0.25, "root_thickness_ratio": 0.95,
               "max_chord_thickness_ratio": 0.38, "tip_thickness_ratio": 0.19},
        hub_radius_m=1.6, overhang_m=5.0))
    t = m.turbines[0]
    assert (t.nacelle_length, t.nacelle_width, t.nacelle_height) == (12, 4, 4.2)
    assert (t.nacelle_ahead, t.nacelle_above_hub, t.hub_radius, t.overhang) == (-2.5, -0.6, 1.6, 5.0)
    np.testing.assert_allclose(t.nacelle_center, [-2.5, 0.0, 59.4], atol=1e-9)  # yaw 90: ahead +x
    assert t.tower_height == pytest.approx(60 - 0.6 - 2.1)
    A, B = t.blade_semi_axes(np.array([0.0, 0.25, 1.0]))
    np.testing.assert_allclose(2 * A, [3.5, 4.6, 1.2])
    np.testing.assert_allclose(B / A, [0.95, 0.38, 0.19])
    # The compiled clearance reads the same model: a point 2 m off the nacelle's front face.
    front = t.nacelle_center + t.axis * (6.0 + 2.0) + np.array([0, 0, 1.0])
    P = np.array([front, t.hub_center + t.axis * 3.0])
    np.testing.assert_allclose(t.clearance(P), t.clearance_by_part(P).min(axis=1), atol=1e-9)


def test_defaults_are_stated_proportions_of_the_rotor_radius():
    t = load_mission_dict(_site()).turbines[0]
    R = 30.0
    assert (t.blade_root_chord, t.blade_max_chord, t.blade_tip_chord) == pytest.approx(
        (0.06 * R, 0.075 * R, 0.03 * R))
    assert (t.blade_max_chord_at, t.blade_root_thickness_ratio, t.blade_max_chord_thickness_ratio,
            t.blade_tip_thickness_ratio) == (0.2, 1.0, 0.45, 0.21)
    assert t.nacelle_ahead == pytest.approx(0.1 * 0.25 * R) and t.nacelle_above_hub == 0.0


@pytest.mark.parametrize("where, value, key", [
    ("blade", {"max_chord_span_fraction": 0.9}, "blade.max_chord_span_fraction"),
    ("blade", {"root_thickness_ratio": 1.5}, "blade.root_thickness_ratio"),
    ("blade", {"max_chord_thickness_ratio": 0.0}, "blade.max_chord_thickness_ratio"),
    ("blade", {"tip_thickness_ratio": "thin"}, "blade.tip_thickness_ratio"),
    ("nacelle", {"ahead_m": 50}, "nacelle.ahead_m"),
    ("nacelle", {"above_hub_m": float("nan")}, "nacelle.above_hub_m"),
    ("geometry_uncertainty_m", -0.1, "turbines[0].geometry_uncertainty_m"),
    ("geometry_uncertainty_m", 11, "turbines[0].geometry_uncertainty_m"),
])
def test_bad_dimension_keys_are_refused_naming_the_key(where, value, key):
    with pytest.raises(ConfigError, match=key.replace("[", r"\[").replace("]", r"\]")):
        load_mission_dict(_site(**{where: value}))


def test_bad_mission_uncertainty_is_refused_naming_the_key():
    with pytest.raises(ConfigError, match=r"mission.geometry_uncertainty_m: expected a number in"):
        load_mission_dict(_site(-1))


def test_a_nacelle_below_the_tower_base_is_refused():
    t = load_mission_dict(_site()).turbines[0]
    with pytest.raises(ValueError, match="nacelle's bottom"):
        replace(t, nacelle_above_hub=-60.0)
    with pytest.raises(ValueError, match="blade_tip_thickness_ratio"):
        replace(t, blade_tip_thickness_ratio=0.0)


def test_the_sample_site_states_its_uncertainty(tmp_path):
    from pathlib import Path

    m = load_mission(Path(__file__).resolve().parents[1] / "sample_images" / "turbines.yaml")
    assert all(m.geometry_uncertainty(t.id) >= 0.5 for t in m.turbines)


def load_mission_dict(d: dict):
    return mission_from_dict(d, where="t.yaml")
