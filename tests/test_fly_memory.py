"""Memory on long routes: the same flight, bit for bit, flown and measured in blocks.

``fly`` turns the reference, wind and navigation errors into Python lists (cheap to index in the
flight loop) a block of steps at a time, ``measure_flight`` finds clearance and height a block
at a time, and ``fly_plan`` measures each route as soon as it is flown and keeps of it only what
the report needs (docs/fly.md "Memory"). These tests hold the figures of a two-UAV plan with a
battery swap in each route to those the simulator gave when it made whole-route lists and kept
every route whole, and the flight to itself at other block sizes.
"""

from __future__ import annotations

import numpy as np
import pytest

from wtcli.fly import control, flight
from wtcli.fly.flight import fly_plan, fly_routes, make_ground, measure
from wtcli.fly.scenario import default_scenario
from wtcli.plan_file import Plan, Route
from tests.test_fly import CAM, turbine


def _route(uav: str, legs: list) -> Route:
    """``legs``: (position, how, photo, component); ``how`` is ("v", speed) for a leg flown at
    that speed, ("dwell", s) for standing still, None for the first waypoint."""
    pos, t, spd = [], [], []
    for p, how, _, _ in legs:
        p = np.asarray(p, float)
        if not pos:
            t.append(0.0)
            spd.append(0.0)
        elif how[0] == "dwell":
            t.append(t[-1] + how[1])
            spd.append(0.0)
        else:
            t.append(t[-1] + float(np.linalg.norm(p - pos[-1])) / how[1])
            spd.append(how[1])
        pos.append(p)
    m = len(pos)
    return Route(uav=uav, t=np.array(t), pos=np.array(pos), speed=np.array(spd),
                 yaw_deg=np.full(m, 180.0), gimbal_pitch_deg=np.zeros(m),
                 photo=np.array([leg[2] for leg in legs]),
                 component=np.array([leg[3] for leg in legs], dtype=object))


def two_sortie_plan() -> Plan:
    """Two UAVs, one per turbine; each takes off from its pad, photographs up the front of the
    upright blade, lands, swaps its battery (20 s on the ground), and photographs down it."""
    ts = [turbine(id="T1"), turbine(id="T2", base=(150, 0, 0))]
    routes = []
    for i, tb in enumerate(ts):
        hub = tb.hub_center
        pad = np.array([hub[0] - 20.0, 40.0, 0.0])
        up = np.arange(hub[2] + 4, hub[2] + 28 + 1e-9, 4.0)
        legs = [(pad, None, False, "launch")]
        for sortie, zs in enumerate((up, up[::-1])):
            if sortie:
                legs.append((pad, ("dwell", 20.0), False, "launch"))
            legs += [(pad + [0, 0, 30], ("v", 3.0), False, "transit"),
                     ((hub[0], hub[1] + 6.0, zs[0]), ("v", 4.0), False, "transit")]
            legs += [((hub[0], hub[1] + 6.0, z), ("v", 1.5), True, f"{tb.id}/blade1/leading_edge")
                     for z in zs]
            legs += [((hub[0], hub[1] + 20.0, zs[-1]), ("v", 3.0), False, "transit"),
                     (pad + [0, 0, 30], ("v", 4.0), False, "transit"),
                     (pad, ("v", 2.0), False, "transit")]
        routes.append(_route(f"UAV{i + 1}", legs))
    return Plan(ts, CAM, routes, safe_distance_m=3.0, target_gsd_mm=1.5,
                summary={"battery_minutes": 3.0, "battery_reserve_minutes": 0.5})


# Every code path of the flight loop: the leash (default) and without it, the rigid body and
# the kinematic vehicle, Kaimal and Dryden turbulence with gusts, PID, feed-forward and the
# manual pilot, RTK that degrades near the tower, hills.
SCENARIOS = {
    "default": dict(wind={"speed_ms": 6.0, "reference_height_m": 30.0}, seed=3,
                    baselines={"no_compensation": True, "manual": True}),
    "kinematic": dict(wind={"speed_ms": 5.0, "reference_height_m": 30.0,
                            "turbulence": {"model": "dryden"},
                            "gusts": {"rate_per_min": 2, "amplitude_ms": 1.5}},
                      vehicle={"model": "kinematic"}, control={"leash_m": 0.0},
                      positioning={"mode": "gnss"}, seed=5),
    "hilly": dict(wind={"speed_ms": 8.0, "reference_height_m": 30.0,
                        "turbulence": {"model": "kaimal", "iec_class": "A"}},
                  terrain={"kind": "hilly", "amplitude_m": 10.0},
                  positioning={"mode": "rtk_fixed", "rtk_degrades_near_tower": True}, seed=7),
}


def figures(report, plan: Plan, scn) -> dict:
    """The report's numbers; and, from the routes flown again whole (``fly_routes``), sums
    over every recorded step of the automated flight's tracks."""
    out = {}
    for kind, f in report.flights.items():
        d = f.to_dict()
        out[kind] = {
            "time_s": d["time_s"], "length_m": d["path_length_m"],
            "deviation": [d["deviation_m"][k] for k in ("mean", "rms", "p99_9", "max")],
            "tracking": [d["tracking_error_m"][k] for k in ("mean", "rms", "max")],
            "clearance_min_m": d["clearance"]["min_m"],
            "violations": [(v.kind, v.uav, v.t_start, v.t_end, v.worst_m) for v in f.violations],
            "min_agl_m": d["min_height_above_ground_m"],
            "coverage": d["coverage"]["blade_average"], "photos": d["photos"]["count"],
            "gsd_mm": d["photos"]["gsd_nearest_surface_mm"]["mean"],
            "sorties": [(s["uav"], s["time_s"], s["energy_wh"], s["reserve_intact"])
                        for s in f.sorties_flown()],
            "uavs": [(u["flight_time_s"], u["path_length_m"]) for u in d["uavs"]],
            "photo_steps": [int(u.photo_step.sum()) for u in f.uavs]}
    tracks = fly_routes(plan, scn, make_ground(plan, scn), "pid")
    out["tracks"] = [[float(np.abs(a).sum()) for a in (u.track.pos, u.track.vel, u.track.thrust,
                                                        u.track.wind, u.track.yaw_deg,
                                                        u.track.pitch_deg)] for u in tracks]
    return out


def _same(got, want, where=""):
    """Equal, floats to 1e-12 (they are equal to the bit here; the room is for a hilly ground's
    last bit, which rounds by how many points the terrain is asked for at once)."""
    if isinstance(want, dict):
        assert got.keys() == want.keys(), where
        for k in want:
            _same(got[k], want[k], f"{where}.{k}")
    elif isinstance(want, (list, tuple)):
        assert len(got) == len(want), where
        for i, (g, w) in enumerate(zip(got, want)):
            _same(g, w, f"{where}[{i}]")
    elif isinstance(want, float):
        assert got == pytest.approx(want, rel=1e-12, abs=1e-12), where
    else:
        assert got == want, where


# What the simulator gave before it flew in blocks and measured each route as it was flown
# (every route's reference, wind and errors as whole-route lists, every flight kept whole).
EXPECTED = {'default': {'automated': {'time_s': 189.48,
                                      'length_m': 840.119576517104,
                                      'deviation': [0.07108165784756294, 0.08131868700635049,
                                                    0.21772001795122808, 0.224122992628218],
                                      'tracking': [0.09435872338879839, 0.1048643460200845,
                                                   0.30363987281691296],
                                      'clearance_min_m': 4.84247835804403,
                                      'violations': [],
                                      'min_agl_m': -0.08822168563703867,
                                      'coverage': 0.08453232286070415,
                                      'photos': 28,
                                      'gsd_mm': 1.369490327439063,
                                      'sorties': [('UAV1', 85.0, 20.006253163646495, True),
                                                  ('UAV1', 83.86, 19.73394941561482, True),
                                                  ('UAV2', 84.06, 19.659469419074597, True),
                                                  ('UAV2', 83.86000000000001, 19.803899528584346,
                                                   True)],
                                      'uavs': [(192.48000000000002, 420.3956715934848),
                                               (191.6, 420.1773327515359)],
                                      'photo_steps': [63129, 62798]},
                        'no_compensation': {'time_s': 183.9,
                                            'length_m': 872.349332039665,
                                            'deviation': [49.976678897937894, 57.703164860812464,
                                                          104.26116771210432, 104.44910030641513],
                                            'tracking': [52.68789109891402, 60.95420521249756,
                                                         108.82319155431163],
                                            'clearance_min_m': 6.682686289466619,
                                            'violations': [],
                                            'min_agl_m': 0.004690525091266055,
                                            'coverage': 0.0,
                                            'photos': 28,
                                            'gsd_mm': 9.877066398458306,
                                            'sorties': [('UAV1', 80.76, 19.083957240051003, True),
                                                        ('UAV1', 80.22, 18.809712564136195, True),
                                                        ('UAV2', 80.76, 18.876616646316045, True),
                                                        ('UAV2', 80.22, 18.944833612566548, True)],
                                            'uavs': [(183.9, 435.72791447402665),
                                                     (183.9, 436.62141756563835)],
                                            'photo_steps': [60251, 60251]},
                        'manual': {'time_s': 402.8,
                                   'length_m': 1044.2693283774165,
                                   'deviation': [2.59788092735735, 2.974854471597054,
                                                 7.013667705133875, 7.0904416033047655],
                                   'tracking': [2.9865113510011123, 3.300682233055763,
                                                7.110831569199742],
                                   'clearance_min_m': 2.8657136967254604,
                                   'violations': [('clearance', 'UAV2', 337.96, 338.58,
                                                   2.8657136967254604)],
                                   'min_agl_m': -0.7721797491745643,
                                   'coverage': 0.043146037859102405,
                                   'photos': 28,
                                   'gsd_mm': 1.7674757162900494,
                                   'sorties': [('UAV1', 180.46, 39.757266746485975, False),
                                               ('UAV1', 179.42000000000002, 39.903961776871746,
                                                False),
                                               ('UAV2', 180.46, 39.7234888295659, False),
                                               ('UAV2', 179.42000000000002, 39.08317954450801,
                                                False)],
                                   'uavs': [(402.8, 522.0381978547027),
                                            (402.8, 522.2311305227138)],
                                   'photo_steps': [135615, 135615]},
                        'tracks': [[794191.9519289545, 27989.838370495447, 21556.890132672885,
                                    66713.2596725617, 1732500.0, 0.0],
                                   [2002040.3779551696, 27957.125566862327, 20550.72121383655,
                                    65298.61009131584, 1724580.0, 0.0]]},
            'kinematic': {'automated': {'time_s': 183.9,
                                        'length_m': 843.7924293376791,
                                        'deviation': [1.507325396343195, 1.7390952686709533,
                                                      3.017463590470316, 3.037749142779024],
                                        'tracking': [1.6135758956295359, 1.8415181165789734,
                                                     3.1254191469206636],
                                        'clearance_min_m': 4.7525315236828405,
                                        'violations': [],
                                        'min_agl_m': -0.5505453217088958,
                                        'coverage': 0.04447058477967824,
                                        'photos': 28,
                                        'gsd_mm': 1.5689259229885635,
                                        'sorties': [('UAV1', 80.76, 19.159574955552998, True),
                                                    ('UAV1', 80.22, 19.090225988701388, True),
                                                    ('UAV2', 80.76, 19.223137123195258, True),
                                                    ('UAV2', 80.22, 19.01614857948681, True)],
                                        'uavs': [(183.9, 422.0325733248475),
                                                 (183.9, 421.7598560128317)],
                                        'photo_steps': [60251, 60251]},
                          'no_compensation': {'time_s': 183.9,
                                              'length_m': 859.7327508701067,
                                              'deviation': [46.66803977340962, 54.04491918999239,
                                                            102.5990243601372,
                                                            102.67763196782678],
                                              'tracking': [48.25339420050418, 56.01498536941231,
                                                           102.68235182259826],
                                              'clearance_min_m': 9.783011666343048,
                                              'violations': [],
                                              'min_agl_m': -1.3909451508518509,
                                              'coverage': 0.0,
                                              'photos': 28,
                                              'gsd_mm': 9.287400441435144,
                                              'sorties': [('UAV1', 80.76, 18.955460030577676,
                                                           True),
                                                          ('UAV1', 80.22, 18.954413680660746,
                                                           True),
                                                          ('UAV2', 80.76, 19.042018314721282,
                                                           True),
                                                          ('UAV2', 80.22, 18.897439823526863,
                                                           True)],
                                              'uavs': [(183.9, 432.8012783616907),
                                                       (183.9, 426.93147250841594)],
                                              'photo_steps': [60251, 60251]},
                          'manual': {'time_s': 402.8,
                                     'length_m': 1032.0222019725989,
                                     'deviation': [2.9366005147088554, 3.2214640473463736,
                                                   8.373308475476582, 8.476852734356779],
                                     'tracking': [3.2510536916013164, 3.513806175529113,
                                                  8.564512186903873],
                                     'clearance_min_m': 1.8036926714770007,
                                     'violations': [('clearance', 'UAV2', 51.26, 57.52,
                                                     1.8703291064484933),
                                                    ('clearance', 'UAV2', 57.84, 58.46,
                                                     2.9773515872509484),
                                                    ('clearance', 'UAV2', 67.58, 72.08,
                                                     1.8036926714770007)],
                                     'min_agl_m': -1.983812335345681,
                                     'coverage': 0.03915549369560172,
                                     'photos': 28,
                                     'gsd_mm': 1.552673811198559,
                                     'sorties': [('UAV1', 180.46, 39.69828516527017, False),
                                                 ('UAV1', 179.42000000000002, 39.57770889506377,
                                                  False),
                                                 ('UAV2', 180.46, 39.821721909142674, False),
                                                 ('UAV2', 179.42000000000002, 39.51039724124869,
                                                  False)],
                                     'uavs': [(402.8, 516.0395113293371),
                                              (402.8, 515.9826906432618)],
                                     'photo_steps': [135615, 135615]},
                          'tracks': [[790472.686834625, 28340.54879050272, 22561.975267182974,
                                      56844.435022565696, 1655280.0, 0.0],
                                     [1923361.1950341659, 28243.851780881763, 21299.89959615373,
                                      52582.224209606764, 1655280.0, 0.0]]},
            'hilly': {'automated': {'time_s': 195.96,
                                    'length_m': 843.1006781798208,
                                    'deviation': [0.1276438679971138, 0.14670639839316013,
                                                  0.6172129032224445, 0.6462223703537346],
                                    'tracking': [0.15200511905992173, 0.17060792711907752,
                                                 0.6566943881625619],
                                    'clearance_min_m': 4.808798876895113,
                                    'violations': [],
                                    'min_agl_m': -0.07491656436367959,
                                    'coverage': 0.08428209750553224,
                                    'photos': 28,
                                    'gsd_mm': 1.365843719778647,
                                    'sorties': [('UAV1', 88.60000000000001, 21.110240002793688,
                                                 True),
                                                ('UAV1', 86.19999999999999, 20.292727249303667,
                                                 True),
                                                ('UAV2', 86.88, 20.463721276680552, True),
                                                ('UAV2', 86.15999999999998, 20.389504070038544,
                                                 True)],
                                    'uavs': [(198.96, 421.7942084298495),
                                             (197.28, 422.0328701267907)],
                                    'photo_steps': [65765, 64662]},
                      'no_compensation': {'time_s': 183.9,
                                          'length_m': 897.3984699703931,
                                          'deviation': [63.76121780450403, 72.30478607477978,
                                                        124.67861480862688, 124.93690916848544],
                                          'tracking': [65.90169391683358, 74.85271156809705,
                                                       124.93690916848544],
                                          'clearance_min_m': 12.042182495165967,
                                          'violations': [('ground', 'UAV2', 174.12, 178.48,
                                                          -6.950807749421848)],
                                          'min_agl_m': -11.309850246872044,
                                          'coverage': 0.0,
                                          'photos': 28,
                                          'gsd_mm': 10.357251708540153,
                                          'sorties': [('UAV1', 80.76, 19.12034871975441, True),
                                                      ('UAV1', 80.22, 19.006879316468254, True),
                                                      ('UAV2', 80.76, 19.153154928027277, True),
                                                      ('UAV2', 80.22, 19.303351221535305, True)],
                                          'uavs': [(183.9, 450.36418433613994),
                                                   (183.9, 447.03428563425314)],
                                          'photo_steps': [60251, 60251]},
                      'manual': {'time_s': 402.8,
                                 'length_m': 1069.73718154101,
                                 'deviation': [3.327191346766974, 3.7815393019516423,
                                               9.234808512360766, 9.370737189479632],
                                 'tracking': [3.58264111513933, 3.996058519231747,
                                              9.371064865475315],
                                 'clearance_min_m': 0.9095461864952287,
                                 'violations': [('clearance', 'UAV2', 45.26, 54.120000000000005,
                                                 0.9095461864952287),
                                                ('ground', 'UAV1', 223.38, 223.4,
                                                 1.9458946722034336),
                                                ('ground', 'UAV2', 223.38, 223.56,
                                                 1.6304112820635446)],
                                 'min_agl_m': -1.7940892684931522,
                                 'coverage': 0.05456360808696795,
                                 'photos': 28,
                                 'gsd_mm': 1.7909733531538727,
                                 'sorties': [('UAV1', 180.46, 40.05269768529312, False),
                                             ('UAV1', 179.42000000000002, 39.993111299440365,
                                              False),
                                             ('UAV2', 180.46, 40.38680943033603, False),
                                             ('UAV2', 179.42000000000002, 40.989678750146396,
                                              False)],
                                 'uavs': [(402.8, 530.5629896295104), (402.8, 539.1741919114995)],
                                 'photo_steps': [135615, 135615]},
                      'tracks': [[821693.8053264834, 28412.688169089583, 26264.876733000194,
                                  88318.77490886359, 1790820.0, 0.0],
                                 [2062039.1468270933, 28460.99494085757, 25248.77033447011,
                                  87615.5023537894, 1775700.0, 0.0]]}}


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_a_two_sortie_plan_flies_as_it_did_with_whole_route_lists(name):
    plan = two_sortie_plan()
    scn = default_scenario(**SCENARIOS[name])
    report = fly_plan(plan, scn, baselines=True)
    got = figures(report, plan, scn)
    assert [u for u, *_ in got["automated"]["sorties"]] == ["UAV1", "UAV1", "UAV2", "UAV2"]
    _same(got, EXPECTED[name], name)


def test_the_block_sizes_change_nothing(monkeypatch):
    """Blocks of 37 steps (many block edges, the leash's set-point crossing them) and of 1000
    steps for clearance: the same report, to the bit, as the default blocks."""
    plan = two_sortie_plan()
    for name in ("default", "kinematic"):
        scn = default_scenario(**SCENARIOS[name])
        want = fly_plan(plan, scn, baselines=True)
        with monkeypatch.context() as m:
            m.setattr(control, "BLOCK_STEPS", 37)
            m.setattr(flight, "MEASURE_BLOCK", 1000)
            got = fly_plan(plan, scn, baselines=True)
        assert got.to_dict() == want.to_dict(), name
        for k in want.flights:
            for a in ("deviation", "tracking_error", "clearance", "agl"):
                assert np.array_equal(getattr(got.flights[k], a), getattr(want.flights[k], a))
            for u, v in zip(got.flights[k].uavs, want.flights[k].uavs):
                assert np.array_equal(u.track.pos, v.track.pos)
                assert np.array_equal(u.track.t, v.track.t)


def test_a_report_keeps_of_each_flight_what_it_needs_and_measures_it_as_measure_does():
    plan = two_sortie_plan()
    scn = default_scenario(**SCENARIOS["hilly"])
    report = fly_plan(plan, scn).automated
    for u in report.uavs:
        assert u.ref is None and u.track.vel is None and u.track.thrust is None
        assert u.track.pos.shape == (len(u.track.t), 3) and len(u.photo_pos) == len(u.photo_step)
    ground = make_ground(plan, scn)
    whole = fly_routes(plan, scn, ground, "pid")
    again = measure("automated", "pid", plan, whole, scn, ground, planned_coverage=True)
    assert again.to_dict() == report.to_dict()
    with pytest.raises(ValueError, match="already measured"):
        measure("automated", "pid", plan, report.uavs, scn, ground)


def test_rows_are_the_arrays_rows_a_block_at_a_time():
    a = np.arange(30.0).reshape(10, 3)
    r = control.Rows(a, block=4)
    assert len(r) == 10
    assert [r[k] for k in range(10)] == a.tolist()
    assert r[7] == [21.0, 22.0, 23.0] and r[2] == [6.0, 7.0, 8.0] and r[-1] == [27.0, 28.0, 29.0]
    assert control.Rows(np.arange(5.0), block=2)[3] == 3.0
    with pytest.raises(IndexError):
        r[10]


@pytest.mark.slow
def test_flying_a_long_route_needs_memory_for_a_block_not_the_route(monkeypatch):
    """The flight loop's own allocations, beyond the track it returns, stay within a block's
    lists: 11 000 steps in blocks of 500 take ~1 MB more (whole-route lists took 25 MB)."""
    import tracemalloc

    from wtcli.fly.navigation import make_navigation
    from wtcli.fly.sim import fly, make_controller, make_reference
    from wtcli.fly.wind import make_wind

    monkeypatch.setattr(control, "BLOCK_STEPS", 500)
    scn = default_scenario(wind={"speed_ms": 5.0, "reference_height_m": 30.0})
    P = np.array([[0, 0, 30], [200, 0, 30], [200, 200, 30], [0, 200, 30], [0, 0, 30]], float)
    ref = make_reference(np.array([0.0, 50, 100, 150, 200]), P, np.zeros(5), np.zeros(5), 0.02, 0.3,
                         settle_s=30.0)
    n, sub = len(ref.t), scn.substeps
    wind = make_wind(scn.wind, 1.0, n * sub, 0.02 / sub, 30.0, np.random.default_rng(0))
    nav = make_navigation("rtk_fixed", n, 0.02, np.random.default_rng(1), 0.0, 0.0)
    assert n > 10_000
    fly(ref, scn, wind, np.zeros(n), make_controller("pid", ref, scn), nav)  # numba compiles here
    controller = make_controller("pid", ref, scn)
    tracemalloc.start()
    try:
        track = fly(ref, scn, wind, np.zeros(n), controller, nav)
        now, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    kept = sum(a.nbytes for a in (track.t, track.pos, track.vel, track.thrust, track.wind,
                                  track.yaw_deg, track.pitch_deg, track.progress))
    assert peak - kept < 4e6, (peak, kept)
