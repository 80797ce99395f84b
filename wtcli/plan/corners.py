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
"""

from __future__ import annotations

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
    on: q = 180 deg, no limit), and never above either leg's speed."""
    P = np.asarray(pos, float)
    vc = np.zeros(len(P))
    if len(P) < 3:
        return vc
    turn = turn_angles(P)[1:-1]
    sh = np.cos(np.radians(turn) / 2)  # sin(q/2), q = 180 deg - turn the legs' interior angle
    with np.errstate(divide="ignore", invalid="ignore"):
        lim = np.where(sh > 0.9999, np.inf, np.sqrt(accel * corner_m * sh / np.maximum(1 - sh, 1e-9)))
    v_leg = np.asarray(v_leg, float)
    inner = np.minimum(np.minimum(v_leg[:-1], v_leg[1:]), lim)
    vc[1:-1] = np.where(stops(P)[1:-1], 0.0, inner)
    return vc
