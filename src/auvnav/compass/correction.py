"""The compass correction file, format ``auvnav-compass-correction/1`` (DESIGN section 6).

A YAML document read by navigation, SLAM, the simulator's guidance and (through its table) vehicle
firmware::

    format: auvnav-compass-correction/1
    model: fourier                 # delta(h) = a0 + sum_k a_k cos(k h) + b_k sin(k h)  (paper eq. 5)
    harmonics: 3
    a0_deg: 0.81
    a_deg: [1.52, -0.61, 0.29]
    b_deg: [-0.98, 0.41, -0.22]
    constant: {source: gps-transits, sigma_deg: 0.12,   # how a0 was fixed, its 1-sigma;
               legs: 4, transit_rms_deg: 0.1,           # with transits: the legs used, their
               dives: [transit]}                        # residual RMS and their dives (optional)
    fit: {reference: truth, dives: [navcheck], pairs: 1180}   # what the shape was fitted to (optional)
    residual_rms_deg: 0.29         # of the shape fit's inliers (against its reference); null without a fit
    covariance_deg2: [[...], ...]  # of [a0, a1, b1, ..., aN, bN], deg^2; null when unknown
    gaps_deg: [[150.0, 1.0]]       # compass sectors (clockwise start, end) with no data; null
    table:                         # 360 rows [compass_heading_deg, correction_deg]
      - [0.0, -0.1869]
      ...

The corrected heading is ``compass + correction``. Reading is strict: an unknown or missing key, a
wrong type or size, or a table that disagrees with the coefficients is a
:class:`~auvnav.errors.ConfigError` naming the file and the key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from auvnav.compass.deviation import CONSTANT_SOURCES, DeviationFit, DeviationModel
from auvnav.config import cut, dump_yaml, load_yaml, quote
from auvnav.errors import ConfigError, OutputExistsError
from auvnav.streams import atomic_write

FORMAT = "auvnav-compass-correction/1"
MODEL = "fourier"
TABLE_ROWS = 360
# Table corrections are written to 1e-4 degree; a table further than this from the coefficients
# was edited by hand.
_TABLE_DECIMALS = 4
_TABLE_TOLERANCE_DEG = 1e-3

_REQUIRED = ("format", "model", "harmonics", "a0_deg", "a_deg", "b_deg", "constant", "table")
_OPTIONAL = ("residual_rms_deg", "covariance_deg2", "gaps_deg", "fit")
_CONSTANT_REQUIRED, _CONSTANT_OPTIONAL = ("source",), ("sigma_deg", "legs", "transit_rms_deg", "dives")
_FIT_KEYS = ("reference", "dives", "pairs")

_HEADER = """\
# Compass correction (auvnav). corrected heading = compass heading + correction, where
# correction(h) = a0 + sum_k a_k cos(k h) + b_k sin(k h) (Jakuba, Pizarro and Williams, eq. 5),
# h the measured compass heading. Angles in degrees; the table is the same curve at each degree.
"""


@dataclass(frozen=True)
class FitRecord:
    """Where a correction came from, written with it (the file's optional keys).

    Parameters
    ----------
    reference : str or None
        What the shape was fitted against: ``"truth"``, ``"slam"`` or a trajectory file.
    dives : tuple of str
        The dives whose heading pairs were fitted.
    pairs : int or None
        Heading pairs used.
    transit_dives : tuple of str
        The dives whose GPS course made good fixed the constant.
    transit_legs : int or None
        Sub-sea legs used for the constant.
    transit_rms_rad : float or None
        RMS of the legs' residuals about the fixed correction, radians.
    """

    reference: str | None = None
    dives: tuple[str, ...] = ()
    pairs: int | None = None
    transit_dives: tuple[str, ...] = ()
    transit_legs: int | None = None
    transit_rms_rad: float | None = None


def _table(model: DeviationModel) -> list[list[float]]:
    h_deg = np.arange(TABLE_ROWS, dtype=float)
    correction_deg = np.round(np.degrees(model(np.radians(h_deg))), _TABLE_DECIMALS)
    return [[float(h), float(c)] for h, c in zip(h_deg, correction_deg, strict=True)]


def write_correction(
    fit_or_model: DeviationFit | DeviationModel,
    path: str | Path,
    *,
    overwrite: bool = False,
    record: FitRecord | None = None,
) -> None:
    """Write a deviation fit or model as an ``auvnav-compass-correction/1`` file.

    Parameters
    ----------
    fit_or_model : DeviationFit or DeviationModel
        A fit also records its residual RMS and the heading gaps.
    path : str or Path
        The YAML file to write (parent folders are created).
    overwrite : bool
        Replace an existing file.
    record : FitRecord, optional
        Where the fit and its constant came from (the ``fit`` key and the ``constant`` details).

    Raises
    ------
    OutputExistsError
        ``path`` exists and ``overwrite`` is False.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path}: exists (use --overwrite to replace it)")
    fit = fit_or_model if isinstance(fit_or_model, DeviationFit) else None
    model = fit.model if fit is not None else fit_or_model
    cov = model.covariance
    doc: dict[str, Any] = {
        "format": FORMAT,
        "model": MODEL,
        "harmonics": model.harmonics,
        "a0_deg": math.degrees(model.a0_rad),
        "a_deg": np.degrees(model.a_rad).tolist(),
        "b_deg": np.degrees(model.b_rad).tolist(),
        "constant": {
            "source": model.constant_source,
            "sigma_deg": None if cov is None else math.degrees(math.sqrt(cov[0, 0])),
        },
        "residual_rms_deg": None if fit is None else math.degrees(fit.residual_rms_rad),
        "covariance_deg2": None if cov is None else np.degrees(np.degrees(cov)).tolist(),
        "gaps_deg": None
        if fit is None
        else [[math.degrees(s) % 360.0, math.degrees(e) % 360.0] for s, e in fit.gaps],
    }
    if record is not None and record.transit_legs is not None:
        doc["constant"]["legs"] = record.transit_legs
        doc["constant"]["transit_rms_deg"] = (
            None if record.transit_rms_rad is None else math.degrees(record.transit_rms_rad)
        )
        doc["constant"]["dives"] = list(record.transit_dives)
    if record is not None and record.reference is not None:
        doc["fit"] = {"reference": record.reference, "dives": list(record.dives), "pairs": record.pairs}
    doc["table"] = _table(model)
    text = _HEADER + dump_yaml(doc, default_flow_style=None, width=100)
    atomic_write(path, lambda p: p.write_text(text, encoding="utf-8"))


def _number(path: Path, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{path}: {key}: expected a finite number; found {quote(value)}")
    return float(value)


def _numbers(path: Path, key: str, value: Any, n: int) -> np.ndarray:
    if not isinstance(value, list) or len(value) != n:
        raise ConfigError(f"{path}: {key}: expected a list of {n} numbers; found {quote(value)}")
    return np.array([_number(path, f"{key}[{i}]", v) for i, v in enumerate(value)])


def _count(path: Path, key: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ConfigError(f"{path}: {key}: expected a non-negative integer; found {quote(value)}")
    return value


def _names(path: Path, key: str, value: Any) -> list[str]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ConfigError(f"{path}: {key}: expected a list of names; found {quote(value)}")
    return value


def _keys(path: Path, where: str, doc: Any, required: tuple[str, ...], optional: tuple[str, ...]) -> None:
    """Raise ConfigError for an unknown or missing key of the mapping ``doc`` at ``where``."""
    if not isinstance(doc, dict):
        raise ConfigError(f"{path}: {where or 'document'}: expected a mapping; found {quote(doc)}")
    prefix = f"{where}." if where else ""
    for key in doc:
        if key not in required + optional:
            raise ConfigError(f"{path}: {cut(prefix + str(key))}: unknown key")
    for key in required:
        if key not in doc:
            raise ConfigError(f"{path}: {prefix}{key}: missing")


def read_correction(path: str | Path) -> DeviationModel:
    """Read an ``auvnav-compass-correction/1`` file, strictly.

    Parameters
    ----------
    path : str or Path
        The YAML file.

    Returns
    -------
    DeviationModel
        Coefficients and covariance in radians, with the constant's source.

    Raises
    ------
    ConfigError
        No such file, bad YAML, an unknown or missing key, a wrong type or size, or a table that
        disagrees with the coefficients; one line naming the file and the key.
    """
    path = Path(path)
    doc, problems = load_yaml(path, str(path))
    if problems:
        raise ConfigError(str(problems[0]))
    _keys(path, "", doc, _REQUIRED, _OPTIONAL)
    if doc["format"] != FORMAT:
        raise ConfigError(f"{path}: format: expected {FORMAT!r}; found {quote(doc['format'])}")
    if doc["model"] != MODEL:
        raise ConfigError(f"{path}: model: expected {MODEL!r}; found {quote(doc['model'])}")
    n = _count(path, "harmonics", doc["harmonics"])
    a0 = _number(path, "a0_deg", doc["a0_deg"])
    a = _numbers(path, "a_deg", doc["a_deg"], n)
    b = _numbers(path, "b_deg", doc["b_deg"], n)
    _keys(path, "constant", doc["constant"], _CONSTANT_REQUIRED, _CONSTANT_OPTIONAL)
    source = doc["constant"]["source"]
    if source not in CONSTANT_SOURCES:
        raise ConfigError(
            f"{path}: constant.source: expected one of {', '.join(CONSTANT_SOURCES)}; found {quote(source)}"
        )
    for key in ("sigma_deg", "transit_rms_deg"):
        if doc["constant"].get(key) is not None:
            _number(path, f"constant.{key}", doc["constant"][key])
    if "legs" in doc["constant"]:
        _count(path, "constant.legs", doc["constant"]["legs"])
    if "dives" in doc["constant"]:
        _names(path, "constant.dives", doc["constant"]["dives"])
    if "fit" in doc:
        _keys(path, "fit", doc["fit"], _FIT_KEYS, ())
        if not isinstance(doc["fit"]["reference"], str):
            raise ConfigError(
                f"{path}: fit.reference: expected a string; found {quote(doc['fit']['reference'])}"
            )
        _names(path, "fit.dives", doc["fit"]["dives"])
        if doc["fit"]["pairs"] is not None:
            _count(path, "fit.pairs", doc["fit"]["pairs"])
    if doc.get("residual_rms_deg") is not None:
        _number(path, "residual_rms_deg", doc["residual_rms_deg"])
    cov = None
    if doc.get("covariance_deg2") is not None:
        rows = doc["covariance_deg2"]
        p = 2 * n + 1
        if not isinstance(rows, list) or len(rows) != p:
            raise ConfigError(f"{path}: covariance_deg2: expected {p} rows of {p} numbers")
        cov = np.radians(
            np.radians(np.array([_numbers(path, f"covariance_deg2[{i}]", r, p) for i, r in enumerate(rows)]))
        )
        if not np.allclose(cov, cov.T, rtol=1e-9, atol=0.0):
            raise ConfigError(f"{path}: covariance_deg2: not symmetric")
    gaps = doc.get("gaps_deg")
    if gaps is not None:
        if not isinstance(gaps, list):
            raise ConfigError(f"{path}: gaps_deg: expected a list of [start, end] pairs")
        for i, gap in enumerate(gaps):
            _numbers(path, f"gaps_deg[{i}]", gap, 2)
    try:
        model = DeviationModel(math.radians(a0), np.radians(a), np.radians(b), cov, constant_source=source)
    except ValueError as err:
        raise ConfigError(f"{path}: {err}") from None
    table = doc["table"]
    if not isinstance(table, list) or len(table) != TABLE_ROWS:
        raise ConfigError(f"{path}: table: expected {TABLE_ROWS} rows [heading_deg, correction_deg]")
    rows = np.array([_numbers(path, f"table[{i}]", r, 2) for i, r in enumerate(table)])
    if not np.array_equal(rows[:, 0], np.arange(TABLE_ROWS)):
        raise ConfigError(f"{path}: table: headings must be 0, 1, ..., {TABLE_ROWS - 1} degrees")
    with np.errstate(over="ignore", invalid="ignore"):
        expected = np.degrees(model(np.radians(rows[:, 0])))
        error = np.abs(rows[:, 1] - expected)
    worst = int(np.argmax(np.where(np.isfinite(error), error, np.inf)))
    if not error[worst] <= _TABLE_TOLERANCE_DEG:
        raise ConfigError(
            f"{path}: table[{worst}]: correction {rows[worst, 1]:.4f} deg disagrees with the "
            f"coefficients ({expected[worst]:.4f} deg)"
        )
    return model
