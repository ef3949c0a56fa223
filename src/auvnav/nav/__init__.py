"""Navigation: dead reckoning, an EKF with a Rauch-Tung-Striebel smoother, course made good.

- :mod:`~auvnav.nav.inputs`: the dive's sensors on the DVL's time base (compass correction, paper
  eq. 5, and declination applied; DVL mount, lever arm and dropouts handled; TEOS-10 depth).
- :mod:`~auvnav.nav.deadreckon`: the dead-reckoned track.
- :mod:`~auvnav.nav.filter`: the EKF and smoother fusing DVL, attitude, depth, GPS and USBL, with
  gated fixes and logged innovations (the paper's Fig. 9).
- :mod:`~auvnav.nav.cmg`: GPS course made good on sub-sea legs against dead reckoning (Fig. 5b).
- :mod:`~auvnav.nav.products`: the stage (``auvnav navigate``) and its products in ``products/nav/``.
- :mod:`~auvnav.nav.synthetic`: small synthetic dives with an exact truth, for tests and benchmarks.
"""

from auvnav.nav.cmg import TransitLeg, course_made_good
from auvnav.nav.deadreckon import Start, dead_reckon, start_position
from auvnav.nav.filter import FilterConfig, FilterResult, Innovations, run_filter
from auvnav.nav.inputs import Dropouts, HeadingCorrection, NavInputs, PositionFixes, declination, nav_inputs
from auvnav.nav.products import NavResult, format_summary, navigate, run_navigation, write_products

__all__ = [
    "Dropouts",
    "FilterConfig",
    "FilterResult",
    "HeadingCorrection",
    "Innovations",
    "NavInputs",
    "NavResult",
    "PositionFixes",
    "Start",
    "TransitLeg",
    "course_made_good",
    "dead_reckon",
    "declination",
    "format_summary",
    "nav_inputs",
    "navigate",
    "run_filter",
    "run_navigation",
    "start_position",
    "write_products",
]
