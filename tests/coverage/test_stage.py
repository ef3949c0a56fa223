"""The coverage stage, its commands and its evaluation on a small simulated survey."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from auvnav import products as P
from auvnav.cli import main
from auvnav.coverage.stage import CoverageSettings
from auvnav.evaluate import evaluate_dive
from auvnav.pipeline import run_stage
from auvnav.plan.missions import survey, write_mission
from auvnav.raster import read_geotiff
from auvnav.sim.camera import default_stereo_rig
from auvnav.sim.run import run_scenario
from auvnav.trajectory import read_trajectory, write_trajectory
from auvnav.vehicle import read_vehicle, write_vehicle

GEOMETRY = {"width_m": 20.0, "height_m": 3.0, "lead_in_m": 5.0}


@pytest.fixture(scope="module")
def dive(tmp_path_factory) -> tuple[Path, Path]:
    """A 4-line survey flown with the raw compass (its deviation opens the lines), with the camera's
    trigger log and calibration, navigated; and its mission file."""
    root = tmp_path_factory.mktemp("coverage")
    path = root / "survey"
    run_scenario("survey", path, seed=5, geometry=GEOMETRY, truth_loops=True)
    vehicle = read_vehicle(path / "vehicle.yaml")
    write_vehicle(dataclasses.replace(vehicle, stereo=default_stereo_rig()), path / "vehicle.yaml")
    mission = root / "survey.yaml"
    write_mission(survey(**GEOMETRY), mission)
    run_stage(path, "nav")
    return path, mission


def test_coverage_command_writes_every_product(dive, capsys) -> None:
    path, mission = dive
    assert main(["coverage", str(path), "--mission", str(mission), "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["trajectory"] == "filter"  # no SLAM: the filter, and it says so
    assert summary["region"] == "planned"
    assert summary["plan"]["area_m2"] == pytest.approx(60.0)
    for product in (P.COVERAGE_TIF, P.COVERAGE_PNG, P.COVERAGE_LINES, P.COVERAGE_SPACING, P.COVERAGE_GAPS):
        assert product.path(path).is_file(), product.rel
    bands, profile = read_geotiff(P.COVERAGE_TIF.path(path))
    assert profile["crs"].to_epsg() == 32751  # UTM 51 south: Scott Reef
    assert profile["dtype"] == "uint16" and bands.max() >= 2  # consecutive images overlap
    cells = summary["imaged_area_m2"] / summary["cell_area_m2"]
    assert np.count_nonzero(bands[0]) == pytest.approx(cells, rel=1e-9)
    image = cv2.imread(str(P.COVERAGE_PNG.path(path)))
    assert image is not None and image.shape[0] > 100
    lines = pd.read_csv(P.COVERAGE_LINES.path(path))
    assert len(lines) == summary["lines"]["pairs"] == 3
    assert set(lines["class"]) <= {"on plan", "accordion", "figure 8"}
    assert 0 < summary["coverage_pct"] <= 100
    assert summary["along_track_overlap"]["median"] == pytest.approx(
        0.5, abs=0.1
    )  # 0.5 m of a ~1 m footprint


def test_best_trajectory_is_slam_and_matches_the_truth(dive) -> None:
    """Footprints placed with the true poses as 'SLAM': the evaluation finds the truth's coverage (the
    floors differ: the DVL's altitude against the seafloor under the camera)."""
    path, mission = dive
    copy = path.parent / "survey-slam"
    if copy.exists():
        shutil.rmtree(copy)
    shutil.copytree(path, copy, ignore=shutil.ignore_patterns("coverage"))
    truth = read_trajectory(copy / "truth" / "trajectory.csv")
    index = pd.read_csv(copy / "images" / "index.csv")
    P.SLAM_TRAJECTORY.path(copy).parent.mkdir(parents=True, exist_ok=True)
    write_trajectory(truth.interpolate(index["t"].to_numpy()), P.SLAM_TRAJECTORY.path(copy))
    summary = run_stage(copy, "coverage", CoverageSettings(mission=mission))
    assert summary["trajectory"] == "slam"
    scores = evaluate_dive(copy)["coverage"]
    assert scores["coverage_pct"] == pytest.approx(scores["coverage_pct_true"], abs=1.0)
    assert scores["spacing_rmse_m"] < 0.005
    assert scores["pairs"] == 3 and scores["pairs_class_agreement"] == 1.0
    assert set(scores) >= {
        "coverage_pct",
        "coverage_pct_true",
        "gap_area_m2",
        "gap_area_true_m2",
        "spacing_rmse_m",
    }


def test_without_a_mission_the_flown_lines_bound_the_area(dive) -> None:
    path, _ = dive
    summary = run_stage(path, "coverage", CoverageSettings(mission=None, trajectory="dr"))
    assert summary["trajectory"] == "dr"
    assert summary["region"] == "flown lines"
    assert summary["lines"]["pairs"] >= 2 and summary["lines"]["planned_spacing_m"] is None


def test_a_dive_without_a_trigger_log_cannot_give_coverage(dive, capsys) -> None:
    path, mission = dive
    bare = path.parent / "bare"
    if bare.exists():
        shutil.rmtree(bare)
    shutil.copytree(path, bare, ignore=shutil.ignore_patterns("images"))
    assert main(["coverage", str(bare), "--mission", str(mission)]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("auvnav:")]
    assert len(err) == 1 and "images/index.csv" in err[0]


def test_a_missing_mission_file_is_one_line(dive, capsys) -> None:
    path, _ = dive
    assert main(["coverage", str(path), "--mission", str(path / "nope.yaml")]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("auvnav:")]
    assert len(err) == 1 and "nope.yaml" in err[0]


def test_predict_command_before_the_dive(dive, tmp_path, capsys) -> None:
    path, mission = dive
    vehicle = str(path / "vehicle.yaml")
    args = ["coverage", "predict", str(mission), "--vehicle", vehicle, "--line-margin-m", "2", "--json"]
    assert main([*args, "--deviation-peak-deg", "0"]) == 0
    none = json.loads(capsys.readouterr().out)
    assert none["p_gap"] == 0.0 and none["coverage_pct_mean"] == pytest.approx(100.0)
    assert none["footprint_width_m"] == pytest.approx(1.22, abs=0.03)
    out = tmp_path / "prediction.json"
    assert main([*args, "--deviation-peak-deg", "3", "--draws", "50", "--out", str(out)]) == 0
    big = json.loads(capsys.readouterr().out)
    assert big["draws"] == 50 and big["p_gap"] > 0.2  # the accordion's half of the phases
    assert big["coverage_pct_mean"] < 95 and big["not_surveyed_m2_mean"] > 0  # the figure 8's shortfall
    assert json.loads(out.read_text())["pairs"][0]["line_a"] == 0


@pytest.mark.parametrize(
    "extra",
    [
        [],  # neither a correction nor a deviation
        ["--deviation-peak-deg", "1", "--compass-correction", "c.yaml"],  # both
        ["--deviation-peak-deg", "1", "--uncorrected"],  # --uncorrected without a correction
    ],
)
def test_predict_needs_one_heading_error(dive, extra: list[str]) -> None:
    _, mission = dive
    assert main(["coverage", "predict", str(mission), "--footprint-width-m", "1.2", *extra]) == 2


def test_predict_with_a_missing_mission_is_one_line(tmp_path, capsys) -> None:
    code = main(
        [
            "coverage",
            "predict",
            str(tmp_path / "m.yaml"),
            "--deviation-peak-deg",
            "1",
            "--footprint-width-m",
            "1",
        ]
    )
    assert code == 1
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
