"""Navigation: dead reckoning, an EKF with a Rauch-Tung-Striebel smoother, course made good.

- :mod:`~auvnav.nav.inputs`: the dive's sensors on the DVL's time base (compass correction, paper
  eq. 5, and declination applied; DVL mount, lever arm and dropouts handled; TEOS-10 depth).
- :mod:`~auvnav.nav.deadreckon`: the dead-reckoned track.
- :mod:`~auvnav.nav.filter`: the EKF and smoother fusing DVL, attitude, depth, GPS and USBL, with
  gated fixes and logged innovations (the paper's Fig. 9).
- :mod:`~auvnav.nav.cmg`: GPS course made good on sub-sea legs against dead reckoning (Fig. 5b).
- :mod:`~auvnav.nav.navigate`: all of it for one dive, in one result with its summary.
- :mod:`~auvnav.nav.stage`: the stage (``auvnav navigate``) and its products in ``products/nav/``.
- :mod:`~auvnav.nav.synthetic`: small synthetic dives with an exact truth, for tests and benchmarks.

Import from the modules; the package itself imports nothing, so that its parts load only when used.
"""
