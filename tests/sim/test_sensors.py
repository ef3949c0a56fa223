"""Sensor models: the loop's scalar forms against the library's vectorised ones, the deviation, tide, pressure."""

from __future__ import annotations

import datetime as dt
import math

import gsw
import numpy as np
import pytest

from auvnav.compass.field import earth_field
from auvnav.compass.magnetometer import deviation_from_iron, distort_field, heading_from_magnetometer
from auvnav.frames import euler2rot
from auvnav.sim.sensors import (
    DEFAULT_IRON,
    NO_IRON,
    SCOTT_REEF_LATITUDE_DEG,
    SCOTT_REEF_LONGITUDE_DEG,
    SensorModels,
    absolute_pressure_pa,
    body2ned,
    compass_heading,
    default_tide,
    deviation_table,
    distort,
    iron_rows,
    ned2body,
)
from auvnav.vehicle import Vehicle

LAT = math.radians(SCOTT_REEF_LATITUDE_DEG)
SCOTT_REEF_2009 = earth_field(
    LAT,
    math.radians(SCOTT_REEF_LONGITUDE_DEG),
    dt.datetime(2009, 10, 15, 1, tzinfo=dt.timezone.utc).timestamp(),
)
rng = np.random.default_rng(42)
ATTITUDES = np.column_stack(
    [rng.uniform(-np.pi, np.pi, 200), rng.uniform(-0.3, 0.3, 200), rng.uniform(-0.3, 0.3, 200)]
)


def test_scalar_rotations_match_frames() -> None:
    v = rng.standard_normal((200, 3))
    for (yaw, pitch, roll), x in zip(ATTITUDES, v, strict=True):
        R = euler2rot(yaw, pitch, roll)
        np.testing.assert_allclose(ned2body(yaw, pitch, roll, *x), R.T @ x, atol=1e-12)
        np.testing.assert_allclose(body2ned(yaw, pitch, roll, *x), R @ x, atol=1e-12)


def test_scalar_compass_matches_eq_1_and_2() -> None:
    """The loop's eq. 2 and eq. 1 equal auvnav.compass.magnetometer's."""
    rows = iron_rows(DEFAULT_IRON)
    b_ned = SCOTT_REEF_2009.b_ned_T
    for yaw, pitch, roll in ATTITUDES:
        b_body = euler2rot(yaw, pitch, roll).T @ b_ned
        m = distort(rows, *b_body)
        np.testing.assert_allclose(
            m, distort_field(b_body, DEFAULT_IRON.H_soft, DEFAULT_IRON.h_hard_body_T), rtol=0, atol=1e-18
        )
        h_lib = heading_from_magnetometer(np.asarray(m), pitch, roll)
        assert compass_heading(*m, pitch, roll) == pytest.approx(float(h_lib), abs=1e-12)


def test_deviation_table_sign_and_inverse() -> None:
    """delta(h): true magnetic heading = h + delta(h), where the compass reads h (eq. 5's sign)."""
    h = np.radians(np.arange(360.0))
    delta = deviation_table(DEFAULT_IRON, SCOTT_REEF_2009, h)
    error_at_true = deviation_from_iron(
        DEFAULT_IRON.H_soft, DEFAULT_IRON.h_hard_body_T, SCOTT_REEF_2009, h + delta
    )
    np.testing.assert_allclose(error_at_true, -delta, atol=1e-10)
    np.testing.assert_allclose(deviation_table(NO_IRON, SCOTT_REEF_2009, h), 0.0, atol=1e-15)


def test_default_deviation_is_a_few_degrees_with_a_constant() -> None:
    delta_deg = np.degrees(deviation_table(DEFAULT_IRON, SCOTT_REEF_2009, np.radians(np.arange(360.0))))
    assert 2.0 < np.ptp(delta_deg) < 6.0  # "a few degrees peak to peak"
    assert 0.5 < np.mean(delta_deg) < 2.0  # the constant part
    assert delta_deg[0] - delta_deg[180] > 2.0  # reciprocal lines disagree: the accordion's cause


def test_without_errors_zeroes_every_error() -> None:
    exact = SensorModels.from_vehicle(Vehicle()).without_errors()
    errors = [v for k, v in vars(exact).items() if "sigma" in k or "resolution" in k]
    assert len(errors) == 11 and all(v == 0.0 for v in errors)
    assert exact.dvl_max_altitude_m == 30.0  # ranges are kept


def test_pressure_through_teos10() -> None:
    sensors = SensorModels.from_vehicle(Vehicle())
    depth = np.array([0.0, 10.0, 100.0])
    exact = absolute_pressure_pa(depth, LAT, 101325.0, np.zeros(3), sensors.without_errors())
    expected = gsw.p_from_z(-depth, SCOTT_REEF_LATITUDE_DEG) * 1e4 + 101325.0
    np.testing.assert_allclose(exact, expected, rtol=0, atol=1e-6)
    assert exact[1] - exact[0] == pytest.approx(1.0056e5, rel=2e-3)  # ~1.0056 dbar per metre near the surface
    noisy = absolute_pressure_pa(depth, LAT, 101325.0, np.ones(3), sensors)
    np.testing.assert_allclose(noisy - exact, sensors.pressure_sigma_pa, atol=sensors.pressure_resolution_pa)
    assert np.all(np.mod(noisy, sensors.pressure_resolution_pa) < 1e-6)


def test_default_tide_is_macrotidal() -> None:
    tide = default_tide(LAT)
    assert [c.name for c in tide.constituents] == ["M2", "S2", "K1", "O1"]
    t = dt.datetime(2009, 10, 1, tzinfo=dt.timezone.utc).timestamp() + np.arange(0, 30 * 86400, 600.0)
    eta = tide.predict(t)
    daily_range = [np.ptp(eta[i : i + 144]) for i in range(0, eta.size - 144, 144)]
    assert 3.5 < max(daily_range) < 5.0  # spring range of about 4 m (Holloway 1983)
    assert min(daily_range) < 2.5  # neaps
