"""Fixtures shared by the pose-graph tests: the reference folder and small synthetic graphs."""

from __future__ import annotations

from pathlib import Path

import pytest

from auvnav.slam.synthetic import SyntheticPoseGraph, survey_pose_graph


@pytest.fixture(scope="session")
def pose_graph_dir(reference_dir: Path) -> Path:
    """``../shared/reference/pose_graph_g2o`` (SE-Sync and GTSAM benchmark files, see its PROVENANCE.md)."""
    path = reference_dir / "pose_graph_g2o"
    if not path.is_dir():
        pytest.skip(f"{path} is missing")
    return path


@pytest.fixture(scope="session")
def small_survey() -> SyntheticPoseGraph:
    """100 poses on 4 track lines, 50 loop closures of which 10 (20%) are gross false ones."""
    return survey_pose_graph(100, 50, per_line=25, outlier_fraction=0.2, seed=3)
