"""Compile the planner's and the simulator's numba kernels once, ahead of the first plan.

    python -m wtcli.warmup

The clearance, site and coverage kernels (``wtcli/geometry/*_kernel.py``,
``wtcli/plan/clearance_site_kernel.py``) and the flight's rigid-body physics
(``wtcli/fly/rigid.py``) are compiled on a machine's first use, 10-20 s on two cores,
then loaded from numba's cache (the package's ``__pycache__``) in a fraction of a second.
``scripts/setup-venv.sh`` runs this, so that a user's first ``plan`` or ``fly`` does not pay
it. It goes through the same calls the planner and ``fly`` make, so the argument types (and
hence the compiled versions) are the ones they use (``tests/test_latency_paths.py`` checks that
a plan then compiles nothing).

``imports_frozen``, for the same end: a command's garbage collections leave alone what it
imported.
"""

from __future__ import annotations

import gc
import time
from contextlib import contextmanager
from typing import Iterator

import numpy as np


@contextmanager
def imports_frozen() -> Iterator[None]:
    """Keep every object alive so far (the libraries and planner modules a command imported)
    out of the garbage collector's full passes while the command runs: a plan's two full
    passes walked them all, ~0.08 s of a 2 s photo -> plan. They live as long as the process.
    Where the caller has frozen objects of its own, its choice is left as it is."""
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def warm_up() -> float:
    """Call every kernel once on a small site; returns the seconds it took."""
    from wtcli.geometry import Camera, Turbine, look_at_rotation
    from wtcli.geometry.coverage import measure_coverage, turbine_coverage
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
    # Photos 6 m off the surface along its normals, so that (sample, photo) pairs pass the
    # cheap tests and the line-of-sight rounds' kernels are compiled too.
    k = np.linspace(0, len(samples.points) - 1, 4).astype(int)
    at = samples.points[k]
    C = np.concatenate([P, at + 6.0 * samples.normals[k]])
    R = np.stack([look_at_rotation(c, a) for c, a in zip(C, np.concatenate([[t.hub_center] * len(P), at]))])
    measure_coverage(samples, Camera(5456, 3632, 16, 23.2), C, R, 2.0)
    turbine_coverage(t, Camera(5456, 3632, 16, 23.2), C, R, 2.0, 2.0)  # the refinement's kernel
    _warm_flight()
    return time.perf_counter() - t0


def _warm_flight() -> None:
    """``fly``'s rigid-body kernel, with the argument types ``wtcli.fly.sim`` passes (Python
    floats and ints from its lists, float64 arrays)."""
    from wtcli.fly import rigid

    g = 9.81
    S = rigid.initial_state(np.zeros(3), g)
    P = rigid.params(0.5, 5.0, 4.0, 0.3, 0.02, 0.1, 200.0, 0.05, 30.0, g)
    wind = np.ascontiguousarray(np.zeros((4, 3)), dtype=float)
    rigid.substeps(S, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, wind, 0 * 2, 2, 0.0, 0.0, 0.0, P, 0.05 / 2,
                   np.zeros(6))


if __name__ == "__main__":
    print(f"wtinspect: numba kernels ready ({warm_up():.1f} s)")
