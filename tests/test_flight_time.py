"""Flight time: capture while moving (photo interval, motion blur, the fleet's cap), the speed of
each kind of leg, and the per-turbine time budget (docs/plan.md, "Capture while moving" and
"Time budget")."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from wtcli.errors import ConfigError
from wtcli.geometry import Camera, Turbine
from wtcli.plan.config import Capture, Fleet, Mission, Settings, default_dict, mission_from_dict
from wtcli.plan.mission import (ACCEL_M_S2, BUDGET_KEYS, Speeds, _flown, _flown_leg_times,
                                _photo_waits, capture_speed, chunk_time, leg_speeds, pass_params,
                                plan_mission)
from wtcli.plan.paths import WP, Chunk

CAM = Camera(5456, 3632, 16, 23.2)


def _wp(x, photo, slow=True, standoff=None, comp="T1/blade1/leading_edge"):
    return WP(np.array([float(x), 0.0, 50.0]), np.array([0.0, 1.0, 0.0]), photo, comp, slow,
              standoff)


SP = Speeds(capture=2.8, blur_per_m=0.5, closest=4.0, turn=4.0, cruise=8.0, climb=3.0)


def test_leg_speeds_by_kind_and_blur_at_each_station():
    # photo-photo legs at the capture speed, capped by each end's blur limit (0.5 m/s per m
    # of standoff: 5 m -> 2.5, 4 m -> 2.0); no-photo legs at the turn speed; transits cruise
    wps = [_wp(0, True, standoff=5.0), _wp(2, True, standoff=5.0), _wp(4, True, standoff=4.0),
           _wp(10, False), _wp(20, False), _wp(60, False, slow=False)]
    v = leg_speeds(wps, SP)
    assert v.tolist() == [2.5, 2.0, 4.0, 4.0, 8.0]
    # the station at x=4 is passed at most at its limit: the slower of its legs is 2.0
    assert min(v[1], v[2]) <= 2.0


def test_a_photo_between_two_fast_legs_gets_the_leg_into_it_slowed():
    # an extra view reached by turns on both sides, with no recorded standoff: the closest
    # standoff's limit (0.5 * 4 = 2 m/s) applies to the leg into it
    wps = [_wp(0, False), _wp(10, True), _wp(20, False), _wp(120, True, slow=False, standoff=40.0),
           _wp(200, False, slow=False)]
    v = leg_speeds(wps, SP)
    assert v[0] == pytest.approx(2.0) and v[1] == 4.0
    # a far photo (the overview, 40 m away: 20 m/s) between cruise legs keeps the cruise speed
    assert v[2] == 8.0 and v[3] == 8.0


def test_photo_waits_keep_the_camera_interval():
    dt = np.array([0.5, 0.5, 2.0, 0.1, 0.1])
    photo = np.array([True, True, True, False, False, True])
    w = _photo_waits(dt, photo, 0.7)
    t = np.r_[0.0, np.cumsum(dt + w)]
    assert np.diff(t[photo]).min() == pytest.approx(0.7)
    assert w.tolist() == pytest.approx([0.2, 0.2, 0.0, 0.0, 0.0])  # only where it binds
    assert not _photo_waits(dt, photo, 0.0).any()


def test_chunk_time_counts_the_photo_interval_waits():
    # what the battery decisions rest on: photos 0.5 m apart at 2.5 m/s (0.2 s) wait for 0.7 s
    ch = Chunk("T1", "blade1", [_wp(0.5 * k, True, standoff=5.0) for k in range(11)])
    flown = chunk_time(ch, SP)  # 5 m at 2.5 m/s from and to a stop: 2 + 2.5 / 2.5 s
    assert flown == pytest.approx(5.0 / 2.5 + 2.5 / ACCEL_M_S2)
    assert chunk_time(ch, replace(SP, interval=0.7)) == pytest.approx(10 * 0.7)  # every leg < 0.7 s


def test_flown_leg_times_pay_for_speed_changes_and_corners():
    line = np.array([[0.0, 0, 50], [50, 0, 50], [100, 0, 50]])
    t = _flown_leg_times(line, np.array([5.0, 5.0]), 3.0)
    assert t.sum() == pytest.approx(100 / 5 + 5 / ACCEL_M_S2)  # straight on: no corner cost
    corner = np.array([[0.0, 0, 50], [50, 0, 50], [50, 50, 50]])
    assert _flown_leg_times(corner, np.array([5.0, 5.0]), 3.0).sum() > t.sum() + 1.0
    # a vertical climb at the climb rate, from and to a stop
    assert _flown(np.array([[0.0, 0, 0], [0, 0, 10]]), 8.0, 3.0) == pytest.approx(
        10 / 3 + 3 / ACCEL_M_S2)


def test_the_aircraft_flies_through_gentle_bends_and_stops_at_sharp_corners():
    """As a DJI mission flies (wtcli/plan/corners.py): a bend of 20 deg or less costs nothing at
    pass speed, a sharper corner is a full stop: the two legs timed as if flown apart."""
    from wtcli.plan.corners import PASS_TURN_DEG, stops

    def bent(deg):
        u = np.radians(deg)
        return np.array([[0.0, 0, 50], [50, 0, 50], [50 + 50 * np.cos(u), 50 * np.sin(u), 50]])

    v = np.array([2.7, 2.7])
    one_leg = _flown(np.array([[0.0, 0, 50], [100, 0, 50]]), 2.7, 3.0)
    assert _flown_leg_times(bent(10), v, 3.0).sum() == pytest.approx(one_leg)
    assert _flown_leg_times(bent(PASS_TURN_DEG), v, 3.0).sum() == pytest.approx(one_leg)
    apart = 2 * _flown(np.array([[0.0, 0, 50], [50, 0, 50]]), 2.7, 3.0)
    for deg in (PASS_TURN_DEG + 1, 45, 90):
        assert _flown_leg_times(bent(deg), v, 3.0).sum() == pytest.approx(apart)
    assert list(stops(bent(10))) == [True, False, True]
    assert list(stops(bent(30))) == [True, True, True]


def _corner(deg, leg=20.0):
    u = np.radians(deg)
    return (np.array([-leg, 0.0, 50.0]), np.array([0.0, 0.0, 50.0]),
            np.array([leg * np.cos(u), leg * np.sin(u), 50.0]))


@pytest.mark.parametrize("deg", [30, 60, 90, 120, 135])
def test_an_arc_rounds_a_corner_in_bends_the_aircraft_flies_through(deg):
    """corners.arc: tangent to both legs, one radius, bends under PASS_TURN_DEG (no stop
    between the legs' far ends), legs DJI accepts (>= 0.5 m); flown at most at sqrt(a r)
    through its waypoints and quicker than stopping at the corner."""
    from wtcli.plan.corners import (ARC_MIN_LEG_M, ARC_STEP_DEG, arc, corner_speeds, stops,
                                    turn_angles)
    a, c, b = _corner(deg)
    r = 2.5
    q = arc(a, c, b, r)
    chain = np.vstack([a, q, b])
    assert list(stops(chain)) == [True] + [False] * len(q) + [True]
    assert turn_angles(chain)[1:-1].max() <= ARC_STEP_DEG + 1e-6
    assert np.linalg.norm(np.diff(q, axis=0), axis=1).min() >= ARC_MIN_LEG_M
    # tangent points on the legs, as far from the corner as r tan(turn / 2)
    tan = r * np.tan(np.radians(deg) / 2)
    assert np.linalg.norm(q[0] - (c + tan * (a - c) / np.linalg.norm(a - c))) < 1e-9
    assert np.linalg.norm(q[-1] - (c + tan * (b - c) / np.linalg.norm(b - c))) < 1e-9
    inward = (b - c) / np.linalg.norm(b - c) - (c - a) / np.linalg.norm(c - a)
    centre = c + inward / np.linalg.norm(inward) * r / np.cos(np.radians(deg) / 2)
    assert np.linalg.norm(q - centre, axis=1) == pytest.approx(np.full(len(q), r))
    # through the arc no faster than a sideways acceleration of ACCEL_M_S2 allows
    vc = corner_speeds(chain, np.full(len(chain) - 1, 2.7), ACCEL_M_S2, 0.05)
    assert (vc[1:-1] > 0).all() and (vc[1:-1] <= np.sqrt(ACCEL_M_S2 * r) * 1.02).all()
    v = np.full(len(chain) - 1, 2.7)
    sharp = np.array([a, c, b])
    assert _flown_leg_times(chain, v, 3.0).sum() < _flown_leg_times(sharp, v[:2], 3.0).sum()


def test_an_arc_is_refused_where_it_would_not_fly_through_or_fit():
    from wtcli.plan.corners import ARC_MIN_RADIUS_M, arc
    assert arc(*_corner(15), 2.5) is None  # flown through as it is
    assert arc(*_corner(150), 2.5) is None  # doubling back: stays a stop
    assert arc(*_corner(90, leg=2.0), 2.5) is None  # the tangent points beyond the legs
    assert arc(*_corner(90), 0.5 * ARC_MIN_RADIUS_M) is None  # legs under 0.5 m
    # an arc that fits its shorter leg exactly (it starts at the waypoint before the corner)
    for deg in (37.0, 61.0, 90.0, 113.0):
        a, c, b = _corner(deg, leg=2.9)
        q = arc(a, c, b, 2.9 / np.tan(np.radians(deg) / 2))
        assert q is not None and np.allclose(q[0], a) and np.allclose(q[-1], b), deg


class _Ball:
    """A keep-out ball in place of a site: exact clearance of points and legs."""

    def __init__(self, centre, radius):
        self.c, self.r = np.asarray(centre, float), radius

    def segment_clearance(self, p0, p1, step=0.5, cap=None):
        d = p1 - p0
        t = np.clip(((self.c - p0) * d).sum(1) / np.maximum((d * d).sum(1), 1e-12), 0, 1)
        return np.linalg.norm(p0 + t[:, None] * d - self.c, axis=1) - self.r

    def clearance(self, points, cap=None):
        return np.linalg.norm(np.asarray(points) - self.c, axis=1) - self.r

    def above_ground(self, points, height):
        return np.asarray(points)[:, 2] >= height


def test_round_corners_moves_the_corner_photo_onto_the_arc_and_keeps_clear():
    """A pass's end photo at a 90 deg corner is taken on the arc (begun at the pass's station
    before it), at its point nearest the corner (about r (sqrt 2 - 1) off), aimed as before;
    the waypoints added are no photos, aimed in between; the corner is flown through. A
    keep-out ball inside the corner that the legs pass but the arc would cut leaves it a stop;
    so do ``move_photos`` False and a photo that would move by more than ARC_PHOTO_SHIFT of its
    standoff."""
    from wtcli.plan.corners import ARC_RADIUS_M, arc, stops
    from wtcli.plan.paths import round_corners
    east, north = np.array([0.0, 1.0, 0.0]), np.array([-1.0, 0.0, 0.0])
    pas = [WP(np.array([-3.0 * k, 0.0, 50.0]), east, True, "T1/blade1/leading_edge", standoff=11.0)
           for k in range(5, -1, -1)]  # along +x to the corner at the origin, looking north
    join = [WP(np.array([0.0, 20.0, 50.0]), north, True, "T1/blade1/trailing_edge", standoff=11.0)]
    ch = Chunk("T1", "blade1", pas + join)
    far = _Ball([50.0, -50.0, 50.0], 1.0)
    out = round_corners(ch, far, 3.0, 10.0)
    P = np.array([w.pos for w in out.wps])
    assert not stops(P)[1:-1].any()
    photos = [w for w in out.wps if w.photo]
    assert len(photos) == len(pas) + len(join)
    moved = photos[len(pas) - 1]
    # the arc of the greatest radius that fits: it starts at the pass's last station but one
    r = min(ARC_RADIUS_M, 3.0)
    corner = pas[-1].pos
    q = arc(pas[-2].pos, corner, join[0].pos, r)
    assert np.allclose(q[0], pas[-2].pos) and np.allclose(P[len(pas) - 1:-1], q[1:])
    # the arc's waypoint nearest the corner: r (sqrt 2 - 1) off with an even number of bends,
    # a little more with an odd one
    shift = np.linalg.norm(moved.pos - corner)
    assert shift == pytest.approx(np.linalg.norm(q - corner, axis=1).min())
    assert r * (np.sqrt(2) - 1) - 1e-9 <= shift <= 0.5 * r
    assert np.allclose(moved.fwd, east)
    # its blur limit from a lower bound of its distance to what it images: the planned one
    # less the shift, or the clearance there if nearer than planned (here nothing is near)
    assert moved.standoff == pytest.approx(max(11.0 - shift, min(11.0, far.clearance(
        moved.pos[None])[0])))
    added = [w for w in out.wps if not w.photo]
    assert added and all(abs(np.linalg.norm(w.fwd) - 1) < 1e-9 for w in added)
    # the camera turns from the pass's aim to the join's along the way
    yaws = [np.degrees(np.arctan2(w.fwd[0], w.fwd[1])) for w in out.wps[len(pas):-1]]
    assert all(-90.0 - 1e-6 <= y <= 1e-6 for y in yaws) and yaws == sorted(yaws, reverse=True)
    # a ball inside the corner 1.6 m from either leg, 1.3 m from the arc: not clear of 1.5 m
    inside = _Ball([-2.1, 2.1, 50.0], 0.5)
    legs = np.array([pas[0].pos, corner, join[0].pos])
    assert inside.segment_clearance(legs[:-1], legs[1:]).min() >= 1.6 - 1e-9
    kept = round_corners(ch, inside, 1.5, 10.0)
    assert [w.pos.tolist() for w in kept.wps] == [w.pos.tolist() for w in ch.wps]
    still = round_corners(ch, far, 3.0, 10.0, move_photos=False)
    assert [w.pos.tolist() for w in still.wps] == [w.pos.tolist() for w in ch.wps]
    # a close view (4 m from its surface) would move by a third of that: it stays a stop
    near = replace(ch, wps=[replace(w, standoff=4.0) for w in ch.wps])
    assert [w.pos.tolist() for w in round_corners(near, far, 3.0, 10.0).wps] == \
        [w.pos.tolist() for w in ch.wps]


def test_capture_speed_is_the_slowest_of_cap_interval_and_blur():
    m = Mission((Turbine.with_rotor_azimuth(90, id="T1", base=(0, 0, 0), hub_height=80,
                                            rotor_diameter=90, yaw_deg=0),), CAM)
    pp = pass_params(m)[0]
    v, lim = capture_speed(m, pp)
    gsd = float(CAM.gsd_mm(pp.standoff))
    assert lim["motion_blur_m_s"] == pytest.approx(1.0 * gsd / 1000 / 0.0005)
    assert lim["photo_interval_m_s"] == pytest.approx(pp.spacing(pp.standoff) / 0.7)
    assert lim["fleet_m_s"] == 4.0 and v == min(lim.values())
    slow_shutter = replace(m, capture=Capture(shutter_s=1 / 500))
    assert capture_speed(slow_shutter, pp)[0] == pytest.approx(gsd / 1000 * 500)
    capped = replace(m, fleet=replace(m.fleet, inspection_speed_m_s=1.0))
    assert capture_speed(capped, pp)[0] == 1.0


def test_camera_capture_keys_are_read_and_checked():
    d = default_dict()
    d["turbines"] = [{"id": "T1", "position": [0, 0, 0], "hub_height_m": 80, "rotor_diameter_m": 90, "yaw_deg": 0}]
    d["camera"].update(min_photo_interval_s=1.5, shutter_s=0.001, max_blur_px=0.5)
    m = mission_from_dict(d)
    assert m.capture == Capture(1.5, 0.001, 0.5)
    assert Capture() == Capture(**{k: default_dict()["camera"][k] for k in
                                   ("min_photo_interval_s", "shutter_s", "max_blur_px")})
    d["camera"]["shutter_s"] = 0
    with pytest.raises(ConfigError, match=r"camera.*shutter_s"):
        mission_from_dict(d)


@pytest.fixture(scope="module")
def swapped_plan():
    """One turbine on batteries too small for it in one sortie: a swap, every kind of leg."""
    t = Turbine.with_rotor_azimuth(90, id="T1", base=(0, 0, 0), hub_height=80, rotor_diameter=90,
                                   yaw_deg=0)
    fleet = Fleet(battery_minutes=6.0, battery_reserve_minutes=1.0, battery_swap_s=120.0)
    m = Mission((t,), CAM, fleet=fleet, settings=Settings(min_side_coverage=0.0))
    return m, plan_mission(m)


def test_time_budget_adds_up_to_the_flight_and_names_every_kind(swapped_plan):
    m, plan = swapped_plan
    s = plan.summary
    b = s["time_budget"]["T1"]
    assert set(b) == {*BUDGET_KEYS, "total_s"}
    r = plan.routes[0]
    assert b["total_s"] == pytest.approx(r.duration_s, abs=0.05)
    assert b["total_s"] == pytest.approx(sum(b[k] for k in BUDGET_KEYS), abs=0.05)
    assert r.summary["battery_swaps"] >= 1
    assert b["battery_swaps_s"] == pytest.approx(120.0 * r.summary["battery_swaps"])
    sorties = r.summary["sorties"]
    # take-off climb and landing descent: takeoff_altitude_m at climb_rate_m_s, each sortie,
    # from a stop on the ground, through the corner above the launch point
    up = _flown(np.array([[0.0, 0, 0], [0, 0, 10]]), 8.0, 3.0)
    assert 2 * sorties * 10 / 3 < b["climbs_s"] <= 2 * sorties * up + 0.05
    assert b["capture_s"] > b["turns_s"] > 0 and b["transit_s"] > 0
    assert s["per_uav"]["UAV1"]["time_budget"] == s["time_budget"]


def test_photos_are_flown_within_the_capture_limits(swapped_plan):
    m, plan = swapped_plan
    s = plan.summary
    r = plan.routes[0]
    v_cap = s["capture"]["speed_m_s"]
    assert v_cap == pytest.approx(min(s["capture"]["limits"].values()))
    i = np.nonzero(r.photo)[0]
    # consecutive photos at least the camera's interval apart
    assert np.diff(r.t[i]).min() >= m.capture.min_photo_interval_s - 1e-6
    # every inspection photo: the slower of the legs beside it within the fleet's cap and the
    # photo interval's limit (the overview, tens of metres from the rotor, has a blur limit
    # above the cruise speed; each photo's own blur limit:
    # test_every_photo_is_passed_within_the_blur_limit_of_the_nearest_surface)
    lim = s["capture"]["limits"]
    near = i[[not str(c).endswith("/overview") for c in r.component[i]]]
    assert len(near) == len(i) - 1
    v_in = r.speed[near]
    v_out = np.r_[r.speed[1:], np.inf][near]
    assert (np.minimum(v_in, v_out)
            <= min(lim["fleet_m_s"], lim["photo_interval_m_s"]) + 1e-6).all()
    # and the passes do fly at it (not at the fleet's cap)
    both = r.photo[1:] & r.photo[:-1] & (np.diff(r.t) > 0)
    assert np.median(r.speed[1:][both]) == pytest.approx(v_cap, rel=0.05)


def test_a_slower_camera_makes_a_longer_flight_and_more_capture_time(swapped_plan):
    m, plan = swapped_plan
    # the same chunks on a battery that holds the slower components
    slow = plan_mission(replace(m, capture=Capture(min_photo_interval_s=2.0),
                                fleet=replace(m.fleet, battery_minutes=60.0)))
    b0, b1 = plan.summary["time_budget"]["T1"], slow.summary["time_budget"]["T1"]
    assert slow.summary["capture"]["limits"]["photo_interval_m_s"] < 1.0
    assert b1["capture_s"] > 2 * b0["capture_s"]
    assert slow.summary["photos"] == plan.summary["photos"]  # the same photos, flown slower


def test_nacelle_underside_is_flown_looking_up_where_the_gimbal_reaches():
    from wtcli.plan.clearance import Site
    from wtcli.plan.mission import default_launch
    from wtcli.plan.paths import nacelle_chunk

    t = Turbine.with_rotor_azimuth(75, id="T1", base=(0, 0, 0), hub_height=100,
                                   rotor_diameter=150, yaw_deg=200)
    pp = pass_params(Mission((t,), CAM))[0]
    site = Site([t], launch=default_launch(t))
    up = [w for w in nacelle_chunk(t, site, pp).wps if w.photo and w.fwd[2] > 0.99]
    assert len(up) >= 2 and all(w.pos[2] < t.nacelle_center[2] for w in up)
    assert site.clearance(np.array([w.pos for w in up])).min() >= pp.required
    # over the tower top no station keeps the clearance: the pass is split round it
    axis_dist = np.linalg.norm(np.array([w.pos[:2] for w in up]) - t.base_xyz[:2], axis=1)
    assert axis_dist.min() > t.tower_top_radius + pp.required
    under_slung = replace(pp, pitch_range=(-90.0, 30.0))
    assert not [w for w in nacelle_chunk(t, site, under_slung).wps if w.photo and w.fwd[2] > 0.5]


def test_an_autopilot_flies_the_plan_in_about_the_planned_time(swapped_plan):
    """fly's set-point (trapezoidal speed changes, junction-deviation corners) on the plan's
    route: the plan's times already pay for the corners, so it runs only a little behind."""
    from wtcli.fly.sim import make_reference

    _, plan = swapped_plan
    r = plan.routes[0]
    ref = make_reference(r.t, r.pos, r.yaw_deg, r.gimbal_pitch_deg, 0.1, 0.0, ACCEL_M_S2, 0.05,
                         r.speed)
    assert r.duration_s <= ref.t[-1] <= 1.08 * r.duration_s


@pytest.fixture(scope="module")
def big_plan():
    """A large turbine with the default camera (a DJI P1 35 mm: blades as rings of four passes,
    the nacelle's underside in oblique rows, four tower columns with foot views)."""
    c = default_dict()["camera"]
    cam = Camera(c["width_px"], c["height_px"], c["focal_mm"], c["sensor_width_mm"])
    t = Turbine.with_rotor_azimuth(20, id="T1", base=(0, 0, 0), hub_height=100,
                                   rotor_diameter=150, yaw_deg=35)
    m = Mission((t,), cam, settings=Settings(min_side_coverage=0.0))
    return m, plan_mission(m)


def test_every_photo_is_passed_within_the_blur_limit_of_the_nearest_surface(big_plan):
    # Measured from the geometry, not from the standoff a station was planned at: the slower
    # leg beside each photo within the blur limit at the photo's distance to the part it is of
    # (its nearest surface: never a looser limit than the surface it images).
    m, plan = big_plan
    t, r = m.turbines[0], plan.routes[0]
    i = np.nonzero(r.photo & np.array(["/overview" not in str(c) for c in r.component]))[0]
    part = [t.part_names().index(str(c).split("/")[1]) for c in r.component[i]]
    d = t.clearance_by_part(r.pos[i])[np.arange(len(i)), part]
    limit = np.array([m.capture.blur_speed_m_s(float(m.camera.gsd_mm(x))) for x in d])
    v = np.minimum(r.speed[i], np.r_[r.speed[1:], np.inf][i])
    # (1 %: the blade distance is a slightly conservative lower bound, 10.74 m for 10.78)
    assert (v <= 1.01 * limit).all(), r.component[i][v > 1.01 * limit]
    # the tower's foot views (a few metres from the tower) are among them, passed slowly
    tower = [str(c) == "T1/tower" for c in r.component[i]]
    assert d[tower].min() < 6.0


def test_rings_end_at_a_root_next_to_the_next_blade(big_plan):
    # an even ring ends at the root (out and back in turn) on the side facing the next blade:
    # no return leg to its start, and the hop to the next blade is a few metres
    m, plan = big_plan
    t, r = m.turbines[0], plan.routes[0]
    comps = [str(c) for c in r.component]
    assert not [c for c in comps if c.endswith("/return") and "blade" in c]
    blades = [c.split("/")[1] for c in comps if "/blade" in c]
    order = list(dict.fromkeys(blades))
    assert len(order) == 3
    for a, b in zip(order, order[1:]):
        last = max(j for j, c in enumerate(comps) if f"/{a}/" in c)
        first = min(j for j, c in enumerate(comps) if f"/{b}/" in c and r.photo[j])
        hop = np.linalg.norm(np.diff(r.pos[last:first + 1], axis=0), axis=1).sum()
        assert hop < 15.0, (a, b, hop)
        # both ends at the root: within a few metres of the hub's edge
        for j in (last, first):
            assert np.linalg.norm(r.pos[j] - t.hub_center) < t.blade_root_offset + 15.0


def test_nacelle_underside_in_oblique_rows_either_side_of_the_tower_top(big_plan):
    # the default camera's standoff puts a row straight under the nacelle over the tower top:
    # the underside is seen in two rows beside it, each looking up and in at its own half
    m, plan = big_plan
    t, r = m.turbines[0], plan.routes[0]
    i = np.nonzero(r.photo & (r.component == "T1/nacelle"))[0]
    up = i[r.gimbal_pitch_deg[i] > 20.0]
    side = np.cross([0.0, 0.0, 1.0], t.axis)
    off = (r.pos[up] - t.nacelle_center) @ side
    assert (off > 0).sum() >= 2 and (off < 0).sum() >= 2
    assert (r.pos[up, 2] < t.nacelle_center[2] - t.nacelle_height / 2).all()
    assert t.clearance(r.pos[up]).min() >= m.settings.safe_distance_m + m.settings.tracking_margin_m
    # the underside's whole width within the GSD's reach of one row or the other
    from wtcli.geometry.coverage import measure_coverage
    from wtcli.plan.mission import _photos_of
    pos, rot = _photos_of(t, plan.routes)
    samples = t.surface_samples(0.5)
    cov = measure_coverage(samples, m.camera, pos, rot, plan.summary["coverage_gsd_mm"])
    bottom = (samples.part == t.part_names().index("nacelle")) & (samples.normals[:, 2] < -0.9)
    assert cov.fraction(bottom) > 0.9


def test_planned_corners_are_rounded_where_clear_and_the_plan_is_quicker(monkeypatch):
    """The planner's own corners (paths.round_corners) against the same plan with every corner
    a stop: the blades stop at most half as often (their passes flown end to end, the rest at
    the root's detours and where they meet), the plan is quicker,
    keeps the clearance and still meets min_side_coverage."""
    import wtcli.plan.mission as mission
    from wtcli.plan.corners import stops
    t = Turbine.with_rotor_azimuth(90, id="T1", base=(0, 0, 0), hub_height=98,
                                   rotor_diameter=150, yaw_deg=0)
    m = Mission((t,), Camera(8192, 5460, 35, 35.9), settings=Settings())
    rounded = plan_mission(m)
    monkeypatch.setattr(mission, "round_corners", lambda ch, *a, **k: ch)
    sharp = plan_mission(m)

    def blade_stops(plan):
        r = plan.routes[0]
        s = stops(r.pos)
        return sum(int(s[[f"/blade{k}" in str(c) for c in r.component]].sum()) for k in (1, 2, 3))

    assert blade_stops(rounded) <= blade_stops(sharp) // 2, (blade_stops(rounded), blade_stops(sharp))
    t_r, t_s = (p.summary["flight_time_sum_s"] for p in (rounded, sharp))
    assert t_r < t_s - 30.0, (t_r, t_s)
    assert not any(rounded.summary["violations"].values())
    assert rounded.summary["predicted_coverage"]["T1"]["min_side"] >= m.settings.min_side_coverage
