"""Loop closures from the truth: footprint geometry, overlap, noise that matches its covariance,
false loop closures, the files and the ``simulate`` options."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from auvnav.cli import main
from auvnav.dive import ImageIndex
from auvnav.frames import angle_diff, rot2euler, se3_inverse
from auvnav.sim.camera import body_poses
from auvnav.sim.truthloops import (
    FALSE_OFFSET_M,
    MAX_PER_IMAGE,
    SIGMA_ROTATION_RAD,
    SIGMA_TRANSLATION_M,
    truth_loops,
)
from auvnav.streams import read_stream
from auvnav.trajectory import Trajectory
from auvnav.vision.loopfile import read_loops


def _lawnmower(lines: int = 4, line_m: float = 20.0, spacing_m: float = 1.0) -> Trajectory:
    """Straight lines north and south at 0.5 m/s, ``spacing_m`` apart, sampled at 10 Hz."""
    step = 0.05
    parts = []
    for k in range(lines):
        s = np.arange(0.0, line_m, step)
        north = s if k % 2 == 0 else line_m - s
        parts.append(np.column_stack([north, np.full(s.size, k * spacing_m), np.full(s.size, 8.0)]))
    p = np.concatenate(parts)
    yaw = np.concatenate([np.full(int(line_m / step), 0.0 if k % 2 == 0 else math.pi) for k in range(lines)])
    n = len(p)
    rng = np.random.default_rng(1)
    return Trajectory(
        t_s=1e9 + 0.1 * np.arange(n),
        p_ned_m=p,
        roll_rad=rng.normal(0, 0.01, n),
        pitch_rad=rng.normal(0, 0.01, n),
        yaw_rad=yaw,
    )


@pytest.fixture(scope="module")
def lawnmower_loops(level_floor):
    truth = _lawnmower()
    times = truth.t_s[0] + np.arange(0.0, truth.t_s[-1] - truth.t_s[0], 1.0)
    return truth, times, truth_loops(truth, level_floor(10.0), times, false_fraction=0.2, seed=5)


def test_loops_join_consecutive_pairs_and_adjacent_lines(lawnmower_loops) -> None:
    _, times, result = lawnmower_loops
    true = ~result.is_false
    i, j = result.loops.i[true], result.loops.j[true]
    along_a_line = {(k, k + 1) for k in range(len(times) - 1) if k // 40 == (k + 1) // 40}  # 40 s per line
    assert along_a_line <= set(zip(i.tolist(), j.tolist(), strict=True))
    assert np.all(i < j)
    assert np.all(result.overlap[true] >= 0.2)
    # Lines 1 m apart (footprints 1.3 m wide) overlap: loops between lines, capped per image.
    line = (times[i] - times[0]) // 40.0
    other = (times[j] - times[0]) // 40.0
    assert np.count_nonzero(line != other) > 50
    per_image = np.bincount(np.concatenate([i[j - i > 1], j[j - i > 1]]))
    assert per_image.max() <= MAX_PER_IMAGE


def test_noise_matches_the_covariance(lawnmower_loops) -> None:
    """True rows differ from the true relative pose by noise of the file's covariance (1 cm, 0.1 deg)."""
    truth, times, result = lawnmower_loops
    true = ~result.is_false
    loops = result.loops.select(true)
    T = body_poses(truth.interpolate(times))
    T_true = se3_inverse(T[loops.i]) @ T[loops.j]
    yaw, pitch, roll = rot2euler(T_true[:, :3, :3])
    error = np.column_stack(
        [
            loops.t_ij_m - T_true[:, :3, 3],
            angle_diff(loops.rpy_ij_rad[:, 0], roll),
            angle_diff(loops.rpy_ij_rad[:, 1], pitch),
            angle_diff(loops.rpy_ij_rad[:, 2], yaw),
        ]
    )
    sigma = np.sqrt(np.diagonal(loops.covariance, axis1=1, axis2=2))
    np.testing.assert_allclose(sigma[0], np.repeat([SIGMA_TRANSLATION_M, SIGMA_ROTATION_RAD], 3))
    z = error / sigma
    assert np.abs(z).max() < 5.5
    np.testing.assert_allclose(z.std(axis=0), 1.0, atol=0.1)  # several hundred rows
    np.testing.assert_allclose(z.mean(axis=0), 0.0, atol=0.15)


def test_false_loops_are_a_fraction_of_the_rows_and_wrong(lawnmower_loops) -> None:
    truth, times, result = lawnmower_loops
    n_false = int(result.is_false.sum())
    assert n_false == round(0.2 * len(result.loops))
    false = result.loops.select(result.is_false)
    assert np.all(np.abs(false.j - false.i) > 1)
    assert np.all(np.abs(false.t_ij_m[:, :2]) <= FALSE_OFFSET_M)
    T = body_poses(truth.interpolate(times))
    true_distance = np.linalg.norm((se3_inverse(T[false.i]) @ T[false.j])[:, :2, 3], axis=1)
    claimed = np.linalg.norm(false.t_ij_m[:, :2], axis=1)
    assert np.all(true_distance - claimed > 0.5)  # the footprints do not overlap; the claim says they do


def test_same_seed_same_loops(level_floor) -> None:
    truth = _lawnmower(lines=2)
    times = truth.t_s[0] + np.arange(0.0, 70.0, 1.0)
    a = truth_loops(truth, level_floor(10.0), times, false_fraction=0.1, seed=3)
    b = truth_loops(truth, level_floor(10.0), times, false_fraction=0.1, seed=3)
    c = truth_loops(truth, level_floor(10.0), times, false_fraction=0.1, seed=4)
    np.testing.assert_array_equal(a.loops.t_ij_m, b.loops.t_ij_m)
    assert not np.array_equal(a.loops.t_ij_m, c.loops.t_ij_m)


def test_simulate_writes_truth_loops(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``auvnav simulate --truth-loops --false-loops``: the camera's trigger log, loops and their record."""
    out = tmp_path / "dive"
    args = ["simulate", "navcheck", "--out", str(out), "--headings", "2", "--leg-m", "6", "--grid-m", "2"]
    args += ["--no-images", "--truth-loops"]
    assert main([*args, "--false-loops", "0.25", "--json", "-q"]) == 0
    times = read_stream(ImageIndex, out / "images" / "index.csv").t_s
    loops = read_loops(out / "truth" / "loops.csv", n_poses=len(times))
    info = yaml.safe_load((out / "truth" / "loops.yaml").read_text(encoding="utf-8"))
    assert info["false_fraction"] == 0.25
    assert len(info["false_rows"]) == round(0.25 * len(loops))
    np.testing.assert_allclose(loops.t_i_s, times[loops.i])
    assert '"truth_loops"' in capsys.readouterr().out


def test_false_loops_need_truth_loops(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["simulate", "spin", "--out", str(tmp_path / "d"), "--no-images", "--false-loops", "0.2"]
    assert main(args) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["auvnav: error: --false-loops needs --truth-loops"]
