"""Dead reckoning from exact sensor streams: mounts, lever arms, declination, correction, dropouts."""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np
import pytest

from auvnav.compass.deviation import DeviationModel
from auvnav.compass.field import earth_field
from auvnav.errors import InsufficientDataError
from auvnav.frames import euler2rot
from auvnav.nav.deadreckon import dead_reckon
from auvnav.nav.inputs import nav_inputs
from auvnav.nav.synthetic import Motion, Noise, synthetic_dive
from auvnav.vehicle import Mount, Vehicle

# Exact streams leave only the integration error: the trapezoidal rule on 0.2 s steps through smooth
# turns of 0.1 rad/s peak (local error u w^2 dt^3 / 12, about 2e-7 m a step).
ATOL_EXACT_M = 1e-3  # 1 mm
DEG = math.pi / 180.0

MOUNTED = Vehicle(
    dvl=Mount(euler2rot(45 * DEG, 0.0, 180 * DEG), np.array([0.8, 0.1, 0.3])),
    compass=Mount(euler2rot(-90 * DEG, 0.0, 0.0), np.array([0.2, 0.0, 0.0])),
    pressure=Mount(np.eye(3), np.array([-0.5, 0.0, -0.2])),
    gps=Mount(np.eye(3), np.array([0.0, 0.0, -1.0])),
)


def _end_error_m(dive, motion: Motion, correction=None) -> float:
    dr = dead_reckon(nav_inputs(dive, correction))
    return float(np.linalg.norm(dr.p_ned_m[-1] - motion.truth.p_ned_m[-1]))


@pytest.mark.parametrize("vehicle", [Vehicle(), MOUNTED], ids=["aligned", "mounted"])
def test_exact_streams_reproduce_the_truth(survey: Motion, vehicle: Vehicle) -> None:
    dive = synthetic_dive(survey, vehicle=vehicle, gps_times_s=survey.truth.t_s[:1])
    dr = dead_reckon(nav_inputs(dive))
    np.testing.assert_allclose(dr.t_s, survey.truth.t_s)
    np.testing.assert_allclose(dr.p_ned_m, survey.truth.p_ned_m, atol=ATOL_EXACT_M)
    yaw_error = np.angle(np.exp(1j * (dr.yaw_rad - survey.truth.yaw_rad)))
    assert np.max(np.abs(yaw_error)) < 1e-9


def test_track_before_the_first_fix_is_kept(survey: Motion) -> None:
    """A fix halfway through places the whole track, the part before it included."""
    dive = synthetic_dive(survey, gps_times_s=survey.truth.t_s[[2000, 2001]])
    dr = dead_reckon(nav_inputs(dive))
    assert dr.t_s[0] == survey.truth.t_s[0]
    np.testing.assert_allclose(dr.p_ned_m[0], survey.truth.p_ned_m[0], atol=ATOL_EXACT_M)


def test_without_fixes_the_track_starts_at_the_origin(survey: Motion) -> None:
    shifted = dataclasses.replace(survey.truth, p_ned_m=survey.truth.p_ned_m + np.array([50.0, -20.0, 0.0]))
    dive = synthetic_dive(Motion(shifted, survey.v_body_mps, survey.omega_body_rps))
    dr = dead_reckon(nav_inputs(dive))
    np.testing.assert_allclose(dr.p_ned_m[0, :2], [0.0, 0.0])
    np.testing.assert_allclose(
        dr.p_ned_m - dr.p_ned_m[0], shifted.p_ned_m - shifted.p_ned_m[0], atol=ATOL_EXACT_M
    )


def test_declination_is_added_to_a_magnetic_heading(transit: Motion) -> None:
    dive = synthetic_dive(transit, declination_rad=10 * DEG, gps_times_s=transit.truth.t_s[:1])
    assert _end_error_m(dive, transit) < ATOL_EXACT_M
    # The same streams read as a true heading miss by the declination: 2 sin(5 deg) of the distance.
    as_true = dataclasses.replace(dive, info=dataclasses.replace(dive.info, heading_reference="true"))
    displacement = np.linalg.norm(transit.truth.p_ned_m[-1] - transit.truth.p_ned_m[0])
    assert _end_error_m(as_true, transit) == pytest.approx(2 * math.sin(5 * DEG) * displacement, rel=1e-3)


def test_automatic_declination_comes_from_the_geomagnetic_model(transit: Motion) -> None:
    dive = synthetic_dive(transit)
    auto = dataclasses.replace(dive, info=dataclasses.replace(dive.info, declination_rad=None))
    inputs = nav_inputs(auto)
    origin = dive.info.origin
    field = earth_field(origin.latitude_rad, origin.longitude_rad, dive.info.start_time_s)
    assert inputs.declination_rad == field.declination_rad
    assert inputs.declination_source == field.model


def test_compass_correction_is_added_to_the_measured_heading(transit: Motion) -> None:
    """Paper eq. 5: corrected heading = h + delta(h); a 3 degree compass error is undone exactly."""
    dive = synthetic_dive(transit, compass_error_rad=3 * DEG, gps_times_s=transit.truth.t_s[:1])
    correction = DeviationModel.from_coefficients([-3 * DEG, 0.0, 0.0])
    assert _end_error_m(dive, transit, correction) < ATOL_EXACT_M
    assert _end_error_m(dive, transit) > 0.05 * 600  # uncorrected: about sin(3 deg) of the transit


def test_depth_is_teos10_depth_of_the_reference_point(survey: Motion) -> None:
    dive = synthetic_dive(survey, vehicle=MOUNTED)
    np.testing.assert_allclose(nav_inputs(dive).depth_m, survey.truth.p_ned_m[:, 2], atol=1e-9)


def test_invalid_dvl_for_a_minute_is_bridged_and_counted(survey: Motion, caplog) -> None:
    valid = np.ones(len(survey.truth.t_s), dtype=bool)
    valid[100:400] = False  # 60 s on the first line: constant velocity, bridged exactly
    dive = synthetic_dive(survey, dvl_valid=valid, gps_times_s=survey.truth.t_s[:1])
    with caplog.at_level(logging.WARNING, logger="auvnav.nav.inputs"):
        inputs = nav_inputs(dive)
    assert inputs.dropouts.count == 1
    assert inputs.dropouts.total_s == pytest.approx(60.2)
    assert "bridged 1 dropout(s)" in caplog.text and "60.2 s" in caplog.text
    dr = dead_reckon(inputs)
    np.testing.assert_allclose(dr.p_ned_m, survey.truth.p_ned_m, atol=ATOL_EXACT_M)


def test_a_dropout_is_bridged_from_the_mean_velocity_at_its_edges(survey: Motion) -> None:
    """One ping's noise is not held across the dropout: the bridged velocity's error is about the
    DVL's sigma over the square root of the pings in the edge windows (25 each side), not the sigma."""
    valid = np.ones(len(survey.truth.t_s), dtype=bool)
    valid[100:400] = False
    sigma = 0.01
    errors = []
    for seed in range(8):
        noise = Noise(dvl_velocity_sigma_mps=sigma, heading_sigma_rad=0.0, seed=seed)
        inputs = nav_inputs(synthetic_dive(survey, dvl_valid=valid, noise=noise))
        v_ned = np.einsum("nij,nj->ni", inputs.R_ned_body, inputs.v_body_mps)
        v_true = np.gradient(survey.truth.p_ned_m, survey.truth.t_s, axis=0)
        errors.append((v_ned - v_true)[inputs.bridged, :2].mean(axis=0))
    rms = float(np.sqrt(np.mean(np.square(errors))))
    assert rms < 0.4 * sigma  # one ping held: about 0.7 sigma; 25 pings a side: about 0.15 sigma


def test_missing_dvl_rows_are_filled_and_bridged(survey: Motion, caplog) -> None:
    dive = synthetic_dive(survey, gps_times_s=survey.truth.t_s[:1])
    keep = np.ones(len(dive.dvl), dtype=bool)
    keep[100:400] = False
    holed = dataclasses.replace(dive, dvl=dive.dvl.select(keep))
    with caplog.at_level(logging.WARNING, logger="auvnav.nav.inputs"):
        inputs = nav_inputs(holed)
    assert len(inputs) == len(survey.truth.t_s)  # the hole is filled at the DVL's period
    assert inputs.dropouts.count == 1 and inputs.dropouts.total_s == pytest.approx(60.2)
    assert np.count_nonzero(inputs.bridged) == 300
    assert "bridged 1 dropout(s)" in caplog.text
    np.testing.assert_allclose(dead_reckon(inputs).p_ned_m, survey.truth.p_ned_m, atol=ATOL_EXACT_M)


def test_no_valid_dvl_is_an_error(survey: Motion) -> None:
    dive = synthetic_dive(survey, dvl_valid=np.zeros(len(survey.truth.t_s), dtype=bool))
    with pytest.raises(InsufficientDataError, match="no sample is marked valid"):
        nav_inputs(dive)


def test_attitude_gaps_are_interpolated_with_a_warning(survey: Motion, caplog) -> None:
    dive = synthetic_dive(survey, gps_times_s=survey.truth.t_s[:1])
    keep = np.ones(len(dive.attitude), dtype=bool)
    keep[100:150] = False  # 10 s on a straight line
    holed = dataclasses.replace(dive, attitude=dive.attitude.select(keep))
    with caplog.at_level(logging.WARNING, logger="auvnav.nav.inputs"):
        dr = dead_reckon(nav_inputs(holed))
    assert "nav/attitude: 1 gap(s) longer than 5 median periods (1 s), the longest 10.2 s" in caplog.text
    np.testing.assert_allclose(dr.p_ned_m, survey.truth.p_ned_m, atol=ATOL_EXACT_M)
