"""The synthetic survey graphs: their noise is what their information says."""

from __future__ import annotations

import numpy as np
import pytest

from auvnav.slam.solve import chi2_cost
from auvnav.slam.synthetic import survey_pose_graph


def test_chi2_at_truth_follows_its_distribution() -> None:
    """At the true poses each edge's chi-square is chi2(6): the sum has mean 6M and sd sqrt(12M)."""
    survey = survey_pose_graph(400, 600, seed=1)
    graph = survey.graph
    cost = chi2_cost(graph, survey.T_world_true)
    m = graph.n_edges
    assert abs(cost - 6 * m) < 5 * np.sqrt(12 * m)
    assert graph.n_edges == 399 + 600
    assert not survey.is_outlier.any()
    # Loop closures join different track lines, close together.
    rows_i, rows_j = graph.edge_i[399:], graph.edge_j[399:]
    assert np.all(rows_i // 100 != rows_j // 100)
    gap = np.linalg.norm(survey.T_world_true[rows_i, :2, 3] - survey.T_world_true[rows_j, :2, 3], axis=1)
    assert gap.max() <= 2.3


def test_outliers_are_gross_and_marked() -> None:
    survey = survey_pose_graph(100, 50, per_line=25, outlier_fraction=0.2, seed=0)
    graph = survey.graph
    assert survey.is_outlier.sum() == 10
    assert not graph.is_odometry[survey.is_outlier].any()
    T_true = np.linalg.inv(survey.T_world_true[graph.edge_i]) @ survey.T_world_true[graph.edge_j]
    error_m = np.linalg.norm(T_true[:, :3, 3] - graph.T_ij[:, :3, 3], axis=1)
    assert error_m[survey.is_outlier].min() > 3.0
    assert error_m[~survey.is_outlier].max() < 0.5


def test_too_many_loop_closures_is_an_error() -> None:
    with pytest.raises(ValueError, match="loop-closure candidates"):
        survey_pose_graph(50, 1000, per_line=25)
