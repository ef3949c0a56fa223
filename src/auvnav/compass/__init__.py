"""Compass: the Earth field and declination, magnetometer heading and calibration, and the
deviation correction of the paper (eq. 1-6) with its correction file.

- :mod:`~auvnav.compass.field`: geomagnetic field (WMM / IGRF) at a place and date; magnetic <-> true.
- :mod:`~auvnav.compass.magnetometer`: eq. 1 heading, eq. 2-4 hard/soft-iron forward model,
  ellipsoid and levelled calibration.
- :mod:`~auvnav.compass.deviation`: eq. 5 model, eq. 6 (robust) fit, the constant from GPS transits.
- :mod:`~auvnav.compass.correction`: the ``auvnav-compass-correction/1`` file.
- :mod:`~auvnav.compass.evaluate`: a correction against a simulated dive's true deviation.
- :mod:`~auvnav.compass.fit`: the fit from dives (heading pairs against SLAM, truth or a trajectory;
  the constant from GPS course made good on transits), behind ``auvnav compass fit``.
- :mod:`~auvnav.compass.calibrate`: a dive's magnetometer calibration, ``auvnav compass calibrate``.

``fit`` and ``calibrate`` build on :mod:`auvnav.nav` (which uses this package), so they are imported
from their modules, not from here.
"""

from auvnav.compass.correction import FitRecord, read_correction, write_correction
from auvnav.compass.deviation import (
    DeviationFit,
    DeviationModel,
    fit_deviation,
    fix_constant,
    fourier_design,
    heading_gaps,
    transit_deviation,
)
from auvnav.compass.evaluate import compass_section, read_true_deviation
from auvnav.compass.field import (
    EarthField,
    GeomagneticModelError,
    decimal_year2posix,
    earth_field,
    magnetic2true,
    posix2decimal_year,
    true2magnetic,
)
from auvnav.compass.magnetometer import (
    MagnetometerCalibration,
    calibrate_magnetometer,
    deviation_from_iron,
    distort_field,
    heading_from_magnetometer,
    level_rotation,
)

__all__ = [
    "DeviationFit",
    "DeviationModel",
    "EarthField",
    "FitRecord",
    "GeomagneticModelError",
    "MagnetometerCalibration",
    "calibrate_magnetometer",
    "compass_section",
    "decimal_year2posix",
    "deviation_from_iron",
    "distort_field",
    "earth_field",
    "fit_deviation",
    "fix_constant",
    "fourier_design",
    "heading_from_magnetometer",
    "heading_gaps",
    "level_rotation",
    "magnetic2true",
    "posix2decimal_year",
    "read_correction",
    "read_true_deviation",
    "transit_deviation",
    "true2magnetic",
    "write_correction",
]
