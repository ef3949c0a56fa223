"""The loop-closure file: lossless round trip and one-line errors naming the row."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from auvnav.errors import DiveFormatError
from auvnav.frames import euler2rot, se3
from auvnav.vision.loopfile import loops_from_transforms, read_loops, write_loops


def _loops(n: int = 4):
    rng = np.random.default_rng(3)
    T = se3(
        euler2rot(rng.uniform(-3, 3, n), rng.uniform(-0.1, 0.1, n), rng.uniform(-0.1, 0.1, n)),
        rng.normal(0, 1, (n, 3)),
    )
    A = rng.normal(0, 1e-3, (n, 6, 6))
    cov = A @ np.swapaxes(A, 1, 2) + 1e-8 * np.eye(6)
    return (
        loops_from_transforms(
            np.arange(n),
            np.arange(n) + 10,
            100.0 + np.arange(n),
            200.0 + np.arange(n),
            T,
            cov,
            np.full(n, 50),
        ),
        T,
        cov,
    )


def test_round_trip(tmp_path: Path) -> None:
    loops, T, cov = _loops()
    write_loops(loops, tmp_path / "loops.csv")
    back = read_loops(tmp_path / "loops.csv", n_poses=20)
    np.testing.assert_allclose(back.T_i_j, T, atol=1e-12)
    np.testing.assert_allclose(back.covariance, cov, rtol=1e-12)
    np.testing.assert_array_equal(back.j, loops.j)
    assert back.i.dtype == np.int64


def test_missing_pose_and_bad_covariance_name_the_row(tmp_path: Path) -> None:
    loops, _, _ = _loops()
    write_loops(loops, tmp_path / "loops.csv")
    text = (tmp_path / "loops.csv").read_text().splitlines()
    header = text[0].split(",")
    row = text[2].split(",")
    row[header.index("cov00")] = "-1e-3"
    text[2] = ",".join(row)
    (tmp_path / "loops.csv").write_text("\n".join(text) + "\n")
    with pytest.raises(DiveFormatError) as info:
        read_loops(tmp_path / "loops.csv", n_poses=12)
    lines = str(info.value).splitlines()
    assert any("row 2" in line and "not positive definite" in line for line in lines)
    assert any("row 3" in line and "names pose 2 -> 12; poses are 0..11" in line for line in lines)


def test_fractional_pose_index_is_an_error(tmp_path: Path) -> None:
    loops, _, _ = _loops()
    write_loops(loops, tmp_path / "loops.csv")
    path = tmp_path / "loops.csv"
    text = path.read_text().splitlines()
    text[1] = "0.5" + text[1][1:]
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(DiveFormatError, match=r"row 1: column i: not an integer"):
        read_loops(path)
