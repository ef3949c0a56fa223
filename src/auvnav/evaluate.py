"""Scoring a simulated dive's products against its truth (DESIGN section 7, ``auvnav evaluate``).

Each section of the result scores one stage's products and appears only when they exist; the truth
is ``DIVE/truth/trajectory.csv`` written by the simulator. A stage adds its section to
:data:`SECTIONS`: a function of the dive folder and the truth that returns the section's keys, or
None when the stage's products are absent.

Trajectory scores (:func:`score_trajectory`) compare positions at the estimate's times, the truth
interpolated there (estimate samples outside the truth's span are left out, with a warning):

- ``ate_rmse_m``: root mean square of the 3D position error with no alignment (truth and estimate
  share the dive's origin); the same number as evo's APE on the translation part
  (``evo_ape tum truth.tum estimate.tum``) for the same samples;
- ``ate_aligned_rmse_m``: the same after the best rigid alignment in x, y, z and yaw
  (:func:`align_yaw_translation`), the consistency the paper is about;
- ``end_error_m``: 3D error at the estimate's last sample, and ``end_error_pct`` = end error /
  ``distance_m`` x 100, ``distance_m`` the length of the whole true track (3D);
- ``yaw_rmse_deg``: root mean square of the heading error.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from auvnav import products as P
from auvnav.compass.evaluate import compass_section
from auvnav.errors import DiveFormatError, Problem
from auvnav.frames import FloatArray, angle_diff, rot_z
from auvnav.trajectory import Trajectory, read_trajectory

log = logging.getLogger(__name__)

TRUTH_FILE = Path("truth") / "trajectory.csv"


@dataclass(frozen=True)
class TrajectoryScore:
    """How an estimated trajectory compares with the truth (see the module docstring).

    Parameters
    ----------
    end_error_m, end_error_pct, ate_rmse_m, ate_aligned_rmse_m : float
        Metres, percent of the true distance, metres, metres.
    yaw_rmse_deg : float
        Degrees.
    """

    end_error_m: float
    end_error_pct: float
    ate_rmse_m: float
    ate_aligned_rmse_m: float
    yaw_rmse_deg: float

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def align_yaw_translation(p_est_m: FloatArray, p_ref_m: FloatArray) -> tuple[float, FloatArray]:
    """The rotation about the vertical and translation that best map ``p_est`` onto ``p_ref``.

    Least squares, ``min sum |Rz(yaw) p_est_i + t - p_ref_i|^2``: with the centred points ``e``,
    ``r``, ``yaw = atan2(sum e_n r_e - e_e r_n, sum e_n r_n + e_e r_e)`` and
    ``t = mean(p_ref) - Rz(yaw) mean(p_est)`` (the 4-DOF case of Umeyama, "Least-squares estimation
    of transformation parameters between two point patterns", IEEE TPAMI 13(4), 1991).

    Parameters
    ----------
    p_est_m, p_ref_m : ndarray, shape (N, 3), metres, local NED

    Returns
    -------
    yaw_rad : float
    t_ned_m : ndarray, shape (3,)
    """
    mean_est, mean_ref = p_est_m.mean(axis=0), p_ref_m.mean(axis=0)
    e, r = p_est_m - mean_est, p_ref_m - mean_ref
    yaw = math.atan2(
        float(np.sum(e[:, 0] * r[:, 1] - e[:, 1] * r[:, 0])),
        float(np.sum(e[:, 0] * r[:, 0] + e[:, 1] * r[:, 1])),
    )
    return yaw, mean_ref - rot_z(yaw) @ mean_est


def _rms_norm(x: FloatArray) -> float:
    """Root mean square of the row norms of ``x`` (N, k), or of ``x`` (N,)."""
    squares = x**2 if x.ndim == 1 else np.sum(x**2, axis=1)
    return float(np.sqrt(np.mean(squares)))


def score_trajectory(
    truth: Trajectory, estimate: Trajectory, distance_m: float, what: str = "estimate"
) -> TrajectoryScore:
    """Score an estimate against the truth at the estimate's times (see the module docstring).

    Parameters
    ----------
    truth, estimate : Trajectory
    distance_m : float
        Length of the true track, metres (for ``end_error_pct``).
    what : str
        Names the estimate in messages.

    Raises
    ------
    DiveFormatError
        No estimate sample lies inside the truth's span.
    """
    inside = (estimate.t_s >= truth.t_s[0]) & (estimate.t_s <= truth.t_s[-1])
    if not np.any(inside):
        raise DiveFormatError([Problem(what, "no sample lies inside the truth's time span")])
    if not np.all(inside):
        log.warning(
            "%s: %d of %d samples lie outside the truth's time span, not scored",
            what,
            np.count_nonzero(~inside),
            len(inside),
        )
    est = estimate.select(inside)
    ref = truth.interpolate(est.t_s)
    error = est.p_ned_m - ref.p_ned_m
    yaw, t = align_yaw_translation(est.p_ned_m, ref.p_ned_m)
    aligned = est.p_ned_m @ rot_z(yaw).T + t
    end = float(np.linalg.norm(error[-1]))
    return TrajectoryScore(
        end_error_m=end,
        end_error_pct=100.0 * end / distance_m if distance_m > 0 else math.nan,
        ate_rmse_m=_rms_norm(error),
        ate_aligned_rmse_m=_rms_norm(aligned - ref.p_ned_m),
        yaw_rmse_deg=math.degrees(_rms_norm(angle_diff(est.yaw_rad, ref.yaw_rad))),
    )


Section = Callable[[Path, Trajectory, float], "dict[str, Any] | None"]


def trajectory_section(product: P.Product) -> Section:
    """A section scoring a trajectory product."""

    def section(dive_path: Path, truth: Trajectory, distance_m: float) -> dict[str, Any] | None:
        path = product.path(dive_path)
        if not path.is_file():
            return None
        return score_trajectory(truth, read_trajectory(path), distance_m, str(path)).as_dict()

    return section


def _compass(dive_path: Path, truth: Trajectory, distance_m: float) -> dict[str, Any] | None:
    """The dive's own compass correction against its true deviation (:mod:`auvnav.compass.evaluate`)."""
    path = P.COMPASS_CORRECTION.path(dive_path)
    return compass_section(dive_path, path) if path.is_file() else None


def _slam(dive_path: Path, truth: Trajectory, distance_m: float) -> dict[str, Any] | None:
    """The SLAM trajectory's scores; with a deviation estimated in the graph, also that curve's
    (``deviation_rmse_deg`` as the compass section's, ``deviation_shape_rmse_deg`` without the constant)."""
    scores = trajectory_section(P.SLAM_TRAJECTORY)(dive_path, truth, distance_m)
    estimated = P.existing(dive_path, P.SLAM_CORRECTION)
    if scores is not None and estimated is not None:
        compass = compass_section(dive_path, estimated)
        scores["deviation_rmse_deg"] = compass["deviation_rmse_deg"]
        scores["deviation_shape_rmse_deg"] = compass["shape_rmse_deg"]
    return scores


def _loops(dive_path: Path, truth: Trajectory, distance_m: float) -> dict[str, Any] | None:
    """Visual loop closures against the truly overlapping pairs (:mod:`auvnav.vision.evaluate`)."""
    from auvnav.vision.evaluate import loops_section

    return loops_section(dive_path, truth, distance_m)


def _depth(dive_path: Path, truth: Trajectory, distance_m: float) -> dict[str, Any] | None:
    """Loop-closure depth residuals before and after the tide (:mod:`auvnav.depth.evaluate`)."""
    from auvnav.depth.evaluate import depth_section

    return depth_section(dive_path)


#: Sections in output order (DESIGN section 7): name -> scorer (None when its products are absent).
SECTIONS: dict[str, Section] = {
    "dr": trajectory_section(P.NAV_DR),
    "filter": trajectory_section(P.NAV_FILTER),
    "slam": _slam,
    "loops": _loops,
    "compass": _compass,
    "depth": _depth,
}


def read_truth(dive_path: Path) -> Trajectory:
    """A simulated dive's true trajectory; a one-line error when the dive has none."""
    path = Path(dive_path) / TRUTH_FILE
    if not path.is_file():
        raise DiveFormatError(
            [Problem(str(path), "not found: only simulated dives have a truth to score against")]
        )
    return read_trajectory(path)


def evaluate_dive(dive_path: Path, *, compass_correction: Path | None = None) -> dict[str, Any]:
    """Score every product of a simulated dive that exists against its truth.

    Parameters
    ----------
    dive_path : Path
        A dive folder with ``truth/trajectory.csv``.
    compass_correction : Path, optional
        A compass correction file to score in the ``compass`` section instead of the dive's own
        ``products/compass/correction.yaml``.

    Returns
    -------
    dict
        ``{"distance_m": float, <section>: {...}, ...}`` (DESIGN section 7), a section per stage whose
        products exist.
    """
    dive_path = Path(dive_path)
    truth = read_truth(dive_path)
    distance = truth.distance_m()
    result: dict[str, Any] = {"distance_m": distance}
    for name, section in SECTIONS.items():
        if name == "compass" and compass_correction is not None:
            scores = compass_section(dive_path, Path(compass_correction))
        else:
            scores = section(dive_path, truth, distance)
        if scores is not None:
            result[name] = scores
    return result


def format_scores(result: dict[str, Any]) -> str:
    """A short human-readable table of :func:`evaluate_dive`'s result."""
    lines = [f"distance travelled (truth): {result['distance_m']:.1f} m"]
    sections = [(name, value) for name, value in result.items() if isinstance(value, dict)]
    if not sections:
        lines.append("no products to score")
    for name, scores in sections:
        cells = ", ".join(
            f"{key} {value:.4g}" if isinstance(value, float) else f"{key} {value}"
            for key, value in scores.items()
        )
        lines.append(f"{name:8s} {cells}")
    return "\n".join(lines)
