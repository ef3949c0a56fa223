"""The loop-closure file ``products/vision/loops.csv`` (DESIGN section 6): one reader, one writer.

Each row is a 6-DOF relative pose between two stereo pairs ``i`` and ``j`` (0-based rows of
``images/index.csv``, so pose indices in the SLAM graph):

``T_i_j = inv(T_ned_body_i) @ T_ned_body_j``, the pose of body ``j`` expressed in body ``i``:
``x_m, y_m, z_m`` is the position of j's origin in i's FRD axes, ``roll_deg, pitch_deg, yaw_deg`` the
Euler ZYX angles of ``R_i_j``. The 21 columns ``cov00 .. cov55`` (upper triangle, row-major, indices
0..5 = x, y, z, roll, pitch, yaw) are the covariance of that 6-vector in SI units and radians (m^2,
m rad, rad^2). ``inliers`` counts the feature correspondences that support the estimate. The
optional ``method`` says how the loop stage registered the pair: ``features`` (matched stereo
features) or ``images`` (the direct, photometric registration of :mod:`auvnav.vision.direct`, whose
``inliers`` are the stereo points of j inside image i's view); loop files from elsewhere may omit it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from auvnav.errors import DiveFormatError
from auvnav.frames import from_pose6, pose6
from auvnav.products import LOOPS
from auvnav.streams import Field, Stream, flag_rows, read_stream, write_stream

DEG = np.pi / 180.0
_UPPER = [(a, b) for a in range(6) for b in range(a, 6)]
COV_COLUMNS = tuple(f"cov{a}{b}" for a, b in _UPPER)


@dataclass(frozen=True)
class LoopClosures(Stream):
    """Relative-pose measurements between stereo pairs.

    Parameters
    ----------
    i, j : ndarray of int, shape (N,)
        Pose (image pair) indices, 0-based.
    t_i_s, t_j_s : ndarray, shape (N,)
        Image times, POSIX seconds.
    t_ij_m : ndarray, shape (N, 3)
        Position of j in body i, metres, FRD.
    rpy_ij_rad : ndarray, shape (N, 3)
        Roll, pitch, yaw of ``R_i_j`` (Euler ZYX), radians.
    cov_upper : ndarray, shape (N, 21)
        Upper triangle of the 6x6 covariance of (x, y, z, roll, pitch, yaw), row-major, SI and radians.
    inliers : ndarray of int, shape (N,)
    method : ndarray of str, shape (N,), optional
        ``features`` or ``images`` (module docstring); None when the file has no such column.
    """

    i: NDArray[np.int64]
    j: NDArray[np.int64]
    t_i_s: NDArray[np.float64]
    t_j_s: NDArray[np.float64]
    t_ij_m: NDArray[np.float64]
    rpy_ij_rad: NDArray[np.float64]
    cov_upper: NDArray[np.float64]
    inliers: NDArray[np.int64]
    method: NDArray[np.str_] | None = None
    FILE: ClassVar[str] = "products/vision/loops"
    TIME_ORDERED: ClassVar[bool] = False
    FIELDS: ClassVar[tuple[Field, ...]] = (
        Field("i", ("i",), kind="int"),
        Field("j", ("j",), kind="int"),
        Field("t_i_s", ("t_i",)),
        Field("t_j_s", ("t_j",)),
        Field("t_ij_m", ("x_m", "y_m", "z_m")),
        Field("rpy_ij_rad", ("roll_deg", "pitch_deg", "yaw_deg"), DEG),
        Field("cov_upper", COV_COLUMNS),
        Field("inliers", ("inliers",), kind="int"),
        Field("method", ("method",), kind="str", required=False),
    )

    @property
    def covariance(self) -> NDArray[np.float64]:
        """Full 6x6 covariances, shape (N, 6, 6)."""
        C = np.zeros((len(self), 6, 6))
        for k, (a, b) in enumerate(_UPPER):
            C[:, a, b] = C[:, b, a] = self.cov_upper[:, k]
        return C

    @property
    def T_i_j(self) -> NDArray[np.float64]:
        """Relative poses as 4x4 transforms, shape (N, 4, 4)."""
        return from_pose6(np.column_stack([self.t_ij_m, self.rpy_ij_rad]))


def loops_from_transforms(
    i: NDArray[np.int64],
    j: NDArray[np.int64],
    t_i_s: NDArray[np.float64],
    t_j_s: NDArray[np.float64],
    T_i_j: NDArray[np.float64],
    covariance: NDArray[np.float64],
    inliers: NDArray[np.int64],
    method: NDArray[np.str_] | None = None,
) -> LoopClosures:
    """Build :class:`LoopClosures` from 4x4 relative poses and 6x6 covariances (x, y, z, r, p, y order)."""
    p6 = pose6(T_i_j).reshape(-1, 6)
    a, b = zip(*_UPPER, strict=True)
    return LoopClosures(
        i=np.asarray(i, dtype=np.int64),
        j=np.asarray(j, dtype=np.int64),
        t_i_s=np.asarray(t_i_s, dtype=float),
        t_j_s=np.asarray(t_j_s, dtype=float),
        t_ij_m=p6[:, :3],
        rpy_ij_rad=p6[:, 3:],
        cov_upper=covariance[:, list(a), list(b)],
        inliers=np.asarray(inliers, dtype=np.int64),
        method=None if method is None else np.asarray(method, dtype=str),
    )


def check_loops(loops: LoopClosures, n_poses: int, display: str) -> None:
    """Raise :class:`DiveFormatError` naming the rows whose poses do not exist, that join a pose to
    itself, or whose covariance is not positive definite (1-based data rows; a few of each kind, then
    a count)."""
    outside = (loops.i < 0) | (loops.i >= n_poses) | (loops.j < 0) | (loops.j >= n_poses)
    eig_min = _smallest_eigenvalues(loops.covariance)
    problems = flag_rows(
        outside,
        display,
        None,
        lambda r: f"names pose {loops.i[r - 1]} -> {loops.j[r - 1]}; poses are 0..{n_poses - 1}",
        "rows naming poses that do not exist",
    )
    problems += flag_rows(
        loops.i == loops.j, display, None, lambda r: f"joins pose {loops.i[r - 1]} to itself", "self-loops"
    )
    problems += flag_rows(
        ~(eig_min > 0),
        display,
        None,
        lambda r: f"covariance is not positive definite (smallest eigenvalue {eig_min[r - 1]:.3g})",
        "covariances that are not positive definite",
    )
    if problems:
        raise DiveFormatError(problems)


def _smallest_eigenvalues(C: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each covariance's smallest eigenvalue; NaN where it has none (values too large to decompose)."""
    out = np.full(len(C), np.nan)
    sane = np.isfinite(C).all(axis=(1, 2)) & (np.abs(C).max(axis=(1, 2), initial=0.0) < 1e150)
    if not sane.any():
        return out
    try:
        out[sane] = np.linalg.eigvalsh(C[sane])[:, 0]
    except np.linalg.LinAlgError:
        for k in np.flatnonzero(sane):
            try:
                out[k] = np.linalg.eigvalsh(C[k])[0]
            except np.linalg.LinAlgError:
                pass
    return out


#: Loop-file times may differ from the image times by this much, seconds.
LOOP_TIME_TOLERANCE_S = 1e-3


def check_loop_times(loops: LoopClosures, image_t_s: NDArray[np.float64], display: str) -> None:
    """Raise :class:`DiveFormatError` naming the rows whose times are not the image times of their
    poses (a loop file of another dive); ``image_t_s`` may hold NaN for images to leave unchecked."""
    off = np.fmax(np.abs(image_t_s[loops.i] - loops.t_i_s), np.abs(image_t_s[loops.j] - loops.t_j_s))
    problems = flag_rows(
        off > LOOP_TIME_TOLERANCE_S,
        display,
        None,
        lambda r: (
            f"times of poses {loops.i[r - 1]} -> {loops.j[r - 1]} differ from the image times by "
            f"{off[r - 1]:.3f} s (a loop file of another dive?)"
        ),
        "rows whose times differ",
    )
    if problems:
        raise DiveFormatError(problems)


def read_loops(path: Path, *, n_poses: int | None = None) -> LoopClosures:
    """Read a loop-closure file; every problem is a line naming the file and row.

    With ``n_poses``, also check that every row names existing poses and carries a positive-definite
    covariance.
    """
    loops = read_stream(LoopClosures, Path(path), str(path))
    if n_poses is not None:
        check_loops(loops, n_poses, str(path))
    return loops


def loops_file(dive: Path, given: Path | None = None) -> Path | None:
    """The loop closures a stage reads: the file given, else the loop-closure stage's
    (``products/vision/loops.csv``) when it exists."""
    if given is not None:
        return Path(given)
    path = LOOPS.path(dive)
    return path if path.is_file() else None


def write_loops(loops: LoopClosures, path: Path) -> None:
    """Write a loop-closure file (CSV or Parquet by suffix), atomically."""
    write_stream(loops, Path(path))
