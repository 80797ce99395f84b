"""The flight controllers alone (wtcli.fly.control): step response, anti-windup, derivative
filter, the velocity envelope, the pilot's delay and deadband, and reset().

Each controller is closed around a simple plant written here (a point mass whose velocity
follows the command with a first-order lag), not the simulator's loop, so these tests pin the
controllers' own behaviour.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wtcli.fly.control import (FeedForwardController, PidController, PilotController,
                               PilotInputs, VelocityLimits)

DT = 0.02
WIDE = VelocityLimits(100.0, 100.0, 100.0)


def pid(n, ref_pos=(0.0, 0.0, 0.0), ref_vel=(0.0, 0.0, 0.0), kp=1.6, ki=0.4, kd=0.5,
        filt=0.05, ilim=4.0, ff=True, limits=WIDE) -> PidController:
    return PidController([list(ref_pos)] * n, [list(ref_vel)] * n, DT, kp, ki, kd, filt, ilim, ff,
                         limits)


def close_loop(ctrl, n, tau=0.5, push=(0.0, 0.0, 0.0), p0=(0.0, 0.0, 0.0)):
    """A point mass: dv/dt = (v_cmd - v) / tau + push. Returns positions (n, 3)."""
    p, v = np.array(p0, float), np.zeros(3)
    out = []
    for k in range(n):
        c = np.array(ctrl.step(k, tuple(p), tuple(v), tuple(p)))
        v = v + ((c - v) / tau + np.asarray(push)) * DT
        p = p + v * DT
        out.append(p.copy())
    return np.array(out)


def test_velocity_envelope_keeps_direction_and_flags_saturation():
    lim = VelocityLimits(10.0, 5.0, 4.0)
    assert lim.apply(3.0, 4.0, 1.0) == (3.0, 4.0, 1.0, False)
    cx, cy, cz, sat = lim.apply(30.0, 40.0, 0.0)
    assert sat and math.isclose(math.hypot(cx, cy), 10.0) and math.isclose(cy / cx, 4 / 3)
    assert lim.apply(0.0, 0.0, 9.0)[2:] == (5.0, True)
    assert lim.apply(0.0, 0.0, -9.0)[2:] == (-4.0, True)


def test_pid_step_response_settles_on_the_set_point_without_large_overshoot():
    n = int(20 / DT)
    c = pid(n, ref_pos=(2.0, -1.0, 0.5))
    p = close_loop(c, n)
    err = np.linalg.norm(p - [2.0, -1.0, 0.5], axis=1)
    assert err[-1] < 0.01  # settled
    assert err[int(5 / DT)] < 0.2 * err[0] + 0.5  # most of the step done within 5 s
    overshoot = (p[:, 0] - 2.0).max()
    assert overshoot < 0.3 * 2.0


def test_pid_integral_removes_a_steady_push_and_proportional_alone_does_not():
    n = int(60 / DT)
    push = (0.8, 0.0, 0.0)  # a steady wind's acceleration
    p_i = close_loop(pid(n), n, push=push)
    p_p = close_loop(pid(n, ki=0.0), n, push=push)
    assert abs(p_i[-1, 0]) < 0.02
    # Without the integral the offset stays: push * tau / (kp) = 0.8 * 0.5 / 1.6 = 0.25 m.
    assert p_p[-1, 0] == pytest.approx(0.8 * 0.5 / 1.6, rel=0.05)


def test_pid_anti_windup_freezes_the_integral_while_saturated():
    n = int(10 / DT)
    tight = VelocityLimits(1.0, 1.0, 1.0)
    c = pid(n, ref_pos=(50.0, 0.0, 0.0), limits=tight)
    for k in range(n):  # far from the set-point: the command stays saturated throughout
        cx, _, _ = c.step(k, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        assert cx == pytest.approx(1.0)
    assert c.ix == 0.0  # nothing integrated while saturated
    # Unsaturated, the integral is clamped at integral_limit_ms / ki.
    c2 = pid(n, ref_pos=(0.5, 0.0, 0.0), ki=0.4, ilim=0.2)
    for k in range(n):
        c2.step(k, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert c2.ix == pytest.approx(0.2 / 0.4)


def test_pid_derivative_filter_is_first_order_with_its_time_constant():
    n = 400
    c = pid(n, kp=0.0, ki=0.0, kd=1.0, filt=0.2, ff=False)
    out = [c.step(k, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 0.0))[0] for k in range(n)]
    # d term = kd * (v_ref - v_f) = -v_f; v_f follows the unit step with a = dt / (T + dt).
    a = DT / (0.2 + DT)
    expect = [-(1 - (1 - a) ** (k + 1)) for k in range(n)]
    np.testing.assert_allclose(out, expect, rtol=1e-12)
    k63 = int(np.argmax(np.asarray(out) <= -(1 - math.exp(-1))))
    assert abs(k63 * DT - 0.2) < 3 * DT  # ~63 % after one time constant
    # Noise on the measured velocity is attenuated by the filter.
    rng = np.random.default_rng(0)
    c_f, c_n = pid(n, kp=0, ki=0, kd=1, filt=0.2, ff=False), pid(n, kp=0, ki=0, kd=1, filt=0.0,
                                                                     ff=False)
    noise = rng.standard_normal(n)
    f = [c_f.step(k, (0, 0, 0), (noise[k], 0, 0), (0, 0, 0))[0] for k in range(n)]
    u = [c_n.step(k, (0, 0, 0), (noise[k], 0, 0), (0, 0, 0))[0] for k in range(n)]
    assert np.std(f) < 0.4 * np.std(u)


def test_pid_no_derivative_kick_on_a_set_point_step():
    n = 10
    c = pid(n, ref_pos=(5.0, 0.0, 0.0), kp=0.0, ki=0.0, kd=2.0, ff=False)
    assert c.step(0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)) == (0.0, 0.0, 0.0)


def test_reset_forgets_integral_and_filter():
    n = 200
    c = pid(n, ref_pos=(1.0, 0.0, 0.0))
    first = [c.step(k, (0, 0, 0), (0.3, 0, 0), (0, 0, 0)) for k in range(n)]
    c.reset()
    again = [c.step(k, (0, 0, 0), (0.3, 0, 0), (0, 0, 0)) for k in range(n)]
    assert first == again


def test_feedforward_flies_the_reference_velocity_only():
    V = [[3.0, 4.0, 9.0], [20.0, 0.0, -1.0]]
    c = FeedForwardController(V, VelocityLimits(10.0, 5.0, 4.0))
    assert c.step(0, (99.0, 99.0, 99.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)) == (3.0, 4.0, 5.0)
    assert c.step(1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)) == (10.0, 0.0, -1.0)
    assert c.feeds_acceleration and not c.holds_position


def test_pilot_corrects_late_beyond_the_deadband_and_caps_the_correction():
    n = 100
    inputs = PilotInputs(delay_steps=5, gain=0.5, deadband=0.8, perception=np.zeros((n, 3)),
                         stick=np.zeros((n, 3)), max_correction=2.0)
    R = [[0.0, 0.0, 0.0]] * n
    V = [[0.0, 0.0, 0.0]] * n
    c = PilotController(R, V, inputs, WIDE)
    # The drone is 3 m east of the set-point from the start: nothing for the first 5 steps.
    out = [c.step(k, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (3.0, 0.0, 0.0)) for k in range(8)]
    assert all(o == (0.0, 0.0, 0.0) for o in out[:5])
    assert out[5][0] == pytest.approx(-0.5 * (3.0 - 0.8))
    # Inside the deadband: no correction.
    c.reset()
    out = [c.step(k, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.5, 0.0, 0.0)) for k in range(8)]
    assert out[-1] == (0.0, 0.0, 0.0)
    # Far off: the correction speed is capped.
    c.reset()
    out = [c.step(k, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 40.0, 0.0)) for k in range(8)]
    assert math.hypot(*out[-1]) == pytest.approx(2.0)
    assert not c.feeds_acceleration and not c.holds_position
