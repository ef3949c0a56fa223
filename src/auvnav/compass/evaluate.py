"""A compass correction scored against a simulated dive's true deviation (``auvnav evaluate``).

The simulator writes the true correction ``delta(h)`` at level attitude, one row per whole degree of
compass heading, to ``truth/deviation.csv`` (``compass_heading_deg, deviation_deg``; true magnetic
heading = ``h + delta(h)``, the correction's sign). A correction file is evaluated at the same
headings; its error ``correction(h) - delta(h)`` is scored over the whole rose.

The constant term is what relative data cannot see (DESIGN section 7): the scores include it where
the correction fixed it (``constant.source`` other than ``arbitrary``) and leave it out (the error's
mean over the rose removed) where it is arbitrary. The constant's error is reported separately
either way, and so is the shape's (the error with its mean removed).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from auvnav.compass.correction import read_correction
from auvnav.errors import DiveFormatError, Problem
from auvnav.frames import FloatArray, wrap_angle
from auvnav.streams import Field, read_table

TRUE_DEVIATION_FILE = Path("truth") / "deviation.csv"
_DEG = math.pi / 180.0
_FIELDS = (
    Field("compass_heading_rad", ("compass_heading_deg",), _DEG),
    Field("deviation_rad", ("deviation_deg",), _DEG),
)


def read_true_deviation(dive_path: Path) -> tuple[FloatArray, FloatArray]:
    """A simulated dive's true deviation.

    Parameters
    ----------
    dive_path : Path
        A dive folder with ``truth/deviation.csv``.

    Returns
    -------
    compass_heading_rad : ndarray, shape (K,)
    deviation_rad : ndarray, shape (K,)
        ``delta(h)``: true magnetic heading = ``h + delta(h)``.

    Raises
    ------
    DiveFormatError
        The file is missing or bad (one line per problem, naming the file).
    """
    path = Path(dive_path) / TRUE_DEVIATION_FILE
    if not path.is_file():
        raise DiveFormatError([Problem(str(path), "not found: only simulated dives have a true deviation")])
    values, problems, _ = read_table(path, _FIELDS, str(path), time_ordered=False)
    if problems:
        raise DiveFormatError(problems)
    return (
        np.asarray(values["compass_heading_deg"], dtype=float) * _DEG,
        np.asarray(values["deviation_deg"], dtype=float) * _DEG,
    )


def compass_section(dive_path: Path, correction_path: Path) -> dict[str, Any]:
    """Score a compass correction against a simulated dive's true deviation (degrees).

    Parameters
    ----------
    dive_path : Path
        A simulated dive folder (``truth/deviation.csv``).
    correction_path : Path
        An ``auvnav-compass-correction/1`` file.

    Returns
    -------
    dict
        ``deviation_rmse_deg`` and ``deviation_max_error_deg`` (constant included where it was
        fixed, excluded where arbitrary: ``constant_included``), ``constant_error_deg`` (the
        error's mean over the rose: the correction's constant minus the true one),
        ``shape_rmse_deg`` and ``shape_max_error_deg`` (constant excluded), ``constant_source``.
    """
    h, delta = read_true_deviation(dive_path)
    model = read_correction(correction_path)
    error = wrap_angle(model(h) - delta)
    constant = float(np.mean(error))
    shape = error - constant
    included = model.constant_source != "arbitrary"
    scored = error if included else shape
    return {
        "deviation_rmse_deg": math.degrees(float(np.sqrt(np.mean(scored**2)))),
        "deviation_max_error_deg": math.degrees(float(np.max(np.abs(scored)))),
        "constant_included": included,
        "constant_error_deg": math.degrees(constant),
        "shape_rmse_deg": math.degrees(float(np.sqrt(np.mean(shape**2)))),
        "shape_max_error_deg": math.degrees(float(np.max(np.abs(shape)))),
        "constant_source": model.constant_source,
    }
