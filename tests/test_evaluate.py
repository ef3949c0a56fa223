"""Scoring products against a simulated dive's truth (DESIGN section 7), checked against evo."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from auvnav.cli import main
from auvnav.dive import write_dive
from auvnav.evaluate import align_yaw_translation, evaluate_dive, score_trajectory
from auvnav.frames import rot_z
from auvnav.nav.synthetic import Noise, lawnmower_legs, legs_motion, synthetic_dive
from auvnav.trajectory import Trajectory, read_trajectory, write_trajectory, write_tum

ATOL_EVO_M = 1e-6  # the acceptance bound of issue 4: 1 micrometre


@pytest.fixture(scope="module")
def truth() -> Trajectory:
    return legs_motion(lawnmower_legs(3, 60.0, 10.0), rate_hz=2.0, turn_rate_rps=0.1).truth


def _perturbed(truth: Trajectory, seed: int = 0) -> Trajectory:
    rng = np.random.default_rng(seed)
    drift = np.cumsum(rng.normal(0.0, 0.05, truth.p_ned_m.shape), axis=0)
    return dataclasses.replace(truth, p_ned_m=truth.p_ned_m + drift, yaw_rad=truth.yaw_rad + 0.01)


def test_ate_matches_evo_ape(tmp_path: Path, truth: Trajectory) -> None:
    from evo.core import metrics, sync
    from evo.main_ape import ape
    from evo.tools import file_interface

    estimate = _perturbed(truth).select(np.arange(len(truth.t_s)) % 3 != 0)  # its own times
    ours = score_trajectory(truth, estimate, truth.distance_m())
    write_tum(truth.interpolate(estimate.t_s), tmp_path / "truth.tum")
    write_tum(estimate, tmp_path / "estimate.tum")
    ref = file_interface.read_tum_trajectory_file(str(tmp_path / "truth.tum"))
    est = file_interface.read_tum_trajectory_file(str(tmp_path / "estimate.tum"))
    ref, est = sync.associate_trajectories(ref, est)
    result = ape(ref, est, pose_relation=metrics.PoseRelation.translation_part)
    assert ours.ate_rmse_m == pytest.approx(result.stats["rmse"], abs=ATOL_EVO_M)
    assert ours.ate_rmse_m > 0.1


def test_alignment_recovers_a_rigid_yaw_and_translation(truth: Trajectory) -> None:
    moved = truth.p_ned_m @ rot_z(0.3).T + [5.0, -7.0, 1.5]
    yaw, t = align_yaw_translation(moved, truth.p_ned_m)
    assert yaw == pytest.approx(-0.3, abs=1e-12)
    np.testing.assert_allclose(moved @ rot_z(yaw).T + t, truth.p_ned_m, atol=1e-9)
    estimate = dataclasses.replace(truth, p_ned_m=moved)
    score = score_trajectory(truth, estimate, truth.distance_m())
    assert score.ate_aligned_rmse_m < 1e-9 < 1.0 < score.ate_rmse_m
    assert score.end_error_m == pytest.approx(np.linalg.norm(moved[-1] - truth.p_ned_m[-1]))
    assert score.end_error_pct == pytest.approx(100 * score.end_error_m / truth.distance_m())


def test_yaw_rmse_wraps(truth: Trajectory) -> None:
    near_pi = dataclasses.replace(truth, yaw_rad=np.full(len(truth.t_s), math.pi - 0.01))
    across = dataclasses.replace(truth, yaw_rad=np.full(len(truth.t_s), -math.pi + 0.01))
    assert score_trajectory(near_pi, across, 1.0).yaw_rmse_deg == pytest.approx(math.degrees(0.02))


def _simulated_dive(tmp_path: Path) -> Path:
    motion = legs_motion(lawnmower_legs(3, 60.0, 10.0), rate_hz=2.0, turn_rate_rps=0.1)
    dive = synthetic_dive(motion, gps_times_s=motion.truth.t_s[:20], noise=Noise(seed=2))
    return write_dive(
        dive, tmp_path / "sim", extra={"truth/trajectory.csv": lambda p: write_trajectory(motion.truth, p)}
    )


def test_evaluate_scores_the_products_that_exist(tmp_path: Path, capsys) -> None:
    path = _simulated_dive(tmp_path)
    assert main(["evaluate", str(path), "--json"]) == 0
    before = json.loads(capsys.readouterr().out)
    assert set(before) == {"distance_m"}
    assert main(["navigate", str(path), "-q"]) == 0
    capsys.readouterr()
    result = evaluate_dive(path)
    assert set(result) == {"distance_m", "dr", "filter"}
    keys = {"end_error_m", "end_error_pct", "ate_rmse_m", "ate_aligned_rmse_m"}
    assert keys <= set(result["dr"]) and keys <= set(result["filter"])
    assert result["distance_m"] == pytest.approx(read_trajectory(path / "truth/trajectory.csv").distance_m())
    assert 250.0 < result["distance_m"] < 270.0  # 200 m of lines and spacing, 4 quarter turns of 15.7 m
    assert 0 < result["dr"]["ate_aligned_rmse_m"] <= result["dr"]["ate_rmse_m"] < 10.0
    assert main(["evaluate", str(path)]) == 0
    out = capsys.readouterr().out
    assert "distance travelled (truth)" in out and "filter" in out and "ate_rmse_m" in out


def test_evaluate_without_truth_fails_with_one_line(tmp_path: Path, capsys) -> None:
    path = _simulated_dive(tmp_path)
    (path / "truth/trajectory.csv").unlink()
    assert main(["evaluate", str(path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "truth/trajectory.csv" in err[0]
