"""Flown lines, their spacing and classification, and the prediction's physics (paper section I, Fig. 2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from auvnav.compass.deviation import DeviationModel
from auvnav.coverage.lines import match_lines, pair_spacing, runs_as_plan, straight_runs
from auvnav.coverage.plan import survey_plan
from auvnav.coverage.predict import (
    FootprintExtent,
    HeadingErrorPrior,
    compass_headings,
    predict_survey,
    propagate,
)
from auvnav.plan.missions import Ascend, Descend, Line, Mission, Surface, survey

DEG = math.pi / 180
SMALL = survey(width_m=40.0, height_m=4.0, spacing_m=1.0, lead_in_m=10.0)  # 5 lines of 40 m


def _errors(plan, north_rad: float, south_rad: float, other_rad: float = 0.0) -> np.ndarray:
    """Heading error per leg: by the leg's direction (north, south, anything else)."""
    out = []
    for leg in plan.legs:
        b = leg.bearing_rad
        out.append(north_rad if abs(b) < 0.1 else south_rad if abs(abs(b) - math.pi) < 0.1 else other_rad)
    return np.array(out)[None, :]


def _track(plan, e: np.ndarray, step_m: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Samples every ``step_m`` along the true legs (1 s apart): times and north-east positions."""
    start, end = propagate(plan, e)
    pts = []
    for k in range(len(plan.legs)):
        n = max(int(np.hypot(*(end[0, k] - start[0, k])) / step_m), 1)
        f = np.arange(n)[:, None] / n
        pts.append(start[0, k] + f * (end[0, k] - start[0, k]))
    p = np.concatenate(pts)
    return 1.25e9 + np.arange(len(p), dtype=float), p


def test_one_degree_over_100_m_is_about_two_metres() -> None:
    """The paper's arithmetic: 1 degree over a 100 m line is a 1.75 m arc (its 'approximately 2 m')."""
    mission = Mission("line", (Line(((0.0, 0.0), (100.0, 0.0))),))
    plan = survey_plan(mission)
    _, end = propagate(plan, np.array([[1.0 * DEG]]))
    assert end[0, 0, 1] == pytest.approx(100 * math.sin(DEG), rel=1e-12)
    assert end[0, 0, 0] == pytest.approx(100 * math.cos(DEG), rel=1e-12)


@pytest.mark.parametrize(("north_deg", "south_deg"), [(0.5, -0.5), (-0.4, 0.4), (0.7, 0.7), (0.0, 0.0)])
def test_reciprocal_errors_open_or_close_each_pair_by_length_times_their_difference(
    north_deg: float, south_deg: float
) -> None:
    """Each pair is a wedge hinged at its turn end; the far end opens by L x (e_N - e_S) (small angles):
    positive, an accordion; negative, a figure 8; a constant error only shears the survey."""
    plan = survey_plan(SMALL)
    e = _errors(plan, north_deg * DEG, south_deg * DEG)
    t, p = _track(plan, e)
    flown = match_lines(plan, t, p, min_line_m=10.0)
    assert [f.leg for f in flown] == list(plan.lines)
    pairs = pair_spacing(plan, flown, p, station_m=1.0, margin_m=2.0, tolerance_m=0.1)
    assert len(pairs) == 4
    opening = 40.0 * math.radians(north_deg - south_deg)
    for pair in pairs:
        valid = pair.valid
        s = pair.spacing_m[valid]
        far = s[0] if pair.pair.turn_end_at_end else s[-1]  # the end away from the turn
        turn = s[-1] if pair.pair.turn_end_at_end else s[0]
        span = pair.along_m[valid][-1] - pair.along_m[valid][0]
        assert far - turn == pytest.approx(opening * span / 40.0, abs=0.01)
        expected = "on plan" if abs(opening) <= 0.1 else ("accordion" if opening > 0 else "figure 8")
        assert pair.classification == expected


def test_without_a_mission_the_runs_are_the_lines() -> None:
    plan = survey_plan(SMALL)
    t, p = _track(plan, _errors(plan, 0.5 * DEG, -0.5 * DEG))
    runs_plan, flown = runs_as_plan(t, p, min_line_m=10.0)
    assert len(runs_plan.pairs) == 4  # the lead-in and first line run on as one; still 5 lines
    pairs = pair_spacing(runs_plan, flown, p, station_m=1.0, margin_m=2.0, tolerance_m=0.1, planned=False)
    assert all(q.classification == "accordion" for q in pairs)
    assert all(q.planned_m is None for q in pairs)


def test_straight_runs_break_at_turns_and_hovering() -> None:
    line = np.column_stack([np.arange(0, 20, 0.5), np.zeros(40)])
    back = np.column_stack([np.arange(20, 0, -0.5), np.ones(40)])
    hover = np.tile(back[-1], (10, 1))
    runs = straight_runs(np.concatenate([line, back, hover, line + np.array([0.0, 2.0])]), min_length_m=10.0)
    assert len(runs) == 3


def test_epochs_reset_the_error_at_each_surfacing() -> None:
    first, second = Line(((0.0, 0.0), (100.0, 0.0))), Line(((100.0, 0.0), (200.0, 0.0)))
    mission = Mission("two", (Surface(), Descend(), first, Ascend(), Surface(), Descend(), second))
    plan = survey_plan(mission)
    assert [leg.epoch for leg in plan.legs] == [0, 1]
    start, end = propagate(plan, np.array([[DEG, DEG]]))
    assert start[0, 1] == pytest.approx([100.0, 0.0])  # GPS put the vehicle back where it believed
    assert end[0, 1, 1] == pytest.approx(100 * math.sin(DEG))


def test_the_applied_correction_sets_the_compass_heading() -> None:
    plan = survey_plan(SMALL)
    model = DeviationModel(math.radians(2.0), np.zeros(1), np.zeros(1))
    prior = HeadingErrorPrior.from_correction(model, applied=True)
    h = compass_headings(plan, prior, declination_rad=math.radians(1.0))
    assert h[0] == pytest.approx(-math.radians(3.0))  # north = h + 2 deg correction + 1 deg declination


FOOTPRINT = FootprintExtent(forward_m=(-0.1, 0.9), right_m=(-0.61, 0.61))


def test_no_deviation_predicts_full_coverage_and_the_plan() -> None:
    pred = predict_survey(survey_plan(SMALL), HeadingErrorPrior.deviation_peak(0.0), FOOTPRINT, margin_m=2.0)
    s = pred.summary()
    assert pred.draws == 1 and s["p_gap"] == 0.0
    assert s["coverage_pct_mean"] == pytest.approx(100.0)
    assert s["spacing"]["mean_m"] == pytest.approx(1.0, abs=1e-9)
    assert s["pair_class_probability"]["on plan"] == 1.0
    assert any("current" in text for text in s["not_modelled"])


def test_gap_probability_grows_with_the_deviation() -> None:
    """A one-cycle deviation of unknown phase opens the pairs (accordion: gaps between the lines) for
    half the phases and closes them for the other half (figure 8: the survey falls short of its far
    side, not surveyed, no gap between the lines)."""
    plan = survey_plan(SMALL)
    preds = [
        predict_survey(
            plan,
            HeadingErrorPrior.deviation_peak(x * DEG),
            FOOTPRINT,
            draws=200,
            margin_m=2.0,
            gap_width_m=0.1,
        )
        for x in (0.05, 0.3, 2.0)
    ]
    p = [pred.p_gap for pred in preds]
    assert p[0] == 0.0 and p[0] <= p[1] <= p[2]
    assert 0.3 < p[2] < 0.6
    short = [float(pred.not_surveyed_m2.mean()) for pred in preds]
    assert short[0] < short[1] < short[2]


def test_deviation_peak_draws_have_that_peak() -> None:
    prior = HeadingErrorPrior.deviation_peak(0.5 * DEG)
    coef = prior.draw(np.random.default_rng(0), 50)
    assert np.hypot(coef[:, 1], coef[:, 2]) == pytest.approx(np.full(50, 0.5 * DEG))


def test_an_uncorrected_deviation_known_exactly_predicts_its_accordion() -> None:
    """A one-cycle deviation delta(h) = 0.5 deg cos h: +0.5 deg on the northward lines, -0.5 deg on the
    southward ones; flown uncorrected, every pair opens by 40 m x 1 deg = 0.70 m."""
    model = DeviationModel(0.0, np.array([0.5 * DEG]), np.array([0.0]))
    plan = survey_plan(SMALL)
    pred = predict_survey(
        plan,
        HeadingErrorPrior.from_correction(model, applied=False),
        FOOTPRINT,
        margin_m=0.0,
        gap_width_m=0.1,
    )
    for pair in pred.pairs:
        valid = np.isfinite(pair.mean_m)
        span = np.ptp(pair.along_m[valid])  # both lines' common stretch (38-40 m)
        opening = np.nanmax(pair.mean_m) - np.nanmin(pair.mean_m)
        assert opening == pytest.approx(span * math.radians(1.0), abs=0.005)
        assert pair.class_probability["accordion"] == 1.0
    assert pred.p_gap == 1.0
