"""The SLAM pose graph of a dive: every sensor as a factor (GTSAM), solved in batch or incrementally.

Poses
-----
One pose ``X(k) = gtsam.symbol("x", k)`` (``gtsam.Pose3``: ``R_ned_body`` and the reference point's
position, metres, local NED) per stereo pair, at the times of ``images/index.csv`` (or, for a
simulated dive without rendered images, ``truth/image_times.csv``, written by
``auvnav simulate --truth-loops``; its column ``t``), so pose ``i`` of a loop file is row ``i`` of
the image times. Auxiliary poses fill the rest of the navigated span (:class:`PoseTimes`): at every
GPS or USBL fix that does not fall on an image (within :data:`MERGE_S`), and every
``aux_period_s`` through gaps without images (the descent, the surface), so the fixes reach the
images through the DVL.

Factors
-------
- **DVL odometry** between consecutive poses (``BetweenFactorPose3``): the translation is the
  trapezoidal integral of the DVL velocity rotated by the attitude (the navigation's time base,
  :func:`auvnav.nav.nav_inputs`: mount, lever arm and dropouts handled) expressed in the first pose's
  body frame; the rotation is the attitude change. Translation noise per axis: the DVL's white
  velocity noise, ``(sigma_v dt)^2`` per sample; across a bridged dropout of length ``T_g``
  ``sigma_b^2 T_g dt`` per sample, ``sigma_b`` a floor plus a fraction of the speed (as the filter,
  :class:`auvnav.nav.FilterConfig`); the scale error ``(sigma_s |d|)^2`` along the displacement; the
  tilt error ``(sigma_tilt |d|)^2`` vertically. Rotation noise: roll and pitch loose
  (:data:`ODOMETRY_TILT_FACTOR` times the inclinometer's sigma, so the inclinometer counts once,
  through its unary factors); the yaw increment comes from the compass, whose white noise is taken
  as the inclinometer's sigma (a tilt error ``e`` turns the levelled heading by about
  ``e tan(inclination)``, ``|tan I| ~ 1`` at mid latitudes) averaged over the attitude window, plus
  the change of the deviation across a turn: a deviation of amplitude ``A`` in its first harmonic
  changes by up to ``A`` per radian turned, with ``A`` the compass's ``heading_sigma_rad`` when a
  correction is applied and :data:`HEADING_INFLATION` times that for the raw compass (also when
  the deviation is estimated: the increments are the raw compass's). On a straight line the
  increments are as good as the compass's noise; through a turn they give way to the imagery.
- **Roll and pitch** (``AttitudeFactorPose3``: the measured direction of gravity in the body), the
  inclinometer's sigma (``vehicle.pitch_roll_sigma_rad``).
- **Depth** (:func:`position_factor` on the down coordinate only): pressure depth of the reference
  point (TEOS-10, lever arm removed), less the tide when a tide model is given (DESIGN section 4:
  depth below the datum), sigma the pressure sensor's.
- **Compass heading** (:func:`auvnav.slam.compass.heading_factor`, one factor for every mode: exact
  for any heading error, blind to roll and pitch): raw, corrected by a given correction, or joined
  to the deviation's coefficients when they are estimated. Its sigma is an option; by default the
  compass's (``vehicle.heading_sigma_rad``) times :data:`HEADING_INFLATION` for a raw compass (the
  paper's "artificially large heading measurement noise": the headings come from the imagery and
  the compass's bias does not leak into them), and the compass's own with a correction or when
  estimating the deviation.
- **GPS and USBL** (:func:`position_factor` on the horizontal position of the antenna or
  transponder, lever arm included, Huber kernel at :data:`FIX_HUBER_K` sigmas against the odd bad
  fix), their sigmas.
  Without fixes, a prior on the first pose's horizontal position at the dive's origin
  (``FilterConfig.origin_sigma_m``) fixes the gauge.
- **Loop closures** (``BetweenFactorPose3``) with the file's covariance converted to GTSAM's tangent
  (:func:`loop_covariance_tangent`), wrapped in a robust kernel (Cauchy by default) with the back
  end's threshold (:func:`auvnav.slam.solve.robust_threshold`); a loop closure whose whitened
  residual exceeds it at the solution is reported as rejected.

The attitude at a pose is the mean of the navigation samples within ``attitude_window_s`` of its
time (circular for headings), as is its depth.

Solving
-------
Batch (post-processing): Levenberg-Marquardt from dead reckoning. A redescending kernel (Cauchy)
cannot tell a true loop closure from a false one when dead reckoning is metres off, so the batch
solve is graduated, in the spirit of graduated non-convexity (Yang et al. 2020, "Graduated
Non-Convexity for Robust Spatial Perception", IEEE RA-L 5(2)): the kernel's threshold starts
:data:`GRADUATED_SCALES` ``[0]`` times its final value, so that every loop closure but the grossest
pulls quadratically while dead reckoning is metres off, and shrinks stage by stage, each stage
starting from the last one's solution. (GTSAM's ``GncLMOptimizer`` classifies as well but runs a
full solve per step of its schedule, dozens of them: minutes for a navigation check dive.) Each stage's
linear systems are solved by Cholesky, and a last Levenberg-Marquardt run by QR finishes the solve
(:func:`_lm_cholesky_then_qr`).

Incremental (what a vehicle would run): iSAM2, ``poses_per_update`` poses per update
(:data:`DEFAULT_POSES_PER_UPDATE`; 1 is pose by pose), each with every factor that joins it to the
poses before it, the chosen kernel throughout (each new loop closure meets an estimate that the
earlier ones already corrected).

Marginal covariances of the poses come from the Bayes tree of the solved graph, linearised and
eliminated by QR (robust factors at their final weights, the rejected loop closures left out);
``marginal_every`` > 1 computes every that-many-th image pose (and the first and last poses) and
interpolates the sigmas in time between them. Every pose of a navigation check dive takes seconds.
"""

from __future__ import annotations

import itertools
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import gtsam
import numpy as np
from numpy.typing import NDArray

from auvnav.depth.pressure import depth_from_pressure
from auvnav.depth.tide import TideModel
from auvnav.dive import Dive
from auvnav.errors import DiveFormatError, InsufficientDataError, Problem
from auvnav.frames import FloatArray, euler2rot, rot2euler, se3, wrap_angle
from auvnav.nav import FilterConfig, NavInputs, dead_reckon
from auvnav.slam.compass import COEFFICIENTS_KEY, CompassModel
from auvnav.slam.g2o import PoseGraph
from auvnav.slam.solve import PoseGraphSolveError, robust_threshold
from auvnav.streams import Field, read_table
from auvnav.trajectory import Trajectory
from auvnav.vision.loopfile import LoopClosures

log = logging.getLogger(__name__)

Robust = Literal["none", "huber", "cauchy"]

IMAGE_TIMES_FILE = Path("truth") / "image_times.csv"
#: A fix this close to an image time is attached to the image's pose, seconds.
MERGE_S = 0.05
#: Loop-file times may differ from the pose times by this much, seconds.
LOOP_TIME_TOLERANCE_S = 1e-3
#: The raw compass's heading sigma is the vehicle's times this in the graph (paper: "an artificially
#: large heading measurement noise" for the navigation check dive).
HEADING_INFLATION = 10.0
#: The DVL odometry's roll and pitch sigma is the inclinometer's times this (loose: the inclinometer
#: enters through the unary roll and pitch factors).
ODOMETRY_TILT_FACTOR = 5.0
#: The batch solve's robust kernel thresholds, in units of the final one: graduated from residuals of
#: metres (dead reckoning's) down to the chi-square threshold.
GRADUATED_SCALES = (64.0, 8.0, 1.0)
#: Poses per iSAM2 update by default: an update every 10 s for a camera triggered at 1 Hz
#: (benchmarks/bench_slam.py: the per-pose cost falls almost as 1/K, an update's cost being that of
#: re-eliminating the top of the Bayes tree whatever the poses it adds).
DEFAULT_POSES_PER_UPDATE = 10
#: Huber threshold of the GPS and USBL factors, whitened (sigmas).
FIX_HUBER_K = 3.0
#: Sigma of a coordinate a position factor does not measure (a fix's depth, the pressure depth's north
#: and east): infinite, so GTSAM whitens its row to zero (no information, no chi-square).
UNMEASURED_SIGMA_M = math.inf

_IMAGE_TIMES_FIELDS = (Field("t_s", ("t",)),)
# GTSAM's Pose3 tangent is (rotation, translation); g2o's and the loop file's translation first.
_PERM = np.array([3, 4, 5, 0, 1, 2])


def pose_key(k: int) -> int:
    """The GTSAM key of pose ``k``."""
    return gtsam.symbol("x", k)


@dataclass(frozen=True)
class SlamOptions:
    """How the graph is built and solved.

    Parameters
    ----------
    compass_sigma_rad : float or None
        Heading sigma of the compass factors; None for the default (module docstring).
    estimate_compass : bool
        Estimate the deviation's coefficients (eq. 5) with the poses.
    harmonics : int
        Harmonics of the estimated deviation.
    robust : {"cauchy", "huber", "none"}
        Kernel on loop closures.
    robust_k : float or None
        Its threshold on the whitened residual norm (None: the back end's chi-square default).
    incremental : bool
        iSAM2 instead of batch Levenberg-Marquardt.
    poses_per_update : int
        With ``incremental``: poses added per iSAM2 update (1: pose by pose).
    max_iterations : int
        Levenberg-Marquardt iteration limit (per stage).
    aux_period_s : float
        Spacing of the auxiliary poses through gaps without images, seconds.
    attitude_window_s : float
        Width of the window the attitude and depth at a pose are averaged over, seconds.
    marginal_every : int
        Compute the marginal covariance of every this-many-th image pose (1: all); 0 skips them.
    """

    compass_sigma_rad: float | None = None
    estimate_compass: bool = False
    harmonics: int = 3
    robust: Robust = "cauchy"
    robust_k: float | None = None
    incremental: bool = False
    poses_per_update: int = DEFAULT_POSES_PER_UPDATE
    max_iterations: int = 100
    aux_period_s: float = 1.0
    attitude_window_s: float = 1.0
    marginal_every: int = 1

    def __post_init__(self) -> None:
        if self.compass_sigma_rad is not None and not self.compass_sigma_rad > 0:
            raise ValueError(f"compass_sigma_rad must be positive; found {self.compass_sigma_rad}")
        if self.robust not in ("none", "huber", "cauchy"):
            raise ValueError(f"robust must be none, huber or cauchy; found {self.robust!r}")
        if (
            self.harmonics < 0
            or self.max_iterations < 1
            or self.marginal_every < 0
            or self.poses_per_update < 1
        ):
            raise ValueError(
                "harmonics and marginal_every must be non-negative, max_iterations and poses_per_update "
                "positive"
            )
        if not (self.aux_period_s > 0 and self.attitude_window_s >= 0):
            raise ValueError("aux_period_s must be positive and attitude_window_s non-negative")


@dataclass(frozen=True)
class PoseTimes:
    """The graph's poses in time order.

    Parameters
    ----------
    t_s : ndarray, shape (P,)
        POSIX seconds, strictly increasing.
    image_row : ndarray of int64, shape (P,)
        Row of the image times of each pose, -1 for auxiliary poses.
    n_images : int
        Rows of the image times (images outside the navigated span have no pose).
    source : str
        Where the image times came from.
    """

    t_s: FloatArray
    image_row: NDArray[np.int64]
    n_images: int
    source: str

    def __post_init__(self) -> None:
        if np.shape(self.t_s) != np.shape(self.image_row) or np.ndim(self.t_s) != 1:
            raise ValueError(f"t_s and image_row must be 1-D and match; found {np.shape(self.t_s)}")
        if not np.all(np.diff(self.t_s) > 0):
            raise ValueError("pose times must be strictly increasing")

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def is_image(self) -> NDArray[np.bool_]:
        return self.image_row >= 0

    def pose_of_image(self) -> NDArray[np.int64]:
        """Pose index of each image row, -1 for images without a pose; shape (n_images,)."""
        out = np.full(self.n_images, -1, dtype=np.int64)
        out[self.image_row[self.is_image]] = np.flatnonzero(self.is_image)
        return out


def read_image_times(dive_path: Path, dive: Dive) -> tuple[FloatArray, str]:
    """The stereo pairs' times: ``images/index.csv``, else ``truth/image_times.csv`` (column ``t``).

    Raises
    ------
    DiveFormatError
        The dive has neither (one line), or the times file is bad.
    """
    if dive.images is not None:
        return dive.images.t_s, "images/index.csv"
    path = Path(dive_path) / IMAGE_TIMES_FILE
    if not path.is_file():
        raise DiveFormatError(
            [
                Problem(
                    str(Path(dive_path) / "images" / "index.csv"),
                    "not found: the graph has a pose per stereo pair (a simulated dive can have "
                    "truth/image_times.csv instead: auvnav simulate ... --truth-loops)",
                )
            ]
        )
    values, problems, _ = read_table(path, _IMAGE_TIMES_FIELDS, str(path))
    if problems:
        raise DiveFormatError(problems)
    return np.asarray(values["t"], dtype=float), str(IMAGE_TIMES_FILE)


def _distance_to_sorted(sorted_values: FloatArray, x: FloatArray) -> FloatArray:
    """Distance from each ``x`` to the nearest of ``sorted_values`` (ascending, not empty)."""
    j = np.searchsorted(sorted_values, x)
    last = len(sorted_values) - 1
    return np.minimum(
        np.abs(x - sorted_values[np.clip(j - 1, 0, last)]), np.abs(sorted_values[np.clip(j, 0, last)] - x)
    )


def build_pose_times(
    image_t_s: FloatArray, inputs: NavInputs, *, aux_period_s: float = 1.0, source: str = ""
) -> PoseTimes:
    """Image poses inside the navigated span, plus auxiliary poses at fixes and through gaps.

    Parameters
    ----------
    image_t_s : ndarray, shape (I,)
        Stereo pair times, POSIX seconds, strictly increasing.
    inputs : NavInputs
        The navigated span (its time base) and its fixes.
    aux_period_s : float
        Largest spacing of poses through gaps without images, seconds.
    source : str
        Where the image times came from.
    """
    t0, t1 = float(inputs.t_s[0]), float(inputs.t_s[-1])
    inside = (image_t_s >= t0) & (image_t_s <= t1)
    if not np.all(inside):
        log.warning(
            "%s: %d of %d stereo pairs lie outside the navigated span (DVL and attitude): no pose",
            source,
            np.count_nonzero(~inside),
            len(image_t_s),
        )
    if not np.any(inside):
        raise InsufficientDataError(f"{source}: no stereo pair lies inside the navigated span")
    t_img = image_t_s[inside]
    fixes = np.concatenate([f.t_s for f in inputs.fixes]) if inputs.fixes else np.zeros(0)
    anchors = np.unique(np.concatenate([t_img, fixes[_distance_to_sorted(t_img, fixes) > MERGE_S]]))
    filler = [
        a + aux_period_s * np.arange(1, math.ceil((b - a) / aux_period_s))
        for a, b in itertools.pairwise(anchors)
        if b - a > 1.5 * aux_period_s
    ]
    t = np.unique(np.concatenate([anchors, *filler]))
    row = np.full(len(t), -1, dtype=np.int64)
    row[np.searchsorted(t, t_img)] = np.flatnonzero(inside)
    return PoseTimes(t, row, len(image_t_s), source)


@dataclass(frozen=True)
class PoseMeasurements:
    """What the sensors say at each pose (window means on the navigation time base).

    Parameters
    ----------
    R_ned_body : ndarray, shape (P, 3, 3)
        Navigated attitude (compass correction if given, declination, mount).
    compass_heading_rad : ndarray, shape (P,)
        The heading as the compass gives it.
    depth_m : ndarray, shape (P,)
        Depth of the reference point from pressure (less the tide when given), metres.
    samples : ndarray of int, shape (P,)
        Navigation samples averaged (1 where interpolated).
    """

    R_ned_body: FloatArray
    compass_heading_rad: FloatArray
    depth_m: FloatArray
    samples: NDArray[np.int64]


def _window_means(
    t: FloatArray, t_s: FloatArray, columns: FloatArray, window_s: float
) -> tuple[FloatArray, NDArray[np.int64]]:
    """Means of ``columns`` (N, c) over ``|t_s - t| <= window_s / 2``; interpolated where empty."""
    lo = np.searchsorted(t_s, t - 0.5 * window_s, side="left")
    hi = np.searchsorted(t_s, t + 0.5 * window_s, side="right")
    count = hi - lo
    cum = np.concatenate([np.zeros((1, columns.shape[1])), np.cumsum(columns, axis=0)])
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (cum[hi] - cum[lo]) / count[:, None]
    empty = count == 0
    if np.any(empty):
        mean[empty] = np.stack([np.interp(t[empty], t_s, columns[:, c]) for c in range(columns.shape[1])], -1)
    return mean, np.maximum(count, 1).astype(np.int64)


def pose_measurements(
    inputs: NavInputs, t: FloatArray, window_s: float, tide: TideModel | None = None
) -> PoseMeasurements:
    """Attitude, compass heading and depth at pose times, each the mean over a window."""
    yaw, h = inputs.yaw_rad, inputs.compass_heading_rad
    columns = np.column_stack(
        [
            np.cos(yaw),
            np.sin(yaw),
            np.cos(h),
            np.sin(h),
            inputs.pitch_rad,
            np.unwrap(inputs.roll_rad),
            inputs.depth_m,
        ]
    )
    mean, count = _window_means(t, inputs.t_s, columns, window_s)
    depth = mean[:, 6] if tide is None else mean[:, 6] - tide.predict(t)
    return PoseMeasurements(
        R_ned_body=euler2rot(np.arctan2(mean[:, 1], mean[:, 0]), mean[:, 4], wrap_angle(mean[:, 5])),
        compass_heading_rad=np.arctan2(mean[:, 3], mean[:, 2]),
        depth_m=depth,
        samples=count,
    )


def dvl_odometry(
    inputs: NavInputs,
    t: FloatArray,
    R_ned_body: FloatArray,
    config: FilterConfig,
    *,
    yaw_increment_sigma_rad: FloatArray,
    tilt_sigma_rad: float,
) -> tuple[FloatArray, FloatArray]:
    """Relative poses between consecutive pose times and their covariance (module docstring).

    Parameters
    ----------
    inputs : NavInputs
    t : ndarray, shape (P,)
        Pose times inside the time base, POSIX seconds.
    R_ned_body : ndarray, shape (P, 3, 3)
        Attitude at the pose times.
    config : FilterConfig
        The DVL's noise figures (velocity, scale, bridging) and the tilt sigma.
    yaw_increment_sigma_rad : ndarray, shape (P - 1,)
        Sigma of each yaw increment, radians.
    tilt_sigma_rad : float
        Sigma of the roll and pitch increments, radians.

    Returns
    -------
    T_rel : ndarray, shape (P - 1, 4, 4)
        Pose k+1 in body k.
    covariance : ndarray, shape (P - 1, 6, 6)
        In GTSAM's tangent of ``T_rel`` (rotation vector, then translation; right perturbation).
    """
    D = inputs.displacement_ned_m()
    d_ned = np.diff(np.stack([np.interp(t, inputs.t_s, D[:, c]) for c in range(3)], -1), axis=0)
    d_body = np.einsum("nji,nj->ni", R_ned_body[:-1], d_ned)
    R_rel = np.swapaxes(R_ned_body[:-1], 1, 2) @ R_ned_body[1:]

    # Per-sample variance of the integrated velocity (per axis): white noise and bridged dropouts.
    dt = np.diff(inputs.t_s)
    bridged_step = inputs.bridged[1:] | inputs.bridged[:-1]
    drop = inputs.dropouts
    which = np.clip(np.searchsorted(drop.start_s, inputs.t_s[:-1], side="right") - 1, 0, None)
    gap_s = drop.duration_s[which] if drop.count else np.zeros(len(dt))
    speed = np.linalg.norm(inputs.v_body_mps[:-1], axis=1)
    sigma_b = config.bridge_velocity_sigma_mps + config.bridge_speed_fraction * speed
    var_step = (config.dvl_velocity_sigma_mps * dt) ** 2 + np.where(
        bridged_step, sigma_b**2 * gap_s * dt, 0.0
    )
    cum = np.concatenate([[0.0], np.cumsum(var_step)])
    var_iso = np.diff(np.interp(t, inputs.t_s, cum))

    n = len(t) - 1
    cov_t = var_iso[:, None, None] * np.eye(3)
    cov_t += config.dvl_scale_sigma**2 * d_body[:, :, None] * d_body[:, None, :]
    cov_t[:, 2, 2] += (config.tilt_sigma_rad * np.linalg.norm(d_body, axis=1)) ** 2
    cov = np.zeros((n, 6, 6))
    cov[:, 0, 0] = cov[:, 1, 1] = tilt_sigma_rad**2
    cov[:, 2, 2] = yaw_increment_sigma_rad**2
    cov[:, 3:, 3:] = np.swapaxes(R_rel, 1, 2) @ cov_t @ R_rel  # translation tangent: R_rel^T dt
    return se3(R_rel, d_body), cov


def loop_covariance_tangent(loops: LoopClosures) -> FloatArray:
    """Loop-file covariances converted to GTSAM's Pose3 tangent at the measurement, shape (N, 6, 6).

    The file's covariance is of ``(x, y, z, roll, pitch, yaw)`` of ``T_i_j``; GTSAM's error of a
    ``BetweenFactorPose3`` is the right perturbation ``T_meas Exp(xi)``, ``xi = (w, v)``. To first order
    ``v = R^T dt`` and ``w = E(roll, pitch) d(roll, pitch, yaw)`` with the Euler ZYX rate matrix
    ``E = [[1, 0, -sin p], [0, cos r, sin r cos p], [0, -sin r, cos r cos p]]`` (the body angular
    velocity of Euler rates), so ``C_xi = J C J^T``, ``J = [[0, E], [R^T, 0]]`` evaluated at the
    measured relative pose.
    """
    r, p = loops.rpy_ij_rad[:, 0], loops.rpy_ij_rad[:, 1]
    n = len(loops)
    E = np.zeros((n, 3, 3))
    E[:, 0, 0] = 1.0
    E[:, 0, 2] = -np.sin(p)
    E[:, 1, 1] = np.cos(r)
    E[:, 1, 2] = np.sin(r) * np.cos(p)
    E[:, 2, 1] = -np.sin(r)
    E[:, 2, 2] = np.cos(r) * np.cos(p)
    J = np.zeros((n, 6, 6))
    J[:, :3, 3:] = E
    J[:, 3:, :3] = np.swapaxes(loops.T_i_j[:, :3, :3], 1, 2)
    C = J @ loops.covariance @ np.swapaxes(J, 1, 2)
    return 0.5 * (C + np.swapaxes(C, 1, 2))


def position_factor(
    key: int,
    p_ned_m: FloatArray,
    sigma_ned_m: FloatArray,
    lever_body_m: FloatArray | None = None,
    *,
    huber_k: float | None = None,
) -> gtsam.GPSFactorArm:
    """A position measurement of a point on the body: GTSAM's ``GPSFactorArm``, ``e = t + R l - p``.

    A coordinate the sensor does not measure gets :data:`UNMEASURED_SIGMA_M` (its measured value,
    the initial guess's, then does not matter): the pressure depth measures only the down
    coordinate, a fix only north and east.

    Parameters
    ----------
    key : int
    p_ned_m : ndarray, shape (3,)
        Measured position of the point, metres, local NED.
    sigma_ned_m : ndarray, shape (3,)
        1-sigma per axis, metres (:data:`UNMEASURED_SIGMA_M` where not measured).
    lever_body_m : ndarray, shape (3,), optional
        The point relative to the reference point, body FRD (default: the reference point).
    huber_k : float, optional
        Wrap the noise in a Huber kernel with this threshold (whitened).
    """
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigma_ned_m, dtype=float))
    if huber_k is not None:
        noise = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(huber_k), noise)
    lever = np.zeros(3) if lever_body_m is None else np.asarray(lever_body_m, dtype=float)
    return gtsam.GPSFactorArm(key, np.asarray(p_ned_m, dtype=float), lever, noise)


_KERNELS = {"huber": gtsam.noiseModel.mEstimator.Huber, "cauchy": gtsam.noiseModel.mEstimator.Cauchy}


def _loop_factor(pg: PoseGraph, e: int, kernel: Robust, k: float) -> gtsam.BetweenFactorPose3:
    """Edge ``e`` of a pose graph as a ``BetweenFactorPose3``, with ``kernel`` (threshold ``k``)."""
    noise = gtsam.noiseModel.Gaussian.Information(pg.information[e][_PERM][:, _PERM])
    if kernel != "none":
        noise = gtsam.noiseModel.Robust.Create(_KERNELS[kernel].Create(k), noise)
    i, j = int(pg.edge_i[e]), int(pg.edge_j[e])
    return gtsam.BetweenFactorPose3(pose_key(i), pose_key(j), gtsam.Pose3(pg.T_ij[e]), noise)


@dataclass
class _Factors:
    """Factors of the graph in insertion order, with their kind and the pose they join last."""

    robust: list[gtsam.NonlinearFactor] = field(default_factory=list)
    plain: list[gtsam.NonlinearFactor] = field(default_factory=list)
    kind: list[str] = field(default_factory=list)
    last_pose: list[int] = field(default_factory=list)

    def add(
        self,
        kind: str,
        last_pose: int,
        factor: gtsam.NonlinearFactor,
        plain: gtsam.NonlinearFactor | None = None,
    ) -> None:
        self.robust.append(factor)
        self.plain.append(factor if plain is None else plain)
        self.kind.append(kind)
        self.last_pose.append(last_pose)


@dataclass(frozen=True)
class SensorGraph:
    """A dive's factor graph, its initial guess and its bookkeeping.

    Parameters
    ----------
    times : PoseTimes
    initial : ndarray, shape (P, 4, 4)
        Dead reckoning at the pose times (``T_ned_body``).
    factors : list
        Factors in insertion order, loop closures with their robust kernel.
    plain : list
        The same factors with Gaussian noise (for chi-square costs).
    kinds : list of str
        Kind of each factor (``odometry``, ``attitude``, ``depth``, ``compass``, ``gps``, ``usbl``,
        ``loop``, ``prior``).
    last_pose : ndarray of int64
        The latest pose each factor joins (-1 for the coefficients' prior): the step of iSAM2 that
        adds it.
    loop_rows : ndarray of int64, shape (L,)
        0-based rows of the loop file used, in the order of the loop factors.
    loops_outside : int
        Loop rows that name an image without a pose (outside the navigated span).
    loop_k : float
        Robust threshold of the loop closures (whitened residual norm).
    compass : CompassModel
    compass_sigma_rad : float
    pose_graph : PoseGraph
        Odometry and loop closures as relative edges (for ``graph.g2o``), poses = ``initial``.
    """

    times: PoseTimes
    initial: FloatArray
    factors: list[gtsam.NonlinearFactor]
    plain: list[gtsam.NonlinearFactor]
    kinds: list[str]
    last_pose: NDArray[np.int64]
    loop_rows: NDArray[np.int64]
    loops_outside: int
    loop_k: float
    compass: CompassModel
    compass_sigma_rad: float
    pose_graph: PoseGraph

    def factor_counts(self) -> dict[str, int]:
        """Factors by kind."""
        kinds, counts = np.unique(self.kinds, return_counts=True)
        return {str(k): int(c) for k, c in zip(kinds, counts, strict=True)}

    def values(
        self, T_ned_body: FloatArray | None = None, coefficients: FloatArray | None = None
    ) -> gtsam.Values:
        """GTSAM values: the poses (default: the initial guess) and the compass coefficients."""
        poses = self.initial if T_ned_body is None else T_ned_body
        values = gtsam.Values()
        for k, T in enumerate(poses):
            values.insert(pose_key(k), gtsam.Pose3(T))
        if self.compass.estimate:
            x = np.zeros(self.compass.n_coefficients) if coefficients is None else coefficients
            values.insert(COEFFICIENTS_KEY, np.asarray(x, dtype=float))
        return values

    def graph(
        self,
        kernel: Robust | Literal["built"] = "built",
        scale: float = 1.0,
        drop_loops: NDArray[np.bool_] | None = None,
    ) -> gtsam.NonlinearFactorGraph:
        """The GTSAM factor graph.

        Parameters
        ----------
        kernel : {"built", "cauchy", "huber", "none"}
            The loop closures' kernel: as built, or another one with its threshold ``scale`` times
            :attr:`loop_k`.
        scale : float
        drop_loops : ndarray of bool, shape (L,), optional
            Loop closures (in the order of :attr:`loop_rows`) to leave out.
        """
        graph = gtsam.NonlinearFactorGraph()
        loop = 0
        # The loop closures are the pose graph's edges after the odometry.
        first_loop_edge = self.pose_graph.n_poses - 1
        for factor, kind in zip(self.factors, self.kinds, strict=True):
            if kind != "loop":
                graph.add(factor)
                continue
            if drop_loops is None or not drop_loops[loop]:
                if kernel == "built":
                    graph.add(factor)
                else:
                    graph.add(
                        _loop_factor(self.pose_graph, first_loop_edge + loop, kernel, scale * self.loop_k)
                    )
            loop += 1
        return graph


def build_graph(
    dive: Dive,
    inputs: NavInputs,
    times: PoseTimes,
    loops: LoopClosures | None,
    compass: CompassModel,
    *,
    options: SlamOptions,
    tide: TideModel | None = None,
    loops_name: str = "loops",
) -> SensorGraph:
    """Assemble the factor graph of a dive (module docstring).

    Parameters
    ----------
    dive : Dive
        Its vehicle's noise figures and mounts.
    inputs : NavInputs
        The dive's sensors on the navigation time base (no correction when estimating the compass).
    times : PoseTimes
    loops : LoopClosures or None
        Checked against ``times`` (pose indices are image rows).
    compass : CompassModel
    options : SlamOptions
    tide : TideModel, optional
        Subtracted from the pressure depth.
    loops_name : str
        The loop file, for messages.

    Raises
    ------
    DiveFormatError
        A loop's times differ from the image times (a loop file of another dive).
    """
    vehicle = dive.vehicle
    depth_sigma = float(depth_from_pressure(vehicle.pressure_sigma_pa, dive.info.origin.latitude_rad))
    config = FilterConfig.for_vehicle(vehicle, depth_sigma)
    meas = pose_measurements(inputs, times.t_s, options.attitude_window_s, tide)
    P = len(times)

    # Initial guess: dead reckoning's positions, the averaged attitude.
    dr = dead_reckon(inputs)
    p0 = np.stack([np.interp(times.t_s, dr.t_s, dr.p_ned_m[:, c]) for c in range(3)], -1)
    p0[:, 2] = meas.depth_m
    initial = se3(meas.R_ned_body, p0)

    # Noise of the heading factors and of the yaw increments.
    if options.compass_sigma_rad is not None:
        heading_sigma = options.compass_sigma_rad
    elif compass.estimate or compass.correction is not None:
        heading_sigma = vehicle.heading_sigma_rad
    else:
        heading_sigma = HEADING_INFLATION * vehicle.heading_sigma_rad
    yaw, _, _ = rot2euler(meas.R_ned_body)
    turn = np.abs(wrap_angle(np.diff(yaw)))
    white = vehicle.pitch_roll_sigma_rad * np.sqrt(1.0 / meas.samples[:-1] + 1.0 / meas.samples[1:])
    corrected = compass.correction is not None and not compass.estimate
    amplitude = vehicle.heading_sigma_rad * (1.0 if corrected else HEADING_INFLATION)
    yaw_inc_sigma = np.hypot(white, amplitude * turn)
    T_odo, C_odo = dvl_odometry(
        inputs,
        times.t_s,
        meas.R_ned_body,
        config,
        yaw_increment_sigma_rad=yaw_inc_sigma,
        tilt_sigma_rad=ODOMETRY_TILT_FACTOR * vehicle.pitch_roll_sigma_rad,
    )

    factors = _Factors()
    if compass.estimate:
        factors.add("prior", -1, compass.coefficient_prior())
    down = gtsam.Unit3(np.array([0.0, 0.0, 1.0]))
    tilt_noise = gtsam.noiseModel.Isotropic.Sigma(2, vehicle.pitch_roll_sigma_rad)
    for k in range(P):
        key = pose_key(k)
        if k > 0:
            factors.add(
                "odometry",
                k,
                gtsam.BetweenFactorPose3(
                    pose_key(k - 1),
                    key,
                    gtsam.Pose3(T_odo[k - 1]),
                    gtsam.noiseModel.Gaussian.Covariance(C_odo[k - 1]),
                ),
            )
        b_down = gtsam.Unit3(meas.R_ned_body[k].T @ np.array([0.0, 0.0, 1.0]))
        factors.add("attitude", k, gtsam.AttitudeFactorPose3(key, down, tilt_noise, b_down))
        factors.add(
            "depth",
            k,
            position_factor(
                key,
                initial[k, :3, 3],
                np.array([UNMEASURED_SIGMA_M, UNMEASURED_SIGMA_M, config.depth_sigma_m]),
            ),
        )
        factors.add(
            "compass",
            k,
            compass.factor(key, float(meas.compass_heading_rad[k]), meas.R_ned_body[k], heading_sigma),
        )

    # Position fixes at their poses (merged within MERGE_S of an image time), north and east.
    for fixes in inputs.fixes:
        k_fix = np.clip(np.searchsorted(times.t_s, fixes.t_s), 1, P - 1)
        earlier = np.abs(times.t_s[k_fix - 1] - fixes.t_s) < np.abs(times.t_s[k_fix] - fixes.t_s)
        k_fix = np.where(earlier, k_fix - 1, k_fix)
        for k, p, s in zip(k_fix, fixes.p_ned_m, fixes.sigma_m, strict=True):
            lever_ned = initial[k, :3, :3] @ fixes.lever_arm_body_m
            measured = np.array([p[0], p[1], initial[k, 2, 3] + lever_ned[2]])
            sigma = np.array([s, s, UNMEASURED_SIGMA_M])
            lever = fixes.lever_arm_body_m
            factors.add(
                fixes.sensor,
                int(k),
                position_factor(pose_key(int(k)), measured, sigma, lever, huber_k=FIX_HUBER_K),
                position_factor(pose_key(int(k)), measured, sigma, lever),
            )
    if not inputs.fixes:
        sigma = np.array([config.origin_sigma_m, config.origin_sigma_m, UNMEASURED_SIGMA_M])
        factors.add("prior", 0, position_factor(pose_key(0), initial[0, :3, 3], sigma))

    # Loop closures between image poses.
    loop_rows = np.zeros(0, dtype=np.int64)
    outside = 0
    edges_i, edges_j = np.arange(P - 1), np.arange(1, P)
    T_edges, info_edges = T_odo, np.linalg.inv(C_odo)[:, _PERM][:, :, _PERM]
    if loops is not None and len(loops):
        image_t = np.full(times.n_images, np.nan)
        image_t[times.image_row[times.is_image]] = times.t_s[times.is_image]
        _check_loop_times(loops, image_t, loops_name)
        pose_of = times.pose_of_image()
        a, b = pose_of[loops.i], pose_of[loops.j]
        used = (a >= 0) & (b >= 0)
        outside = int(np.count_nonzero(~used))
        if outside:
            log.warning("%s: %d loop closures name images without a pose, not used", loops_name, outside)
        loop_rows = np.flatnonzero(used).astype(np.int64)
        C_loop = loop_covariance_tangent(loops.select(used))
        edges_i = np.concatenate([edges_i, a[used]])
        edges_j = np.concatenate([edges_j, b[used]])
        T_edges = np.concatenate([T_edges, loops.T_i_j[used]])
        info_edges = np.concatenate([info_edges, np.linalg.inv(C_loop)[:, _PERM][:, :, _PERM]])
    pose_graph = PoseGraph(
        3,
        np.arange(P, dtype=np.int64),
        initial,
        edges_i.astype(np.int64),
        edges_j.astype(np.int64),
        T_edges,
        0.5 * (info_edges + np.swapaxes(info_edges, 1, 2)),
        source=loops_name,
    )
    loop_k = robust_threshold(3, options.robust_k)
    for e in range(P - 1, pose_graph.n_edges):
        factors.add(
            "loop",
            int(max(pose_graph.edge_i[e], pose_graph.edge_j[e])),
            _loop_factor(pose_graph, e, options.robust, loop_k),
            _loop_factor(pose_graph, e, "none", loop_k),
        )
    return SensorGraph(
        times=times,
        initial=initial,
        factors=factors.robust,
        plain=factors.plain,
        kinds=factors.kind,
        last_pose=np.array(factors.last_pose, dtype=np.int64),
        loop_rows=loop_rows,
        loops_outside=outside,
        loop_k=loop_k,
        compass=compass,
        compass_sigma_rad=heading_sigma,
        pose_graph=pose_graph,
    )


def _check_loop_times(loops: LoopClosures, image_t_s: FloatArray, display: str) -> None:
    """Loops must carry the image times of their poses (else they belong to another dive)."""
    off = np.fmax(np.abs(image_t_s[loops.i] - loops.t_i_s), np.abs(image_t_s[loops.j] - loops.t_j_s))
    bad = np.flatnonzero(off > LOOP_TIME_TOLERANCE_S)
    if bad.size:
        r = int(bad[0])
        raise DiveFormatError(
            [
                Problem(
                    display,
                    f"times of poses {loops.i[r]} -> {loops.j[r]} differ from the image times by "
                    f"{off[r]:.3f} s (a loop file of another dive?)"
                    + (f"; so do {bad.size - 1} more rows" if bad.size > 1 else ""),
                    r + 1,
                )
            ]
        )


@dataclass(frozen=True)
class SlamSolution:
    """A solved sensor graph.

    Parameters
    ----------
    graph : SensorGraph
    T_ned_body : ndarray, shape (P, 4, 4)
        The solution.
    coefficients_rad : ndarray, shape (2N+1,), or None
        The estimated deviation coefficients ``[a0, a1, b1, ...]``.
    loop_chi2 : ndarray, shape (L,)
        Each used loop closure's chi-square at the solution.
    rejected : ndarray of int64
        Rows of the loop file (0-based) whose whitened residual exceeds the kernel's threshold.
    cost_before, cost_after : float
        The objective (twice GTSAM's error, kernels included) at the initial guess and the solution.
    chi2_after : float
        Chi-square of every factor but the rejected loop closures at the solution.
    iterations : int
        Levenberg-Marquardt iterations (all stages) or iSAM2 updates.
    seconds : float
        Wall time of the solve.
    method : str
        ``"lm"`` or ``"isam2"``.
    robust : str
    """

    graph: SensorGraph
    T_ned_body: FloatArray
    coefficients_rad: FloatArray | None
    loop_chi2: FloatArray
    rejected: NDArray[np.int64]
    cost_before: float
    cost_after: float
    chi2_after: float
    iterations: int
    seconds: float
    method: str
    robust: str

    def values(self) -> gtsam.Values:
        return self.graph.values(self.T_ned_body, self.coefficients_rad)


def _lm(
    graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, max_iterations: int, solver: str
) -> tuple[gtsam.Values, int]:
    """GTSAM's Levenberg-Marquardt (default parameters but the iteration limit) with the linear solver
    ``solver`` (``"MULTIFRONTAL_CHOLESKY"`` or ``"MULTIFRONTAL_QR"``)."""
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(max_iterations)
    params.setLinearSolverType(solver)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    try:
        return optimizer.optimize(), int(optimizer.iterations())
    except RuntimeError as err:
        raise PoseGraphSolveError(f"SLAM solve failed: {_one_line(err)}") from None


def _lm_cholesky_then_qr(
    stages: list[gtsam.NonlinearFactorGraph], values: gtsam.Values, max_iterations: int
) -> tuple[gtsam.Values, int]:
    """Levenberg-Marquardt through the graduated ``stages``, by Cholesky, then on the last stage by QR.

    Cholesky is about 20 times faster per iteration on dive graphs (the check dive with 20% false
    loop closures: 21.7 s against 419 s, the same 32 iterations and the same answer), but with
    thousands of millimetre-precise visual loop closures it cannot solve the lightly damped steps
    that move the dive as a whole towards its GPS fixes (GTSAM calls them indeterminate), and LM
    stalled with the dive 12 m from its fixes; QR, run from wherever Cholesky stopped, finishes
    those solves and confirms the others in an iteration or two.
    """
    total = 0
    for stage in stages:
        try:
            values, n = _lm(stage, values, max_iterations, "MULTIFRONTAL_CHOLESKY")
        except PoseGraphSolveError:
            n = 0  # left to QR
        total += n
    values, n = _lm(stages[-1], values, max_iterations, "MULTIFRONTAL_QR")
    return values, total + n


def _one_line(err: Exception) -> str:
    """GTSAM's multi-paragraph messages as one line (their first paragraph)."""
    return " ".join(str(err).strip().split("\n\n")[0].split())


def _isam2(sg: SensorGraph, poses_per_update: int) -> tuple[gtsam.Values, int]:
    """iSAM2, ``poses_per_update`` poses per update, each with every factor that joins it to earlier poses.

    A new pose's initial guess is the previous pose's (its estimate, or its prediction when it waits
    in the same update) composed with their DVL odometry.
    """
    params = gtsam.ISAM2Params()
    # Cholesky (no damping in iSAM2) reports an indeterminate system on dive graphs; QR does not.
    params.setFactorization("QR")
    isam = gtsam.ISAM2(params)
    order = np.argsort(sg.last_pose, kind="stable")
    bounds = np.searchsorted(sg.last_pose[order], np.arange(-1, len(sg.times) + 1))
    P = len(sg.times)
    current = sg.initial[0]
    updates = 0
    for first in range(0, P, poses_per_update):
        new_factors = gtsam.NonlinearFactorGraph()
        new_values = gtsam.Values()
        if first == 0:
            for f in order[bounds[0] : bounds[1]]:  # the coefficients' prior
                new_factors.add(sg.factors[f])
            if sg.compass.estimate:
                new_values.insert(COEFFICIENTS_KEY, np.zeros(sg.compass.n_coefficients))
        last = min(first + poses_per_update, P) - 1
        for k in range(first, last + 1):
            if k > 0:
                current = current @ sg.pose_graph.T_ij[k - 1]  # predict with the odometry
            new_values.insert(pose_key(k), gtsam.Pose3(current))
            for f in order[bounds[k + 1] : bounds[k + 2]]:
                new_factors.add(sg.factors[f])
        try:
            isam.update(new_factors, new_values)
            current = isam.calculateEstimatePose3(pose_key(last)).matrix()
        except RuntimeError as err:
            raise PoseGraphSolveError(
                f"iSAM2 failed adding poses {first} to {last}: {_one_line(err)}"
            ) from None
        updates += 1
    isam.update()
    return isam.calculateEstimate(), updates


def solve(sg: SensorGraph, options: SlamOptions) -> SlamSolution:
    """Solve a sensor graph: graduated batch Levenberg-Marquardt, or iSAM2 (module docstring)."""
    start = time.perf_counter()
    values0 = sg.values()
    graph = sg.graph()
    cost_before = 2.0 * float(graph.error(values0))
    if options.incremental:
        values, iterations = _isam2(sg, options.poses_per_update)
        method = "isam2"
    else:
        scales = GRADUATED_SCALES if options.robust != "none" else (1.0,)
        stages = [sg.graph(options.robust, scale) if scale != 1.0 else graph for scale in scales]
        values, iterations = _lm_cholesky_then_qr(stages, values0, options.max_iterations)
        method = "lm"
    seconds = time.perf_counter() - start
    T = np.stack([values.atPose3(pose_key(k)).matrix() for k in range(len(sg.times))])
    x = values.atVector(COEFFICIENTS_KEY) if sg.compass.estimate else None
    is_loop = np.array([kind == "loop" for kind in sg.kinds])
    chi2 = np.array([2.0 * f.error(values) for f in sg.plain])
    loop_chi2 = chi2[is_loop]
    over = np.sqrt(loop_chi2) > sg.loop_k if options.robust != "none" else np.zeros(len(loop_chi2), bool)
    rejected = sg.loop_rows[over]
    solution = SlamSolution(
        graph=sg,
        T_ned_body=T,
        coefficients_rad=None if x is None else np.asarray(x, dtype=float),
        loop_chi2=loop_chi2,
        rejected=rejected,
        cost_before=cost_before,
        cost_after=2.0 * float(graph.error(values)),
        chi2_after=float(chi2.sum() - loop_chi2[over].sum()),
        iterations=iterations,
        seconds=seconds,
        method=method,
        robust=options.robust,
    )
    log.info(
        "SLAM (%s, %s): %d poses, cost %.6g -> %.6g in %d iterations, %.1f s; %d of %d loop closures rejected",
        method,
        options.robust,
        len(sg.times),
        solution.cost_before,
        solution.cost_after,
        iterations,
        seconds,
        len(rejected),
        len(loop_chi2),
    )
    return solution


@dataclass(frozen=True)
class PoseMarginals:
    """Marginal uncertainties of a solution.

    Parameters
    ----------
    sigma_ned_m : ndarray, shape (P, 3)
        1-sigma position, metres, NED.
    sigma_yaw_rad : ndarray, shape (P,)
        1-sigma heading (rotation about the vertical), radians.
    coefficients_covariance : ndarray, shape (2N+1, 2N+1), or None
        Of the estimated deviation coefficients, rad^2.
    computed : int
        Poses whose marginal was computed (the others interpolated).
    """

    sigma_ned_m: FloatArray
    sigma_yaw_rad: FloatArray
    coefficients_covariance: FloatArray | None
    computed: int


def marginals(solution: SlamSolution, every: int = 1) -> PoseMarginals:
    """Marginal covariances at the solution (module docstring), robust factors at their final weights.

    The rejected loop closures are left out: their weight is nil, and their structure would only
    slow GTSAM's marginals (a hundredfold with a fifth of them false).

    Parameters
    ----------
    solution : SlamSolution
    every : int
        Compute every this-many-th image pose and the last pose (1: every pose, auxiliary included),
        interpolating the sigmas in time between them.
    """
    sg = solution.graph
    P = len(sg.times)
    graph = sg.graph(drop_loops=np.isin(sg.loop_rows, solution.rejected))
    linear = graph.linearize(solution.values())
    try:
        # QR, not gtsam.Marginals' Cholesky: with thousands of millimetre-precise visual loop
        # closures beside metre-precise GPS fixes, Cholesky's pivots lose their precision and GTSAM
        # calls the system indeterminate (the demo's navigation check dive, 18,000 loop closures).
        m = linear.eliminateMultifrontal(gtsam.Ordering.ColamdGaussianFactorGraph(linear), gtsam.EliminateQR)
    except RuntimeError as err:
        raise PoseGraphSolveError(f"marginals failed: {_one_line(err)}") from None
    if every <= 1:
        rows = np.arange(P)
    else:
        rows = np.union1d(np.flatnonzero(sg.times.is_image)[::every], [0, P - 1])
    sig_p = np.empty((len(rows), 3))
    sig_y = np.empty(len(rows))
    for n, k in enumerate(rows):
        C = m.marginalCovariance(pose_key(int(k)))
        R = solution.T_ned_body[k, :3, :3]
        sig_p[n] = np.sqrt(np.diag(R @ C[3:, 3:] @ R.T))
        sig_y[n] = math.sqrt((R @ C[:3, :3] @ R.T)[2, 2])
    t = sg.times.t_s
    sigma_ned = np.stack([np.interp(t, t[rows], sig_p[:, c]) for c in range(3)], -1)
    cov_x = m.marginalCovariance(COEFFICIENTS_KEY) if sg.compass.estimate else None
    return PoseMarginals(sigma_ned, np.interp(t, t[rows], sig_y), cov_x, len(rows))


def solution_trajectory(solution: SlamSolution, sigmas: PoseMarginals | None) -> Trajectory:
    """The image poses of a solution as a trajectory (with sigmas when given)."""
    image = solution.graph.times.is_image
    yaw, pitch, roll = rot2euler(solution.T_ned_body[image, :3, :3])
    return Trajectory(
        t_s=solution.graph.times.t_s[image],
        p_ned_m=solution.T_ned_body[image, :3, 3],
        roll_rad=roll,
        pitch_rad=pitch,
        yaw_rad=yaw,
        sigma_ned_m=None if sigmas is None else sigmas.sigma_ned_m[image],
        sigma_yaw_rad=None if sigmas is None else sigmas.sigma_yaw_rad[image],
    )
