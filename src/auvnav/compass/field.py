"""The Earth's magnetic field at a place and date, and magnetic <-> true heading.

The field comes from a maintained geomagnetic model: the World Magnetic Model (WMM; NOAA NCEI and
BGS, Chulliat et al., "The US/UK World Magnetic Model for 2020-2025", NOAA Technical Report, 2020)
evaluated by ``pygeomag`` with the coefficient file whose five-year lifespan contains the date
(WMM-2010, WMM-2015v2, WMM-2020, WMM-2025), and outside every WMM lifespan the International
Geomagnetic Reference Field (IGRF-14, IAGA Working Group V-MOD, 2024, doi:10.5281/zenodo.14012302)
evaluated by ``ppigrf``. Both take geodetic coordinates on the WGS84 ellipsoid. Either can be asked
for by name (``model="wmm"`` or ``"igrf"``; ``auvnav compass declination --model``); IGRF-14 is
checked against the IAGA reference implementation's published test values (BGS pyIGRF).

Conventions (DESIGN section 4): the field is in NED (north, east, down) in tesla; declination is
east-positive, inclination down-positive; true heading = magnetic heading + declination.
"""

from __future__ import annotations

import datetime as dt
import functools
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
import ppigrf
from numpy.typing import ArrayLike
from pygeomag import GeoMag

from auvnav.errors import AuvnavError
from auvnav.frames import FloatArray, wrap_angle

NT_PER_T = 1e9

# WMM coefficient files shipped inside pygeomag/wmm, newest first; each is valid for the five years
# from its epoch (NOAA NCEI, WMM technical reports). WMM-2015v2 is NOAA's out-of-cycle 2019
# replacement for WMM-2015, which it supersedes.
_WMM_FILES: tuple[tuple[float, str], ...] = (
    (2025.0, "wmm/WMM_2025.COF"),
    (2020.0, "wmm/WMM_2020.COF"),
    (2015.0, "wmm/WMM_2015v2.COF"),
    (2010.0, "wmm/WMM_2010.COF"),
)
_WMM_LIFESPAN_YEARS = 5.0
# IGRF-14 definitive and predictive span (header of ppigrf/IGRF14.shc).
_IGRF_FIRST_YEAR, _IGRF_LAST_YEAR = 1900.0, 2030.0
_IGRF_NAME = "IGRF14"

ModelName = Literal["WMM2010", "WMM2015v2", "WMM2020", "WMM2025", "IGRF14"]


class GeomagneticModelError(AuvnavError):
    """A date (or place) that no shipped geomagnetic model covers."""


@dataclass(frozen=True)
class EarthField:
    """The geomagnetic main field at one place and time.

    Parameters
    ----------
    b_ned_T : ndarray, shape (3,), tesla, local NED
        North, east and down components.
    declination_rad : float
        Angle from true north to the horizontal field, east positive, radians.
    inclination_rad : float
        Angle of the field below the horizontal, down positive, radians.
    model : str
        The model evaluated, e.g. ``"WMM2025"`` or ``"IGRF14"``.
    """

    b_ned_T: FloatArray
    declination_rad: float
    inclination_rad: float
    model: str

    def __post_init__(self) -> None:
        b = np.array(self.b_ned_T, dtype=float)
        if b.shape != (3,) or not np.all(np.isfinite(b)):
            raise ValueError(f"b_ned_T must be 3 finite numbers; found shape {b.shape}: {b}")
        b.setflags(write=False)
        object.__setattr__(self, "b_ned_T", b)
        for name in ("declination_rad", "inclination_rad"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite; found {getattr(self, name)}")

    @property
    def total_T(self) -> float:
        """Total intensity F, tesla."""
        return float(np.linalg.norm(self.b_ned_T))

    @property
    def horizontal_T(self) -> float:
        """Horizontal intensity H, tesla."""
        return float(np.hypot(self.b_ned_T[0], self.b_ned_T[1]))


def posix2decimal_year(time_s: float) -> float:
    """Decimal year of a POSIX time (UTC): the year plus the elapsed fraction of that year.

    Parameters
    ----------
    time_s : float
        Seconds since the POSIX epoch, UTC.

    Returns
    -------
    float
        E.g. 2020.5 for 2020-07-02T00:00Z (the WMM convention: day-of-year based, leap years
        have 366 days).
    """
    t = dt.datetime.fromtimestamp(time_s, tz=dt.timezone.utc)
    start = dt.datetime(t.year, 1, 1, tzinfo=dt.timezone.utc)
    end = dt.datetime(t.year + 1, 1, 1, tzinfo=dt.timezone.utc)
    return t.year + (time_s - start.timestamp()) / (end.timestamp() - start.timestamp())


def decimal_year2posix(year: float) -> float:
    """POSIX time (UTC, seconds) of a decimal year; the inverse of :func:`posix2decimal_year`."""
    whole = math.floor(year)
    start = dt.datetime(whole, 1, 1, tzinfo=dt.timezone.utc).timestamp()
    end = dt.datetime(whole + 1, 1, 1, tzinfo=dt.timezone.utc).timestamp()
    return start + (year - whole) * (end - start)


@functools.lru_cache(maxsize=len(_WMM_FILES))
def _geomag(coefficients_file: str) -> GeoMag:
    """One loaded pygeomag model per coefficient file."""
    return GeoMag(coefficients_file=coefficients_file)


ModelChoice = Literal["auto", "wmm", "igrf"]


def _field_ned_nT(
    latitude_deg: float, longitude_deg: float, height_km: float, time_s: float, model: ModelChoice = "auto"
) -> tuple[FloatArray, str]:
    """North, east, down field (nT) and the model name."""
    year = posix2decimal_year(time_s)
    if model in ("auto", "wmm"):
        for epoch, coefficients_file in _WMM_FILES:
            if epoch <= year <= epoch + _WMM_LIFESPAN_YEARS:
                geomag = _geomag(coefficients_file)
                r = geomag.calculate(glat=latitude_deg, glon=longitude_deg, alt=height_km, time=year)
                return np.array([r.x, r.y, r.z]), geomag.model.replace("-", "")
        if model == "wmm":
            first, last = _WMM_FILES[-1][0], _WMM_FILES[0][0] + _WMM_LIFESPAN_YEARS
            raise GeomagneticModelError(
                f"the WMM does not cover {year:.3f} (WMM covers {first:.1f}-{last:.1f}): use the IGRF "
                f"(model igrf, IGRF-14 {_IGRF_FIRST_YEAR:.0f}-{_IGRF_LAST_YEAR:.0f})"
            )
    if _IGRF_FIRST_YEAR <= year <= _IGRF_LAST_YEAR:
        date = dt.datetime.fromtimestamp(time_s, tz=dt.timezone.utc).replace(tzinfo=None)
        be, bn, bu = ppigrf.igrf(longitude_deg, latitude_deg, height_km, date)
        return np.array([bn.item(), be.item(), -bu.item()]), _IGRF_NAME
    if model == "igrf":
        raise GeomagneticModelError(
            f"IGRF-14 does not cover {year:.3f} (it covers {_IGRF_FIRST_YEAR:.0f}-{_IGRF_LAST_YEAR:.0f})"
        )
    raise GeomagneticModelError(
        f"no geomagnetic model covers {year:.3f}: WMM covers 2010.0-2030.0 and IGRF-14 "
        f"{_IGRF_FIRST_YEAR:.0f}-{_IGRF_LAST_YEAR:.0f}"
    )


def earth_field(
    latitude_rad: float,
    longitude_rad: float,
    time_s: float,
    *,
    height_m: float = 0.0,
    model: ModelChoice = "auto",
) -> EarthField:
    """The geomagnetic field at a place and time.

    With ``model="auto"`` (the default) the WMM whose five-year lifespan contains the date (the
    newest where two lifespans meet), else IGRF-14 (1900-2030); ``"wmm"`` and ``"igrf"`` ask for one
    model and are an error outside its span. The model used is named in the result.

    Parameters
    ----------
    latitude_rad, longitude_rad : float
        Geodetic (WGS84) latitude and longitude, radians, east positive.
    time_s : float
        Seconds since the POSIX epoch, UTC.
    height_m : float, optional
        Height above the WGS84 ellipsoid, metres (negative below it).
    model : {"auto", "wmm", "igrf"}, optional

    Returns
    -------
    EarthField

    Raises
    ------
    GeomagneticModelError
        The date lies outside the model's span (1900-2030 for ``auto``), or the latitude outside
        [-90, 90] degrees.
    """
    if model not in ("auto", "wmm", "igrf"):
        raise ValueError(f"model must be 'auto', 'wmm' or 'igrf'; found {model!r}")
    latitude_deg, longitude_deg = math.degrees(latitude_rad), math.degrees(longitude_rad)
    if not -90.0 <= latitude_deg <= 90.0:
        raise GeomagneticModelError(f"latitude {latitude_deg:g} deg is outside [-90, 90]")
    longitude_deg = (longitude_deg + 180.0) % 360.0 - 180.0
    b_nT, name = _field_ned_nT(latitude_deg, longitude_deg, height_m / 1000.0, time_s, model)
    return EarthField(
        b_ned_T=b_nT / NT_PER_T,
        declination_rad=math.atan2(b_nT[1], b_nT[0]),
        inclination_rad=math.atan2(b_nT[2], math.hypot(b_nT[0], b_nT[1])),
        model=name,
    )


def magnetic2true(heading_rad: ArrayLike, declination_rad: ArrayLike) -> FloatArray:
    """True heading from magnetic heading: ``wrap(heading + declination)`` (east positive).

    Parameters
    ----------
    heading_rad : array_like, radians
        Heading from magnetic north, clockwise.
    declination_rad : array_like, radians
        Declination, east positive (broadcasts against ``heading_rad``).

    Returns
    -------
    ndarray, radians in (-pi, pi]
    """
    return wrap_angle(np.asarray(heading_rad, dtype=float) + np.asarray(declination_rad, dtype=float))


def true2magnetic(heading_rad: ArrayLike, declination_rad: ArrayLike) -> FloatArray:
    """Magnetic heading from true heading; the inverse of :func:`magnetic2true`."""
    return magnetic2true(heading_rad, -np.asarray(declination_rad, dtype=float))
