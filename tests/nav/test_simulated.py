"""Round trips through the simulator: small simulated missions navigated and scored against truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from auvnav.evaluate import evaluate_dive
from auvnav.pipeline import run_stage
from auvnav.sim.run import run_scenario
from auvnav.trajectory import read_trajectory


def _horizontal_end_error_m(path: Path, product: str) -> float:
    truth = read_trajectory(path / "truth/trajectory.csv")
    estimate = read_trajectory(path / "products/nav" / product)
    at = truth.interpolate(estimate.t_s[-1:])
    return float(np.hypot(*(estimate.p_ned_m[-1, :2] - at.p_ned_m[0, :2])))


def test_exact_transit_is_integrated_to_a_hundredth_of_a_percent(tmp_path: Path) -> None:
    """Every sensor error off: what remains is integration (the 10 Hz truth against 5 Hz DVL)."""
    path = tmp_path / "transit"
    geometry = {"legs": 1, "leg_m": 200.0, "heading_deg": 45.0}
    run_scenario("transit", path, seed=1, deviation="none", sensor_errors="none", geometry=geometry)
    summary = run_stage(path, "nav")
    assert summary["dvl_dropouts"]["count"] == 2  # descent from and ascent to the surface
    distance = evaluate_dive(path)["distance_m"]
    assert _horizontal_end_error_m(path, "dr.csv") < 1e-4 * distance


def test_survey_filter_is_consistent_and_beats_dead_reckoning(tmp_path: Path) -> None:
    """Default sensor errors and compass deviation, GPS before and after the dive."""
    path = tmp_path / "survey"
    geometry = {"width_m": 30.0, "height_m": 10.0, "spacing_m": 2.0, "lead_in_m": 20.0}
    run_scenario("survey", path, seed=2, geometry=geometry)
    summary = run_stage(path, "nav")
    assert summary["innovations_inside_2sigma"] >= 0.9
    scores = evaluate_dive(path)
    assert scores["filter"]["end_error_m"] < scores["dr"]["end_error_m"]
    assert _horizontal_end_error_m(path, "filter.csv") < _horizontal_end_error_m(path, "dr.csv")


def test_usbl_is_fused(tmp_path: Path) -> None:
    path = tmp_path / "usbl"
    run_scenario(
        "transit", path, seed=3, usbl=True, geometry={"legs": 1, "leg_m": 200.0, "heading_deg": 45.0}
    )
    summary = run_stage(path, "nav")
    assert summary["fixes"]["usbl"]["n"] > 10
    assert summary["innovations_inside_2sigma"] >= 0.9
