"""The controllers a flight can be flown with, each a small object with ``reset()`` and ``step()``.

Every controller turns what it knows at one control step into a velocity command ``(vx, vy, vz)``
(m/s, ENU) that the vehicle's velocity loop then tries to realise (``wtcli.fly.sim``), already
limited by the vehicle's horizontal speed and climb/descent limits:

- ``PidController``: the paper's eq. 10 per axis on the position error ``e = r - p_est``:
  ``u = Kp e + Ki int(e) + Kd de/dt`` with ``de/dt = v_ref - v_f`` (derivative on the filtered
  measured velocity, so set-point steps cause no derivative kick), the reference velocity fed
  forward, the integral clamped to ``integral_limit_ms / Ki`` and frozen while the command
  saturates (anti-windup): ``v_cmd = ff v_ref + u``.
- ``FeedForwardController``: ``v_cmd = v_ref``, the plan flown open-loop (no wind compensation).
- ``PilotController``: a manual pilot (``wtcli.fly.pilot``) who sees the true position late and
  misjudged, corrects with a stick gain above a deadband, with stick noise, on top of flying the
  route's velocity.

``step(k, pos, vel, true_pos)`` gets the control step index ``k`` (into the reference), the
navigation estimate of position and velocity (what an autopilot sees) and the true position
(what a pilot's eye sees, before their own misjudgement); a position-holding controller also
takes ``setpoint=(rx, ry, rz, vx, vy, vz)`` in place of the reference at ``k`` when the loop
holds the set-point back for the vehicle (``control.leash_m``). The loop asks each controller whether
it ``feeds_acceleration`` (adds the reference acceleration to the thrust) and whether it
``holds_position`` (then drifting ``divergence_m`` from the set-point is a failed flight).
The arithmetic is written out per axis on floats: step() is called 50 times per simulated second.
The reference's rows reach a controller as Python lists (cheap to index per step), ``Rows`` making
them a block of ``BLOCK_STEPS`` at a time from the arrays: a whole route's lists would take
~150 bytes a row each, over a gigabyte on a wide site's long route (docs/fly.md "Memory").
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections import deque
from dataclasses import dataclass

import numpy as np

BLOCK_STEPS = 4096  # rows made into Python lists at a time (here and in the flight loop)


class Rows:
    """The rows of an (N, d) array as lists of floats (floats for an (N,) array), made a block
    of ``block`` rows at a time from the first row asked for: what a controller indexes per step
    (indexing a list is far cheaper than a numpy scalar) without a list of every row."""

    __slots__ = ("_a", "_block", "_lo", "_hi", "_rows")

    def __init__(self, a: np.ndarray, block: int | None = None) -> None:
        self._a = np.asarray(a, float)
        self._block = max(1, int(block or BLOCK_STEPS))
        self._lo = self._hi = 0
        self._rows: list = []

    def __len__(self) -> int:
        return len(self._a)

    def __getitem__(self, k: int):
        if self._lo <= k < self._hi:
            return self._rows[k - self._lo]
        n = len(self._a)
        if not -n <= k < n:
            raise IndexError(f"expected a row index in [0, {n}), got {k}")
        k = k + n if k < 0 else int(k)
        self._lo, self._hi = k, min(n, k + self._block)
        self._rows = self._a[self._lo:self._hi].tolist()
        return self._rows[0]


@dataclass(frozen=True)
class VelocityLimits:
    """The vehicle's velocity envelope: horizontal speed, climb and descent (m/s, positive)."""

    horizontal: float
    climb: float
    descent: float

    def apply(self, cx: float, cy: float, cz: float) -> tuple[float, float, float, bool]:
        """The command inside the envelope (horizontal direction kept) and whether it was cut."""
        sat = False
        h = math.sqrt(cx * cx + cy * cy)
        if h > self.horizontal:
            f = self.horizontal / h
            cx *= f
            cy *= f
            sat = True
        if cz > self.climb:
            cz = self.climb
            sat = True
        elif cz < -self.descent:
            cz = -self.descent
            sat = True
        return cx, cy, cz, sat


class Controller(ABC):
    """What the flight loop needs of a controller (see the module docstring)."""

    name = "controller"
    feeds_acceleration = False
    holds_position = False

    def reset(self) -> None:
        """Forget all state: the next ``step`` is the first of a new flight."""

    @abstractmethod
    def step(self, k: int, pos: tuple[float, float, float], vel: tuple[float, float, float],
             true_pos: tuple[float, float, float]) -> tuple[float, float, float]:
        """The acceleration command at control step ``k`` from the estimated state."""


class PidController(Controller):
    """Eq. 10 per axis with reference velocity feed-forward, a first-order filter on the measured
    velocity for the derivative term, and a clamped integral frozen while saturated."""

    name = "pid"
    holds_position = True

    def __init__(self, ref_pos: list, ref_vel: list, dt: float, kp: float, ki: float, kd: float,
                 derivative_filter_s: float, integral_limit_ms: float, feed_forward: bool,
                 limits: VelocityLimits) -> None:
        if dt <= 0 or derivative_filter_s < 0:
            raise ValueError(f"expected dt > 0 and derivative_filter_s >= 0, got {dt}, "
                             f"{derivative_filter_s}")
        self.R, self.V = ref_pos, ref_vel
        self.dt = dt
        self.kp, self.ki, self.kd = kp, ki, kd
        self.ff = 1.0 if feed_forward else 0.0
        self.feeds_acceleration = bool(feed_forward)
        self.ilim = integral_limit_ms / ki if ki > 0 else 0.0
        self.af = dt / (derivative_filter_s + dt)
        self.limits = limits
        self.reset()

    def reset(self) -> None:
        self.ix = self.iy = self.iz = 0.0
        self.vfx = self.vfy = self.vfz = 0.0

    def step(self, k, pos, vel, true_pos, setpoint=None):
        if setpoint is None:
            rx, ry, rz = self.R[k]
            vrx, vry, vrz = self.V[k]
        else:  # the set-point the flight loop holds back for the vehicle (control.leash_m)
            rx, ry, rz, vrx, vry, vrz = setpoint
        mx, my, mz = pos
        mvx, mvy, mvz = vel
        ex, ey, ez = rx - mx, ry - my, rz - mz
        af = self.af
        self.vfx += af * (mvx - self.vfx)
        self.vfy += af * (mvy - self.vfy)
        self.vfz += af * (mvz - self.vfz)
        ff, kp, ki, kd = self.ff, self.kp, self.ki, self.kd
        cx = ff * vrx + kp * ex + ki * self.ix + kd * (vrx - self.vfx)
        cy = ff * vry + kp * ey + ki * self.iy + kd * (vry - self.vfy)
        cz = ff * vrz + kp * ez + ki * self.iz + kd * (vrz - self.vfz)
        cx, cy, cz, sat = self.limits.apply(cx, cy, cz)
        if not sat:  # anti-windup: integrate only while the command is inside the envelope
            dt, lim = self.dt, self.ilim
            self.ix = min(max(self.ix + ex * dt, -lim), lim)
            self.iy = min(max(self.iy + ey * dt, -lim), lim)
            self.iz = min(max(self.iz + ez * dt, -lim), lim)
        return cx, cy, cz


class FeedForwardController(Controller):
    """The reference velocity, nothing else: the plan flown without position feedback."""

    name = "feedforward"

    def __init__(self, ref_vel: list, limits: VelocityLimits, feed_forward: bool = True) -> None:
        self.V = ref_vel
        self.limits = limits
        self.feeds_acceleration = bool(feed_forward)

    def step(self, k, pos, vel, true_pos):
        vrx, vry, vrz = self.V[k]
        cx, cy, cz, _ = self.limits.apply(vrx, vry, vrz)
        return cx, cy, cz


@dataclass(frozen=True)
class PilotInputs:
    """Precomputed human-pilot signals (see wtcli.fly.pilot)."""

    delay_steps: int
    gain: float
    deadband: float
    perception: np.ndarray  # (N, 3) judged-position error
    stick: np.ndarray  # (N, 3) stick noise, m/s
    max_correction: float


class PilotController(Controller):
    """A pilot flying the route's velocity and correcting, ``delay_steps`` late, the error they
    perceive (true position plus a judgement error) beyond a deadband, with stick noise; the
    correction's speed is capped at ``max_correction``."""

    name = "pilot"

    def __init__(self, ref_pos: list, ref_vel: list, inputs: PilotInputs,
                 limits: VelocityLimits) -> None:
        self.R, self.V = ref_pos, ref_vel
        self.PP, self.PS = Rows(inputs.perception), Rows(inputs.stick)
        self.delay, self.gain = inputs.delay_steps, inputs.gain
        self.deadband, self.max_correction = inputs.deadband, inputs.max_correction
        self.limits = limits
        self.reset()

    def reset(self) -> None:
        # True positions, seen late: the last delay + 1 of them (the oldest is seen now).
        self.hist: deque[tuple[float, float, float]] = deque(maxlen=max(self.delay, 0) + 1)

    def step(self, k, pos, vel, true_pos):
        vrx, vry, vrz = self.V[k]
        self.hist.append(true_pos)
        j = k - self.delay
        ex = ey = ez = 0.0
        if j >= 0:
            hx, hy, hz = self.hist[0]
            qx, qy, qz = self.PP[j]
            sx, sy, sz = self.R[j]
            ex, ey, ez = sx - (hx + qx), sy - (hy + qy), sz - (hz + qz)
            e = math.sqrt(ex * ex + ey * ey + ez * ez)
            pdb = self.deadband
            if e > pdb:
                g = self.gain * (e - pdb) / e
                if g * (e - pdb) > self.max_correction:
                    g = self.max_correction / e
                ex, ey, ez = g * ex, g * ey, g * ez
            else:
                ex = ey = ez = 0.0
        s0, s1, s2 = self.PS[k]
        cx, cy, cz, _ = self.limits.apply(vrx + ex + s0, vry + ey + s1, vrz + ez + s2)
        return cx, cy, cz


__all__ = ["BLOCK_STEPS", "Controller", "FeedForwardController", "PidController",
           "PilotController", "PilotInputs", "Rows", "VelocityLimits"]
