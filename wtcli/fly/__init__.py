"""The ``fly`` stage: a deterministic flight simulator for inspection plans (docs/fly.md).

scenario.py    the scenario file (wind, terrain, vehicle, positioning, gains, baselines, seed)
wind.py        mean wind with shear, IEC Kaimal or Dryden turbulence, 1-cosine gusts
wake.py        tower wake (deficit, vortex shedding) and the nacelle's lee
navigation.py  positioning errors: RTK fixed / float, plain GNSS, RTK lost near a tower
terrain.py     flat or seeded hilly ground
control.py     the controllers: eq. 10 PID, feed-forward only, manual pilot
rigid.py       the rigid-body multirotor's physics (attitude loop, rotor lag), compiled
sim.py         the set-point generator and the flight loop (rigid or kinematic vehicle)
pilot.py       the manual-pilot baseline's route and signals
flight.py      flying a plan and measuring it (deviation, clearance, coverage, GSD, battery)
run.py         plan-from-mission runs and the paper's Table 1
pictures.py    path, deviation, coverage and sensitivity PNGs
"""

from wtcli.fly.flight import FlightReport, FlightResult, fly_plan
from wtcli.fly.scenario import Scenario, default_scenario, load_scenario

__all__ = ["FlightReport", "FlightResult", "Scenario", "default_scenario", "fly_plan",
           "load_scenario"]
