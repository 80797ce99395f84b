"""The ``fly`` stage: a deterministic flight simulator for inspection plans (docs/fly.md).

scenario.py  the scenario file (wind, terrain, vehicle, gains, baselines, seed), validated
wind.py      mean wind with shear, Dryden turbulence (MIL-HDBK-1797), 1-cosine gusts
terrain.py   flat or seeded hilly ground
sim.py       the set-point generator and the flight loop (kinematic multirotor, eq. 10 PID)
pilot.py     the manual-pilot baseline
flight.py    flying a plan and measuring it (deviation, clearance, coverage, GSD, battery)
run.py       plan-from-mission runs and the paper's Table 1
pictures.py  path, deviation and coverage PNGs
"""

from wtcli.fly.flight import FlightReport, FlightResult, fly_plan
from wtcli.fly.scenario import Scenario, default_scenario, load_scenario

__all__ = ["FlightReport", "FlightResult", "Scenario", "default_scenario", "fly_plan",
           "load_scenario"]
