"""The flight model's parts alone: IEC Kaimal turbulence, positioning errors, the tower and nacelle
wake, the rigid body's attitude lag and limits, and what each does to a flight."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wtcli.errors import ConfigError
from wtcli.fly import rigid
from wtcli.fly.flight import fly_plan
from wtcli.fly.navigation import ERROR_MODEL, gauss_markov, make_navigation, tower_shadow
from wtcli.fly.scenario import default_scenario, load_scenario, shipped_scenarios
from wtcli.fly.wake import STROUHAL, wake_series
from wtcli.fly.wind import IEC_IREF, kaimal_params, kaimal_series
from tests.test_fly import blade_pass_plan, line_plan, turbine


# ---- Kaimal ---------------------------------------------------------------------------------

def test_kaimal_parameters_are_the_iec_normal_turbulence_model():
    w = default_scenario(wind={"speed_ms": 10, "reference_height_m": 100, "shear_exponent": 0.0,
                               "turbulence": {"model": "kaimal", "iec_class": "A"}}).wind
    p = kaimal_params(w, 100.0)
    assert p.sigma_u == pytest.approx(0.16 * (0.75 * 10 + 5.6))
    assert (p.sigma_v, p.sigma_w) == pytest.approx((0.8 * p.sigma_u, 0.5 * p.sigma_u))
    assert (p.L_u, p.L_v, p.L_w) == pytest.approx((8.1 * 42, 2.7 * 42, 0.66 * 42))
    low = kaimal_params(w, 20.0)  # Lambda_1 = 0.7 z below 60 m
    assert low.L_u == pytest.approx(8.1 * 14.0)
    assert IEC_IREF == {"A+": 0.18, "A": 0.16, "B": 0.14, "C": 0.12}


def test_kaimal_series_has_the_model_variance_and_follows_the_height():
    w = default_scenario(wind={"speed_ms": 10, "reference_height_m": 100,
                               "turbulence": {"model": "kaimal", "iec_class": "B"}}).wind
    n, dt = 2 ** 17, 0.05
    flat, params = kaimal_series(w, np.full(n, 100.0), dt, np.random.default_rng(1))
    assert len(params) == 1
    p = params[0]
    np.testing.assert_allclose(flat.std(0), [p.sigma_u, p.sigma_v, p.sigma_w], rtol=0.15)
    # Climbing from 10 m to 100 m: weaker, shorter-scaled turbulence low down.
    h = np.linspace(10.0, 100.0, n)
    climb, bands = kaimal_series(w, h, dt, np.random.default_rng(1))
    assert len(bands) >= 9 and bands[0].sigma_u < bands[-1].sigma_u
    # Deterministic in the seed.
    again, _ = kaimal_series(w, h, dt, np.random.default_rng(1))
    assert np.array_equal(climb, again)


def test_complex_terrain_turbulence_structure_raises_lateral_and_vertical_sigma():
    """IEC 61400-1's complex-terrain structure (sigma_2 / sigma_1 = 1.0, sigma_3 / sigma_1 = 0.7)
    is what paper-s2 flies; the ratios are checked like every other key."""
    base = {"speed_ms": 10, "reference_height_m": 100, "shear_exponent": 0.0}
    w = default_scenario(wind={**base, "turbulence": {"model": "kaimal", "iec_class": "A",
                                                      "lateral_ratio": 1.0,
                                                      "vertical_ratio": 0.7}}).wind
    p = kaimal_params(w, 100.0)
    assert p.sigma_u == pytest.approx(0.16 * (0.75 * 10 + 5.6))
    assert (p.sigma_v, p.sigma_w) == pytest.approx((p.sigma_u, 0.7 * p.sigma_u))
    n, dt = 2 ** 17, 0.05
    series, _ = kaimal_series(w, np.full(n, 100.0), dt, np.random.default_rng(2))
    np.testing.assert_allclose(series.std(0), [p.sigma_u, p.sigma_v, p.sigma_w], rtol=0.15)
    s2 = load_scenario(shipped_scenarios()["paper-s2"]).wind
    assert (s2.turbulence_class, s2.lateral_ratio, s2.vertical_ratio) == ("A", 1.0, 0.7)
    assert s2.gust_rate_per_min == 0  # the Kaimal field holds normal turbulence's gusts
    with pytest.raises(ConfigError, match=r"wind.turbulence.lateral_ratio: expected a number"):
        default_scenario(wind={"turbulence": {"lateral_ratio": 3}})


def test_scenario_refuses_an_unknown_turbulence_class():
    with pytest.raises(ConfigError, match="iec_class"):
        default_scenario(wind={"turbulence": {"iec_class": "D"}})


# ---- positioning ------------------------------------------------------------------------------

def test_gauss_markov_has_its_sigma_and_correlation_time():
    x = gauss_markov(np.random.default_rng(0), 200_000, 1.0, 2.0, 50.0)
    assert x.std() == pytest.approx(2.0, rel=0.1)
    lag = 50
    r = np.corrcoef(x[:-lag], x[lag:])[0, 1]
    assert r == pytest.approx(math.exp(-1), abs=0.08)


def test_positioning_modes_order_rtk_fixed_float_gnss():
    n, dt = 30_000, 0.02
    rms = {}
    for mode in ("rtk_fixed", "rtk_float", "gnss"):
        nav = make_navigation(mode, n, dt, np.random.default_rng(3), 0.02, 0.05)
        rms[mode] = float(np.sqrt((nav.pos_error[:, :2] ** 2).mean()))
    assert rms["rtk_fixed"] < 0.05 < rms["rtk_float"] < 0.6 < rms["gnss"] < 3.0
    assert ERROR_MODEL["gnss"][2] >= 60.0  # a bias that wanders over minutes
    # "ideal" draws exactly the white noise the controller always saw.
    ideal = make_navigation("ideal", 100, dt, np.random.default_rng(5), 0.02, 0.05)
    rng = np.random.default_rng(5)
    assert np.array_equal(ideal.pos_error, rng.standard_normal((100, 3)) * 0.02)


def test_rtk_drops_to_float_near_the_tower_and_refixes_later():
    t = turbine()
    x = np.linspace(-40, 40, 4001)  # 80 m past the tower at 20 m height, 0.02 s steps
    pos = np.stack([x, np.full_like(x, 3.0), np.full_like(x, 20.0)], 1)
    shadow = tower_shadow(pos, [(np.asarray(t.base, float), t.hub_height)], 8.0)
    assert shadow.sum() > 0 and not shadow[0] and not shadow[-1]
    nav = make_navigation("rtk_fixed", len(x), 0.02, np.random.default_rng(0), 0.0, 0.0,
                          near_tower=shadow, refix_s=10.0)
    assert not nav.fixed[shadow].any()
    end = np.nonzero(shadow)[0][-1]
    assert not nav.fixed[end + int(9.9 / 0.02)] and nav.fixed[end + int(10.1 / 0.02) + 1]
    assert nav.fixed[0]


# ---- wake -------------------------------------------------------------------------------------

def test_tower_wake_downwind_only_with_shedding_at_the_strouhal_frequency():
    t = turbine()
    unit = np.array([1.0, 0.0, 0.0])  # wind blowing east
    n, dt = 4096, 0.05
    times = np.arange(n) * dt
    down = np.tile([6.0, 0.0, 20.0], (n, 1))  # 6 m downwind of the tower axis, 20 m up
    up = np.tile([-6.0, 0.0, 20.0], (n, 1))
    U = np.full(n, 10.0)
    w_down, info = wake_series([t], down, times, unit, U, np.random.default_rng(0))
    w_up, _ = wake_series([t], up, times, unit, U, np.random.default_rng(0))
    assert np.all(w_up == 0.0)
    assert w_down[:, 0].mean() < -2.0  # a velocity deficit of metres per second
    assert info["steps_in_wake"] == 1.0 and info["max_deficit_ms"] > 2.0
    D = 2 * float(np.interp(20.0, [0.0, t.tower_height], [t.tower_base_radius, t.tower_top_radius]))
    spec = np.abs(np.fft.rfft(w_down[:, 1] - w_down[:, 1].mean()))
    f = np.fft.rfftfreq(n, dt)
    assert f[np.argmax(spec)] == pytest.approx(STROUHAL * 10.0 / D, rel=0.05)


def test_nacelle_lee_slows_the_wind_behind_it():
    t = turbine()  # rotor faces north: the nacelle lies along y
    unit = np.array([0.0, -1.0, 0.0])  # wind from the north, the nacelle's lee to the south
    c = t.nacelle_center
    behind = np.array([[c[0], c[1] - 0.5 * t.nacelle_length - 1.0, c[2]]])
    w, _ = wake_series([t], behind, np.zeros(1), unit, np.full(1, 10.0), np.random.default_rng(0))
    assert w[0] @ unit < -2.0


# ---- rigid body -------------------------------------------------------------------------------

def test_rigid_body_tilt_lags_and_stays_within_its_limits():
    P = rigid.params(0.5, 9.81 * math.tan(math.radians(30)), 4.0, 0.15, 0.01, 0.15, 150.0, 0.05,
                     30.0, 9.81)
    S = rigid.initial_state([0, 0, 50], 9.81)
    out = np.zeros(6)
    W = np.zeros((10, 3))
    tilt, rate = [], []
    for _ in range(200):  # a 20 m/s velocity step: saturates the tilt
        rigid.substeps(S, 20.0, 0.0, 0.0, 0.0, 0.0, 0.0, W, 0, 2, 0.0, 0.0, 0.0, P, 0.01, out)
        tilt.append(math.degrees(math.hypot(S[rigid.TE], S[rigid.TN])))
        rate.append(math.degrees(abs(S[rigid.WE])))
    assert tilt[0] < 5.0  # not at once
    assert max(tilt) <= 30.0 + 0.5 and max(tilt) > 25.0
    assert max(rate) <= 150.0 + 1e-6


def test_wind_makes_the_rigid_body_deviate_more_than_calm_air_and_gnss_more_than_rtk():
    plan = blade_pass_plan()
    calm = fly_plan(plan, default_scenario()).automated.deviation.mean()
    windy = default_scenario(wind={"speed_ms": 10, "reference_height_m": 60})
    rtk = fly_plan(plan, windy).automated.deviation.mean()
    gnss = fly_plan(plan, default_scenario(wind={"speed_ms": 10, "reference_height_m": 60},
                                           positioning={"mode": "gnss"})).automated.deviation.mean()
    assert calm < rtk < 0.5 < gnss


def test_kinematic_model_is_kept_as_a_named_option():
    plan = line_plan()
    s = default_scenario(vehicle={"model": "kinematic"}, positioning={"mode": "ideal"})
    assert s.vehicle.model == "kinematic"
    assert fly_plan(plan, s).automated.deviation.max() < 0.05
    with pytest.raises(ConfigError, match="model"):
        default_scenario(vehicle={"model": "helicopter"})
