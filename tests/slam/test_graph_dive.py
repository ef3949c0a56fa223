"""SLAM on a small simulated navigation check dive with loop closures from its truth: consistency
against dead reckoning, false loop closures rejected, the deviation estimated in the graph, iSAM2
against batch, the products, and bad input as one-line errors."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from auvnav.cli import main
from auvnav.compass.correction import read_correction, write_correction
from auvnav.compass.deviation import DeviationModel
from auvnav.compass.evaluate import compass_section, read_true_deviation
from auvnav.dive import read_dive
from auvnav.evaluate import evaluate_dive, read_truth, score_trajectory
from auvnav.nav.deadreckon import dead_reckon
from auvnav.nav.inputs import nav_inputs
from auvnav.pipeline import run_stage
from auvnav.sim.truthloops import write_truth_loops
from auvnav.slam.g2o import read_g2o
from auvnav.slam.graph import SlamOptions
from auvnav.slam.result import slam
from auvnav.slam.stage import SlamSettings
from auvnav.trajectory import read_trajectory
from auvnav.vision.loopfile import read_loops

# A navigation check small enough for a test: 4 arms of 8 m and a 2 m grid, about 13 minutes.
GEOMETRY = ["--headings", "4", "--leg-m", "8", "--grid-m", "2"]


@pytest.fixture(scope="module")
def dive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The dive, with truth loops of which a fifth are false (truth/loops.csv) and clean ones."""
    out = tmp_path_factory.mktemp("slam") / "navcheck"
    args = ["simulate", "navcheck", "--out", str(out), "--seed", "2", *GEOMETRY, "--no-images"]
    assert main([*args, "--truth-loops", "--false-loops", "0.2", "-q", "--json"]) == 0
    write_truth_loops(out, seed=2, out=out / "truth" / "clean.csv")
    return out


@pytest.fixture(scope="module")
def batch(dive: Path) -> dict:
    """``auvnav slam`` with the false loop closures (Cauchy kernel, batch)."""
    args = ["slam", str(dive), "--loops", str(dive / "truth" / "loops.csv"), "--marginal-every", "5"]
    assert main([*args, "--json", "-q"]) == 0
    products = dive / "products" / "slam"
    return {
        "summary": json.loads((products / "summary.json").read_text(encoding="utf-8")),
        "trajectory": read_trajectory(products / "trajectory.csv"),
        "scores": evaluate_dive(dive)["slam"],
    }


def test_false_loop_closures_are_rejected(dive: Path, batch: dict) -> None:
    info = yaml.safe_load((dive / "truth" / "loops.yaml").read_text(encoding="utf-8"))
    false = set(info["false_rows"])
    rejected = set(batch["summary"]["loops"]["rejected_rows"])
    assert len(false) > 50
    assert false <= rejected
    assert len(rejected - false) < 0.05 * (info["loops"] - len(false))  # a few true ones (chi2 tail)


def test_slam_is_consistent_where_dead_reckoning_is_not(dive: Path, batch: dict) -> None:
    """Aligned ATE: centimetres for SLAM, decimetres for dead reckoning (its compass is uncorrected)."""
    truth = read_truth(dive)
    dr = dead_reckon(nav_inputs(read_dive(dive)))
    dr_score = score_trajectory(truth, dr, truth.distance_m())
    slam_score = batch["scores"]
    assert slam_score["ate_aligned_rmse_m"] < 0.05
    assert slam_score["ate_aligned_rmse_m"] < dr_score.ate_aligned_rmse_m / 5


def test_products(dive: Path, batch: dict) -> None:
    summary, traj = batch["summary"], batch["trajectory"]
    times = read_dive(dive).images.t_s
    np.testing.assert_allclose(traj.t_s, times)  # one pose per stereo pair
    assert traj.sigma_ned_m is not None and traj.sigma_yaw_rad is not None
    assert np.all((traj.sigma_ned_m > 0) & (traj.sigma_ned_m < 5.0))
    assert np.all(np.isfinite(traj.sigma_yaw_rad))
    graph = read_g2o(dive / "products" / "slam" / "graph.g2o")
    assert graph.n_poses == summary["poses"]
    assert graph.n_edges == summary["poses"] - 1 + summary["loops"]["used"]
    tum = np.loadtxt(dive / "products" / "slam" / "trajectory.tum")
    np.testing.assert_allclose(tum[:, 1:4], traj.p_ned_m, atol=1e-6)
    assert summary["factors"]["compass"] == summary["poses"]
    assert summary["factors"]["gps"] > 0
    assert summary["cost_after"] < summary["cost_before"]


def test_incremental_agrees_with_batch(dive: Path, batch: dict) -> None:
    d = read_dive(dive)
    times = d.images.t_s
    loops = read_loops(dive / "truth" / "loops.csv", n_poses=len(times))
    result = slam(d, times, loops=loops, options=SlamOptions(incremental=True, marginal_every=0))
    assert result.solution.method == "isam2"
    difference = result.trajectory.p_ned_m - batch["trajectory"].p_ned_m
    assert np.sqrt(np.mean(np.sum(difference**2, axis=1))) < 0.02
    info = yaml.safe_load((dive / "truth" / "loops.yaml").read_text(encoding="utf-8"))
    assert set(info["false_rows"]) <= set((result.solution.rejected + 1).tolist())


def test_estimated_deviation_matches_the_true_curve(dive: Path) -> None:
    """--estimate-compass with no reference heading: the deviation's shape within 0.15 deg RMS on this
    13-minute dive (the full navigation check's acceptance is 0.1 deg; benchmarks/bench_slam_dive.py)."""
    settings = SlamSettings(
        loops=dive / "truth" / "clean.csv", estimate_compass=True, robust="none", marginal_every=50
    )
    summary = run_stage(dive, "slam", settings)
    assert summary["compass"]["mode"] == "estimated"
    path = dive / "products" / "slam" / "correction.yaml"
    scores = compass_section(dive, path)
    _, delta = read_true_deviation(dive)
    assert np.degrees(np.std(delta)) > 0.8  # there is a deviation to find
    assert scores["shape_rmse_deg"] < 0.15
    assert read_correction(path).covariance is not None


def _errors(capsys: pytest.CaptureFixture[str]) -> list[str]:
    """The error lines on stderr (warnings about the dive's DVL dropouts aside)."""
    return [line for line in capsys.readouterr().err.splitlines() if line.startswith("auvnav: error:")]


def _bad(dive: Path, tmp_path: Path, edit: str) -> tuple[Path, int]:
    """A copy of the clean loop file with one row broken; the path and the 1-based row."""
    frame = pd.read_csv(dive / "truth" / "clean.csv")
    row = 7
    if edit == "pose":
        frame.loc[row - 1, "j"] = 100000
    elif edit == "self":
        frame.loc[row - 1, "j"] = frame.loc[row - 1, "i"]
    elif edit == "covariance":
        frame.loc[row - 1, "cov00"] = -1e-4
    else:
        frame.loc[row - 1, "t_i"] += 5.0
    path = tmp_path / f"{edit}.csv"
    frame.to_csv(path, index=False)
    return path, row


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ("pose", "names pose"),
        ("self", "to itself"),
        ("covariance", "covariance is not positive definite"),
        ("times", "differ from the image times"),
    ],
)
def test_bad_loop_rows_are_one_line_errors(
    dive: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], edit: str, message: str
) -> None:
    path, row = _bad(dive, tmp_path, edit)
    assert main(["slam", str(dive), "--loops", str(path), "-q"]) == 1
    err = _errors(capsys)
    assert len(err) == 1
    assert str(path) in err[0] and f"row {row}" in err[0] and message in err[0]


def test_missing_inputs_and_conflicting_options_are_one_line_errors(
    dive: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["slam", str(dive), "-q"]) == 1  # no products/vision/loops.csv
    err = _errors(capsys)
    assert len(err) == 1 and "no loop closures" in err[0] and "products/vision/loops.csv" in err[0]

    correction = tmp_path / "correction.yaml"
    write_correction(DeviationModel(0.0, np.array([0.01]), np.array([0.0])), correction)
    loops = str(dive / "truth" / "clean.csv")
    args = [
        "slam",
        str(dive),
        "--loops",
        loops,
        "--compass-correction",
        str(correction),
        "--estimate-compass",
    ]
    assert main([*args, "-q"]) == 1
    assert _errors(capsys) == ["auvnav: error: give --compass-correction or --estimate-compass, not both"]

    no_images = tmp_path / "no-images"
    shutil.copytree(dive, no_images, ignore=shutil.ignore_patterns("products", "images"))
    assert main(["slam", str(no_images), "--loops", loops, "-q"]) == 1
    err = _errors(capsys)
    assert len(err) == 1 and "no images/index.csv" in err[0]
