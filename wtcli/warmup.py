"""Compile the planner's numba kernels once, ahead of the first plan.

    python -m wtcli.warmup

The clearance, site and coverage kernels (``wtcli/geometry/*_kernel.py``,
``wtcli/plan/clearance_site_kernel.py``) are compiled on a machine's first use, 10-20 s on two cores,
then loaded from numba's cache (the package's ``__pycache__``) in a fraction of a second.
``scripts/setup-venv.sh`` runs this, so that a user's first ``plan`` or ``fly`` does not pay
it. It goes through the same calls the planner makes, so the argument types (and hence the
compiled versions) are the ones a plan uses.
"""

from __future__ import annotations

import time

import numpy as np


def warm_up() -> float:
    """Call every kernel once on a small site; returns the seconds it took."""
    from wtcli.geometry import Camera, Turbine, look_at_rotation
    from wtcli.geometry.coverage import measure_coverage
    from wtcli.plan.clearance import Site

    t0 = time.perf_counter()
    ts = [Turbine.with_rotor_azimuth(30.0 * i, id=f"T{i}", base=(300.0 * i, 0.0, 0.0),
                                     hub_height=80.0, rotor_diameter=90.0, yaw_deg=0.0) for i in range(2)]
    site = Site(ts, launch=np.array([-100.0, -100.0, 0.0]))
    t = ts[0]
    P = t.hub_center + np.array([[0.0, -20.0, 0.0], [5.0, -10.0, 30.0], [0.0, 0.0, -60.0]])
    t.clearance(P)
    site.clearance(P)
    site.clearance(P, 5.0)
    site.near(P)
    site.segment_clearance(P[:-1], P[1:], 0.5, 5.0)
    site.lowest_sample(P[0], P[2], 0.5, 5.0)
    site.ground_z(P)
    t.line_of_sight(P, P + 1.0)
    samples = t.surface_samples(2.0)
    R = np.stack([look_at_rotation(p, t.hub_center) for p in P])
    measure_coverage(samples, Camera(5456, 3632, 16, 23.2), P, R, 2.0)
    return time.perf_counter() - t0


if __name__ == "__main__":
    print(f"wtinspect: numba kernels ready ({warm_up():.1f} s)")
