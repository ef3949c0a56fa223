"""The deviation model (eq. 5), its least-squares fit (eq. 6) and the constant from GPS transits."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from auvnav.compass.deviation import (
    DeviationModel,
    fit_deviation,
    fix_constant,
    fourier_design,
    heading_gaps,
    transit_deviation,
)
from auvnav.compass.magnetometer import deviation_from_iron
from auvnav.errors import InsufficientDataError
from auvnav.frames import angle_diff, wrap_angle

RECOVERY_RMS_DEG = 0.1  # issue 5 acceptance
NOISE_DEG = 0.3  # SLAM-minus-compass heading noise per pair
GRID = np.linspace(-np.pi, np.pi, 721)


def _rms_deg(x: np.ndarray) -> float:
    return math.degrees(float(np.sqrt(np.mean(np.square(x)))))


def _pairs(model: DeviationModel, n: int, seed: int, *, headings=None):
    """Compass headings and reference headings ``h + delta(h) + noise``."""
    rng = np.random.default_rng(seed)
    h = rng.uniform(-np.pi, np.pi, n) if headings is None else headings
    ref = wrap_angle(h + model(h) + rng.normal(0.0, math.radians(NOISE_DEG), h.shape))
    return h, ref


def test_design_matrix_is_eq6() -> None:
    h = np.array([0.3, -2.0])
    expected = [[1, np.cos(h0), np.sin(h0), np.cos(2 * h0), np.sin(2 * h0)] for h0 in h]
    np.testing.assert_allclose(fourier_design(h, 2), expected)
    assert fourier_design(0.1, 3).shape == (7,)


def test_model_evaluates_eq5(true_deviation) -> None:
    m = true_deviation
    h = 0.7
    expected = m.a0_rad + sum(
        m.a_rad[k] * math.cos((k + 1) * h) + m.b_rad[k] * math.sin((k + 1) * h) for k in range(3)
    )
    assert m(h) == pytest.approx(expected)
    assert m.correct(math.pi - 0.01) == pytest.approx(wrap_angle(math.pi - 0.01 + m(math.pi - 0.01)))
    assert m.harmonics == 3
    assert np.all(np.isnan(m.sigma(GRID)))  # no covariance: the band is unknown
    x = m.coefficients_rad
    assert DeviationModel.from_coefficients(x)(GRID) == pytest.approx(m(GRID))


def test_model_validation() -> None:
    with pytest.raises(ValueError, match="must match"):
        DeviationModel(0.0, np.zeros(2), np.zeros(3))
    with pytest.raises(ValueError, match=r"shape \(5, 5\)"):
        DeviationModel(0.0, np.zeros(2), np.zeros(2), covariance=np.eye(3))
    with pytest.raises(ValueError, match="constant_source"):
        DeviationModel(0.0, np.zeros(1), np.zeros(1), constant_source="guess")  # type: ignore[arg-type]


@pytest.mark.parametrize("robust", [False, True])
def test_fit_recovers_injected_deviation(true_deviation, robust: bool) -> None:
    h, ref = _pairs(true_deviation, 400, seed=1)
    fit = fit_deviation(h, ref, robust=robust, constant_source="truth")
    assert _rms_deg(fit.model(GRID) - true_deviation(GRID)) < RECOVERY_RMS_DEG
    assert fit.model.constant_source == "truth"
    assert fit.residual_rms_rad == pytest.approx(math.radians(NOISE_DEG), rel=0.15)
    assert fit.cv_harmonics == 3
    assert fit.gaps == []
    # The band is honest: the error sits inside 3 sigma everywhere on the rose.
    assert np.all(np.abs(fit.model(GRID) - true_deviation(GRID)) < 3.0 * fit.model.sigma(GRID) + 1e-3)


def test_band_matches_monte_carlo_scatter(true_deviation) -> None:
    """The 1-sigma band agrees with the scatter of repeated fits to within 20%."""
    h = np.random.default_rng(5).uniform(-np.pi, np.pi, 200)
    probe = np.linspace(-np.pi, np.pi, 13)
    fits = [
        fit_deviation(*_pairs(true_deviation, 0, seed=s, headings=h), cv_max_harmonics=0) for s in range(100)
    ]
    scatter = np.std([f.model(probe) for f in fits], axis=0)
    band = np.mean([f.model.sigma(probe) for f in fits], axis=0)
    np.testing.assert_allclose(band / scatter, 1.0, atol=0.2)


def test_robust_fit_ignores_gross_outliers(true_deviation) -> None:
    """5% of pairs replaced by random headings: the Huber fit still recovers the curve."""
    h, ref = _pairs(true_deviation, 400, seed=2)
    rng = np.random.default_rng(3)
    bad = rng.random(h.size) < 0.05
    ref[bad] = rng.uniform(-np.pi, np.pi, bad.sum())
    robust = fit_deviation(h, ref, robust=True)
    plain = fit_deviation(h, ref, robust=False)
    assert _rms_deg(robust.model(GRID) - true_deviation(GRID)) < RECOVERY_RMS_DEG
    assert _rms_deg(plain.model(GRID) - true_deviation(GRID)) > 1.0  # what the outliers do unchecked
    assert np.all(~robust.inlier[bad])  # every bad pair is flagged
    assert np.sum(~robust.inlier) <= bad.sum() + 5
    assert robust.residual_rms_rad < math.radians(1.5 * NOISE_DEG)


def test_half_rose_runs_and_names_the_gap(true_deviation, caplog) -> None:
    """Headings only between 0 and 150 deg: the fit runs, names the empty sector and its band."""
    h = np.random.default_rng(4).uniform(0.0, math.radians(150.0), 200)
    h, ref = _pairs(true_deviation, 0, seed=4, headings=h)
    with caplog.at_level(logging.WARNING, logger="auvnav.compass.deviation"):
        fit = fit_deviation(h, ref)
    assert len(fit.gaps) == 1
    start, end = fit.gaps[0]
    assert math.degrees(start) == pytest.approx(150.0, abs=2.0)
    assert math.degrees(end) == pytest.approx(0.0, abs=2.0)
    assert fit.gap_sigma_rad[0] > 10.0 * np.max(fit.model.sigma(h))  # the band balloons there
    assert (
        f"no compass headings between {math.degrees(start):.0f} and {math.degrees(end) % 360:.0f} deg"
        in caplog.text
    )
    assert f"band there reaches {math.degrees(fit.gap_sigma_rad[0]):.2f} deg" in caplog.text
    # Where there was data, the fit is still good.
    assert _rms_deg(fit.model(h) - true_deviation(h)) < RECOVERY_RMS_DEG
    assert fit.summary()["gaps_deg"][0][0] == pytest.approx(math.degrees(start) % 360.0)


def test_fewer_samples_than_unknowns_is_one_line_error() -> None:
    h = np.radians([0.0, 60.0, 120.0, 180.0, 240.0])
    with pytest.raises(InsufficientDataError) as err:
        fit_deviation(h, h, harmonics=3)
    assert str(err.value) == (
        "a deviation fit with 3 harmonics has 7 unknowns but only 5 usable heading pairs"
    )


def test_too_few_distinct_headings() -> None:
    """Reciprocal legs only (two headings) cannot determine three harmonics."""
    h = np.repeat(np.radians([10.0, 190.0]), 50)
    with pytest.raises(InsufficientDataError, match="determine only 2 of the 7 unknowns"):
        fit_deviation(h, h)


def test_nan_pairs_are_ignored_with_a_warning(true_deviation, caplog) -> None:
    h, ref = _pairs(true_deviation, 300, seed=6)
    ref[:4] = np.nan
    with caplog.at_level(logging.WARNING, logger="auvnav.compass.deviation"):
        fit = fit_deviation(h, ref)
    assert "ignoring 4 of 300 pairs" in caplog.text
    assert fit.n_samples == 296 and np.all(np.isnan(fit.residuals_rad[:4]))
    assert not fit.inlier[:4].any()


def test_weights_zero_equals_dropping(true_deviation) -> None:
    h, ref = _pairs(true_deviation, 200, seed=7)
    w = np.ones_like(h)
    w[:20] = 0.0
    a = fit_deviation(h, ref, weights=w).model
    b = fit_deviation(h[20:], ref[20:]).model
    np.testing.assert_allclose(a.coefficients_rad, b.coefficients_rad, atol=1e-12)


def test_cross_validation_prefers_fewer_harmonics_for_simpler_curves() -> None:
    one = DeviationModel(0.0, np.radians([2.0]), np.radians([1.0]))
    fit = fit_deviation(*_pairs(one, 300, seed=8), harmonics=3)
    assert fit.cv_harmonics == 1
    assert fit.cv_rms_rad[1] == pytest.approx(math.radians(NOISE_DEG), rel=0.15)


def test_iron_deviation_is_a_three_harmonic_curve(scott_reef_field) -> None:
    """For a level vehicle with modest iron, eq. 5 with 3 harmonics fits the eq. 2-4 deviation.

    The correction at the measured heading is minus the error at the true heading (the paper's
    remark that the Fourier terms follow from hard and soft iron; Fig. 3).
    """
    f = scott_reef_field
    H = np.array([[0.04, 0.02, 0.0], [0.01, -0.03, 0.0], [0.0, 0.0, 0.0]])
    h_hard = np.array([0.05, -0.03, 0.0]) * f.horizontal_T
    psi = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    measured = wrap_angle(psi + deviation_from_iron(H, h_hard, f, psi))
    fit = fit_deviation(measured, psi, robust=False)
    assert fit.residual_rms_rad < math.radians(0.05)
    assert np.ptp(np.degrees(fit.observed_rad)) > 4.0  # a few degrees of deviation to begin with


def test_fix_constant_recovers_offset_holding_shape(true_deviation) -> None:
    """The paper's Fig. 5b: a SLAM fit with an arbitrary constant, then GPS transits fix it."""
    h, ref = _pairs(true_deviation, 400, seed=9)
    shape_only = fit_deviation(h, wrap_angle(ref - 1.0)).model  # constant off by ~57 deg
    transit_h = np.radians([20.0, 95.0, 200.0, 290.0, 340.0])
    rng = np.random.default_rng(10)
    cmg_minus_dr = true_deviation(transit_h) + rng.normal(0.0, math.radians(0.2), transit_h.size)
    fixed = fix_constant(shape_only, transit_h, cmg_minus_dr, weights=[2.0, 1.0, 1.0, 3.0, 1.0])
    assert fixed.constant_source == "gps-transits"
    np.testing.assert_array_equal(fixed.a_rad, shape_only.a_rad)  # shape held
    np.testing.assert_array_equal(fixed.b_rad, shape_only.b_rad)
    sigma0 = math.sqrt(fixed.covariance[0, 0])
    assert abs(fixed.a0_rad - true_deviation.a0_rad) < 3.0 * sigma0
    assert math.radians(0.02) < sigma0 < math.radians(0.5)
    np.testing.assert_allclose(fixed.covariance[1:, 1:], shape_only.covariance[1:, 1:])
    assert _rms_deg(fixed(GRID) - true_deviation(GRID)) < 0.3


def test_fix_constant_exact_data() -> None:
    """Transits that lie on the curve give its constant exactly, with the shape's uncertainty."""
    shape = DeviationModel(5.0, np.radians([1.0]), np.radians([-0.5]), covariance=np.diag([1.0, 1e-6, 1e-6]))
    h = np.radians([0.0, 120.0, 240.0])
    fixed = fix_constant(shape, h, 0.01 + shape(h) - 5.0)
    assert fixed.a0_rad == pytest.approx(0.01, abs=1e-12)
    g = fourier_design(h, 1)[:, 1:].mean(axis=0)
    assert fixed.covariance[0, 0] == pytest.approx(g @ np.diag([1e-6, 1e-6]) @ g, abs=1e-15)


def test_fix_constant_adds_the_common_error(true_deviation) -> None:
    """An error shared by every transit (the DVL's yaw mounting) adds to the constant's variance
    and nothing else; it cannot be negative."""
    h = np.radians([0.0, 90.0, 180.0, 270.0])
    y = true_deviation(h) + np.radians([0.1, -0.05, 0.02, 0.0])
    alone = fix_constant(true_deviation, h, y)
    common = math.radians(0.1)
    both = fix_constant(true_deviation, h, y, common_sigma_rad=common)
    assert both.a0_rad == alone.a0_rad
    assert both.covariance[0, 0] == pytest.approx(alone.covariance[0, 0] + common**2, rel=1e-12)
    np.testing.assert_array_equal(both.covariance[1:], alone.covariance[1:])
    with pytest.raises(ValueError, match="common_sigma_rad"):
        fix_constant(true_deviation, h, y, common_sigma_rad=-0.1)


def test_fix_constant_needs_two_transits(true_deviation) -> None:
    with pytest.raises(InsufficientDataError, match="at least 2 transits; got 1"):
        fix_constant(true_deviation, [0.1], [0.02])


@given(st.lists(st.floats(-np.pi, np.pi), min_size=1, max_size=40), st.floats(0.1, 3.0))
def test_gaps_are_empty_and_wide(headings: list[float], max_gap: float) -> None:
    gaps = heading_gaps(headings, max_gap)
    h = np.asarray(headings)
    for start, end in gaps:
        width = np.mod(end - start, 2 * np.pi) or 2 * np.pi
        assert width > max_gap - 1e-12
        inside = np.mod(h - start, 2 * np.pi)
        assert not np.any((inside > 1e-9) & (inside < width - 1e-9))
    # Every sector between neighbours wider than the threshold is reported.
    s = np.sort(np.mod(h, 2 * np.pi))
    widths = np.diff(np.append(s, s[0] + 2 * np.pi))
    assert len(gaps) == int(np.sum(widths > max_gap))


def test_angle_wrap_in_observations(true_deviation) -> None:
    """Pairs straddling +-180 deg are differenced on the circle, not across it."""
    h = np.radians(np.linspace(170.0, 190.0, 50))
    h = wrap_angle(np.concatenate([h, np.radians(np.linspace(0.0, 340.0, 150))]))
    fit = fit_deviation(*_pairs(true_deviation, 0, seed=11, headings=h))
    assert np.max(np.abs(fit.observed_rad)) < math.radians(10.0)
    assert np.all(np.abs(angle_diff(fit.model.correct(h), h)) < math.radians(10.0))


def test_fix_constant_along_a_dog_leg(true_deviation) -> None:
    """A transit that first runs back to its line measures the correction weighted along it.

    Leg 1 runs 16 m west then 300 m east: its steps project on the eastward course with weights
    -16/284 and 300/284 (they sum to one). Course differences built that way give the constant
    exactly; taking each leg at its final heading does not.
    """
    west, east = math.radians(-90.0), math.radians(90.0)
    headings = [np.array([west, east]), np.radians([0.0]), np.radians([180.0])]
    along = [np.array([-16.0, 300.0]) / 284.0, np.ones(1), np.ones(1)]
    y = np.array([w @ true_deviation(h) for h, w in zip(headings, along, strict=True)])
    shape = DeviationModel(0.0, true_deviation.a_rad, true_deviation.b_rad)
    fixed = fix_constant(shape, headings, y, heading_weights=along)
    assert fixed.a0_rad == pytest.approx(true_deviation.a0_rad, abs=1e-12)
    np.testing.assert_allclose(transit_deviation(fixed, headings, along), y, atol=1e-12)
    naive = fix_constant(shape, np.array([east, 0.0, np.pi]), y)
    # 16/284 of (delta(east) - delta(west)) = -1.6 deg, over three legs: 0.03 deg off.
    assert abs(naive.a0_rad - true_deviation.a0_rad) > math.radians(0.02)
    # One heading per transit with unit weight is the plain form.
    plain = fix_constant(shape, np.radians([10.0, 200.0]), [0.1, 0.2])
    listed = fix_constant(
        shape, [np.radians([10.0]), np.radians([200.0])], [0.1, 0.2], heading_weights=[[1.0], [1.0]]
    )
    assert listed.a0_rad == pytest.approx(plain.a0_rad, abs=1e-15)


def test_fix_constant_checks_heading_weights(true_deviation) -> None:
    with pytest.raises(ValueError, match="same transits"):
        fix_constant(true_deviation, [[0.1], [0.2]], [0.0, 0.0], heading_weights=[[1.0]])
    with pytest.raises(ValueError, match="transit 1: headings and weights must match"):
        fix_constant(true_deviation, [[0.1], [0.2, 0.3]], [0.0, 0.0], heading_weights=[[1.0], [1.0]])
    with pytest.raises(ValueError, match="positive sum"):
        fix_constant(true_deviation, [[0.1], [0.2]], [0.0, 0.0], heading_weights=[[1.0], [0.0]])
