"""Trajectories: timed 6-DOF poses in local NED, the common product of truth, navigation and SLAM.

File form (DESIGN sections 5 and 6): ``t, north_m, east_m, down_m, roll_deg, pitch_deg, yaw_deg`` plus
optional 1-sigma columns ``sigma_north_m, sigma_east_m, sigma_down_m, sigma_yaw_deg``. TUM export
(``timestamp tx ty tz qx qy qz qw``, scalar last, as evo reads it) keeps NED coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from auvnav.errors import DiveFormatError, Problem
from auvnav.frames import euler2rot, rot2quat_wxyz, wrap_angle
from auvnav.streams import Field, Stream, atomic_write, read_stream, write_stream

DEG = np.pi / 180.0

_OPTIONAL_SIGMAS = (
    Field("sigma_ned_m", ("sigma_north_m", "sigma_east_m", "sigma_down_m"), required=False),
    Field("sigma_yaw_rad", ("sigma_yaw_deg",), DEG, required=False),
)


@dataclass(frozen=True)
class Trajectory(Stream):
    """Poses of the vehicle reference point.

    Parameters
    ----------
    t_s : ndarray, shape (N,)
        POSIX seconds, strictly increasing.
    p_ned_m : ndarray, shape (N, 3)
        Position, metres, local NED about the dive's origin.
    yaw_rad, pitch_rad, roll_rad : ndarray, shape (N,)
        Attitude, Euler ZYX of ``R_ned_body``.
    sigma_ned_m : ndarray, shape (N, 3), optional
        1-sigma position uncertainty.
    sigma_yaw_rad : ndarray, shape (N,), optional
        1-sigma heading uncertainty.
    """

    t_s: NDArray[np.float64]
    p_ned_m: NDArray[np.float64]
    roll_rad: NDArray[np.float64]
    pitch_rad: NDArray[np.float64]
    yaw_rad: NDArray[np.float64]
    sigma_ned_m: NDArray[np.float64] | None = None
    sigma_yaw_rad: NDArray[np.float64] | None = None
    FILE: ClassVar[str] = "trajectory"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        Field("t_s", ("t",)),
        Field("p_ned_m", ("north_m", "east_m", "down_m")),
        Field("roll_rad", ("roll_deg",), DEG),
        Field("pitch_rad", ("pitch_deg",), DEG),
        Field("yaw_rad", ("yaw_deg",), DEG),
        *_OPTIONAL_SIGMAS,
    )

    @property
    def R_ned_body(self) -> NDArray[np.float64]:
        """Attitude as rotation matrices, shape (N, 3, 3)."""
        return euler2rot(self.yaw_rad, self.pitch_rad, self.roll_rad)

    def distance_m(self) -> float:
        """Length of the path, metres (3D)."""
        return float(np.linalg.norm(np.diff(self.p_ned_m, axis=0), axis=1).sum())

    def interpolate(self, t_s: NDArray[np.float64]) -> Trajectory:
        """Poses at other times (linear in position, shortest-arc in the angles); times must lie inside."""
        t_s = np.asarray(t_s, dtype=float)
        if t_s.size and (t_s.min() < self.t_s[0] - 1e-9 or t_s.max() > self.t_s[-1] + 1e-9):
            raise ValueError(
                f"times {t_s.min():.3f}..{t_s.max():.3f} lie outside the trajectory {self.t_s[0]:.3f}..{self.t_s[-1]:.3f}"
            )

        def lin(x: NDArray[np.float64]) -> NDArray[np.float64]:
            return np.interp(t_s, self.t_s, x)

        def ang(a: NDArray[np.float64]) -> NDArray[np.float64]:
            return wrap_angle(np.interp(t_s, self.t_s, np.unwrap(a)))

        return Trajectory(
            t_s=t_s,
            p_ned_m=np.stack([lin(self.p_ned_m[:, k]) for k in range(3)], -1),
            roll_rad=ang(self.roll_rad),
            pitch_rad=lin(self.pitch_rad),
            yaw_rad=ang(self.yaw_rad),
            sigma_ned_m=None
            if self.sigma_ned_m is None
            else np.stack([lin(self.sigma_ned_m[:, k]) for k in range(3)], -1),
            sigma_yaw_rad=None if self.sigma_yaw_rad is None else lin(self.sigma_yaw_rad),
        )


def read_trajectory(path: Path) -> Trajectory:
    """Read a trajectory CSV/Parquet (DESIGN section 6 columns); every problem is reported."""
    return read_stream(Trajectory, Path(path), str(path))


def write_trajectory(traj: Trajectory, path: Path) -> None:
    """Write a trajectory as CSV or Parquet (by suffix), atomically."""
    write_stream(traj, Path(path))


def write_tum(traj: Trajectory, path: Path) -> None:
    """Write the TUM format evo reads: ``t x y z qx qy qz qw`` with NED positions."""
    q_wxyz = rot2quat_wxyz(traj.R_ned_body)
    rows = np.column_stack([traj.t_s, traj.p_ned_m, q_wxyz[:, 1:], q_wxyz[:, :1]])

    def write(p: Path) -> None:
        np.savetxt(p, rows, fmt="%.9f", header="timestamp tx ty tz qx qy qz qw (local NED)")

    atomic_write(Path(path), write)


def require_overlap(a: Trajectory, b: Trajectory, what: str) -> tuple[float, float]:
    """The common time span of two trajectories; an error when they do not overlap."""
    t0, t1 = max(a.t_s[0], b.t_s[0]), min(a.t_s[-1], b.t_s[-1])
    if t1 <= t0:
        raise DiveFormatError([Problem(what, "trajectories do not overlap in time")])
    return float(t0), float(t1)
