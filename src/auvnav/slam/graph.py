"""The SLAM factor graph of a dive: every sensor as a factor (GTSAM).

The poses and what the sensors say at each are :mod:`auvnav.slam.poses`'; :mod:`auvnav.slam.optimize`
solves the graph. The factors:

- **DVL odometry** between consecutive poses (``BetweenFactorPose3``): the translation is the
  trapezoidal integral of the DVL velocity rotated by the attitude (the navigation's time base,
  :func:`auvnav.nav.nav_inputs`: mount, lever arm and dropouts handled) expressed in the first pose's
  body frame; the rotation is the attitude change. Translation noise per axis: the DVL's white
  velocity noise, ``(sigma_v dt)^2`` per sample; across a bridged dropout of length ``T_g``
  ``sigma_b^2 T_g dt`` per sample, ``sigma_b`` a floor plus a fraction of the fastest horizontal
  speed bridged (vertically, of the fastest speed in 3D): the filter's process noise
  (:func:`auvnav.nav.filter.process_variance`), so a vehicle hovering at the surface and through its
  descent is held by the average of its GPS fixes, not by the last few; the scale error ``(sigma_s |d|)^2`` along the displacement; the
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
  With ``estimate_dvl`` the translation is corrected by the DVL's calibration, unknowns of the graph
  (:mod:`auvnav.slam.dvl`: scale, mounting, the images' time offset), and the scale error leaves the
  noise.
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
  residual exceeds it at the solution is reported as rejected. Before the solve, by default, the loop
  closures are selected by pairwise consistency against the odometry (:mod:`auvnav.slam.pcm`):
  those it rejects stay out of the graph (:attr:`SlamOptions.loop_selection`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Literal

import gtsam
import numpy as np
from numpy.typing import NDArray

from auvnav.depth.pressure import depth_from_pressure
from auvnav.depth.tide import TideModel
from auvnav.dive import Dive
from auvnav.frames import FloatArray, rot2euler, se3, wrap_angle
from auvnav.nav.deadreckon import dead_reckon
from auvnav.nav.filter import FilterConfig, process_variance
from auvnav.nav.inputs import NavInputs, interp_rows
from auvnav.slam.compass import COEFFICIENTS_KEY, CompassModel
from auvnav.slam.dvl import (
    CALIBRATION_KEY,
    N_CALIBRATION,
    DvlCalibration,
    DvlModel,
    linearized_odometry,
    odometry_sensitivity,
)
from auvnav.slam.g2o import PoseGraph
from auvnav.slam.poses import PoseTimes, pose_key, pose_measurements
from auvnav.slam.solve import robust_threshold
from auvnav.vision.loopfile import LoopClosures, check_loop_times

log = logging.getLogger(__name__)

Robust = Literal["none", "huber", "cauchy"]
Selection = Literal["none", "pcm"]

#: The raw compass's heading sigma is the vehicle's times this in the graph (paper: "an artificially
#: large heading measurement noise" for the navigation check dive).
HEADING_INFLATION = 10.0
#: The DVL odometry's roll and pitch sigma is the inclinometer's times this (loose: the inclinometer
#: enters through the unary roll and pitch factors).
ODOMETRY_TILT_FACTOR = 5.0
#: Poses per iSAM2 update by default: an update every 10 s for a camera triggered at 1 Hz
#: (benchmarks/bench_slam.py: the per-pose cost falls almost as 1/K, an update's cost being that of
#: re-eliminating the top of the Bayes tree whatever the poses it adds).
DEFAULT_POSES_PER_UPDATE = 10
#: Huber threshold of the GPS and USBL factors, whitened (sigmas).
FIX_HUBER_K = 3.0
#: Sigma of a coordinate a position factor does not measure (a fix's depth, the pressure depth's north
#: and east): infinite, so GTSAM whitens its row to zero (no information, no chi-square).
UNMEASURED_SIGMA_M = math.inf

# GTSAM's Pose3 tangent is (rotation, translation); g2o's and the loop file's translation first.
_PERM = np.array([3, 4, 5, 0, 1, 2])


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
    estimate_dvl : bool
        Estimate the DVL odometry's calibration (scale, mounting, the images' time offset) with the
        poses (:mod:`auvnav.slam.dvl`).
    robust : {"cauchy", "huber", "none"}
        Kernel on loop closures.
    robust_k : float or None
        Its threshold on the whitened residual norm (None: the back end's chi-square default).
    loop_selection : {"pcm", "none"}
        Loop closures selected by pairwise consistency against the odometry
        (:mod:`auvnav.slam.pcm`) before the solve, or all of them left to the kernel.
    incremental : bool
        iSAM2 instead of batch Levenberg-Marquardt.
    poses_per_update : int
        With ``incremental`` or ``online``: poses added per iSAM2 update (1: pose by pose).
    online : bool
        Replay the dive in time order as the vehicle would (:mod:`auvnav.slam.online`): loop closures
        added when found and decided, the estimate known at each moment recorded.
    loop_latency_s : float
        With ``online``: time from a loop closure's later image to the front end's finding it, seconds.
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
    estimate_dvl: bool = False
    robust: Robust = "cauchy"
    robust_k: float | None = None
    loop_selection: Selection = "pcm"
    incremental: bool = False
    poses_per_update: int = DEFAULT_POSES_PER_UPDATE
    online: bool = False
    loop_latency_s: float = 1.0
    max_iterations: int = 100
    aux_period_s: float = 1.0
    attitude_window_s: float = 1.0
    marginal_every: int = 1

    def __post_init__(self) -> None:
        if self.compass_sigma_rad is not None and not self.compass_sigma_rad > 0:
            raise ValueError(f"compass_sigma_rad must be positive; found {self.compass_sigma_rad}")
        if self.robust not in ("none", "huber", "cauchy"):
            raise ValueError(f"robust must be none, huber or cauchy; found {self.robust!r}")
        if self.loop_selection not in ("none", "pcm"):
            raise ValueError(f"loop_selection must be none or pcm; found {self.loop_selection!r}")
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
        if not self.loop_latency_s >= 0:
            raise ValueError(f"loop_latency_s must be non-negative; found {self.loop_latency_s}")
        if not (self.aux_period_s > 0 and self.attitude_window_s >= 0):
            raise ValueError("aux_period_s must be positive and attitude_window_s non-negative")


def dvl_odometry(
    inputs: NavInputs,
    t: FloatArray,
    R_ned_body: FloatArray,
    config: FilterConfig,
    *,
    yaw_increment_sigma_rad: FloatArray,
    tilt_sigma_rad: float,
    scale_noise: bool = True,
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
    scale_noise : bool
        Count the DVL's scale error as noise of each odometry (False when the graph estimates it,
        :mod:`auvnav.slam.dvl`).

    Returns
    -------
    T_rel : ndarray, shape (P - 1, 4, 4)
        Pose k+1 in body k.
    covariance : ndarray, shape (P - 1, 6, 6)
        In GTSAM's tangent of ``T_rel`` (rotation vector, then translation; right perturbation).
    """
    D = inputs.displacement_ned_m()
    d_ned = np.diff(interp_rows(t, inputs.t_s, D), axis=0)
    d_body = np.einsum("nji,nj->ni", R_ned_body[:-1], d_ned)
    R_rel = np.swapaxes(R_ned_body[:-1], 1, 2) @ R_ned_body[1:]

    # Variance of the integrated velocity, per horizontal axis and vertically (the filter's process
    # noise: white noise, bridged dropouts), between consecutive poses, rotated into body k.
    Q_h, Q_v = process_variance(inputs, config)
    var_h = np.diff(np.interp(t, inputs.t_s, Q_h))
    var_v = np.diff(np.interp(t, inputs.t_s, Q_v))
    n = len(t) - 1
    R0 = R_ned_body[:-1]
    cov_t = np.einsum("nji,nj,njk->nik", R0, np.stack([var_h, var_h, var_v], -1), R0)
    if scale_noise:
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
        Factors in insertion order, loop closures with their robust kernel. With the DVL
        calibration estimated (:attr:`dvl`), the odometry factors here are the uncalibrated ones:
        the solvers take :meth:`odometry_at`, costs at a solution :meth:`calibrated_odometry`.
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
    dvl : DvlModel or None
        The calibration's prior when the graph estimates the DVL odometry's calibration.
    odometry_sensitivity : ndarray, shape (P - 1, 3, 5), or None
        Each odometry's translation's first-order sensitivity to the calibration (when estimated
        or given; :func:`auvnav.slam.dvl.odometry_sensitivity`).
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
    dvl: DvlModel | None = None
    odometry_sensitivity: FloatArray | None = None

    def factor_counts(self) -> dict[str, int]:
        """Factors by kind."""
        kinds, counts = np.unique(self.kinds, return_counts=True)
        return {str(k): int(c) for k, c in zip(kinds, counts, strict=True)}

    def unknowns(
        self, coefficients: FloatArray | None = None, calibration: FloatArray | None = None
    ) -> gtsam.Values:
        """GTSAM values of the unknowns besides the poses: the compass coefficients and the DVL
        calibration when estimated, at zero (the initial guess) or as given."""
        values = gtsam.Values()
        if self.compass.estimate:
            x = np.zeros(self.compass.n_coefficients) if coefficients is None else coefficients
            values.insert(COEFFICIENTS_KEY, np.asarray(x, dtype=float))
        if self.dvl is not None:
            c = np.zeros(N_CALIBRATION) if calibration is None else calibration
            values.insert(CALIBRATION_KEY, np.asarray(c, dtype=float))
        return values

    def values(
        self,
        T_ned_body: FloatArray | None = None,
        coefficients: FloatArray | None = None,
        calibration: FloatArray | None = None,
    ) -> gtsam.Values:
        """GTSAM values: the poses (default: the initial guess) and the other unknowns (:meth:`unknowns`)."""
        poses = self.initial if T_ned_body is None else T_ned_body
        values = self.unknowns(coefficients, calibration)
        for k, T in enumerate(poses):
            values.insert(pose_key(k), gtsam.Pose3(T))
        return values

    def _odometry(self, f: int) -> tuple[int, int, FloatArray, FloatArray, gtsam.noiseModel.Base]:
        """Keys, uncalibrated measurement, calibration sensitivity and noise of odometry factor ``f`` of
        a graph estimating the DVL calibration."""
        if self.dvl is None or self.odometry_sensitivity is None or self.kinds[f] != "odometry":
            raise ValueError(
                f"factor {f} is not an odometry factor of a graph estimating the DVL calibration"
            )
        k = int(self.last_pose[f])
        noise = self.factors[f].noiseModel()
        return (
            pose_key(k - 1),
            pose_key(k),
            self.pose_graph.T_ij[k - 1],
            self.odometry_sensitivity[k - 1],
            noise,
        )

    def calibrated_odometry(self, f: int, calibration: FloatArray) -> gtsam.BetweenFactorPose3:
        """Odometry factor ``f`` with its translation corrected by a known calibration ``c``,
        ``t + J c`` (:mod:`auvnav.slam.dvl`)."""
        i, j, T, J, noise = self._odometry(f)
        T = T.copy()
        T[:3, 3] += J @ np.asarray(calibration, dtype=float)
        return gtsam.BetweenFactorPose3(i, j, gtsam.Pose3(T), noise)

    def odometry_at(self, f: int, values: gtsam.Values) -> gtsam.LinearContainerFactor:
        """Odometry factor ``f`` with the DVL calibration unknown, linearised at ``values`` (its poses
        and the calibration; :func:`auvnav.slam.dvl.linearized_odometry`)."""
        i, j, T, J, noise = self._odometry(f)
        return linearized_odometry(
            i, j, T, J, noise, values.atPose3(i), values.atPose3(j), values.atVector(CALIBRATION_KEY)
        )

    def graph(
        self,
        kernel: Robust | Literal["built"] = "built",
        scale: float = 1.0,
        drop_loops: NDArray[np.bool_] | None = None,
        *,
        linearized_at: gtsam.Values | None = None,
        calibration: FloatArray | None = None,
    ) -> gtsam.NonlinearFactorGraph:
        """The GTSAM factor graph.

        With the DVL calibration estimated (:attr:`dvl`), the odometry factors are either linearised
        at ``linearized_at`` with the calibration unknown (:meth:`odometry_at`: for solving), or
        exact ``BetweenFactorPose3`` for the given ``calibration`` (for the cost at a solution);
        neither, the uncalibrated odometry.

        Parameters
        ----------
        kernel : {"built", "cauchy", "huber", "none"}
            The loop closures' kernel: as built, or another one with its threshold ``scale`` times
            :attr:`loop_k`.
        scale : float
        drop_loops : ndarray of bool, shape (L,), optional
            Loop closures (in the order of :attr:`loop_rows`) to leave out.
        linearized_at : gtsam.Values, optional
        calibration : ndarray, shape (5,), optional
        """
        graph = gtsam.NonlinearFactorGraph()
        loop = 0
        # The loop closures are the pose graph's edges after the odometry.
        first_loop_edge = self.pose_graph.n_poses - 1
        for f, (factor, kind) in enumerate(zip(self.factors, self.kinds, strict=True)):
            if kind == "odometry" and self.dvl is not None and linearized_at is not None:
                graph.add(self.odometry_at(f, linearized_at))
                continue
            if kind == "odometry" and self.dvl is not None and calibration is not None:
                graph.add(self.calibrated_odometry(f, calibration))
                continue
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
    dvl_calibration: DvlCalibration | None = None,
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
    dvl_calibration : DvlCalibration, optional
        A fixed calibration of the DVL odometry (not with ``options.estimate_dvl``).
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
    p0 = interp_rows(times.t_s, dr.t_s, dr.p_ned_m)
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
        scale_noise=not options.estimate_dvl,
    )
    dvl = DvlModel.for_vehicle(vehicle) if options.estimate_dvl else None
    J_odo = None
    if dvl is not None or dvl_calibration is not None:
        J_odo = odometry_sensitivity(inputs, times.t_s, meas.R_ned_body, times.is_image)
    if dvl is None and dvl_calibration is not None:
        T_odo[:, :3, 3] += J_odo @ dvl_calibration.c

    factors = _Factors()
    if compass.estimate:
        factors.add("prior", -1, compass.coefficient_prior())
    if dvl is not None:
        factors.add("prior", -1, dvl.prior())
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
        check_loop_times(loops, image_t, loops_name)
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
        dvl=dvl,
        odometry_sensitivity=J_odo,
    )
