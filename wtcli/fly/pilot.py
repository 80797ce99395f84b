"""A documented model of a manual pilot (the paper's "traditional" baseline).

The pilot flies the same inspection geometry by sight (they see where the blades are), but:

- slower: every leg at ``speed_factor`` of the planned speed, never above ``max_speed_ms``;
- hover-and-shoot: stops ``hover_per_photo_s`` at each photo point, shoots at the end of it;
- with the drone in GNSS velocity mode (sticks command velocity; the drone's own velocity loop
  runs, there is no position-hold integral because the pilot is steering all the time);
- correcting the position error they *perceive*, ``reaction_delay_s`` late, with a stick gain
  ``gain_per_s`` and a ``deadband_m`` below which they do not correct; the perceived position
  is off by a slowly varying judgement error (Ornstein-Uhlenbeck, ``perception_sigma_m``,
  ``perception_time_s``: distance to a blade is judged from the video feed and the ground);
- with stick noise (the "remnant" of human-operator models, ``stick_noise_ms``) and a camera
  framing error (``aim_sigma_deg`` on heading and gimbal pitch, per photo).

Each number and its source is in docs/fly.md ("The manual pilot").
"""

from __future__ import annotations

import numpy as np

from wtcli.fly.scenario import ManualPilot
from wtcli.fly.control import PilotInputs
from wtcli.fly.wind import shaped_noise
from wtcli.plan_file import Route


def manual_route(route: Route, mp: ManualPilot) -> tuple[Route, np.ndarray]:
    """The route as the pilot flies it, and the time of each photo (end of its hover)."""
    seg = np.linalg.norm(np.diff(route.pos, axis=0), axis=1)
    dt0 = np.diff(route.t)
    moving = seg > 1e-6
    # The planned speed of each leg (its speed column, else length over duration); the rest of
    # a leg's planned time is a hover at its end (kept as it is: e.g. a battery swap).
    v_plan = np.where(route.speed[1:] > 0, route.speed[1:], seg / np.maximum(dt0, 1e-9))
    v_man = np.minimum(v_plan * mp.speed_factor, mp.max_speed_ms)
    travel = np.where(moving, seg / np.maximum(v_plan, 1e-9), 0.0)
    hover = np.maximum(dt0 - travel, 0.0)
    dt_new = np.where(moving, seg / np.maximum(v_man, 1e-9) + hover, dt0 / mp.speed_factor)
    speed_new = np.r_[0.0, np.where(moving, v_man, 0.0)]
    t, pos, yaw, pitch, photo, comp, photo_t = [], [], [], [], [], [], []
    now = float(route.t[0])

    spd: list[float] = []

    def add(time: float, i: int, shoot: bool, v: float) -> None:
        spd.append(v)
        t.append(time)
        pos.append(route.pos[i])
        yaw.append(route.yaw_deg[i])
        pitch.append(route.gimbal_pitch_deg[i])
        photo.append(shoot)
        comp.append(route.component[i])

    for i in range(len(route)):
        if i > 0:
            now += float(dt_new[i - 1])
        if route.photo[i] and mp.hover_per_photo_s > 0:
            add(now, i, False, float(speed_new[i]))  # arrive, then hover, frame and shoot
            now += mp.hover_per_photo_s
            add(now, i, True, 0.0)
        else:
            add(now, i, bool(route.photo[i]), float(speed_new[i]))
        if route.photo[i]:
            photo_t.append(now)
    r = Route(uav=route.uav, t=np.array(t), pos=np.array(pos), speed=np.array(spd),
              yaw_deg=np.array(yaw), gimbal_pitch_deg=np.array(pitch), photo=np.array(photo, bool),
              component=np.array(comp, dtype=object), summary={"flown_by": "manual pilot"})
    return r, np.array(photo_t)


def ou_series(rng: np.random.Generator, n: int, dt: float, sigma: float, tau: float,
              dims: int = 3) -> np.ndarray:
    """Gauss-Markov (Ornstein-Uhlenbeck) noise of standard deviation ``sigma`` and correlation
    time ``tau``, (n, dims): white noise shaped to the spectrum 1 / (1 + (tau w)^2)."""
    if sigma <= 0:
        return np.zeros((n, dims))
    return np.stack([sigma * shaped_noise(rng, n, dt, lambda w: 1.0 / (1.0 + (tau * w) ** 2))
                     for _ in range(dims)], 1)


def pilot_inputs(mp: ManualPilot, n: int, dt: float, rng: np.random.Generator) -> PilotInputs:
    perception = ou_series(rng, n, dt, mp.perception_sigma_m, mp.perception_time_s)
    perception[:, 2] *= 0.5  # height is judged better than depth (altimeter on screen)
    stick = ou_series(rng, n, dt, mp.stick_noise_ms, 0.5)
    return PilotInputs(delay_steps=int(round(mp.reaction_delay_s / dt)), gain=mp.gain_per_s,
                       deadband=mp.deadband_m, perception=perception, stick=stick,
                       max_correction=2.0)
