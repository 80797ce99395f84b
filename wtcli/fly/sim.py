"""The flight loop: a multirotor tracking one route under wind.

Vehicle (per unit mass, ENU), ``vehicle.model``:

- ``rigid`` (the default, ``wtcli.fly.rigid``): the autopilot's velocity loop asks for an
  acceleration, the attitude loop tilts the thrust towards it through a rate-limited inner loop
  and the rotors' lag, and the collective thrust follows with the rotors' lag.
- ``kinematic`` (an option): the velocity loop's acceleration ``a = (v_cmd - v) / tau_v`` (plus
  the reference acceleration as feed-forward) is produced at once, with a thrust ``T = a - D(-v)``
  that includes its own still-air drag, limited by the maximum tilt (horizontal, g tan(tilt))
  and the vertical acceleration limit.

In both the air acts with ``D(w - v) = c (w - v) + k |w - v| (w - v)`` (rotor drag plus body drag)
on the air-relative velocity, so ``dv/dt = T + D(w - v)``: in still air the vehicle gets what it
asked for (after the lags), in wind it is pushed. The wind is the mean wind with shear at the
vehicle's height, the precomputed turbulence and gusts, and the structure's wake.

Controllers (``wtcli.fly.control``: PID, feed-forward only, manual pilot) are objects with
``reset()`` and ``step()``; each returns the velocity command ``v_cmd``, already limited by the
speed and climb limits, and says whether the reference acceleration is fed forward and whether
it holds position (then drifting ``control.divergence_m`` from the set-point fails the flight).
The controller sees the navigation estimate (the true state plus ``wtcli.fly.navigation``'s
errors); deviation and clearance are measured on the truth.

A set-point that waits for the vehicle (``control.leash_m`` = L > 0, position-holding controllers
only): the set-point's clock runs at ``1 - e / L`` of real time, ``e`` the distance between the
navigation estimate and the set-point (filtered over ``LEASH_FILTER_S``), and stops while
``e >= L``, as PX4's trajectory generator does with ``MPC_XY_ERR_MAX`` (the integration speed of the trajectory is reduced linearly with the
tracking error and stopped above it) and as ArduPilot's WPNAV leash holds its target back. So a
gust that pushes the vehicle off does not also let the set-point run on into a corner the vehicle
then cuts. The set-point's velocity and acceleration feed-forward are scaled by the clock's rate;
the wake and the ground are taken where the set-point is; the flight runs until the set-point has
reached the route's end and then ``SETTLE_S``; ``Track.progress`` says where along the reference
(fractional index) the set-point was at each step, and ``Reference.retimed`` turns it into the
reference actually flown.

Physics runs at ``physics_hz`` (semi-implicit Euler), control at ``control_hz``; states are
recorded at the control rate. The controller runs in plain Python per control step, the rigid
body's physics steps compiled; everything else is precomputed or evaluated after the run. The
precomputed inputs reach the loop as Python lists a block of ``BLOCK_STEPS`` steps at a time
(``wtcli.fly.control``), and the track leaves it as arrays a block at a time, so the loop's
own memory does not grow with the route (docs/fly.md "Memory").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wtcli.errors import SimulationError
from wtcli.fly.control import (Controller, FeedForwardController, PidController, PilotController,
                               PilotInputs, Rows, VelocityLimits)
from wtcli.fly import control as controls, rigid
from wtcli.fly.navigation import Navigation
from wtcli.fly.scenario import Scenario
from wtcli.fly.wind import WindSeries
from wtcli.plan.corners import corner_speeds

G = 9.81
SETTLE_S = 3.0  # hover at the last waypoint after the reference ends
DIVERGED_M = 1e5
LEASH_FILTER_S = 0.5  # first-order filter on the leash's error (an EKF's estimate is smooth)


@dataclass(frozen=True)
class Reference:
    """A route sampled at the control rate (what the controller is asked to follow)."""

    t: np.ndarray  # (N,)
    pos: np.ndarray  # (N, 3) smoothed set-point
    vel: np.ndarray  # (N, 3)
    acc: np.ndarray  # (N, 3)
    yaw_deg: np.ndarray  # (N,) unwrapped
    pitch_deg: np.ndarray  # (N,)
    end_index: int  # first index after the route's last waypoint time
    wp_index: np.ndarray  # (N,) fractional waypoint index of the set-point

    def retimed(self, progress: np.ndarray, dt: float) -> "Reference":
        """The set-point actually flown when its clock was held back: this reference sampled at
        the fractional indices ``progress`` (one per control step, non-decreasing), velocities and
        accelerations differentiated again; ``end_index`` is the first step at the route's end
        (``len(progress)`` if it never got there)."""
        prog = np.asarray(progress, float)
        idx = np.arange(len(self.t), dtype=float)
        pos = np.stack([np.interp(prog, idx, self.pos[:, i]) for i in range(3)], 1)
        vel = np.gradient(pos, dt, axis=0) if len(pos) > 1 else np.zeros_like(pos)
        acc = np.gradient(vel, dt, axis=0) if len(pos) > 1 else np.zeros_like(pos)
        at_end = np.nonzero(prog >= self.end_index - 1e-9)[0]
        return Reference(self.t[0] + np.arange(len(prog)) * dt, pos, vel, acc,
                         np.interp(prog, idx, self.yaw_deg), np.interp(prog, idx, self.pitch_deg),
                         int(at_end[0]) if len(at_end) else len(prog),
                         np.interp(prog, idx, self.wp_index))

    def reach_step(self, waypoint: np.ndarray) -> np.ndarray:
        """First step at which the set-point reaches each waypoint index."""
        k = np.searchsorted(self.wp_index, np.asarray(waypoint, float) - 1e-9, side="left")
        return np.clip(k, 0, len(self.t) - 1)


def _box(x: np.ndarray, width: int) -> np.ndarray:
    """Centred moving average along axis 0 with edge padding (odd width)."""
    if width <= 1:
        return x
    h = width // 2
    pad = np.concatenate([np.repeat(x[:1], h, 0), x, np.repeat(x[-1:], h, 0)])
    c = np.cumsum(np.concatenate([np.zeros((1,) + x.shape[1:]), pad]), axis=0)
    return (c[width:] - c[:-width]) / width


def make_reference(t_wp: np.ndarray, pos_wp: np.ndarray, yaw_wp: np.ndarray, pitch_wp: np.ndarray,
                   dt: float, smoothing_s: float, accel: float = 2.5, corner_m: float = 0.05,
                   speed: np.ndarray | None = None, yaw_rate: float | None = None,
                   pitch_rate: float | None = None, settle_s: float = SETTLE_S) -> Reference:
    """The set-point an autopilot's mission mode follows: the planned polyline exactly, each leg
    at the planned ``speed`` (else its length over its planned duration) with trapezoidal speed
    changes at ``accel``, stopping where the exported mission stops (``wtcli.plan.corners``: sharp
    corners, the ends, zero-length legs) and taking the other waypoints at the junction-deviation
    speed; zero-length legs (hover, turning on the spot) keep their planned duration, and a leg's
    planned time beyond flying it so is a hover at its end. Time runs behind a plan that asks
    for instant speed changes or camera turns; photos are triggered when the set-point reaches
    their waypoint. The set-point then hovers at the last waypoint for ``settle_s`` (room for a
    leash's clock)."""
    tw = np.asarray(t_wp, float)
    P = np.asarray(pos_wp, float)
    seg = np.diff(P, axis=0)
    L = np.linalg.norm(seg, axis=1)
    dtp = np.maximum(np.diff(tw), 0.0)
    moving = L > 1e-6
    v_leg = np.where(moving, L / np.maximum(dtp, 1e-9), 0.0)
    v_leg = np.where(moving & (dtp <= 1e-9), 1e3, v_leg)  # an untimed leg: as fast as allowed
    if speed is not None:
        sp = np.asarray(speed, float)[1:]
        v_leg = np.where(moving & (sp > 0), sp, v_leg)
    t_turn = np.zeros(len(L))
    yaw_u = np.degrees(np.unwrap(np.radians(np.asarray(yaw_wp, float))))
    if yaw_rate:
        t_turn = np.maximum(t_turn, np.abs(np.diff(yaw_u)) / (0.5 * yaw_rate))
    if pitch_rate:
        t_turn = np.maximum(t_turn, np.abs(np.diff(np.asarray(pitch_wp, float))) / (0.5 * pitch_rate))
    v_leg = np.where(moving & (t_turn > 0), np.minimum(v_leg, L / np.maximum(t_turn, 1e-9)), v_leg)
    dtp = np.where(~moving, np.maximum(dtp, t_turn), dtp)
    a = float(accel)
    vc = corner_speeds(P, v_leg, a, corner_m)  # 0 where the exported mission stops
    # Forward and backward passes: reachable with |acceleration| <= a along each leg.
    for j in range(len(L)):
        vc[j + 1] = min(vc[j + 1], math.sqrt(vc[j] ** 2 + 2 * a * L[j]))
    for j in range(len(L) - 1, -1, -1):
        vc[j] = min(vc[j], math.sqrt(vc[j + 1] ** 2 + 2 * a * L[j]))
    v0, v1 = vc[:-1], vc[1:]
    vp = np.where(moving, np.minimum(v_leg, np.sqrt((2 * a * L + v0 ** 2 + v1 ** 2) / 2)), 0.0)
    vp = np.maximum(vp, np.maximum(v0, v1))
    d_acc = np.where(moving, (vp ** 2 - v0 ** 2) / (2 * a), 0.0)
    d_dec = np.where(moving, (vp ** 2 - v1 ** 2) / (2 * a), 0.0)
    d_cru = np.maximum(L - d_acc - d_dec, 0.0)
    t_acc = np.where(moving, (vp - v0) / a, 0.0)
    t_dec = np.where(moving, (vp - v1) / a, 0.0)
    t_cru = np.where(moving, d_cru / np.maximum(vp, 1e-9), 0.0)
    t_move = t_acc + t_cru + t_dec
    # A plan's leg time holds its own speed changes (the planner times them as above): only what
    # it allots beyond flying the leg (a battery swap, a wait) is spent hovering at its end.
    dwell = np.where(moving, np.maximum(dtp - t_move, 0.0), 0.0)
    t_leg = np.where(moving, t_move + dwell, dtp)
    T = np.concatenate([[tw[0]], tw[0] + np.cumsum(t_leg)])
    n_end = int(math.ceil((T[-1] - T[0]) / dt)) + 1
    n = n_end + int(round(max(settle_s, 0.0) / dt))
    t = T[0] + np.arange(n) * dt
    j = np.clip(np.searchsorted(T, t, side="right") - 1, 0, len(L) - 1)
    tau = np.clip(t - T[j], 0.0, t_leg[j])
    ta, tc = t_acc[j], t_cru[j]
    s = np.where(tau < ta, v0[j] * tau + 0.5 * a * tau ** 2,
                 np.where(tau < ta + tc, d_acc[j] + vp[j] * (tau - ta),
                          d_acc[j] + d_cru[j] + vp[j] * (tau - ta - tc)
                          - 0.5 * a * (tau - ta - tc) ** 2))
    s = np.where(tau >= t_move[j], L[j], s)  # arrived (and hovering, if the leg has a dwell)
    s = np.clip(np.where(moving[j], s, 0.0), 0.0, L[j])
    frac = np.where(moving[j], s / np.maximum(L[j], 1e-12),
                    tau / np.maximum(t_leg[j], 1e-9))
    frac = np.where(t >= T[-1], 1.0, frac)
    u = j + frac  # fractional waypoint index
    pos = P[j] + (seg[j] / np.maximum(L[j], 1e-12)[:, None]) * s[:, None]
    pos[t >= T[-1]] = P[-1]
    width = max(1, int(round(smoothing_s / dt)) | 1)
    if width > 1:
        pos = _box(pos, width)
    vel = np.gradient(pos, dt, axis=0)
    acc = np.gradient(vel, dt, axis=0)
    idx = np.arange(len(P), dtype=float)
    yaw = np.interp(u, idx, yaw_u)
    pitch = np.interp(u, idx, pitch_wp)
    return Reference(t, pos, vel, acc, yaw, pitch, n_end, u)


@dataclass(frozen=True)
class Track:
    """One simulated flight, at the control rate. ``positions()`` keeps only ``t`` and ``pos``
    (the rest None): what a report keeps of a flight once it is measured."""

    t: np.ndarray  # (N,)
    pos: np.ndarray  # (N, 3) true position
    vel: np.ndarray | None  # (N, 3)
    thrust: np.ndarray | None  # (N, 3) thrust acceleration (for tilt and power)
    wind: np.ndarray | None  # (N, 3) wind at the vehicle
    yaw_deg: np.ndarray | None  # (N,) camera heading actually flown
    pitch_deg: np.ndarray | None  # (N,) gimbal elevation actually flown
    progress: np.ndarray | None = None  # (N,) the set-point's fractional reference index

    def __post_init__(self) -> None:
        n = len(self.t)
        for name in ("pos", "vel", "thrust", "wind"):
            a = getattr(self, name)
            if (a is not None or name == "pos") and np.shape(a) != (n, 3):
                raise ValueError(f"expected {name} of shape ({n}, 3), got {np.shape(a)}")

    def positions(self) -> Track:
        """Only the times and true positions."""
        return Track(self.t, self.pos, None, None, None, None, None)


def fly(ref: Reference, scn: Scenario, wind: WindSeries, ground_under_ref: np.ndarray,
        controller: Controller, nav: Navigation, wake: np.ndarray | None = None,
        block: int | None = None) -> Track:
    """Fly ``ref`` with ``controller`` (reset first) and return the track. The controller sees
    the true state plus the navigation errors ``nav``; ``wake`` (N, 3), if given, is the
    structure's wake added to the wind at each control step. ``scn.vehicle.model`` picks the
    physics: ``rigid`` (wtcli.fly.rigid, compiled) or ``kinematic`` (below). ``block``: control
    steps whose inputs are turned into Python lists at a time (default ``BLOCK_STEPS``); the
    flight is the same, bit for bit, whatever it is."""
    veh, ctl = scn.vehicle, scn.control
    n = len(ref.t)
    sub = scn.substeps
    dt = 1.0 / ctl.control_hz
    dtp = dt / sub
    if len(wind.extra) < n * sub:
        raise ValueError(f"expected {n * sub} wind samples, got {len(wind.extra)}")
    if nav.pos_error.shape != (n, 3) or nav.vel_error.shape != (n, 3):
        raise ValueError(f"expected navigation errors of shape ({n}, 3)")
    block = max(2, int(block or controls.BLOCK_STEPS))
    controller.reset()
    step = controller.step
    name = controller.name
    rigid_model = veh.model == "rigid"

    # Plain Python lists: indexing them is far cheaper than numpy scalars in the loop. They take
    # ~150 bytes a row (a list and its float objects), so they are made a block at a time: the
    # reference's rows from the set-point's index (it lags the step with the leash), the
    # navigation errors and the wind from the step's.
    acc = ref.acc if controller.feeds_acceleration else None
    yaw_rate = np.gradient(ref.yaw_deg, dt)  # set-point rates, fed forward
    pitch_rate = np.gradient(ref.pitch_deg, dt)
    ground = np.asarray(ground_under_ref, float)
    wake_a = None if wake is None else np.asarray(wake, float)

    def ref_rows(r: int):
        """Rows [r, r + block] of the reference (r + 1 is where the leash interpolates to), and
        the first index past which they must be made again."""
        hi = min(n, r + block + 1)
        top = hi - 1 if hi < n else n
        m = hi - r
        return (r, top, ref.pos[r:hi].tolist(), ref.vel[r:hi].tolist(),
                [[0.0, 0.0, 0.0]] * m if acc is None else acc[r:hi].tolist(),
                ref.yaw_deg[r:hi].tolist(), ref.pitch_deg[r:hi].tolist(),
                yaw_rate[r:hi].tolist(), pitch_rate[r:hi].tolist(), ground[r:hi].tolist(),
                [[0.0, 0.0, 0.0]] * m if wake_a is None else wake_a[r:hi].tolist())

    def step_rows(k: int):
        """Rows [k, k + block) of the navigation errors and (kinematic model) the wind."""
        hi = min(n, k + block)
        return (k, hi, nav.pos_error[k:hi].tolist(), nav.vel_error[k:hi].tolist(),
                None if rigid_model else wind.extra[k * sub:hi * sub].tolist())

    rlo, rtop, R, V, A, YR, PR, YF, PF, GR, WK = ref_rows(0)
    klo, khi, npos, nvel, WX = step_rows(0)
    ux_, uy_, _ = wind.unit.tolist()
    wspd, href, alpha = scn.wind.speed_ms, scn.wind.reference_height_m, scn.wind.shear_exponent

    tau = veh.velocity_time_constant_s
    ahmax = G * math.tan(math.radians(veh.max_tilt_deg))
    azmax = veh.max_vertical_accel_ms2
    cd, kq = veh.rotor_drag_per_s, veh.body_drag_per_m
    yr_rate, yr_tau = veh.yaw_rate_deg_s, veh.yaw_time_constant_s
    gp_rate, gp_tau = veh.gimbal_rate_deg_s, veh.gimbal_time_constant_s
    if rigid_model:
        P = rigid.params(tau, ahmax, azmax, cd, kq, veh.attitude_time_constant_s,
                         veh.max_tilt_rate_deg_s, veh.motor_time_constant_s, veh.max_tilt_deg, G)
        S = rigid.initial_state(R[0], G)
        W = np.ascontiguousarray(wind.extra, dtype=float)
        last = np.zeros(6)
        kernel = rigid.substeps

    px, py, pz = R[0]
    vx = vy = vz = 0.0
    yaw, pit = YR[0], PR[0]
    # The track a block at a time: lists while the block is flown, then arrays.
    out = out_p, out_v, out_t, out_w, out_y, out_g, prog = [], [], [], [], [], [], []
    flown: list[list[np.ndarray]] = [[] for _ in out]

    def keep() -> None:
        if out_p:
            for o, f in zip(out, flown):
                f.append(np.array(o, float))
                o.clear()

    tx = ty = tz = 0.0
    wx = wy = wz = 0.0
    lost2 = ctl.divergence_m ** 2 if controller.holds_position else math.inf
    leash = float(getattr(ctl, "leash_m", 0.0) or 0.0) if controller.holds_position else 0.0
    sig = 0.0  # the set-point's fractional index into the reference (leash only)
    ef, lf = 0.0, dt / (LEASH_FILTER_S + dt)
    last_i = n - 1
    end_i, settle_n, k_end = ref.end_index, int(round(SETTLE_S / dt)), -1

    for k in range(n):
        if k >= khi:
            keep()
            klo, khi, npos, nvel, WX = step_rows(k)
        kk = k - klo
        nx, ny, nz = npos[kk]
        mvx, mvy, mvz = nvel[kk]
        ex_p, ey_p, ez_p = px + nx, py + ny, pz + nz
        if leash:
            i = int(sig)
            if i >= rtop:
                rlo, rtop, R, V, A, YR, PR, YF, PF, GR, WK = ref_rows(i)
            ir = i - rlo
            j1 = ir + 1 if i < last_i else ir
            f = sig - i
            g = 1.0 - f
            r0, r1, v0, v1 = R[ir], R[j1], V[ir], V[j1]
            rx = g * r0[0] + f * r1[0]
            ry = g * r0[1] + f * r1[1]
            rz = g * r0[2] + f * r1[2]
            e = math.sqrt((rx - ex_p) ** 2 + (ry - ey_p) ** 2 + (rz - ez_p) ** 2)
            ef += lf * (e - ef)  # the estimate's step-to-step noise is not a tracking error
            rate = 1.0 - ef / leash
            rate = 0.0 if rate < 0.0 else rate
            sp = (rx, ry, rz, rate * (g * v0[0] + f * v1[0]), rate * (g * v0[1] + f * v1[1]),
                  rate * (g * v0[2] + f * v1[2]))
            cx, cy, cz = step(k, (ex_p, ey_p, ez_p), (vx + mvx, vy + mvy, vz + mvz),
                              (px, py, pz), sp)
            a0, a1 = A[ir], A[j1]
            r2 = rate * rate
            arx, ary, arz = (r2 * (g * a0[0] + f * a1[0]), r2 * (g * a0[1] + f * a1[1]),
                             r2 * (g * a0[2] + f * a1[2]))
            kr = i  # the wake, ground and camera set-points where the set-point is
            prog.append(sig)
            at_sig = sig
            sig = sig + rate if sig + rate < last_i else float(last_i)
        else:
            if k >= rtop:
                rlo, rtop, R, V, A, YR, PR, YF, PF, GR, WK = ref_rows(k)
            cx, cy, cz = step(k, (ex_p, ey_p, ez_p), (vx + mvx, vy + mvy, vz + mvz),
                              (px, py, pz))
            ir = k - rlo
            arx, ary, arz = A[ir]
            kr, rate = k, 1.0
        agl = pz - GR[ir]
        shear = wspd * ((agl if agl > 1.0 else 1.0) / href) ** alpha if wspd > 0 else 0.0
        kx, ky, kz = WK[ir]
        mwx, mwy = shear * ux_ + kx, shear * uy_ + ky
        if rigid_model:
            kernel(S, cx, cy, cz, arx, ary, arz, W, k * sub, sub, mwx, mwy, kz, P, dtp, last)
            px, py, pz, vx, vy, vz = S[0], S[1], S[2], S[3], S[4], S[5]
            tx, ty, tz, wx, wy, wz = last
        else:
            k0 = kk * sub
            for s in range(sub):
                ex_ = WX[k0 + s]
                wx, wy, wz = mwx + ex_[0], mwy + ex_[1], kz + ex_[2]
                # Thrust: the acceleration asked for plus the vehicle's own still-air drag.
                sp = math.sqrt(vx * vx + vy * vy + vz * vz)
                dd = cd + kq * sp
                tx = (cx - vx) / tau + arx + dd * vx
                ty = (cy - vy) / tau + ary + dd * vy
                tz = (cz - vz) / tau + arz + dd * vz
                th = math.sqrt(tx * tx + ty * ty)
                if th > ahmax:
                    f = ahmax / th
                    tx *= f
                    ty *= f
                if tz > azmax:
                    tz = azmax
                elif tz < -azmax:
                    tz = -azmax
                rwx, rwy, rwz = wx - vx, wy - vy, wz - vz
                da = cd + kq * math.sqrt(rwx * rwx + rwy * rwy + rwz * rwz)
                vx += (tx + da * rwx) * dtp
                vy += (ty + da * rwy) * dtp
                vz += (tz + da * rwz) * dtp
                px += vx * dtp
                py += vy * dtp
                pz += vz * dtp
        # Camera heading and gimbal: rate feed-forward plus first-order tracking, rate-limited.
        d = rate * YF[ir] + (YR[ir] - yaw) / yr_tau
        yaw += (yr_rate if d > yr_rate else -yr_rate if d < -yr_rate else d) * dt
        d = rate * PF[ir] + (PR[ir] - pit) / gp_tau
        pit += (gp_rate if d > gp_rate else -gp_rate if d < -gp_rate else d) * dt
        out_p.append((px, py, pz))
        out_v.append((vx, vy, vz))
        out_t.append((tx, ty, tz))
        out_w.append((wx, wy, wz))
        out_y.append(yaw)
        out_g.append(pit)
        if k % 25 == 0:
            _check_divergence(ref, kr, name, (px, py, pz), lost2, ctl.divergence_m)
        if leash:
            if k_end < 0 and at_sig >= end_i - 1e-9:
                k_end = k
            if k_end >= 0 and k - k_end >= settle_n:
                break  # at the end and settled: the rest of the reference is slack
    if leash and k_end < 0:
        raise SimulationError(
            f"the set-point waited {(n - end_i) * dt:.0f} s for the vehicle and the route is still "
            f"unfinished ({name} controller, control.leash_m = {leash:g}): the wind may exceed "
            "what the vehicle can hold")
    keep()
    cols = []
    for j in range(len(flown)):  # one column at a time: never the blocks and all columns at once
        cols.append(np.concatenate(flown[j]))
        flown[j] = []
    pos, vel, thrust, wnd, yaw_d, pitch_d, progress = cols
    m = len(pos)
    if not np.isfinite(pos).all() or np.abs(pos).max() >= DIVERGED_M:
        bad = int(np.argmax(~np.isfinite(pos).all(1) | (np.abs(pos).max(1) >= DIVERGED_M)))
        raise SimulationError(f"flight diverged at t={ref.t[bad]:.1f} s ({name} controller); "
                              "check the gains and limits of the scenario")
    return Track(t=ref.t[:m].copy(), pos=pos, vel=vel, thrust=thrust, wind=wnd, yaw_deg=yaw_d,
                 pitch_deg=pitch_d, progress=progress if leash else None)


def _check_divergence(ref: Reference, k: int, name: str, p: tuple[float, float, float],
                      lost2: float, divergence_m: float) -> None:
    """Raise SimulationError if the state blew up, or (``lost2`` finite: a position-holding
    controller) the vehicle is more than ``divergence_m`` from its set-point."""
    px, py, pz = p
    if not (abs(px) + abs(py) + abs(pz) < DIVERGED_M):
        raise SimulationError(
            f"flight diverged at t={ref.t[k]:.1f} s ({name} controller): position "
            f"({px:.3g}, {py:.3g}, {pz:.3g}); check the gains and limits of the scenario")
    rx, ry, rz = ref.pos[k].tolist()
    d2 = (px - rx) ** 2 + (py - ry) ** 2 + (pz - rz) ** 2
    if d2 > lost2:
        raise SimulationError(
            f"flight diverged at t={ref.t[k]:.1f} s: the vehicle is {math.sqrt(d2):.0f} m from "
            f"its set-point (more than control.divergence_m = {divergence_m:g}); the wind "
            "may exceed what the vehicle can hold, or the gains are unstable")


def make_controller(mode: str, ref: Reference, scn: Scenario,
                    pilot: PilotInputs | None = None) -> Controller:
    """The controller a flight kind is flown with: ``pid``, ``feedforward`` or ``pilot``."""
    veh, gains = scn.vehicle, scn.gains
    limits = VelocityLimits(veh.max_speed_ms, veh.max_climb_ms, veh.max_descent_ms)
    R, V = Rows(ref.pos), Rows(ref.vel)
    if mode == "pid":
        return PidController(R, V, 1.0 / scn.control.control_hz, gains.kp, gains.ki, gains.kd,
                             gains.derivative_filter_s, gains.integral_limit_ms,
                             gains.feed_forward, limits)
    if mode == "feedforward":
        return FeedForwardController(V, limits, gains.feed_forward)
    if mode == "pilot":
        if pilot is None:
            raise ValueError("expected pilot inputs for the pilot controller")
        return PilotController(R, V, pilot, limits)
    raise ValueError(f"expected mode pid, feedforward or pilot, got {mode!r}")
