"""Where the aircraft stops on a route, and how fast it takes the waypoints it flies through.

One model for the planner's timing (``wtcli.plan.mission``), fly's set-point
(``wtcli.fly.sim.make_reference``) and the DJI export (``wtcli.plan.dji_kmz``), so that a plan's
minutes are the minutes its exported mission flies:

- **Through** a waypoint where the route bends by at most ``PASS_TURN_DEG`` (a photo pass, the
  taper of a blade's standoff, a ring round the tower): the aircraft keeps flying, at most at the
  "junction deviation" speed of the bend, turning the camera on the way. DJI:
  ``toPointAndPassWithContinuityCurvature`` on straight segments, the gimbal turned evenly along
  the leg (``gimbalEvenlyRotate``).
- **Stops** at a sharper corner, at the ends and around zero-length legs (a hover, a turn on the
  spot). DJI: ``toPointAndStopWithDiscontinuityCurvature``.

A stop is what a DJI waypoint mission does at a corner; other autopilots (ArduPilot, PX4) round it
at speed, so for them the plan's time is an upper bound.

The planner rounds its own corners where it can (``wtcli.plan.paths.round_corners``): a corner
of a blade's or the tower's passes (a pass's end turning into the join to the next, 20-135 deg)
becomes an ``arc`` of bends of at most ARC_STEP_DEG, flown through, its legs checked for
clearance like any other; the corner's photo is taken on the arc, at its point nearest the
corner.
"""

from __future__ import annotations

import math

import numpy as np

PASS_TURN_DEG = 20.0  # sharper bends are stops; the junction-deviation speed at 20 deg and 0.05 m
# (2.9 m/s) is about a photo pass's, so a pass's own bends never slow it


def turn_angles(pos: np.ndarray) -> np.ndarray:
    """The route's change of direction at each waypoint, degrees (0 straight on; 180 at the ends
    and next to zero-length legs, where it has no direction)."""
    P = np.asarray(pos, float)
    out = np.full(len(P), 180.0)
    if len(P) < 3:
        return out
    D = np.diff(P, axis=0)
    L = np.linalg.norm(D, axis=1)
    u = D / np.maximum(L, 1e-12)[:, None]
    ang = np.degrees(np.arccos(np.clip((u[:-1] * u[1:]).sum(1), -1.0, 1.0)))
    out[1:-1] = np.where((L[:-1] > 1e-6) & (L[1:] > 1e-6), ang, 180.0)
    return out


def stops(pos: np.ndarray) -> np.ndarray:
    """True at each waypoint where the aircraft stops: the ends, zero-length legs and bends
    sharper than PASS_TURN_DEG."""
    return turn_angles(pos) > PASS_TURN_DEG + 1e-6


def corner_speeds(pos: np.ndarray, v_leg: np.ndarray, accel: float, corner_m: float) -> np.ndarray:
    """Speed allowed through each waypoint: 0 where the aircraft ``stops``, else the "junction
    deviation" limit sqrt(a d sin(q/2) / (1 - sin(q/2))) at a turn of interior angle q (straight
    on: q = 180 deg, no limit), the turn's own limit sqrt(a r) where r = (mean of its legs) /
    turn (radians) is the radius of the curve the polyline follows there (an arc of short legs
    is flown no faster than ``a`` sideways; at its ends too: the least of a waypoint's and its
    neighbours'), and never above either leg's speed."""
    P = np.asarray(pos, float)
    vc = np.zeros(len(P))
    if len(P) < 3:
        return vc
    turn = turn_angles(P)[1:-1]
    sh = np.cos(np.radians(turn) / 2)  # sin(q/2), q = 180 deg - turn the legs' interior angle
    L = np.linalg.norm(np.diff(P, axis=0), axis=1)
    bend = np.radians(turn)
    with np.errstate(divide="ignore", invalid="ignore"):
        lim = np.where(sh > 0.9999, np.inf, np.sqrt(accel * corner_m * sh / np.maximum(1 - sh, 1e-9)))
        radius = 0.5 * (L[:-1] + L[1:]) / np.maximum(bend, 1e-12)
        # (a stop's own bend is no arc: it limits no neighbour)
        curve = np.where((bend > 1e-6) & ~stops(P)[1:-1], np.sqrt(accel * radius), np.inf)
        # an arc's first and last waypoints (half its bend, beside a long straight) are already
        # on it: its speed holds from one end to the other
        lim = np.minimum(lim, np.minimum(curve, np.minimum(np.r_[curve[1:], np.inf],
                                                           np.r_[np.inf, curve[:-1]])))
    v_leg = np.asarray(v_leg, float)
    inner = np.minimum(np.minimum(v_leg[:-1], v_leg[1:]), lim)
    vc[1:-1] = np.where(stops(P)[1:-1], 0.0, inner)
    return vc


# ---- rounding the planner's corners ------------------------------------------------------------
ROUND_MAX_DEG = 135.0  # sharper corners (a leg doubling back) stay stops: an arc round them
# would stand far off the corner
ARC_STEP_DEG = 19.0  # an arc's bends, just under PASS_TURN_DEG: flown through
ARC_RADIUS_M = 3.0  # flown at 2.7 m/s at 2.5 m/s^2 sideways, about a photo pass's blur limit
ARC_MIN_RADIUS_M = 1.0  # a tighter arc is flown too slowly to beat the stop
ARC_MIN_LEG_M = 0.6  # DJI takes waypoints at least 0.5 m apart


def arc(a: np.ndarray, c: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray | None:
    """The arc of ``radius`` tangent to the legs a -> c and c -> b, cutting the corner at c, as
    waypoints from its tangent point on a -> c to the one on c -> b: equal bends of at most
    ARC_STEP_DEG, legs of at least ARC_MIN_LEG_M. None where the corner is no sharper than
    PASS_TURN_DEG or sharper than ROUND_MAX_DEG, or a tangent point falls outside its leg."""
    a, c, b = (np.asarray(x, float) for x in (a, c, b))
    la, lb = float(np.linalg.norm(c - a)), float(np.linalg.norm(b - c))
    if la < 1e-6 or lb < 1e-6:
        return None
    u1, u2 = (c - a) / la, (b - c) / lb
    turn = math.degrees(math.acos(max(-1.0, min(1.0, float(u1 @ u2)))))
    if not PASS_TURN_DEG < turn <= ROUND_MAX_DEG:
        return None
    phi = math.radians(turn)
    tangent = radius * math.tan(phi / 2)
    n = math.ceil(turn / ARC_STEP_DEG)
    if tangent > min(la, lb) + 1e-9 or 2 * radius * math.sin(phi / (2 * n)) < ARC_MIN_LEG_M:
        return None
    inward = (u2 - u1) / np.linalg.norm(u2 - u1)
    centre = c + inward * radius / math.cos(phi / 2)
    s1, s2 = c - tangent * u1 - centre, c + tangent * u2 - centre
    return np.array([centre + (math.sin((1 - k / n) * phi) * s1 + math.sin(k / n * phi) * s2)
                     / math.sin(phi) for k in range(n + 1)])
