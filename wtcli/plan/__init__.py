"""`plan`: turbines.yaml + blade angles -> a safe, timed inspection plan (paper steps 1.1, 1.5).

Where things are:

* ``config.py``  turbines.yaml -> a validated, frozen ``Mission`` (``load_mission``)
* ``zone.py``    eq. 1-3: zone sphere C_i/R_i, initial point S_p; blade angles from a photo -> 3D
* ``paths.py``   eq. 8-9: passes along each blade side, tower and nacelle trajectories, arcs
* ``clearance.py`` clearance of points and legs to every part of every turbine, and the ground:
  the one place plan and fly check it (``clearance_site_kernel.py`` compiled; one turbine:
  ``wtcli/geometry/clearance_kernel.py``)
* ``mission.py`` ``plan_mission``: order, fleet split, batteries, timing, checks, coverage
* ``corners.py`` where the aircraft stops and how fast it flies through the other waypoints: one
  model for the plan's timing, fly's set-point and the DJI export
* ``exports.py`` QGroundControl .plan, MAVLink QGC WPL 110, GeoJSON
* ``path_views.py`` front/side/top views of the path (PNG)
"""
