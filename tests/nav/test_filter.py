"""The EKF and RTS smoother on synthetic dives with noise: consistency, gating, reset, smoothing."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from auvnav.nav.deadreckon import dead_reckon, start_position
from auvnav.nav.filter import FilterConfig, run_filter
from auvnav.nav.inputs import nav_inputs
from auvnav.nav.synthetic import Motion, Noise, synthetic_dive

DEG = math.pi / 180.0
CONFIG = FilterConfig(
    dvl_velocity_sigma_mps=0.003,
    dvl_scale_sigma=0.002,
    heading_bias_sigma_rad=1.0 * DEG,
    heading_bias_walk=1.0 * DEG / 60.0,
    deviation_sigma_rad=1.0 * DEG,
    tilt_sigma_rad=0.2 * DEG,
    depth_sigma_m=0.01,
)


def _surface_times(motion: Motion, n: int = 30, step: int = 5) -> np.ndarray:
    """GPS at 1 Hz (5 Hz samples) for ``n`` s at the start and the end."""
    t = motion.truth.t_s
    return np.concatenate([t[: n * step : step], t[-n * step :: step]])


def _run(dive, config: FilterConfig = CONFIG):
    inputs = nav_inputs(dive)
    start = start_position(inputs, inputs.displacement_ned_m())
    return inputs, dead_reckon(inputs, start), run_filter(inputs, start, config)


def _deviation(h_rad: np.ndarray) -> np.ndarray:
    """A compass deviation of the paper's kind: 0.5 deg constant, 2 deg first harmonic."""
    return 0.5 * DEG + 2.0 * DEG * np.cos(h_rad - 0.3)


@pytest.fixture(scope="module")
def noisy_survey(survey: Motion):
    """The survey with noise, a DVL scale error and the deviation: an 'accordion' of about 14 m."""
    noise = Noise(dvl_scale_error=0.002, seed=3)
    dive = synthetic_dive(
        survey, gps_times_s=_surface_times(survey), noise=noise, compass_error_rad=_deviation
    )
    return _run(dive)


def test_innovations_are_consistent(noisy_survey) -> None:
    _, _, result = noisy_survey
    inn = result.innovations
    assert len(inn) == 60 and np.all(inn.accepted)
    assert np.mean(inn.inside(2.0)) >= 0.9
    np.testing.assert_array_equal(inn.sensor, "gps")


def test_filter_beats_dead_reckoning_and_its_sigmas_bound_its_errors(noisy_survey, survey: Motion) -> None:
    _, dr, result = noisy_survey
    truth = survey.truth.p_ned_m
    smoothed = result.smoothed
    dr_error = np.linalg.norm(dr.p_ned_m[:, :2] - truth[:, :2], axis=1)
    filter_error = np.linalg.norm(smoothed.p_ned_m[:, :2] - truth[:, :2], axis=1)
    assert dr_error[-1] > 10.0 and filter_error[-1] < 2.0
    assert np.sqrt(np.mean(filter_error**2)) < 0.2 * np.sqrt(np.mean(dr_error**2))
    error = np.abs(smoothed.p_ned_m - truth)[:, :2]
    assert np.mean(error <= 3 * smoothed.sigma_ned_m[:, :2]) > 0.99


def test_the_accordion_is_the_first_harmonic_of_the_deviation(noisy_survey) -> None:
    """North and south lines see cos h = +-1: the filter recovers a1 of the correction (eq. 5)."""
    inputs, _, result = noisy_survey
    a1_true = -2.0 * DEG * np.cos(0.3)  # the correction undoes the error
    assert result.deviation_rad[0] == pytest.approx(a1_true, abs=0.3 * DEG)
    residual = result.heading_error_rad + _deviation(inputs.compass_heading_rad)
    assert np.sqrt(np.mean(residual**2)) < 0.5 * DEG


def test_a_compass_error_is_estimated_on_a_transit(transit: Motion) -> None:
    """GPS before and after a 600 m transit sees a 2 degree compass error (about 20 m sideways)."""
    dive = synthetic_dive(
        transit, gps_times_s=_surface_times(transit), noise=Noise(seed=8), compass_error_rad=2 * DEG
    )
    _, dr, result = _run(dive)
    assert np.mean(result.heading_error_rad) == pytest.approx(-2 * DEG, abs=0.5 * DEG)
    truth = transit.truth.p_ned_m
    assert np.max(np.linalg.norm(result.smoothed.p_ned_m - truth, axis=1)) < 3.0
    assert np.linalg.norm(dr.p_ned_m[-1] - truth[-1]) > 15.0


def test_without_deviation_states_the_heading_error_alone_takes_a_constant_error(transit: Motion) -> None:
    dive = synthetic_dive(
        transit, gps_times_s=_surface_times(transit), noise=Noise(seed=8), compass_error_rad=2 * DEG
    )
    _, _, result = _run(dive, dataclasses.replace(CONFIG, deviation_harmonics=0))
    assert result.deviation_rad.shape == (0,)
    assert np.mean(result.heading_error_rad) == pytest.approx(-2 * DEG, abs=0.3 * DEG)
    assert np.max(np.linalg.norm(result.smoothed.p_ned_m - transit.truth.p_ned_m, axis=1)) < 3.0


def test_smoother_keeps_and_corrects_the_track_before_the_first_fix(survey: Motion) -> None:
    late = survey.truth.t_s[-150::5]  # fixes in the last 30 s only
    dive = synthetic_dive(survey, gps_times_s=late, noise=Noise(seed=4))
    _, _, result = _run(dive)
    assert result.smoothed.t_s[0] == survey.truth.t_s[0]
    assert np.linalg.norm(result.smoothed.p_ned_m[0, :2] - survey.truth.p_ned_m[0, :2]) < 5.0
    # The forward filter's prior before the first fix is diffuse; the smoother's is not.
    assert result.innovations.sigma_ne_m[0, 0] > 100.0
    assert result.smoothed.sigma_ned_m[0, 0] < 10.0


def test_gross_outlier_is_gated_and_logged(survey: Motion) -> None:
    times = _surface_times(survey)
    dive = synthetic_dive(survey, gps_times_s=times, noise=Noise(seed=5))
    gps = dive.gps
    lat = gps.latitude_rad.copy()
    lat[10] += 100.0 / 6.378e6  # 100 m north
    dive = dataclasses.replace(dive, gps=dataclasses.replace(gps, latitude_rad=lat))
    _, _, result = _run(dive)
    inn = result.innovations
    assert not inn.accepted[10] and inn.mahalanobis[10] > 10.0
    assert np.count_nonzero(~inn.accepted) == 1 and not np.any(inn.reset)
    at_outlier = np.searchsorted(survey.truth.t_s, times[10])
    assert (
        np.linalg.norm(result.smoothed.p_ned_m[at_outlier, :2] - survey.truth.p_ned_m[at_outlier, :2]) < 3.0
    )


def test_filter_resets_when_every_fix_disagrees(transit: Motion) -> None:
    """A 15 degree compass error the noise model does not allow: the end fixes reset the position."""
    dive = synthetic_dive(
        transit, gps_times_s=_surface_times(transit), noise=Noise(seed=6), compass_error_rad=15 * DEG
    )
    _, dr, result = _run(dive)
    inn = result.innovations
    assert np.count_nonzero(inn.reset) == 1
    first_end = 30
    assert not np.any(inn.accepted[first_end : first_end + CONFIG.reset_after - 1])
    assert inn.accepted[first_end + CONFIG.reset_after - 1]
    truth = transit.truth.p_ned_m
    assert (
        np.linalg.norm(result.smoothed.p_ned_m[-1] - truth[-1])
        < 5.0
        < np.linalg.norm(dr.p_ned_m[-1] - truth[-1])
    )


def test_without_fixes_the_filter_starts_at_the_origin_and_its_uncertainty_grows(survey: Motion) -> None:
    dive = synthetic_dive(survey, noise=Noise(seed=7))
    _, dr, result = _run(dive)
    assert len(result.innovations) == 0
    np.testing.assert_allclose(result.smoothed.p_ned_m[0, :2], [0.0, 0.0], atol=1e-9)
    sigma = result.smoothed.sigma_ned_m[:, 0]
    assert sigma[0] == pytest.approx(CONFIG.origin_sigma_m, rel=1e-3)
    assert sigma[-1] > sigma[0]
    np.testing.assert_allclose(result.smoothed.p_ned_m[:, :2], dr.p_ned_m[:, :2], atol=0.05)


@pytest.mark.parametrize(
    ("setting", "value"),
    [("period_s", 0.0), ("gate_probability", 1.0), ("reset_after", 0), ("deviation_harmonics", -1)],
)
def test_bad_settings_are_refused(setting: str, value: float) -> None:
    from auvnav.errors import ConfigError

    with pytest.raises(ConfigError, match=setting):
        dataclasses.replace(CONFIG, **{setting: value})


def test_usbl_fixes_hold_the_track_under_water(transit: Motion) -> None:
    """USBL every 10 s (5 m) and no GPS: a 5 degree compass error no longer runs away."""
    t = transit.truth.t_s
    dive = synthetic_dive(transit, usbl_times_s=t[::50], noise=Noise(seed=9), compass_error_rad=5 * DEG)
    inputs, dr, result = _run(dive)
    assert [f.sensor for f in inputs.fixes] == ["usbl"]
    inn = result.innovations
    np.testing.assert_array_equal(inn.sensor, "usbl")
    assert np.mean(inn.inside(2.0)) >= 0.9
    truth = transit.truth.p_ned_m
    filter_error = np.linalg.norm(result.smoothed.p_ned_m[:, :2] - truth[:, :2], axis=1)
    assert np.max(filter_error) < 5.0 < np.linalg.norm(dr.p_ned_m[-1, :2] - truth[-1, :2])
