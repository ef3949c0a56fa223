"""Pressure to depth: TEOS-10 by default, UNESCO 1983 for comparison with older processing.

Conventions (DESIGN section 4): depth is positive down, metres; pressures are pascals inside the code
(dbar only in files); sea pressure = absolute pressure - atmospheric pressure;
``depth = -gsw.z_from_p(sea pressure in dbar, latitude in degrees)``.

Atmospheric pressure is a constant or a time series read from a CSV file with the columns
``t`` (float seconds since the POSIX epoch, UTC) and ``pressure_dbar``; lines starting with ``#`` are
comments, other columns are ignored. The series is interpolated linearly in time.

References
----------
IOC, SCOR and IAPSO (2010). The international thermodynamic equation of seawater - 2010 (TEOS-10),
    Intergovernmental Oceanographic Commission, Manuals and Guides No. 56; implemented by the GSW
    toolbox (``gsw.z_from_p``, ``gsw.p_from_z``).
Fofonoff, N. P. and Millard, R. C. Jr (1983). Algorithms for computation of fundamental properties of
    seawater. UNESCO Technical Papers in Marine Science 44, pp. 25-28 (pressure to depth; check values
    on p. 28).
"""

from __future__ import annotations

import csv
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import gsw
import numpy as np
from numpy.typing import ArrayLike

from auvnav.config import quote, read_text
from auvnav.errors import DiveFormatError, Problem
from auvnav.frames import FloatArray

log = logging.getLogger(__name__)

DBAR_TO_PA: float = 1e4
"""Pascals per decibar (1 dbar = 10 kPa, exact)."""

ATMOSPHERIC_PLAUSIBLE_PA: tuple[float, float] = (5.0e4, 1.1e5)
"""Range of atmospheric pressures accepted, Pa. The extremes recorded at sea level are about 870 and
1084 hPa (WMO World Weather and Climate Extremes Archive); 500 hPa admits lakes up to about 5 km.
A value outside it is a unit error (hPa, kPa, bar, psi), not weather."""

_ATMOSPHERIC_COLUMNS = ("t", "pressure_dbar")
_MAX_PROBLEMS = 10
_MAX_ATMOSPHERIC_BYTES = 64 * 2**20  # a year of one-minute readings is about 15 MB

# UNESCO 1983 depth (Fofonoff & Millard 1983, pp. 25-28): the integrated specific volume of the
# standard ocean (S = 35, T = 0 degC) as a polynomial in p [dbar], coefficients c1..c4 ...
_UNESCO_C = (9.72659, -2.2512e-5, 2.279e-10, -1.82e-15)
# ... divided by gravity: International Gravity Formula 1967 at the latitude ...
_UNESCO_G0_MPS2 = 9.780318
_UNESCO_G2 = 5.2788e-3
_UNESCO_G4 = 2.36e-5
# ... plus half the mean vertical gradient of gravity, gamma' = 2.184e-6 m s-2 dbar-1.
_UNESCO_HALF_GAMMA = 1.092e-6


def _latitude_deg(latitude_rad: float) -> float:
    if not -math.pi / 2 <= latitude_rad <= math.pi / 2:
        raise ValueError(f"latitude must lie in [-pi/2, pi/2] rad; found {latitude_rad}")
    return math.degrees(latitude_rad)


def _unesco1983_depth_m(p_dbar: FloatArray, latitude_rad: float) -> FloatArray:
    """Depth [m] of sea pressure ``p_dbar`` by Fofonoff & Millard (1983), pp. 25-28."""
    x = math.sin(latitude_rad) ** 2
    gravity = _UNESCO_G0_MPS2 * (1.0 + (_UNESCO_G2 + _UNESCO_G4 * x) * x) + _UNESCO_HALF_GAMMA * p_dbar
    c1, c2, c3, c4 = _UNESCO_C
    return (((c4 * p_dbar + c3) * p_dbar + c2) * p_dbar + c1) * p_dbar / gravity


def depth_from_pressure(
    sea_pressure_pa: ArrayLike,
    latitude_rad: float,
    *,
    method: Literal["teos10", "unesco1983"] = "teos10",
) -> FloatArray:
    """Depth below the sea surface from sea pressure.

    Parameters
    ----------
    sea_pressure_pa : array_like, any shape, Pa
        Sea (gauge) pressure: absolute pressure minus atmospheric pressure.
    latitude_rad : float
        Latitude of the dive, radians (gravity depends on it).
    method : {"teos10", "unesco1983"}
        ``"teos10"``: ``-gsw.z_from_p`` (TEOS-10, dynamic height anomaly 0), the default.
        ``"unesco1983"``: Fofonoff & Millard (1983), the formula of older processing; it differs
        from TEOS-10 by decimetres at 10000 dbar and by millimetres at AUV depths.

    Returns
    -------
    ndarray, shape of ``sea_pressure_pa``, metres, positive down
    """
    latitude_deg = _latitude_deg(latitude_rad)
    p_dbar = np.asarray(sea_pressure_pa, dtype=float) / DBAR_TO_PA
    if method == "teos10":
        return -np.asarray(gsw.z_from_p(p_dbar, latitude_deg), dtype=float)
    if method == "unesco1983":
        return _unesco1983_depth_m(p_dbar, latitude_rad)
    raise ValueError(f"method must be 'teos10' or 'unesco1983'; found {method!r}")


def pressure_from_depth(depth_m: ArrayLike, latitude_rad: float) -> FloatArray:
    """Sea pressure at a depth (TEOS-10, ``gsw.p_from_z``); the inverse of :func:`depth_from_pressure`.

    Parameters
    ----------
    depth_m : array_like, any shape, metres, positive down
    latitude_rad : float
        Latitude, radians.

    Returns
    -------
    ndarray, shape of ``depth_m``, Pa (sea pressure)
    """
    latitude_deg = _latitude_deg(latitude_rad)
    z_m = -np.asarray(depth_m, dtype=float)
    return np.asarray(gsw.p_from_z(z_m, latitude_deg), dtype=float) * DBAR_TO_PA


def _implausible_atmospheric(pressure_pa: FloatArray) -> FloatArray:
    """Mask of pressures [Pa] outside :data:`ATMOSPHERIC_PLAUSIBLE_PA` (NaN included)."""
    low, high = ATMOSPHERIC_PLAUSIBLE_PA
    return ~((pressure_pa >= low) & (pressure_pa <= high))


def _check_atmospheric_pa(pressure_pa: FloatArray) -> None:
    bad = _implausible_atmospheric(pressure_pa)
    if np.any(bad):
        low, high = ATMOSPHERIC_PLAUSIBLE_PA
        raise ValueError(
            f"atmospheric pressure must lie in [{low:g}, {high:g}] Pa; "
            f"found {np.count_nonzero(bad)} values outside, e.g. {pressure_pa[bad][0]!r}"
        )


@dataclass(frozen=True)
class AtmosphericSeries:
    """Atmospheric pressure as a time series, interpolated linearly in time.

    Parameters
    ----------
    t_s : ndarray, shape (N,), seconds since the POSIX epoch, UTC
        Strictly increasing, N >= 1.
    pressure_pa : ndarray, shape (N,), Pa
        Absolute atmospheric pressure, within :data:`ATMOSPHERIC_PLAUSIBLE_PA`.
    """

    t_s: FloatArray
    pressure_pa: FloatArray

    def __post_init__(self) -> None:
        t = np.array(self.t_s, dtype=float)
        p = np.array(self.pressure_pa, dtype=float)
        if t.ndim != 1 or t.shape != p.shape:
            raise ValueError(f"t_s and pressure_pa must be 1-D and match; found {t.shape} and {p.shape}")
        if t.size == 0:
            raise ValueError("an atmospheric series needs at least one sample; found none")
        if not np.all(np.isfinite(t)):
            raise ValueError("t_s must be finite")
        if np.any(np.diff(t) <= 0):
            raise ValueError("t_s must be strictly increasing")
        _check_atmospheric_pa(p)
        t.setflags(write=False)
        p.setflags(write=False)
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "pressure_pa", p)

    def pressure_at(self, t_s: ArrayLike) -> FloatArray:
        """Atmospheric pressure [Pa] at times ``t_s`` [s, POSIX]; any shape.

        Times outside the series take the nearest end value, with a warning that counts them.
        """
        t = np.asarray(t_s, dtype=float)
        outside = (t < self.t_s[0]) | (t > self.t_s[-1])
        if np.any(outside):
            beyond_s = np.max(np.maximum(self.t_s[0] - t, t - self.t_s[-1])[outside])
            log.warning(
                "%d of %d times lie outside the atmospheric series (up to %.0f s beyond it); "
                "they take its nearest end value",
                np.count_nonzero(outside),
                t.size,
                beyond_s,
            )
        return np.interp(t, self.t_s, self.pressure_pa)


def read_atmospheric(path: Path) -> AtmosphericSeries:
    """Read an atmospheric pressure series from a CSV file (columns ``t``, ``pressure_dbar``).

    Rows are sorted by time. Every problem is reported with the file, data row (the header is row 0)
    and column: missing columns, unparsable or non-finite numbers, duplicate times, pressures outside
    :data:`ATMOSPHERIC_PLAUSIBLE_PA` (a unit error).

    Raises
    ------
    DiveFormatError
        The file breaks the format; one line per problem.
    """
    path = Path(path)
    name = str(path)
    text, problems = read_text(path, name, max_bytes=_MAX_ATMOSPHERIC_BYTES)
    if text is None:
        raise DiveFormatError(problems)
    lines = text.removeprefix("\ufeff").splitlines()
    try:
        return _atmospheric_rows(name, lines)
    except csv.Error as err:
        raise DiveFormatError([Problem(name, f"not a CSV file ({quote(str(err))})")]) from None


def _atmospheric_rows(name: str, lines: list[str]) -> AtmosphericSeries:
    rows = csv.reader(line for line in lines if line.strip() and not line.lstrip().startswith("#"))
    header = [field.strip() for field in next(rows, [])]
    missing = [c for c in _ATMOSPHERIC_COLUMNS if c not in header]
    if missing:
        found = quote(",".join(header)) if header else "nothing"
        message = f"missing column(s) {', '.join(missing)} in the header; found {found}"
        raise DiveFormatError([Problem(name, message, row=0)])
    columns = [header.index(c) for c in _ATMOSPHERIC_COLUMNS]

    problems: list[Problem] = []
    data: list[tuple[int, float, float]] = []  # (data row, t [s], pressure [dbar]), all finite
    for row, fields in enumerate(rows, start=1):
        if len(fields) != len(header):
            problems.append(Problem(name, f"expected {len(header)} fields, found {len(fields)}", row))
            continue
        parsed = []
        for column, index in zip(_ATMOSPHERIC_COLUMNS, columns, strict=True):
            try:
                parsed.append(float(fields[index]))
            except ValueError:
                parsed.append(math.nan)
            if not math.isfinite(parsed[-1]):
                message = f"{quote(fields[index].strip())} is not a finite number"
                problems.append(Problem(name, message, row, column))
        if all(math.isfinite(v) for v in parsed):
            data.append((row, parsed[0], parsed[1]))
    if not data and not problems:
        problems.append(Problem(name, "no data rows"))

    data.sort(key=lambda item: item[1])  # stable: equal times keep their file order
    row_of = [item[0] for item in data]
    if row_of != sorted(row_of):
        log.info("%s: rows are not in time order; sorted", name)
    t_s = np.array([item[1] for item in data])
    with np.errstate(over="ignore"):  # 1e308 dbar is inf Pa: implausible below
        p_pa = np.array([item[2] for item in data]) * DBAR_TO_PA
    for i in np.flatnonzero(np.diff(t_s) == 0) + 1:
        problems.append(Problem(name, f"duplicate time {float(t_s[i])!r}", row_of[i], "t"))
    implausible = np.flatnonzero(_implausible_atmospheric(p_pa))
    if implausible.size:
        low, high = (bound / DBAR_TO_PA for bound in ATMOSPHERIC_PLAUSIBLE_PA)
        first = implausible[0]
        message = (
            f"{implausible.size} pressures outside the plausible [{low:g}, {high:g}] dbar, "
            f"first {float(p_pa[first] / DBAR_TO_PA)!r} (is the unit hPa, kPa, bar or psi?)"
        )
        problems.append(Problem(name, message, row_of[first], "pressure_dbar"))
    if problems:
        if len(problems) > _MAX_PROBLEMS:
            hidden = len(problems) - _MAX_PROBLEMS
            problems = [*problems[:_MAX_PROBLEMS], Problem(name, f"and {hidden} more problems")]
        raise DiveFormatError(problems)
    return AtmosphericSeries(t_s=t_s, pressure_pa=p_pa)


def sea_pressure(
    pressure_pa: ArrayLike,
    t_s: ArrayLike,
    *,
    pressure_type: Literal["absolute", "sea"],
    atmospheric_pa: float | AtmosphericSeries,
) -> FloatArray:
    """Sea pressure from a pressure sensor's record.

    Parameters
    ----------
    pressure_pa : array_like, shape (N,), Pa
        The sensor's pressure, absolute or sea (gauge) as ``pressure_type`` says.
    t_s : array_like, shape (N,), seconds since the POSIX epoch, UTC
        Sample times (used to interpolate an atmospheric series).
    pressure_type : {"absolute", "sea"}
        What the sensor reports (dive.yaml ``pressure.type``). A sea-pressure record is returned as
        it is and ``atmospheric_pa`` is not used.
    atmospheric_pa : float or AtmosphericSeries
        Atmospheric pressure, Pa: a constant or a series interpolated at ``t_s``.

    Returns
    -------
    ndarray, shape (N,), Pa
        Sea pressure = absolute pressure - atmospheric pressure.
    """
    p = np.array(pressure_pa, dtype=float)
    t = np.asarray(t_s, dtype=float)
    if p.shape != t.shape:
        raise ValueError(f"pressure_pa and t_s must match; found {p.shape} and {t.shape}")
    if pressure_type == "sea":
        return p
    if pressure_type != "absolute":
        raise ValueError(f"pressure_type must be 'absolute' or 'sea'; found {pressure_type!r}")
    if isinstance(atmospheric_pa, AtmosphericSeries):
        return p - atmospheric_pa.pressure_at(t)
    atmospheric = np.asarray(atmospheric_pa, dtype=float)
    if atmospheric.ndim != 0:
        raise ValueError(
            f"atmospheric_pa must be a number or an AtmosphericSeries; found shape {atmospheric.shape}"
        )
    _check_atmospheric_pa(atmospheric.reshape(1))
    return p - float(atmospheric)
