"""The compass fit from dives (issue 5): heading pairs, the shape against the simulator's true curve,
the constant from GPS course made good on transits, the single-dive variant, and the command."""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from auvnav.cli import main
from auvnav.compass.correction import read_correction, write_correction
from auvnav.compass.deviation import DeviationModel, fit_deviation
from auvnav.compass.evaluate import compass_section, read_true_deviation
from auvnav.compass.field import magnetic2true
from auvnav.compass.fit import (
    DVL_YAW_SIGMA_DEG,
    HeadingPairs,
    fit_compass,
    heading_pairs,
    smooth_surface_fixes,
)
from auvnav.dive import Dive, GpsStream
from auvnav.frames import euler2rot, geodetic2ned, ned2geodetic, wrap_angle
from auvnav.nav.deadreckon import dead_reckon
from auvnav.nav.inputs import nav_inputs
from auvnav.nav.synthetic import Noise, legs_motion, synthetic_dive
from auvnav.trajectory import Trajectory, read_trajectory, write_trajectory
from auvnav.vehicle import Mount

# The small navcheck (8 arms of 15 m, ~570 pairs at 8 headings) against the 0.1 degree RMS
# on the default one (12 arms of 50 m): a looser bound for the smaller dive.
SHAPE_RMS_DEG = 0.15
SHAPE_MAX_DEG = 0.3
# Truth as the reference gives the true constant, up to the pairs' noise (0.2 deg over ~570 pairs).
TRUTH_CONSTANT_DEG = 0.05
# Four legs of 300 m between surface stays of two minutes of 3 m GPS fixes (1 sigma), smoothed: 0.54 m
# at each end of a leg, 0.15 deg of course noise per leg and 0.07 deg on the constant, plus the
# DVL's yaw misalignment (0.1 deg, 1 sigma); the bound is about three times that.
TRANSIT_CONSTANT_DEG = 0.35


def _fit_json(capsys, *args: str) -> dict:
    capsys.readouterr()
    assert main(["compass", "fit", *args, "--json", "-q"]) == 0
    return json.loads(capsys.readouterr().out)


def _one_line_error(capsys, *args: str) -> str:
    capsys.readouterr()
    assert main(["compass", *args, "-q"]) == 1
    errors = [line for line in capsys.readouterr().err.splitlines() if line.startswith("auvnav: error: ")]
    assert len(errors) == 1
    return errors[0]


# --- heading pairs ----------------------------------------------------------------------------


def test_pairs_turn_the_reference_into_the_compass_frame_and_magnetic(small_dive) -> None:
    """reference - compass is the correction: body yaw through the compass mount, less declination.

    The reference is built so that the true magnetic heading of the compass is compass + 0.02 rad
    with the compass mounted 0.01 rad to starboard: every pair observes exactly 0.02 rad. The first
    10 s are at the surface and counted.
    """
    dive: Dive = small_dive(seconds=60.0)
    mount = Mount(R_body_sensor=euler2rot(0.01, 0.0, 0.0))
    dive = Dive(**{**dive.__dict__, "vehicle": type(dive.vehicle)(name="m", compass=mount)})
    att = dive.attitude
    body_yaw = magnetic2true(att.heading_rad + 0.02, dive.info.declination_rad) - 0.01
    depth = np.where(att.t_s - att.t_s[0] < 10.0, 0.5, 20.0)
    reference = Trajectory(
        t_s=att.t_s,
        p_ned_m=np.column_stack([np.zeros_like(depth), np.zeros_like(depth), depth]),
        roll_rad=np.zeros_like(depth),
        pitch_rad=np.zeros_like(depth),
        yaw_rad=wrap_angle(body_yaw),
    )
    pairs = heading_pairs(dive, reference, max_turn_rate_rad_s=0.1)  # the circle turns 0.05 rad/s
    observed = wrap_angle(pairs.reference_heading_rad - pairs.compass_heading_rad)
    np.testing.assert_allclose(observed, 0.02, atol=1e-9)
    assert pairs.candidates == 60 and pairs.surface == 10 and pairs.turning == 0 and len(pairs) == 50
    steady = heading_pairs(dive, reference)  # 2 deg/s: the 2.9 deg/s circle is all turning
    assert len(steady) == 0 and steady.turning == 50
    pooled = HeadingPairs.concatenate([pairs, pairs])
    assert len(pooled) == 100 and pooled.dives == ("small", "small") and set(pooled.dive_index) == {0, 1}


# --- surface fixes smoothed through dead reckoning ------------------------------------------------

STAY_FIXES = 120  # two minutes of 1 Hz fixes, as the simulator's surface waits


@pytest.fixture(scope="module")
def two_stays():
    """A 1 km leg at 030 (2 Hz) with two minutes of 3 m GPS fixes at each end, its dead reckoning
    and the fixes' antenna positions in local NED."""
    motion = legs_motion([(math.radians(30.0), 1000.0)], rate_hz=2.0)
    t = motion.truth.t_s
    gps_t = np.concatenate([t[0] + np.arange(STAY_FIXES), t[-1] - np.arange(STAY_FIXES)[::-1]])
    dive = synthetic_dive(motion, gps_times_s=gps_t, noise=Noise(seed=11))
    dr = dead_reckon(nav_inputs(dive))
    return motion, dive, dr


def _fixes_ned(dive: Dive) -> np.ndarray:
    g = dive.gps
    return geodetic2ned(g.latitude_rad, g.longitude_rad, np.zeros(len(g)), dive.info.origin)[:, :2]


def test_smoothed_fixes_are_closer_to_the_truth(two_stays) -> None:
    """Each stay's fixes follow the dead reckoning about a fitted line: the error of the fixes
    shrinks by about sqrt(n), and each sigma is the line's at its time."""
    motion, dive, dr = two_stays
    smoothed = smooth_surface_fixes(dive, dr)
    true = motion.truth.interpolate(dive.gps.t_s).p_ned_m[:, :2]
    raw_rms = np.sqrt(np.mean((_fixes_ned(dive) - true) ** 2))
    smooth_rms = np.sqrt(np.mean((_fixes_ned(smoothed) - true) ** 2))
    assert 2.5 < raw_rms < 3.5 and smooth_rms < 0.25 * raw_rms
    dt = np.arange(STAY_FIXES) - (STAY_FIXES - 1) / 2.0
    end_sigma = 3.0 * math.sqrt(1.0 / STAY_FIXES + dt[-1] ** 2 / float(dt @ dt))  # 0.54 m
    assert smoothed.gps.sigma_m[0] == pytest.approx(end_sigma) == smoothed.gps.sigma_m[-1]
    np.testing.assert_array_equal(smoothed.gps.t_s, dive.gps.t_s)
    assert smoothed.dvl is dive.dvl and dive.gps.sigma_m[0] == 3.0  # a copy; the input is unchanged


def test_smoothing_follows_a_drift_the_dead_reckoning_misses(two_stays) -> None:
    """A steady 5 cm/s drift of the fixes within each stay (a surface current without bottom lock)
    is followed to the stay's end, where a plain mean of the offsets would be 3 m off."""
    motion, dive, dr = two_stays
    g = dive.gps
    stay_start = np.where(np.arange(len(g)) < STAY_FIXES, g.t_s[0], g.t_s[STAY_FIXES])
    p = geodetic2ned(g.latitude_rad, g.longitude_rad, np.zeros(len(g)), dive.info.origin)
    p[:, 0] += 0.05 * (g.t_s - stay_start)
    lat, lon, _ = ned2geodetic(p, dive.info.origin)
    drifting = dataclasses.replace(dive, gps=GpsStream(g.t_s, lat, lon, g.sigma_m))
    smoothed = _fixes_ned(smooth_surface_fixes(drifting, dr))
    true = motion.truth.interpolate(g.t_s).p_ned_m[:, :2]
    true[:, 0] += 0.05 * (g.t_s - stay_start)
    ends = [STAY_FIXES - 1, STAY_FIXES]  # the ends of the leg between the stays
    assert np.all(np.linalg.norm(smoothed[ends] - true[ends], axis=1) < 1.0)


def test_short_stays_are_kept(two_stays) -> None:
    """Stays of fewer than three fixes are left as they are."""
    motion, _dive, dr = two_stays
    t = motion.truth.t_s
    dive = synthetic_dive(motion, gps_times_s=np.array([t[0], t[1], t[-1]]), noise=Noise(seed=12))
    smoothed = smooth_surface_fixes(dive, dr)
    np.testing.assert_array_equal(smoothed.gps.latitude_rad, dive.gps.latitude_rad)
    np.testing.assert_array_equal(smoothed.gps.sigma_m, dive.gps.sigma_m)


# --- the fit from simulated dives ----------------------------------------------------------------


@pytest.fixture(scope="module")
def truth_fit(simulated, tmp_path_factory) -> tuple[dict, Path]:
    out = tmp_path_factory.mktemp("fit") / "truth.yaml"
    return _fit_json_module(str(simulated.navcheck), "--reference", "truth", "--out", str(out)), out


def _fit_json_module(*args: str) -> dict:
    """``compass fit --json`` outside a test's capsys (module fixtures)."""
    import contextlib
    import io

    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        assert main(["compass", "fit", *args, "--json", "-q"]) == 0
    return json.loads(buffer.getvalue())


def test_navcheck_fit_matches_true_curve(simulated, truth_fit) -> None:
    summary, out = truth_fit
    score = compass_section(simulated.navcheck, out)
    assert score["shape_rmse_deg"] <= SHAPE_RMS_DEG and score["shape_max_error_deg"] <= SHAPE_MAX_DEG
    assert abs(score["constant_error_deg"]) <= TRUTH_CONSTANT_DEG
    assert score["constant_source"] == "truth" and score["constant_included"]
    p = summary["pairs"]
    assert p["used"] > 400 and p["surface"] > 0 and p["turning"] > 0
    assert p["used"] + p["surface"] + p["turning"] + p["outside_reference"] == p["candidates"]
    assert summary["gaps_deg"] == []  # 8 arms and the grid: no sector wider than 60 deg
    doc = yaml.safe_load(out.read_text())
    assert doc["constant"]["source"] == "truth"
    assert doc["fit"] == {"reference": "truth", "dives": ["navcheck"], "pairs": p["used"]}
    assert out.with_suffix(".png").stat().st_size > 10_000


def test_constant_from_small_transits(simulated, truth_fit, tmp_path: Path, capsys) -> None:
    """The constant from GPS course made good with the shape held (paper Fig. 5b)."""
    out = tmp_path / "c.yaml"
    summary = _fit_json(
        capsys,
        str(simulated.navcheck),
        "--reference",
        "truth",
        "--transits",
        str(simulated.transit),
        "--out",
        str(out),
    )
    c = summary["constant"]
    assert c["source"] == "gps-transits" and c["legs"] == 4 and c["dives"] == ["transit"]
    assert c["dvl_yaw_sigma_deg"] == pytest.approx(DVL_YAW_SIGMA_DEG) and c["sigma_deg"] > DVL_YAW_SIGMA_DEG
    assert all(leg["course_sigma_deg"] < 0.2 for leg in summary["legs"])  # smoothed fixes: 0.15 deg
    assert all(leg["used"] for leg in summary["legs"])
    headings = sorted(leg["heading_deg"] for leg in summary["legs"])
    assert np.allclose(np.diff(headings), 90.0, atol=5.0)  # the four legs of the square
    score = compass_section(simulated.navcheck, out)
    assert abs(score["constant_error_deg"]) <= min(TRANSIT_CONSTANT_DEG, 3.0 * c["sigma_deg"])
    assert score["constant_included"] and score["deviation_rmse_deg"] >= score["shape_rmse_deg"]
    fixed, shape = read_correction(out), read_correction(truth_fit[1])
    np.testing.assert_allclose(fixed.a_rad, shape.a_rad, atol=1e-9)  # the shape is held
    np.testing.assert_allclose(fixed.b_rad, shape.b_rad, atol=1e-9)
    doc = yaml.safe_load(out.read_text())
    assert doc["constant"]["legs"] == 4 and doc["constant"]["dives"] == ["transit"]


def test_single_dive_gives_shape_and_constant(simulated, tmp_path: Path) -> None:
    """The paper's future work: one dive with long legs between GPS fixes gives both.

    The reference is the truth with its heading turned by 5 degrees, as a relative reference
    (SLAM) may be: the shape fit's constant is then off by 5 degrees, and the dive's own legs fix it.
    Four legs fly four headings, enough for one harmonic.
    """
    truth = read_trajectory(simulated.transit / "truth" / "trajectory.csv")
    truth = truth.select(np.arange(len(truth.t_s)) % 5 == 0)  # 2 Hz is plenty for 1 Hz pairs
    turned = Trajectory(
        truth.t_s,
        truth.p_ned_m,
        truth.roll_rad,
        truth.pitch_rad,
        wrap_angle(truth.yaw_rad + math.radians(5.0)),
    )
    reference = tmp_path / "turned.csv"
    write_trajectory(turned, reference)

    shape_only = fit_compass([simulated.transit], reference=str(reference), harmonics=1)
    assert shape_only.fit.model.constant_source == "arbitrary"
    both = fit_compass(
        [simulated.transit], reference=str(reference), transits=[simulated.transit], harmonics=1
    )
    assert both.fit.model.constant_source == "gps-transits" and len(both.used_legs) == 4
    h = np.radians(np.arange(360.0))
    true = np.radians(pd.read_csv(simulated.transit / "truth" / "deviation.csv")["deviation_deg"].to_numpy())
    assert math.degrees(np.mean(shape_only.fit.model(h) - true)) == pytest.approx(5.0, abs=0.1)
    assert abs(math.degrees(np.mean(both.fit.model(h) - true))) <= TRANSIT_CONSTANT_DEG


def test_dives_are_pooled(simulated, truth_fit) -> None:
    """Two dives' pairs are fitted together; the transit's four headings add to the navcheck's."""
    pooled = fit_compass([simulated.navcheck, simulated.transit], reference="truth")
    assert pooled.pairs.dives == ("navcheck", "transit")
    navcheck = pooled.pairs.dive_index == 0
    assert np.count_nonzero(navcheck) == truth_fit[0]["pairs"]["used"] and np.count_nonzero(~navcheck) > 1000
    assert np.all(np.diff(pooled.pairs.t_s[~navcheck]) > 0)  # the transit's own pairs, in time order
    assert pooled.fit.n_samples == len(pooled.pairs)


# --- the command's bad input -----------------------------------------------------------------------


def test_slam_reference_missing_is_one_line(simulated, tmp_path: Path, capsys) -> None:
    """``--reference slam`` is the default: a dive without SLAM products says to run ``auvnav slam``."""
    line = _one_line_error(capsys, "fit", str(simulated.navcheck), "--out", str(tmp_path / "c.yaml"))
    assert "products/slam/trajectory.csv: not found" in line and "run `auvnav slam" in line
    line = _one_line_error(capsys, "fit", str(simulated.navcheck), "--reference", "nowhere.csv")
    assert "nowhere.csv: --reference is neither truth, slam nor a trajectory file" in line


def test_no_silent_overwrite(truth_fit, simulated, capsys) -> None:
    line = _one_line_error(
        capsys, "fit", str(simulated.navcheck), "--reference", "truth", "--out", str(truth_fit[1])
    )
    assert "exists (use --overwrite to replace it)" in line


@pytest.fixture(scope="module")
def spin_window(simulated) -> tuple[Trajectory, np.ndarray]:
    """The spin's truth and the times when it turns (over 3 deg/s, submerged)."""
    truth = read_trajectory(simulated.spin / "truth" / "trajectory.csv")
    rate = np.abs(np.gradient(np.unwrap(truth.yaw_rad), truth.t_s))
    return truth, np.flatnonzero((rate > math.radians(3.0)) & (truth.p_ned_m[:, 2] > 1.0))


def _window_reference(truth: Trajectory, rows: np.ndarray, path: Path) -> Path:
    write_trajectory(truth.select(np.isin(np.arange(len(truth.t_s)), rows)), path)
    return path


def test_half_rose_runs_and_names_the_gap(simulated, spin_window, tmp_path: Path, capsys) -> None:
    """A reference over 30 s of the 5 deg/s spin: 150 degrees of the rose. The fit runs, and says
    which sector is empty and how wide the band grows there."""
    truth, turning = spin_window
    reference = _window_reference(truth, turning[: 30 * 10], tmp_path / "part.csv")
    args = [str(simulated.spin), "--reference", str(reference), "--max-turn-rate-deg-s", "10"]
    summary = _fit_json(capsys, *args, "--out", str(tmp_path / "c.yaml"))
    assert 25 <= summary["pairs"]["used"] <= 31
    ((start, end),) = summary["gaps_deg"]
    assert 200.0 <= (end - start) % 360.0 <= 215.0
    assert summary["gap_sigma_deg"][0] > 10.0 * summary["residual_rms_deg"]
    capsys.readouterr()
    assert main(["compass", "fit", *args, "--out", str(tmp_path / "d.yaml"), "-q"]) == 0
    out = capsys.readouterr().out
    assert f"no compass headings from {start:.0f} to {end:.0f} deg" in out and "1-sigma band reaches" in out


def test_fewer_pairs_than_unknowns_is_one_line(simulated, spin_window, tmp_path: Path, capsys) -> None:
    truth, turning = spin_window
    reference = _window_reference(truth, turning[: 5 * 10], tmp_path / "short.csv")
    line = _one_line_error(
        capsys,
        "fit",
        str(simulated.spin),
        "--reference",
        str(reference),
        "--max-turn-rate-deg-s",
        "10",
        "--out",
        str(tmp_path / "c.yaml"),
    )
    assert "7 unknowns but only 5 usable heading pairs" in line


def test_transits_without_usable_legs_is_one_line(simulated, tmp_path: Path, capsys) -> None:
    """A spin has one sub-sea leg, a few metres long: it cannot fix the constant."""
    line = _one_line_error(
        capsys,
        "fit",
        str(simulated.navcheck),
        "--reference",
        "truth",
        "--transits",
        str(simulated.spin),
        "--out",
        str(tmp_path / "c.yaml"),
    )
    assert "--transits: 0 usable sub-sea legs of 1" in line


# --- evaluate ----------------------------------------------------------------------------------------


def test_evaluate_scores_the_correction(simulated, truth_fit, capsys) -> None:
    capsys.readouterr()
    assert (
        main(["evaluate", str(simulated.navcheck), "--compass-correction", str(truth_fit[1]), "--json"]) == 0
    )
    section = json.loads(capsys.readouterr().out)["compass"]
    assert {"deviation_rmse_deg", "deviation_max_error_deg"} <= section.keys()
    assert section == compass_section(simulated.navcheck, truth_fit[1])
    assert section["deviation_rmse_deg"] <= SHAPE_RMS_DEG


def test_evaluate_leaves_out_an_arbitrary_constant(simulated, tmp_path: Path) -> None:
    """An arbitrary constant is reported, not scored; a fixed one is scored."""
    h, delta = read_true_deviation(simulated.navcheck)
    exact = fit_deviation(h, wrap_angle(h + delta), harmonics=6, robust=False).model
    for source, scored_deg in (("arbitrary", 0.0), ("truth", 3.0)):
        path = tmp_path / f"{source}.yaml"
        shifted = DeviationModel(
            exact.a0_rad + math.radians(3.0), exact.a_rad, exact.b_rad, constant_source=source
        )
        write_correction(shifted, path)
        score = compass_section(simulated.navcheck, path)
        assert score["constant_error_deg"] == pytest.approx(3.0, abs=0.01)
        assert score["shape_rmse_deg"] < 0.01
        assert score["deviation_rmse_deg"] == pytest.approx(
            max(scored_deg, score["shape_rmse_deg"]), abs=0.01
        )
        assert score["constant_included"] == (source == "truth")


def test_default_output_is_a_product_that_evaluate_finds(simulated, tmp_path: Path, capsys) -> None:
    dive = tmp_path / "navcheck"
    shutil.copytree(simulated.navcheck, dive)
    summary = _fit_json(capsys, str(dive), "--reference", "truth")
    assert summary["correction"] == str(dive / "products" / "compass" / "correction.yaml")
    assert summary["figure"] == str(dive / "products" / "report" / "figures" / "fig5_compass.png")
    assert (dive / "products" / "report" / "figures" / "fig5_compass.png").is_file()
    capsys.readouterr()
    assert main(["evaluate", str(dive), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["compass"]["constant_source"] == "truth"


def test_missing_true_deviation_is_one_line(simulated, truth_fit, tmp_path: Path, capsys) -> None:
    dive = tmp_path / "navcheck"
    shutil.copytree(simulated.navcheck, dive)
    (dive / "truth" / "deviation.csv").unlink()
    capsys.readouterr()
    assert main(["evaluate", str(dive), "--compass-correction", str(truth_fit[1])]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "truth/deviation.csv: not found" in err[0]
