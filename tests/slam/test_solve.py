"""Pose-graph solving: reference optima, robust loop closures, iSAM2, marginal covariances."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from auvnav.errors import InsufficientDataError
from auvnav.frames import euler2rot, se3
from auvnav.slam.g2o import PoseGraph, read_g2o
from auvnav.slam.solve import (
    ANCHOR_SIGMA,
    chi2_cost,
    marginal_covariances,
    optimize_batch,
    optimize_incremental,
    to_gtsam,
)
from auvnav.slam.synthetic import SyntheticPoseGraph

# Chi-square at the optimum = 2 x the GTSAM error after Levenberg-Marquardt from the file's vertices,
# ../shared/reference/pose_graph_g2o/gtsam_computed_reference_costs.csv (computed with GTSAM from
# PyPI, prior 1e-6 on the first pose; not certified optima, so a lower cost is also acceptable).
REFERENCE_CHI2 = {
    "parking-garage.g2o": 2 * 0.6341924,
    "sphere2500.g2o": 2 * 675.700963,
    "smallGrid3D.g2o": 2 * 517.925332,
    "tinyGrid3D.g2o": 2 * 9.31390943,
    "intel.g2o": 2 * 22.5021165,
    "MIT.g2o": 2 * 385.119492,
}
# ... and at the file's vertices (column gtsam_error_at_file_vertices).
REFERENCE_CHI2_BEFORE = {"parking-garage.g2o": 2 * 8363.60195, "sphere2500.g2o": 2 * 1305657.71}
REL_TOL = 1e-3  # the acceptance tolerance of issue 7 (0.1%)


def _position_error_m(a: PoseGraph, b: PoseGraph) -> float:
    """Largest distance between corresponding positions of two solutions of the same graph, metres."""
    return float(np.linalg.norm(a.T_world_pose[:, :3, 3] - b.T_world_pose[:, :3, 3], axis=1).max())


@pytest.mark.parametrize("name", sorted(REFERENCE_CHI2))
def test_batch_reaches_reference_optimum(pose_graph_dir: Path, name: str) -> None:
    result = optimize_batch(read_g2o(pose_graph_dir / name))
    assert result.cost_after <= REFERENCE_CHI2[name] * (1 + REL_TOL)
    assert result.cost_after >= REFERENCE_CHI2[name] * (1 - REL_TOL)  # lower would need a look
    if name in REFERENCE_CHI2_BEFORE:
        assert result.cost_before == pytest.approx(REFERENCE_CHI2_BEFORE[name], rel=1e-6)
    assert 0 < result.iterations < 100


def test_gauss_newton_and_chordal_reach_the_same_optimum(pose_graph_dir: Path) -> None:
    """Both optimisers, from the file's vertices or GTSAM's chordal relaxation (sphere2500 in benchmarks/)."""
    name = "parking-garage.g2o"
    graph = read_g2o(pose_graph_dir / name)
    for method, initial in [("gn", "file"), ("lm", "chordal")]:
        result = optimize_batch(graph, method=method, initial=initial)
        assert result.cost_after == pytest.approx(REFERENCE_CHI2[name], rel=REL_TOL)


def test_edges_only_2d_file_with_lago(pose_graph_dir: Path) -> None:
    """CSAIL (edges only): odometry composition and LAGO reach the same optimum."""
    graph = read_g2o(pose_graph_dir / "CSAIL.g2o")
    odometry = optimize_batch(graph)
    lago = optimize_batch(graph, initial="chordal")
    assert lago.cost_before < odometry.cost_before
    assert lago.cost_after == pytest.approx(odometry.cost_after, rel=1e-6)


def test_chi2_of_posegraph_equals_factor_graph(pose_graph_dir: Path) -> None:
    """The anchor adds nothing at the file's vertices; a robust graph costs less with outliers."""
    graph = read_g2o(pose_graph_dir / "smallGrid3D.g2o")
    factor_graph, values = to_gtsam(graph)
    assert factor_graph.size() == graph.n_edges + 1
    assert chi2_cost(factor_graph, values) == pytest.approx(chi2_cost(graph), rel=1e-12)
    robust_graph, _ = to_gtsam(graph, robust="cauchy")
    assert chi2_cost(robust_graph, values) < chi2_cost(graph)


@pytest.mark.parametrize("robust", ["cauchy", "huber"])
def test_robust_kernel_rejects_false_loop_closures(small_survey: SyntheticPoseGraph, robust: str) -> None:
    """20% gross false loop closures bend a least-squares solution by metres; the kernels do not."""
    graph, outliers = small_survey.graph, np.flatnonzero(small_survey.is_outlier)
    clean = optimize_batch(graph.subgraph(~small_survey.is_outlier))
    plain = optimize_batch(graph)
    robust_result = optimize_batch(graph, robust=robust)
    assert _position_error_m(plain.graph, clean.graph) > 2.0
    assert plain.rejected.size == 0
    # Cauchy's influence vanishes for gross errors; Huber's is bounded but constant.
    bound_m = 0.1 if robust == "cauchy" else 0.3 * _position_error_m(plain.graph, clean.graph)
    assert _position_error_m(robust_result.graph, clean.graph) < bound_m
    assert set(outliers) <= set(robust_result.rejected)
    assert len(set(robust_result.rejected) - set(outliers)) <= 2  # a 1% tail of 40 true ones
    assert not small_survey.graph.is_odometry[robust_result.rejected].any()


@pytest.mark.parametrize("poses_per_update", [1, 7])
def test_isam2_matches_batch(small_survey: SyntheticPoseGraph, poses_per_update: int) -> None:
    graph = small_survey.graph.subgraph(~small_survey.is_outlier)
    batch = optimize_batch(graph)
    incremental = optimize_incremental(graph, relinearize_skip=1, poses_per_update=poses_per_update)
    assert incremental.method == "isam2"
    updates = -(-graph.n_poses // poses_per_update)  # ceil: the last update takes the rest
    assert incremental.iterations == updates and incremental.update_seconds.shape == (updates,)
    assert incremental.step_seconds.shape == (graph.n_poses,)
    assert np.all(incremental.step_seconds > 0)
    # Each pose carries its update's time shared among the poses the update added.
    assert incremental.step_seconds.sum() == pytest.approx(incremental.update_seconds.sum())
    assert incremental.cost_after == pytest.approx(batch.cost_after, rel=1e-2)
    assert _position_error_m(incremental.graph, batch.graph) < 0.01  # 1 cm over a 100 m survey


def test_isam2_robust_rejects_false_loop_closures(small_survey: SyntheticPoseGraph) -> None:
    result = optimize_incremental(small_survey.graph, robust="cauchy")
    clean = optimize_batch(small_survey.graph.subgraph(~small_survey.is_outlier))
    assert set(np.flatnonzero(small_survey.is_outlier)) <= set(result.rejected)
    assert _position_error_m(result.graph, clean.graph) < 0.15


def _two_pose_graph(dim: int, information: np.ndarray) -> PoseGraph:
    if dim == 3:
        T = se3(euler2rot(0.3, -0.2, 0.1), [1.0, 2.0, -0.5])
    else:
        c, s = np.cos(0.4), np.sin(0.4)
        T = np.array([[c, -s, 1.0], [s, c, 2.0], [0, 0, 1]])
    return PoseGraph(
        dim,
        np.array([0, 1]),
        np.stack([np.eye(dim + 1), T]),
        np.array([0]),
        np.array([1]),
        T[None],
        information[None],
    )


@pytest.mark.parametrize("dim", [2, 3])
def test_marginal_of_single_edge_is_its_covariance(dim: int) -> None:
    """With the first pose anchored, the second's covariance (own frame) is the edge's inverse information.

    A full information matrix with distinct translation and rotation blocks checks the order
    (x, y, z, rx, ry, rz) survives GTSAM's rotation-first tangent.
    """
    k = 3 * (dim - 1)
    A = np.arange(1.0, k * k + 1).reshape(k, k) / (k * k)
    information = A @ A.T + np.diag(np.linspace(10.0, 400.0, k))
    graph = _two_pose_graph(dim, information)
    cov = marginal_covariances(graph)
    assert cov.shape == (2, k, k)
    np.testing.assert_allclose(cov[1], np.linalg.inv(information), rtol=1e-6)
    assert np.all(np.abs(cov[0]) < 10 * ANCHOR_SIGMA**2)


def test_marginals_grow_along_odometry_and_shrink_with_loops(small_survey: SyntheticPoseGraph) -> None:
    graph = small_survey.graph
    solved = optimize_batch(graph, robust="cauchy")
    odometry_only = graph.subgraph(graph.is_odometry).with_poses(solved.graph.T_world_pose)
    with_loops = solved.graph
    last = graph.ids[-1:]
    var_odo = np.trace(marginal_covariances(odometry_only, last)[0, :3, :3])
    var_loops = np.trace(marginal_covariances(with_loops, last, exclude_edges=solved.rejected)[0, :3, :3])
    var_mid = np.trace(marginal_covariances(odometry_only, graph.ids[50:51])[0, :3, :3])
    assert var_mid < var_odo
    assert var_loops < 0.5 * var_odo


def test_disconnected_graph_is_a_one_line_error() -> None:
    T = np.eye(3)
    graph = PoseGraph(
        2,
        np.array([0, 1, 2, 3]),
        np.stack([T] * 4),
        np.array([0, 2]),
        np.array([1, 3]),
        np.stack([T] * 2),
        np.stack([np.eye(3)] * 2),
        source="two.g2o",
    )
    with pytest.raises(InsufficientDataError, match=r"^two\.g2o: the edges form 2 disconnected pieces"):
        optimize_batch(graph)


def test_incremental_needs_an_edge_to_an_earlier_pose() -> None:
    T = np.eye(3)
    graph = PoseGraph(
        2,
        np.array([0, 1, 2]),
        np.stack([T] * 3),
        np.array([0, 2]),
        np.array([2, 1]),
        np.stack([T] * 2),
        np.stack([np.eye(3)] * 2),
        source="g",
    )
    with pytest.raises(InsufficientDataError, match="vertex 1 has no edge to a vertex with a lower id"):
        optimize_incremental(graph)
