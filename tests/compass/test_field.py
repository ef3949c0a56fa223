"""The geomagnetic field against NOAA's official WMM test values, model choice, heading conversion."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from auvnav.compass.field import (
    GeomagneticModelError,
    decimal_year2posix,
    earth_field,
    magnetic2true,
    posix2decimal_year,
    true2magnetic,
)
from auvnav.frames import angle_diff

ATOL_DEG = 0.01  # issue 5 acceptance: NOAA's test values to 0.01 degree
ATOL_NT = 0.1  # NOAA's tables give components to 0.1 nT (the WMM2025 table to 1e-6 nT)
ROUNDING_NT = 0.05  # half the last digit of the tables rounded to 0.1 nT


def _deg_error(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


def test_official_wmm_values(wmm_rows) -> None:
    for row in wmm_rows:
        f = earth_field(
            math.radians(row.lat),
            math.radians(row.lon),
            decimal_year2posix(row.year),
            height_m=1000.0 * row.height_km,
        )
        assert f.model == row.model, row
        assert _deg_error(math.degrees(f.declination_rad), row.D) <= ATOL_DEG, row
        assert abs(math.degrees(f.inclination_rad) - row.I) <= ATOL_DEG, row
        tol = ATOL_NT + (0.0 if row.model == "WMM2025" else ROUNDING_NT)
        np.testing.assert_allclose(f.b_ned_T * 1e9, [row.X, row.Y, row.Z], atol=tol, err_msg=str(row))
        assert abs(f.total_T * 1e9 - row.F) <= tol, row


@pytest.mark.parametrize(
    ("year", "model"),
    [
        (1950.0, "IGRF14"),
        (2009.786, "IGRF14"),  # the simulator's default date (Scott Reef, October 2009)
        (2010.0, "WMM2010"),
        (2014.99, "WMM2010"),
        (2015.0, "WMM2015v2"),  # lifespans meet: the newer model
        (2019.5, "WMM2015v2"),
        (2024.99, "WMM2020"),
        (2027.0, "WMM2025"),
        (2030.0, "WMM2025"),
    ],
)
def test_model_choice(year: float, model: str) -> None:
    f = earth_field(math.radians(-14.0), math.radians(121.8), decimal_year2posix(year))
    assert f.model == model


def test_igrf_meets_wmm_at_2010() -> None:
    """IGRF-14 before 2010.0 and WMM-2010 after agree to a few hundredths of a degree at the site."""
    lat, lon = math.radians(-14.0), math.radians(121.8)
    before = earth_field(lat, lon, decimal_year2posix(2010.0) - 1.0)
    after = earth_field(lat, lon, decimal_year2posix(2010.0))
    assert (before.model, after.model) == ("IGRF14", "WMM2010")
    assert abs(math.degrees(before.declination_rad - after.declination_rad)) < 0.05
    assert np.linalg.norm(before.b_ned_T - after.b_ned_T) < 50e-9  # 50 nT


def test_scott_reef_field(scott_reef_field) -> None:
    """Southern tropics: field points up (negative inclination), small easterly declination."""
    f = scott_reef_field
    assert -50.0 < math.degrees(f.inclination_rad) < -35.0
    assert 0.0 < math.degrees(f.declination_rad) < 5.0
    assert 40e-6 < f.total_T < 55e-6
    assert math.isclose(f.horizontal_T, math.hypot(*f.b_ned_T[:2]))


def test_height_reduces_the_field() -> None:
    lat, lon, t = math.radians(45.0), math.radians(10.0), decimal_year2posix(2022.0)
    assert earth_field(lat, lon, t, height_m=100e3).total_T < earth_field(lat, lon, t).total_T


@pytest.mark.parametrize("year", [1899.5, 2030.5])
def test_date_outside_every_model(year: float) -> None:
    with pytest.raises(GeomagneticModelError, match="no geomagnetic model covers"):
        earth_field(0.0, 0.0, decimal_year2posix(year))


def test_latitude_outside_range() -> None:
    with pytest.raises(GeomagneticModelError, match="latitude"):
        earth_field(math.radians(91.0), 0.0, decimal_year2posix(2020.0))


def test_decimal_year_convention() -> None:
    """WMM convention: 2020-07-02T00:00Z is 2020.5 (leap year, day 183 of 366)."""
    assert posix2decimal_year(1593648000.0) == pytest.approx(2020.5, abs=1e-12)
    assert decimal_year2posix(2020.5) == pytest.approx(1593648000.0, abs=1e-3)


@given(st.floats(1900.0, 2100.0))
def test_decimal_year_round_trip(year: float) -> None:
    assert posix2decimal_year(decimal_year2posix(year)) == pytest.approx(year, abs=1e-9)


@given(st.floats(-10.0, 10.0), st.floats(-0.5, 0.5))
def test_magnetic_true_round_trip(heading_rad: float, declination_rad: float) -> None:
    true = magnetic2true(heading_rad, declination_rad)
    assert -math.pi < true <= math.pi
    assert abs(angle_diff(true, heading_rad + declination_rad)) < 1e-12
    assert abs(angle_diff(true2magnetic(true, declination_rad), heading_rad)) < 1e-12


def test_magnetic2true_east_declination() -> None:
    """Heading 179 deg magnetic with 2 deg east declination is -179 deg true (wrapped)."""
    assert math.degrees(magnetic2true(math.radians(179.0), math.radians(2.0))) == pytest.approx(-179.0)


# IGRF-14 reference values published with the IAGA V-MOD reference implementation (pyIGRF, C. Beggan,
# British Geological Survey: github.com/ciaranbe/pyIGRF, tests/tests_igrf14.py, "checked
# independently against igrf.f and D. Kerridge's implementation"): decimal year, geocentric
# colatitude (deg), longitude (deg), radius (km) -> geocentric X (north), Y (east), Z (down), nT.
IGRF14_BGS = [
    (1900, 175, -150, 6300, (-5072.93, 10620.34, -67233.55)),
    (1915, 155, -120, 6350, (14692.62, 12387.97, -59640.81)),
    (1930, 135, -90, 6400, (23925.47, 10358.94, -30640.98)),
    (1945, 115, -60, 6450, (23642.86, -200.29, -7607.92)),
    (1960, 95, -30, 6500, (23647.00, -9302.27, -3610.73)),
    (1975, 75, 0, 6550, (30050.59, -3367.82, 6332.69)),
    (1990, 55, 30, 6600, (25224.81, 1058.25, 30965.61)),
    (2005, 35, 60, 6650, (14718.37, 2842.99, 46050.88)),
    (2020, 15, 90, 6700, (3734.07, 1294.17, 50833.13)),
    (2025, 90, 45, 6900, (25587.26, -826.43, -7422.32)),
]


def _ned_basis(lat: float, lon: float) -> np.ndarray:
    """Rows: north, east, down unit vectors (ECEF) at a latitude (geodetic or geocentric)."""
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array([[-sl * co, -sl * so, cl], [-so, co, 0.0], [-cl * co, -cl * so, -sl]])


@pytest.mark.parametrize("row", IGRF14_BGS, ids=[str(r[0]) for r in IGRF14_BGS])
def test_igrf14_reference_values(row) -> None:
    """model="igrf" against the published IGRF-14 values: declination within 0.01 degree (issue 15;
    measured: within 1e-4 degree) and the components within 0.1 nT. The reference point is
    geocentric: placed on the WGS84 ellipsoid and its field turned into the geocentric frame."""
    import pymap3d

    year, colat, lon, radius_km, xyz = row
    lat_c, lon_r = math.radians(90.0 - colat), math.radians(lon)
    ecef = (
        1e3
        * radius_km
        * np.array([math.cos(lat_c) * math.cos(lon_r), math.cos(lat_c) * math.sin(lon_r), math.sin(lat_c)])
    )
    lat, lon_g, h = pymap3d.ecef2geodetic(*ecef, deg=False)
    f = earth_field(lat, lon_g, decimal_year2posix(year), height_m=h, model="igrf")
    assert f.model == "IGRF14"
    b_ecef = _ned_basis(lat, lon_g).T @ f.b_ned_T
    geocentric_nT = _ned_basis(lat_c, lon_r) @ b_ecef * 1e9
    np.testing.assert_allclose(geocentric_nT, xyz, atol=0.1)
    d = math.degrees(math.atan2(geocentric_nT[1], geocentric_nT[0]))
    assert _deg_error(d, math.degrees(math.atan2(xyz[1], xyz[0]))) <= ATOL_DEG


def test_explicit_model_choice() -> None:
    lat, lon = math.radians(-14.0), math.radians(121.8)
    assert earth_field(lat, lon, decimal_year2posix(2020.5), model="igrf").model == "IGRF14"
    assert earth_field(lat, lon, decimal_year2posix(2020.5), model="wmm").model == "WMM2020"
    with pytest.raises(GeomagneticModelError, match="the WMM does not cover 2009"):
        earth_field(lat, lon, decimal_year2posix(2009.5), model="wmm")
    with pytest.raises(GeomagneticModelError, match="IGRF-14 does not cover 1850"):
        earth_field(lat, lon, decimal_year2posix(1850.5), model="igrf")
