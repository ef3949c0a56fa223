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
- :mod:`~auvnav.compass.stage`: the compass stage and its products in ``products/compass/``.

Import from the modules; the package itself imports nothing, so that its parts load only when used.
"""
