"""The navigation stage on a dive folder: products, summary, the command and its bad inputs."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from auvnav.cli import main
from auvnav.compass.correction import write_correction
from auvnav.compass.deviation import DeviationModel
from auvnav.dive import write_dive
from auvnav.nav.stage import NavSettings
from auvnav.nav.synthetic import Motion, Noise, synthetic_dive
from auvnav.pipeline import run_stage
from auvnav.trajectory import read_trajectory

DEG = math.pi / 180.0
TRAJECTORY_COLUMNS = ["t", "north_m", "east_m", "down_m", "roll_deg", "pitch_deg", "yaw_deg"]
SIGMA_COLUMNS = ["sigma_north_m", "sigma_east_m", "sigma_down_m", "sigma_yaw_deg"]
INNOVATION_COLUMNS = [
    "t",
    "sensor",
    "innovation_north_m",
    "innovation_east_m",
    "sigma_north_m",
    "sigma_east_m",
    "cov_north_east_m2",
    "mahalanobis",
    "accepted",
    "reset",
]


@pytest.fixture
def dive_path(tmp_path: Path, transit: Motion) -> Path:
    t = transit.truth.t_s
    gps = np.concatenate([t[:100:5], t[-100::5]])
    dive = synthetic_dive(
        transit, gps_times_s=gps, noise=Noise(seed=11), compass_error_rad=3 * DEG, name="transit"
    )
    return write_dive(dive, tmp_path / "transit")


def test_navigate_writes_the_products(dive_path: Path, capsys) -> None:
    assert main(["navigate", str(dive_path)]) == 0
    out = capsys.readouterr().out
    assert "dive 'transit'" in out and "gps" in out and "innovations inside 2 sigma" in out
    nav = dive_path / "products/nav"
    assert sorted(p.name for p in nav.iterdir()) == [
        "cmg.csv",
        "dr.csv",
        "dr.tum",
        "filter.csv",
        "filter.tum",
        "innovations.csv",
        "stage.json",
        "summary.json",
    ]
    assert list(pd.read_csv(nav / "dr.csv").columns) == TRAJECTORY_COLUMNS
    assert list(pd.read_csv(nav / "filter.csv").columns) == TRAJECTORY_COLUMNS + SIGMA_COLUMNS
    innovations = pd.read_csv(nav / "innovations.csv")
    assert list(innovations.columns) == INNOVATION_COLUMNS and len(innovations) == 40
    filtered = read_trajectory(nav / "filter.csv")
    tum = np.loadtxt(nav / "filter.tum")
    np.testing.assert_allclose(tum[:, 1:4], filtered.p_ned_m, atol=1e-8)
    cmg = pd.read_csv(nav / "cmg.csv")
    assert len(cmg) == 1 and cmg["course_error_deg"][0] == pytest.approx(-3.0, abs=0.5)
    summary = json.loads((nav / "summary.json").read_text())
    assert summary["fixes"]["gps"]["n"] == 40 and summary["legs"] == 1


def test_navigate_json_and_rerun_replaces_products(dive_path: Path, capsys) -> None:
    assert main(["navigate", str(dive_path), "--json", "-q"]) == 0
    first = json.loads(capsys.readouterr().out)
    assert first["declination_source"] == "dive.yaml" and first["compass_correction"] is None
    assert first["end_fix"]["dr_error_m"] > 20.0  # 3 degrees over 600 m
    (dive_path / "products/nav/dr.csv").write_text("garbage\n")
    assert main(["navigate", str(dive_path), "--json", "-q"]) == 0
    assert json.loads(capsys.readouterr().out) == first
    assert list(pd.read_csv(dive_path / "products/nav/dr.csv").columns) == TRAJECTORY_COLUMNS


def test_compass_correction_option_applies_the_file(dive_path: Path, tmp_path: Path) -> None:
    correction = tmp_path / "correction.yaml"
    write_correction(DeviationModel.from_coefficients([-3 * DEG, 0.0, 0.0]), correction)
    summary = run_stage(dive_path, "nav", NavSettings(compass_correction=correction))
    assert summary["compass_correction"] == str(correction)
    assert summary["end_fix"]["dr_error_m"] < 10.0  # the fixes alone are 3 m (1 sigma per axis) off


def test_dive_without_attitude_fails_with_one_line(dive_path: Path, capsys) -> None:
    (dive_path / "nav/attitude.csv").unlink()
    assert main(["navigate", str(dive_path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nav/attitude.csv" in err[0] and "missing" in err[0]


def test_missing_correction_file_fails_with_one_line(dive_path: Path, tmp_path: Path, capsys) -> None:
    assert main(["navigate", str(dive_path), "--compass-correction", str(tmp_path / "nope.yaml")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nope.yaml" in err[0]


def test_dvl_invalid_for_a_minute_is_bridged_with_a_warning(tmp_path: Path, transit: Motion, capsys) -> None:
    valid = np.ones(len(transit.truth.t_s), dtype=bool)
    valid[1000:1300] = False
    path = write_dive(synthetic_dive(transit, dvl_valid=valid), tmp_path / "d")
    assert main(["navigate", str(path), "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["dvl_dropouts"]["count"] == 1
    warnings = [line for line in captured.err.splitlines() if line.startswith("WARNING")]
    assert len(warnings) == 1 and "bridged 1 dropout(s)" in warnings[0] and "60.2 s" in warnings[0]
