"""Solving pose graphs with GTSAM: batch Levenberg-Marquardt, incremental iSAM2, robust loop closures,
marginal covariances.

The cost everywhere is the chi-square of the graph: the sum over edges of the information-weighted
squared residual ``e^T Lambda e``, with ``e`` GTSAM's ``BetweenFactor`` error (the local coordinates of
the measured relative pose against the estimated one; rotation vector in radians, translation in the
file's unit). It is twice GTSAM's ``NonlinearFactorGraph.error`` and is the quantity tabulated in
``../shared/reference/pose_graph_g2o/gtsam_computed_reference_costs.csv`` (chi2 = 2 x error).

The gauge is fixed as in that table: a prior on the first pose (lowest id) at its initial value with
standard deviation :data:`ANCHOR_SIGMA` in every tangent direction. Its residual is (numerically) zero
at the optimum, so it does not enter the reported costs, which sum the file's edges only.

Robust solving (``robust="huber"`` or ``"cauchy"``) wraps every *loop closure* (an edge between poses
that are not adjacent in id order, :attr:`PoseGraph.is_odometry`) in an M-estimator; odometry edges
stay Gaussian. GTSAM applies the kernel to the whitened residual norm ``r = sqrt(e^T Lambda e)``. Its
threshold ``k`` is by default the square root of the chi-square quantile :data:`ROBUST_QUANTILE` for
the edge's degrees of freedom (3 in 2D, 6 in 3D), so inliers are barely down-weighted; a loop closure
whose ``r`` exceeds ``k`` at the solution is reported as rejected. Kernels: Huber (1964), "Robust
estimation of a location parameter"; Cauchy as in GTSAM's ``mEstimator::Cauchy``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from typing import Literal

import gtsam
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.stats import chi2 as chi2_distribution

from auvnav.errors import AuvnavError, InsufficientDataError
from auvnav.slam.g2o import FloatArray, IntArray, PoseGraph, inverse_rigid

log = logging.getLogger(__name__)

Robust = Literal["none", "huber", "cauchy"]
Initial = Literal["file", "chordal"]

#: Standard deviation of the prior that anchors the first pose (metres and radians), as used for the
#: reference costs (PROVENANCE.md of ../shared/reference/pose_graph_g2o: "prior 1e-6 on the first pose").
ANCHOR_SIGMA = 1e-6

#: Chi-square quantile whose square root is the default robust threshold k for an edge's whitened
#: residual norm (k = 4.10 for 6 degrees of freedom, 3.37 for 3).
ROBUST_QUANTILE = 0.99

# GTSAM's Pose3 tangent is (rx, ry, rz, x, y, z); ours and g2o's is (x, y, z, rx, ry, rz). The
# permutation is its own inverse. Pose2 uses (x, y, theta) in both.
_PERM_3D = np.array([3, 4, 5, 0, 1, 2])


class PoseGraphSolveError(AuvnavError):
    """The solver failed on a graph (an indeterminate system, a failed initialisation)."""


@dataclass(frozen=True)
class SolveResult:
    """The outcome of a pose-graph solve.

    Parameters
    ----------
    graph : PoseGraph
        The input graph with the solution as ``T_world_pose``.
    cost_before, cost_after : float
        Chi-square over all edges at the initial guess and at the solution (dimensionless).
    iterations : int
        Optimiser iterations (batch) or iSAM2 updates (incremental).
    seconds : float
        Wall time of building the factor graph and solving, seconds.
    edge_chi2 : ndarray, shape (M,)
        Each edge's chi-square ``e^T Lambda e`` at the solution.
    rejected : ndarray of int64, shape (R,)
        Indices of the loop closures the robust solution rejects (whitened residual norm above the
        kernel's threshold); empty for ``robust="none"``.
    robust : str
        The kernel used on loop closures.
    method : str
        ``"lm"``, ``"gn"`` or ``"isam2"``.
    step_seconds : ndarray, shape (N,)
        Incremental solves only: wall time per added pose (its update's time divided by the poses
        that update added), seconds; else empty.
    update_seconds : ndarray, shape (U,)
        Incremental solves only: wall time of each iSAM2 update, seconds; else empty.
    """

    graph: PoseGraph
    cost_before: float
    cost_after: float
    iterations: int
    seconds: float
    edge_chi2: FloatArray
    rejected: IntArray
    robust: str
    method: str
    step_seconds: FloatArray = field(default_factory=lambda: np.zeros(0))
    update_seconds: FloatArray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        if np.shape(self.edge_chi2) != (self.graph.n_edges,):
            raise ValueError(
                f"edge_chi2 must have shape ({self.graph.n_edges},); found {np.shape(self.edge_chi2)}"
            )
        if np.ndim(self.rejected) != 1:
            raise ValueError(f"rejected must be 1-D; found shape {np.shape(self.rejected)}")

    def summary(self) -> dict[str, object]:
        """The machine-readable summary (the keys of ``auvnav graph optimize --json``)."""
        return {
            "source": self.graph.source,
            "dim": self.graph.dim,
            "n_poses": self.graph.n_poses,
            "n_edges": self.graph.n_edges,
            "method": self.method,
            "robust": self.robust,
            "cost_before": self.cost_before,
            "cost_after": self.cost_after,
            "iterations": self.iterations,
            "seconds": self.seconds,
            "rejected_edges": [int(e) for e in self.rejected],
        }


def _pose_to_gtsam(T: FloatArray) -> gtsam.Pose2 | gtsam.Pose3:
    if T.shape == (3, 3):
        return gtsam.Pose2(T[0, 2], T[1, 2], np.arctan2(T[1, 0], T[0, 0]))
    return gtsam.Pose3(T)


def _values(graph: PoseGraph, T_world_pose: FloatArray | None = None) -> gtsam.Values:
    """GTSAM values keyed by vertex id, from ``T_world_pose`` (default: the graph's poses)."""
    poses = graph.T_world_pose if T_world_pose is None else np.asarray(T_world_pose, dtype=float)
    values = gtsam.Values()
    for key, T in zip(graph.ids, poses, strict=True):
        values.insert(int(key), _pose_to_gtsam(T))
    return values


def _poses_from_values(graph: PoseGraph, values: gtsam.Values) -> FloatArray:
    """Poses (N, d+1, d+1) in the order of ``graph.ids``."""
    at = values.atPose2 if graph.dim == 2 else values.atPose3
    return np.stack([at(int(key)).matrix() for key in graph.ids])


def _gtsam_information(graph: PoseGraph) -> FloatArray:
    """Edge information in GTSAM's tangent order, (M, k, k)."""
    if graph.dim == 2:
        return graph.information
    return graph.information[:, _PERM_3D][:, :, _PERM_3D]


def robust_threshold(dim: int, robust_k: float | None = None) -> float:
    """The robust kernel's threshold k on the whitened residual norm of an edge.

    ``robust_k`` when given, else the square root of the chi-square :data:`ROBUST_QUANTILE` quantile
    for the edge's degrees of freedom (3 for ``dim`` 2, 6 for ``dim`` 3).
    """
    if robust_k is None:
        return float(np.sqrt(chi2_distribution.ppf(ROBUST_QUANTILE, 3 * (dim - 1))))
    if not robust_k > 0:
        raise ValueError(f"robust_k must be positive; found {robust_k}")
    return float(robust_k)


def _between_factors(
    graph: PoseGraph, robust: Robust = "none", robust_k: float | None = None
) -> list[gtsam.NonlinearFactor]:
    """One ``BetweenFactor`` per edge, in edge order; loop closures robust when asked."""
    kernels = {"huber": gtsam.noiseModel.mEstimator.Huber, "cauchy": gtsam.noiseModel.mEstimator.Cauchy}
    if robust != "none" and robust not in kernels:
        raise ValueError(f"robust must be one of none, huber, cauchy; found {robust!r}")
    between = gtsam.BetweenFactorPose2 if graph.dim == 2 else gtsam.BetweenFactorPose3
    info = _gtsam_information(graph)
    loop = ~graph.is_odometry if robust != "none" else np.zeros(graph.n_edges, dtype=bool)
    k = robust_threshold(graph.dim, robust_k)
    factors = []
    for e in range(graph.n_edges):
        noise = gtsam.noiseModel.Gaussian.Information(info[e])
        if loop[e]:
            noise = gtsam.noiseModel.Robust.Create(kernels[robust].Create(k), noise)
        factors.append(
            between(int(graph.edge_i[e]), int(graph.edge_j[e]), _pose_to_gtsam(graph.T_ij[e]), noise)
        )
    return factors


def _anchor(graph: PoseGraph, T_world_first: FloatArray) -> gtsam.NonlinearFactor:
    """The prior that fixes the gauge: the first pose at ``T_world_first``."""
    dof = 3 if graph.dim == 2 else 6
    prior = gtsam.PriorFactorPose2 if graph.dim == 2 else gtsam.PriorFactorPose3
    noise = gtsam.noiseModel.Isotropic.Sigma(dof, ANCHOR_SIGMA)
    return prior(int(graph.ids[0]), _pose_to_gtsam(T_world_first), noise)


def to_gtsam(
    graph: PoseGraph,
    *,
    robust: Robust = "none",
    robust_k: float | None = None,
) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """A GTSAM factor graph and initial values for a pose graph.

    Parameters
    ----------
    graph : PoseGraph
        The graph; its ``T_world_pose`` become the values, keyed by vertex id.
    robust : {"none", "huber", "cauchy"}
        M-estimator on loop closures (odometry edges stay Gaussian).
    robust_k : float or None
        Kernel threshold on the whitened residual norm; None for :func:`robust_threshold`'s default.

    Returns
    -------
    NonlinearFactorGraph, Values
        One ``BetweenFactorPose2/3`` per edge in edge order, then the anchor prior on the first pose.
    """
    factor_graph = gtsam.NonlinearFactorGraph()
    for factor in _between_factors(graph, robust, robust_k):
        factor_graph.add(factor)
    factor_graph.add(_anchor(graph, graph.T_world_pose[0]))
    return factor_graph, _values(graph)


def _edge_chi2(factors: list[gtsam.NonlinearFactor], values: gtsam.Values) -> FloatArray:
    """Chi-square of each (Gaussian) factor: twice GTSAM's factor error."""
    return np.array([2.0 * f.error(values) for f in factors])


def chi2_cost(
    graph: PoseGraph | gtsam.NonlinearFactorGraph,
    values: gtsam.Values | FloatArray | None = None,
) -> float:
    """The chi-square cost: sum of information-weighted squared residuals.

    Parameters
    ----------
    graph : PoseGraph or gtsam.NonlinearFactorGraph
        A pose graph (every edge counts, Gaussian, no anchor) or a GTSAM factor graph (every factor
        counts; equals the chi-square only when its noise models are Gaussian: a robust model
        contributes twice its M-estimator loss instead).
    values : gtsam.Values or ndarray (N, d+1, d+1) or None
        Where to evaluate; None (pose graphs only) means ``graph.T_world_pose``.

    Returns
    -------
    float
        The cost, dimensionless; twice GTSAM's ``error``.
    """
    if isinstance(graph, PoseGraph):
        if not isinstance(values, gtsam.Values):
            values = _values(graph, values)
        return float(_edge_chi2(_between_factors(graph), values).sum())
    if not isinstance(values, gtsam.Values):
        raise TypeError("a GTSAM factor graph is evaluated at gtsam.Values")
    return 2.0 * float(graph.error(values))


def _check_connected(graph: PoseGraph) -> None:
    """A graph in several pieces has no unique solution: say so before GTSAM does, in one line."""
    n = graph.n_poses
    rows_i, rows_j = graph.rows(graph.edge_i), graph.rows(graph.edge_j)
    adjacency = coo_matrix((np.ones(graph.n_edges), (rows_i, rows_j)), shape=(n, n))
    n_parts, labels = connected_components(adjacency, directed=False)
    if n_parts > 1:
        other = graph.ids[int(np.flatnonzero(labels != labels[0])[0])]
        raise InsufficientDataError(
            f"{graph.source or 'pose graph'}: the edges form {n_parts} disconnected pieces "
            f"(no path from vertex {graph.ids[0]} to vertex {other}); the relative placement is undetermined"
        )


def one_line(err: Exception) -> str:
    """GTSAM's multi-paragraph messages as one line: the first paragraph, whitespace collapsed."""
    return " ".join(str(err).strip().split("\n\n")[0].split()) or type(err).__name__


def _initial_poses(graph: PoseGraph, initial: Initial | FloatArray) -> FloatArray:
    """The initial guess: the graph's poses, a chordal relaxation, or given poses."""
    if isinstance(initial, str) and initial == "file":
        return graph.T_world_pose
    if isinstance(initial, str) and initial == "chordal":
        try:
            if graph.dim == 3:
                values = gtsam.InitializePose3.initialize(to_gtsam(graph)[0])
            else:
                # LAGO takes diagonal noise models only; the initial guess needs no more than that.
                diagonal = np.eye(3) * np.diagonal(graph.information, axis1=1, axis2=2)[:, None, :]
                values = gtsam.lago.initialize(to_gtsam(replace(graph, information=diagonal))[0])
        except (RuntimeError, ValueError) as err:
            raise PoseGraphSolveError(
                f"{graph.source or 'pose graph'}: chordal initialisation failed: {one_line(err)}"
            ) from None
        return _poses_from_values(graph, values)
    if isinstance(initial, str):
        raise ValueError(f"initial must be 'file', 'chordal' or an array of poses; found {initial!r}")
    poses = np.asarray(initial, dtype=float)
    if poses.shape != graph.T_world_pose.shape:
        raise ValueError(f"initial poses must have shape {graph.T_world_pose.shape}; found {poses.shape}")
    return poses


def _rejected(graph: PoseGraph, edge_chi2: FloatArray, robust: Robust, robust_k: float | None) -> IntArray:
    """Loop closures whose whitened residual norm exceeds the kernel threshold (robust runs only)."""
    if robust == "none":
        return np.zeros(0, dtype=np.int64)
    over = np.sqrt(edge_chi2) > robust_threshold(graph.dim, robust_k)
    return np.flatnonzero(over & ~graph.is_odometry).astype(np.int64)


def optimize_batch(
    graph: PoseGraph,
    *,
    robust: Robust = "none",
    robust_k: float | None = None,
    max_iterations: int = 100,
    initial: Initial | FloatArray = "file",
    method: Literal["lm", "gn"] = "lm",
) -> SolveResult:
    """Solve a pose graph in batch (post-processing).

    Parameters
    ----------
    graph : PoseGraph
        The graph, 2D or 3D.
    robust : {"none", "huber", "cauchy"}
        M-estimator on loop closures; the result lists the loop closures it rejects.
    robust_k : float or None
        Kernel threshold on the whitened residual norm (None: :func:`robust_threshold`).
    max_iterations : int
        Iteration limit of the optimiser.
    initial : {"file", "chordal"} or ndarray (N, d+1, d+1)
        The initial guess: the graph's poses (for the reference graphs, these reach the tabulated
        optimum), GTSAM's chordal relaxation (``InitializePose3`` in 3D, LAGO in 2D; escapes the
        local minimum odometry initialisation finds on torus3D), or given poses.
    method : {"lm", "gn"}
        GTSAM's Levenberg-Marquardt (default) or Gauss-Newton optimiser.

    Returns
    -------
    SolveResult
        ``cost_before`` is the chi-square at the initial guess.

    Raises
    ------
    InsufficientDataError
        When the edges do not connect every pose.
    PoseGraphSolveError
        When GTSAM fails (indeterminate system, failed initialisation).
    """
    if method not in ("lm", "gn"):
        raise ValueError(f"method must be 'lm' or 'gn'; found {method!r}")
    _check_connected(graph)
    start = time.perf_counter()
    T0 = _initial_poses(graph, initial)
    plain = _between_factors(graph)
    factor_graph = gtsam.NonlinearFactorGraph()
    for factor in _between_factors(graph, robust, robust_k) if robust != "none" else plain:
        factor_graph.add(factor)
    factor_graph.add(_anchor(graph, T0[0]))
    values0 = _values(graph, T0)
    if method == "lm":
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(max_iterations)
        optimizer = gtsam.LevenbergMarquardtOptimizer(factor_graph, values0, params)
    else:
        params = gtsam.GaussNewtonParams()
        params.setMaxIterations(max_iterations)
        optimizer = gtsam.GaussNewtonOptimizer(factor_graph, values0, params)
    try:
        values = optimizer.optimize()
    except RuntimeError as err:
        raise PoseGraphSolveError(f"{graph.source or 'pose graph'}: solve failed: {one_line(err)}") from None
    seconds = time.perf_counter() - start
    edge_chi2 = _edge_chi2(plain, values)
    result = SolveResult(
        graph=graph.with_poses(_poses_from_values(graph, values)),
        cost_before=float(_edge_chi2(plain, values0).sum()),
        cost_after=float(edge_chi2.sum()),
        iterations=int(optimizer.iterations()),
        seconds=seconds,
        edge_chi2=edge_chi2,
        rejected=_rejected(graph, edge_chi2, robust, robust_k),
        robust=robust,
        method=method,
    )
    log.debug(
        "%s: chi2 %.6g -> %.6g in %d iterations, %.3f s",
        graph.source,
        result.cost_before,
        result.cost_after,
        result.iterations,
        seconds,
    )
    return result


def optimize_incremental(
    graph: PoseGraph,
    *,
    robust: Robust = "none",
    robust_k: float | None = None,
    poses_per_update: int = 1,
    relinearize_threshold: float = 0.1,
    relinearize_skip: int = 10,
) -> SolveResult:
    """Solve a pose graph incrementally with iSAM2 (what a vehicle would run).

    Poses are added in id order, each with every edge that joins it to a pose added before it or
    with it; every ``poses_per_update`` poses go to iSAM2 in one update, after which the newest
    pose's estimate is read (a vehicle that triggers its camera at 1 Hz and updates every K poses
    has a new solution every K seconds). A new pose's initial guess is its latest neighbour's
    current estimate (its prediction, when the neighbour waits in the same update) composed with
    their edge: dead reckoning from the current solution, so the file's vertices are used for the
    first pose only.

    Parameters
    ----------
    graph : PoseGraph
        The graph; every pose but the first needs an edge to a pose with a lower id.
    robust, robust_k
        As for :func:`optimize_batch`.
    poses_per_update : int
        Poses per iSAM2 update, K >= 1 (1: pose by pose).
    relinearize_threshold : float
        iSAM2 relinearises a variable whose delta exceeds this (radians and file units; GTSAM's
        default 0.1).
    relinearize_skip : int
        iSAM2 checks for relinearisation every this many updates (GTSAM's default 10).

    Returns
    -------
    SolveResult
        ``method="isam2"``; ``update_seconds[u]`` is the wall time of update ``u`` (building its
        factors, the iSAM2 update and reading its newest pose's estimate) and ``step_seconds[r]``
        the time per added pose of the update that added the pose in row r (its update's time
        divided by the poses it added); ``cost_before`` is the chi-square at the graph's own poses;
        ``iterations`` counts iSAM2 updates.

    Raises
    ------
    InsufficientDataError
        When a pose has no edge to an earlier pose.
    PoseGraphSolveError
        When iSAM2 fails.
    """
    if poses_per_update < 1:
        raise ValueError(f"poses_per_update must be at least 1; found {poses_per_update}")
    rows_i, rows_j = graph.rows(graph.edge_i), graph.rows(graph.edge_j)
    step = np.maximum(rows_i, rows_j)
    orphans = np.setdiff1d(np.arange(1, graph.n_poses), step)
    if orphans.size:
        raise InsufficientDataError(
            f"{graph.source or 'pose graph'}: vertex {graph.ids[orphans[0]]} has no edge to a vertex "
            "with a lower id; incremental solving adds poses in id order"
        )
    start = time.perf_counter()
    factors = _between_factors(graph, robust, robust_k)
    params = gtsam.ISAM2Params()
    params.setRelinearizeThreshold(relinearize_threshold)
    params.relinearizeSkip = relinearize_skip
    isam = gtsam.ISAM2(params)
    at = isam.calculateEstimatePose2 if graph.dim == 2 else isam.calculateEstimatePose3
    order = np.argsort(step, kind="stable")
    bounds = np.searchsorted(step[order], np.arange(graph.n_poses + 1))
    first_rows = np.arange(0, graph.n_poses, poses_per_update)
    update_seconds = np.zeros(len(first_rows))
    for u, first in enumerate(first_rows):
        t0 = time.perf_counter()
        new_factors = gtsam.NonlinearFactorGraph()
        new_values = gtsam.Values()
        predicted: dict[int, FloatArray] = {}  # poses of this update, by row
        last = min(first + poses_per_update, graph.n_poses) - 1
        for r in range(first, last + 1):
            edges = order[bounds[r] : bounds[r + 1]]
            for e in edges:
                new_factors.add(factors[e])
            if r == 0:
                new_factors.add(_anchor(graph, graph.T_world_pose[0]))
                predicted[r] = graph.T_world_pose[0]
            else:
                # Predict from the latest neighbour: the odometry edge when there is one.
                e = edges[np.argmax(np.minimum(rows_i[edges], rows_j[edges]))]
                forward = rows_j[e] == r
                other = int(rows_i[e] if forward else rows_j[e])
                T_other = predicted[other] if other in predicted else at(int(graph.ids[other])).matrix()
                predicted[r] = T_other @ (graph.T_ij[e] if forward else inverse_rigid(graph.T_ij[e]))
            new_values.insert(int(graph.ids[r]), _pose_to_gtsam(predicted[r]))
        try:
            isam.update(new_factors, new_values)
            at(int(graph.ids[last]))
        except RuntimeError as err:
            raise PoseGraphSolveError(
                f"{graph.source or 'pose graph'}: iSAM2 failed adding vertices {graph.ids[first]} to "
                f"{graph.ids[last]}: {one_line(err)}"
            ) from None
        update_seconds[u] = time.perf_counter() - t0
    values = isam.calculateEstimate()
    seconds = time.perf_counter() - start
    plain = _between_factors(graph)
    edge_chi2 = _edge_chi2(plain, values)
    sizes = np.diff(np.append(first_rows, graph.n_poses))
    return SolveResult(
        graph=graph.with_poses(_poses_from_values(graph, values)),
        cost_before=float(_edge_chi2(plain, _values(graph)).sum()),
        cost_after=float(edge_chi2.sum()),
        iterations=len(first_rows),
        seconds=seconds,
        edge_chi2=edge_chi2,
        rejected=_rejected(graph, edge_chi2, robust, robust_k),
        robust=robust,
        method="isam2",
        step_seconds=np.repeat(update_seconds / sizes, sizes),
        update_seconds=update_seconds,
    )


def marginal_covariances(
    graph: PoseGraph,
    ids: IntArray | None = None,
    *,
    exclude_edges: IntArray | None = None,
) -> FloatArray:
    """Marginal covariances of poses at the graph's poses (normally a solution's ``graph``).

    Parameters
    ----------
    graph : PoseGraph
        The graph, linearised at ``T_world_pose``; the first pose is anchored (:data:`ANCHOR_SIGMA`),
        so covariances are relative to it.
    ids : ndarray of int, shape (K,), or None
        Vertex ids; None for every pose.
    exclude_edges : ndarray of int or None
        Edge indices to leave out, e.g. ``SolveResult.rejected``.

    Returns
    -------
    ndarray, shape (K, k, k)
        Covariance of the right perturbation ``T = T_hat @ exp(xi)`` in the pose's own frame, order
        (x, y, theta) in 2D (metres, radians) or (x, y, z, rx, ry, rz) in 3D.
    """
    wanted = graph.ids if ids is None else np.asarray(ids, dtype=np.int64)
    graph.rows(wanted)  # unknown ids raise ValueError before the factorisation
    marginals, _ = solution_marginals(graph, exclude_edges=exclude_edges)
    try:
        cov = np.stack([marginals.marginalCovariance(int(key)) for key in wanted])
    except RuntimeError as err:
        raise PoseGraphSolveError(
            f"{graph.source or 'pose graph'}: marginals failed: {one_line(err)}"
        ) from None
    if graph.dim == 3:
        cov = cov[:, _PERM_3D][:, :, _PERM_3D]
    return cov


def solution_marginals(
    graph: PoseGraph, *, exclude_edges: IntArray | None = None, robust: Robust = "none"
) -> tuple[gtsam.Marginals, gtsam.Values]:
    """GTSAM's marginals of a graph linearised at its poses (normally a solution's ``graph``), without
    the edges ``exclude_edges`` (e.g. ``SolveResult.rejected``), loop closures behind the ``robust``
    kernel; and the values they were linearised at (keyed by vertex id). A factorisation GTSAM
    cannot do raises :class:`PoseGraphSolveError`."""
    if exclude_edges is not None and len(exclude_edges):
        keep = np.ones(graph.n_edges, dtype=bool)
        keep[np.asarray(exclude_edges, dtype=np.int64)] = False
        graph = graph.subgraph(keep)
    _check_connected(graph)
    factor_graph, values = to_gtsam(graph, robust=robust)
    try:
        return gtsam.Marginals(factor_graph, values), values
    except RuntimeError as err:
        raise PoseGraphSolveError(
            f"{graph.source or 'pose graph'}: marginals failed: {one_line(err)}"
        ) from None
