"""The simulator: every later stage is measured against its truth (DESIGN section 8).

- :mod:`auvnav.sim.seafloor`: seeded procedural bathymetry as a function of world coordinates;
- :mod:`auvnav.sim.sensors`: DVL, compass (paper eq. 1-4), inclinometer, pressure (TEOS-10, tide),
  GPS and USBL models with their datasheet defaults;
- :mod:`auvnav.sim.vehicle`: dynamics and guidance closed on the vehicle's own onboard navigation;
- :mod:`auvnav.sim.run`: :func:`~auvnav.sim.run.simulate` a mission into a dive folder with ``truth/``.
"""
