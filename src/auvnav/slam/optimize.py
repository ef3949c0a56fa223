"""Solving a dive's SLAM graph (:mod:`auvnav.slam.graph`), and the marginal uncertainties.

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

Loop closures are first selected by pairwise consistency against the odometry
(:mod:`auvnav.slam.pcm`, ``loop_selection="pcm"``, the default): the Cauchy kernel alone follows false
loop closures wherever they outnumber the true ones (the default survey flown with the raw compass,
20% false: 28.3 m aligned ATE against 2.8 m clean; with the selection 2.75 m,
benchmarks/bench_slam_robust.py). The rejected ones stay out of every stage of the solve.

Online (``online``): the dive replayed in time order, :mod:`auvnav.slam.online`.

Incremental (what a vehicle would run): iSAM2, ``poses_per_update`` poses per update
(:data:`auvnav.slam.graph.DEFAULT_POSES_PER_UPDATE`; 1 is pose by pose), each with every factor that joins it to the
poses before it, the chosen kernel throughout (each new loop closure meets an estimate that the
earlier ones already corrected).

Marginal covariances of the poses come from the Bayes tree of the solved graph, linearised and
eliminated by QR (robust factors at their final weights, the rejected loop closures left out);
``marginal_every`` > 1 computes every that-many-th image pose (and the first and last poses) and
interpolates the sigmas in time between them. Every pose of a navigation check dive takes seconds.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray

from auvnav.frames import FloatArray, rot2euler
from auvnav.slam.compass import COEFFICIENTS_KEY
from auvnav.slam.dvl import CALIBRATION_KEY
from auvnav.slam.graph import SensorGraph, SlamOptions
from auvnav.slam.online import CalibratedOdometry, OnlineRecord, isam2_update, relinearize_thresholds, replay
from auvnav.slam.pcm import LoopSelection, select_loops
from auvnav.slam.poses import pose_key
from auvnav.slam.solve import PoseGraphSolveError, one_line
from auvnav.trajectory import Trajectory

log = logging.getLogger(__name__)

#: The batch solve's robust kernel thresholds, in units of the final one: graduated from residuals of
#: metres (dead reckoning's) down to the chi-square threshold.
GRADUATED_SCALES = (64.0, 8.0, 1.0)
#: With the DVL calibration estimated, the batch solve relinearises the odometry until no pose's
#: rotation matrix or position changes by more than this between rounds (m), or this many rounds
#: (:func:`lm_relinearized`).
RELINEARIZED_TOLERANCE = 1e-4
MAX_RELINEARIZATIONS = 5
#: GTSAM's default relinearisation threshold of iSAM2, which ``--incremental`` keeps.
ISAM2_RELINEARIZE_THRESHOLD = 0.1


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
    calibration : ndarray, shape (5,), or None
        The estimated DVL calibration (:class:`auvnav.slam.dvl.DvlCalibration`'s ``c``).
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
    selection : LoopSelection or None
        The pairwise-consistency selection made before the solve (its rejections are in ``rejected``).
    online : OnlineRecord or None
        The online replay's record (``options.online``).
    """

    graph: SensorGraph
    T_ned_body: FloatArray
    coefficients_rad: FloatArray | None
    calibration: FloatArray | None
    loop_chi2: FloatArray
    rejected: NDArray[np.int64]
    cost_before: float
    cost_after: float
    chi2_after: float
    iterations: int
    seconds: float
    method: str
    robust: str
    selection: LoopSelection | None = None
    online: OnlineRecord | None = None

    def values(self) -> gtsam.Values:
        return self.graph.values(self.T_ned_body, self.coefficients_rad, self.calibration)


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
        raise PoseGraphSolveError(f"SLAM solve failed: {one_line(err)}") from None


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


def lm_solve(
    graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, max_iterations: int = 100
) -> gtsam.Values:
    """Levenberg-Marquardt by Cholesky, finished by QR (:func:`_lm_cholesky_then_qr`), on one graph."""
    return _lm_cholesky_then_qr([graph], values, max_iterations)[0]


def _isam2(
    sg: SensorGraph, poses_per_update: int, drop_loops: NDArray[np.bool_] | None = None
) -> tuple[gtsam.Values, int]:
    """iSAM2, ``poses_per_update`` poses per update, each with every factor that joins it to earlier poses.

    A new pose's initial guess is the previous pose's (its estimate, or its prediction when it waits
    in the same update) composed with their DVL odometry.
    """
    skip = np.zeros(len(sg.factors), dtype=bool)
    if drop_loops is not None:
        skip[np.array([kind == "loop" for kind in sg.kinds], dtype=bool)] = drop_loops
    params = gtsam.ISAM2Params()
    # Cholesky (no damping in iSAM2) reports an indeterminate system on dive graphs; QR does not.
    params.setFactorization("QR")
    if sg.dvl is not None:
        params.setRelinearizeThreshold(relinearize_thresholds(sg, ISAM2_RELINEARIZE_THRESHOLD))
    isam = gtsam.ISAM2(params)
    order = np.argsort(sg.last_pose, kind="stable")
    bounds = np.searchsorted(sg.last_pose[order], np.arange(-1, len(sg.times) + 1))
    P = len(sg.times)
    current = sg.initial[0]
    updates = 0
    odometry = (
        None
        if sg.dvl is None
        else CalibratedOdometry(sg, ISAM2_RELINEARIZE_THRESHOLD, params.relinearizeSkip)
    )
    for first in range(0, P, poses_per_update):
        last = min(first + poses_per_update, P) - 1
        # the priors of the other unknowns come with the first update
        new = order[bounds[0] if first == 0 else bounds[first + 1] : bounds[last + 2]]
        factors = [int(f) for f in new if not skip[f]]
        current = isam2_update(isam, sg, odometry, factors, first, last, current)[-1]
        updates += 1
    isam.update()
    return isam.calculateBestEstimate(), updates


def lm_relinearized(
    build: Callable[[gtsam.Values], gtsam.NonlinearFactorGraph],
    values: gtsam.Values,
    max_iterations: int = 100,
) -> tuple[gtsam.Values, int]:
    """Levenberg-Marquardt (Cholesky, then QR: :func:`_lm_cholesky_then_qr`) on ``build(values)``, the
    graph built again at each solution, until no pose's rotation matrix or position changes by more
    than :data:`RELINEARIZED_TOLERANCE` (at most :data:`MAX_RELINEARIZATIONS` rounds): a graph whose
    DVL odometry is linearised where it is built (:meth:`~auvnav.slam.graph.SensorGraph.odometry_at`)
    is solved by Gauss-Newton on that odometry, two or three rounds. Returns the solution and the
    iterations of all rounds."""
    total = 0
    for _ in range(MAX_RELINEARIZATIONS):
        before = gtsam.utilities.extractPose3(values)
        values, n = _lm_cholesky_then_qr([build(values)], values, max_iterations)
        total += n
        if np.max(np.abs(gtsam.utilities.extractPose3(values) - before)) < RELINEARIZED_TOLERANCE:
            break
    return values, total


def solve(sg: SensorGraph, options: SlamOptions) -> SlamSolution:
    """Solve a sensor graph: graduated batch Levenberg-Marquardt, or iSAM2 (module docstring), the
    loop closures first selected by pairwise consistency (:mod:`auvnav.slam.pcm`) when asked."""
    start = time.perf_counter()
    selection = None
    drop = None
    record = None
    if options.online:
        values, record = replay(
            sg, options.poses_per_update, options.loop_latency_s, select=options.loop_selection == "pcm"
        )
        selection, drop = record.selection, ~record.selection.keep
    elif options.loop_selection == "pcm":
        selection = select_loops(sg.pose_graph, len(sg.times) - 1)
        drop = ~selection.keep
        log.info(
            "pairwise consistency: %d of %d loop closures kept (%d pairs tested)",
            int(np.count_nonzero(selection.keep)),
            len(selection.keep),
            selection.pairs,
        )
    values0 = sg.values()
    graph = sg.graph(drop_loops=drop)
    cost_before = 2.0 * float(graph.error(values0))
    if record is not None:
        iterations, method = len(record.update_seconds), "isam2-online"
    elif options.incremental:
        values, iterations = _isam2(sg, options.poses_per_update, drop)
        method = "isam2"
    else:
        scales = GRADUATED_SCALES if options.robust != "none" else (1.0,)
        stages = [
            sg.graph(options.robust, scale, drop_loops=drop) if scale != 1.0 else graph for scale in scales
        ]
        values, iterations = _lm_cholesky_then_qr(stages, values0, options.max_iterations)
        if sg.dvl is not None:  # the final stage again, with the DVL calibration unknown
            values, more = lm_relinearized(
                lambda at: sg.graph(drop_loops=drop, linearized_at=at), values, options.max_iterations
            )
            iterations += more
        method = "lm"
    seconds = time.perf_counter() - start
    T = np.stack([values.atPose3(pose_key(k)).matrix() for k in range(len(sg.times))])
    x = values.atVector(COEFFICIENTS_KEY) if sg.compass.estimate else None
    c = values.atVector(CALIBRATION_KEY) if sg.dvl is not None else None
    is_loop = np.array([kind == "loop" for kind in sg.kinds])
    plain = [
        sg.calibrated_odometry(f, c) if c is not None and kind == "odometry" else factor
        for f, (factor, kind) in enumerate(zip(sg.plain, sg.kinds, strict=True))
    ]
    chi2 = np.array([2.0 * f.error(values) for f in plain])
    at_solution = graph if c is None else sg.graph(drop_loops=drop, calibration=c)
    loop_chi2 = chi2[is_loop]
    over = np.sqrt(loop_chi2) > sg.loop_k if options.robust != "none" else np.zeros(len(loop_chi2), bool)
    if drop is not None:
        over |= drop
    rejected = sg.loop_rows[over]
    solution = SlamSolution(
        graph=sg,
        T_ned_body=T,
        coefficients_rad=None if x is None else np.asarray(x, dtype=float),
        calibration=None if c is None else np.asarray(c, dtype=float),
        loop_chi2=loop_chi2,
        rejected=rejected,
        cost_before=cost_before,
        cost_after=2.0 * float(at_solution.error(values)),
        chi2_after=float(chi2.sum() - loop_chi2[over].sum()),
        iterations=iterations,
        seconds=seconds,
        method=method,
        robust=options.robust,
        selection=selection,
        online=record,
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
    calibration_covariance : ndarray, shape (5, 5), or None
        Of the estimated DVL calibration.
    computed : int
        Poses whose marginal was computed (the others interpolated).
    """

    sigma_ned_m: FloatArray
    sigma_yaw_rad: FloatArray
    coefficients_covariance: FloatArray | None
    calibration_covariance: FloatArray | None
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
    values = solution.values()
    graph = sg.graph(drop_loops=np.isin(sg.loop_rows, solution.rejected), linearized_at=values)
    linear = graph.linearize(values)
    try:
        # QR, not gtsam.Marginals' Cholesky: with thousands of millimetre-precise visual loop
        # closures beside metre-precise GPS fixes, Cholesky's pivots lose their precision and GTSAM
        # calls the system indeterminate (the demo's navigation check dive, 18,000 loop closures).
        m = linear.eliminateMultifrontal(gtsam.Ordering.ColamdGaussianFactorGraph(linear), gtsam.EliminateQR)
    except RuntimeError as err:
        raise PoseGraphSolveError(f"marginals failed: {one_line(err)}") from None
    if every <= 1:
        rows = np.arange(P)
    else:
        rows = np.union1d(np.flatnonzero(sg.times.is_image)[::every], [0, P - 1])
    sig_p = np.empty((len(rows), 3))
    sig_y = np.empty(len(rows))
    for n, k in enumerate(rows):
        C = _marginal_covariance(m, pose_key(int(k)))
        R = solution.T_ned_body[k, :3, :3]
        sig_p[n] = np.sqrt(np.diag(R @ C[3:, 3:] @ R.T))
        sig_y[n] = math.sqrt((R @ C[:3, :3] @ R.T)[2, 2])
    t = sg.times.t_s
    sigma_ned = np.stack([np.interp(t, t[rows], sig_p[:, c]) for c in range(3)], -1)
    cov_x = _marginal_covariance(m, COEFFICIENTS_KEY) if sg.compass.estimate else None
    cov_c = _marginal_covariance(m, CALIBRATION_KEY) if sg.dvl is not None else None
    return PoseMarginals(sigma_ned, np.interp(t, t[rows], sig_y), cov_x, cov_c, len(rows))


def _marginal_covariance(tree: gtsam.GaussianBayesTree, key: int) -> FloatArray:
    """A variable's marginal covariance from the Bayes tree, its marginal factor eliminated by QR too
    (``marginalCovariance`` re-eliminates by Cholesky, which calls a 25-minute cut of the check dive
    indeterminate at a pose in a DVL dropout)."""
    try:
        return np.linalg.inv(tree.marginalFactor(key, gtsam.EliminateQR).information())
    except (RuntimeError, np.linalg.LinAlgError) as err:
        raise PoseGraphSolveError(
            f"marginals failed at {gtsam.DefaultKeyFormatter(key)}: {one_line(err)}"
        ) from None


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
