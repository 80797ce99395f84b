"""The rigid-body multirotor's physics between two control steps, compiled (numba).

State (per unit mass, ENU): position p, velocity v, the thrust direction as two tilt angles
(theta_e towards east, theta_n towards north: the body's z axis is (tan theta_e, tan theta_n, 1)
normalised), their rates, and the specific thrust f (m/s^2 along the body z axis).

Each physics step:

1. The autopilot's velocity loop asks for ``a = (v_cmd - v) / tau_v + a_ref + D(-v)`` (its own
   still-air drag cancelled), limited to ``g tan(max_tilt)`` horizontally and
   ``max_vertical_accel`` vertically, i.e. a specific force ``F = a + g z``.
2. Attitude (the inner loop): the tilt that points the thrust along F, clamped to ``max_tilt``;
   a rate command ``(theta_d - theta) / tau_att`` clamped to ``max_tilt_rate``, which the body
   rate follows with the motors' time constant ``tau_m`` (rotor speed changes make the torque).
3. Collective thrust: f follows |F| with ``tau_m``.
4. ``dv/dt = f n(theta) - g z + D(w - v)``, ``D(u) = c u + k |u| u`` (rotor drag and body drag
   on the air-relative velocity), semi-implicit Euler.

So wind and set-point changes reach the vehicle only through the attitude and rotor lags, as on
a real multirotor: two first-order lags and a rate limit between the command and the force.
"""

from __future__ import annotations

import math

import numpy as np

from wtcli.geometry.clearance_kernel import _jit

# State vector layout.
PX, PY, PZ, VX, VY, VZ, TE, TN, WE, WN, F = range(11)
NSTATE = 11
# Parameter vector layout.
TAU_V, AHMAX, AZMAX, CD, KQ, TAU_ATT, RATE_MAX, TAU_M, TILT_MAX, G_ = range(10)


def params(tau_v: float, ahmax: float, azmax: float, cd: float, kq: float, tau_att: float,
           rate_max_deg_s: float, tau_m: float, tilt_max_deg: float, g: float) -> np.ndarray:
    return np.array([tau_v, ahmax, azmax, cd, kq, tau_att, math.radians(rate_max_deg_s), tau_m,
                     math.radians(tilt_max_deg), g])


def initial_state(pos, g: float) -> np.ndarray:
    """At rest at ``pos``, level, thrust balancing gravity."""
    s = np.zeros(NSTATE)
    s[PX:PZ + 1] = pos
    s[F] = g
    return s


@_jit
def substeps(S: np.ndarray, cx: float, cy: float, cz: float, ax_ff: float, ay_ff: float,
             az_ff: float, wind: np.ndarray, k0: int, sub: int, mwx: float, mwy: float,
             mwz: float, P: np.ndarray, dtp: float, out: np.ndarray) -> None:
    """Advance the state ``S`` by ``sub`` physics steps of ``dtp`` under the velocity command
    ``c`` and acceleration feed-forward ``a_ff``; the wind is ``(mwx, mwy, mwz) + wind[k0 + s]``.
    ``out`` gets the last step's thrust acceleration (without gravity) and wind."""
    tau_v, ahmax, azmax, cd, kq = P[0], P[1], P[2], P[3], P[4]
    tau_att, rate_max, tau_m, tilt_max, g = P[5], P[6], P[7], P[8], P[9]
    px, py, pz, vx, vy, vz = S[0], S[1], S[2], S[3], S[4], S[5]
    te, tn, we, wn, f = S[6], S[7], S[8], S[9], S[10]
    tx = ty = tz = 0.0
    wx = wy = wz = 0.0
    for s in range(sub):
        wx = mwx + wind[k0 + s, 0]
        wy = mwy + wind[k0 + s, 1]
        wz = mwz + wind[k0 + s, 2]
        sp = math.sqrt(vx * vx + vy * vy + vz * vz)
        dd = cd + kq * sp
        ax = (cx - vx) / tau_v + ax_ff + dd * vx
        ay = (cy - vy) / tau_v + ay_ff + dd * vy
        az = (cz - vz) / tau_v + az_ff + dd * vz
        ah = math.sqrt(ax * ax + ay * ay)
        if ah > ahmax:
            ax *= ahmax / ah
            ay *= ahmax / ah
        if az > azmax:
            az = azmax
        elif az < -azmax:
            az = -azmax
        fz = az + g
        ted = math.atan2(ax, fz)
        tnd = math.atan2(ay, fz)
        m = math.sqrt(ted * ted + tnd * tnd)
        if m > tilt_max:
            ted *= tilt_max / m
            tnd *= tilt_max / m
        fd = math.sqrt(ax * ax + ay * ay + fz * fz)
        re = (ted - te) / tau_att
        rn = (tnd - tn) / tau_att
        if re > rate_max:
            re = rate_max
        elif re < -rate_max:
            re = -rate_max
        if rn > rate_max:
            rn = rate_max
        elif rn < -rate_max:
            rn = -rate_max
        we += (re - we) * dtp / tau_m
        wn += (rn - wn) * dtp / tau_m
        te += we * dtp
        tn += wn * dtp
        f += (fd - f) * dtp / tau_m
        nx, ny = math.tan(te), math.tan(tn)
        nn = math.sqrt(nx * nx + ny * ny + 1.0)
        tx = f * nx / nn
        ty = f * ny / nn
        tz = f / nn - g
        rwx, rwy, rwz = wx - vx, wy - vy, wz - vz
        da = cd + kq * math.sqrt(rwx * rwx + rwy * rwy + rwz * rwz)
        vx += (tx + da * rwx) * dtp
        vy += (ty + da * rwy) * dtp
        vz += (tz + da * rwz) * dtp
        px += vx * dtp
        py += vy * dtp
        pz += vz * dtp
    S[0], S[1], S[2], S[3], S[4], S[5] = px, py, pz, vx, vy, vz
    S[6], S[7], S[8], S[9], S[10] = te, tn, we, wn, f
    out[0], out[1], out[2] = tx, ty, tz
    out[3], out[4], out[5] = wx, wy, wz


__all__ = ["NSTATE", "initial_state", "params", "substeps"]
