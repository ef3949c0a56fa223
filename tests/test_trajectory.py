"""Trajectories: CSV round trip, interpolation across the heading wrap, TUM files evo reads back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from evo.tools import file_interface

from auvnav.frames import angle_diff
from auvnav.trajectory import Trajectory, read_trajectory, write_trajectory, write_tum


def _spiral(n: int = 200) -> Trajectory:
    t = 1.25e9 + np.arange(n) * 0.5
    a = np.linspace(0, 4 * np.pi, n)
    return Trajectory(
        t_s=t,
        p_ned_m=np.column_stack([10 * np.cos(a), 10 * np.sin(a), 20 + 0.01 * np.arange(n)]),
        roll_rad=0.02 * np.sin(a),
        pitch_rad=0.01 * np.cos(a),
        yaw_rad=np.angle(np.exp(1j * (a + np.pi / 2))),
        sigma_ned_m=np.full((n, 3), 0.1),
        sigma_yaw_rad=np.full(n, 0.01),
    )


def test_csv_round_trip_keeps_sigmas(tmp_path: Path) -> None:
    traj = _spiral()
    write_trajectory(traj, tmp_path / "t.csv")
    back = read_trajectory(tmp_path / "t.csv")
    np.testing.assert_allclose(back.p_ned_m, traj.p_ned_m, rtol=1e-15)
    np.testing.assert_allclose(back.yaw_rad, traj.yaw_rad, rtol=1e-14)
    assert back.sigma_ned_m is not None and back.sigma_yaw_rad is not None


def test_interpolation_takes_the_short_way_round_the_wrap() -> None:
    traj = Trajectory(
        t_s=np.array([0.0, 1.0]),
        p_ned_m=np.zeros((2, 3)),
        roll_rad=np.zeros(2),
        pitch_rad=np.zeros(2),
        yaw_rad=np.radians([179.0, -179.0]),
    )
    mid = traj.interpolate(np.array([0.5]))
    assert abs(angle_diff(mid.yaw_rad[0], np.pi)) < 1e-12
    with pytest.raises(ValueError, match="outside"):
        traj.interpolate(np.array([2.0]))


def test_evo_reads_back_the_tum_file(tmp_path: Path) -> None:
    traj = _spiral()
    write_tum(traj, tmp_path / "t.tum")
    evo_traj = file_interface.read_tum_trajectory_file(str(tmp_path / "t.tum"))
    np.testing.assert_allclose(evo_traj.timestamps, traj.t_s, atol=1e-6)
    poses = np.stack(evo_traj.poses_se3)
    np.testing.assert_allclose(poses[:, :3, 3], traj.p_ned_m, atol=1e-8)
    np.testing.assert_allclose(poses[:, :3, :3], traj.R_ned_body, atol=1e-8)
