"""Round trips through the simulator: small simulated missions navigated and scored against truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from auvnav.dive import read_dive
from auvnav.evaluate import evaluate_dive
from auvnav.nav.inputs import nav_inputs, smooth_tilt
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


def test_the_tilt_sensors_white_noise_is_smoothed_away_and_the_vehicles_pitching_kept(tmp_path: Path) -> None:
    """The simulator's tilt sensor: 0.2 deg of white noise at 10 Hz on a vehicle that pitches and
    rolls. The navigated pitch and roll at the DVL's samples are within half of that of the truth."""
    path = tmp_path / "navcheck"
    run_scenario("navcheck", path, seed=3, geometry={"headings": 2, "leg_m": 20.0, "grid_m": 4.0})
    dive = read_dive(path)
    inputs = nav_inputs(dive)
    truth = read_trajectory(path / "truth/trajectory.csv").interpolate(inputs.t_s)
    att = dive.attitude
    errors = {
        "smoothed": (inputs.pitch_rad, inputs.roll_rad),
        "measured": (
            np.interp(inputs.t_s, att.t_s, att.pitch_rad),
            np.interp(inputs.t_s, att.t_s, att.roll_rad),
        ),
    }
    sigma = dive.vehicle.pitch_roll_sigma_rad
    rms = {
        k: [np.sqrt(np.mean((e - t) ** 2)) for e, t in zip(v, (truth.pitch_rad, truth.roll_rad), strict=True)]
        for k, v in errors.items()
    }
    assert all(0.8 * sigma < r < 1.2 * sigma for r in rms["measured"]), rms
    assert all(r < 0.6 * sigma for r in rms["smoothed"]), rms
    assert np.ptp(truth.pitch_rad) > 20 * sigma  # the vehicle does pitch: a mean would not do


def test_tilt_is_smoothed_within_each_stretch_and_a_coarse_record_kept() -> None:
    rng = np.random.default_rng(0)
    t = np.concatenate([np.arange(0.0, 20.0, 0.1), np.arange(60.0, 80.0, 0.1)])
    true = np.where(t < 40, 0.05 * np.sin(t), -0.3)  # a step across the gap
    noisy = true + rng.normal(0.0, 0.0035, len(t))
    smooth = smooth_tilt(t, noisy)
    assert np.std(smooth - true) < 0.5 * np.std(noisy - true)
    assert abs(smooth[t > 60][:5].mean() + 0.3) < 0.003  # no smoothing across the gap
    coarse = t[::20]  # 0.5 Hz: fewer than 5 samples in a window
    assert np.allclose(smooth_tilt(coarse, noisy[::20]), noisy[::20], rtol=0.0, atol=1e-12)
