"""``auvnav graph optimize``: the acceptance run on the reference graphs, outputs, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from auvnav.cli import main
from auvnav.slam.g2o import read_g2o, write_g2o
from auvnav.slam.solve import chi2_cost
from auvnav.slam.synthetic import SyntheticPoseGraph

# 2 x the GTSAM error after LM, gtsam_computed_reference_costs.csv in ../shared/reference/pose_graph_g2o.
ACCEPTANCE = {"sphere2500.g2o": 2 * 675.700963, "parking-garage.g2o": 2 * 0.6341924}


@pytest.mark.parametrize("name", sorted(ACCEPTANCE))
def test_optimize_reaches_reference_cost(
    pose_graph_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str
) -> None:
    out = tmp_path / "out.g2o"
    assert main(["graph", "optimize", str(pose_graph_dir / name), "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert {"cost_before", "cost_after", "iterations", "seconds"} <= set(summary)
    assert summary["cost_after"] == pytest.approx(ACCEPTANCE[name], rel=1e-3)
    assert summary["cost_before"] > 1e3 * summary["cost_after"]
    solved = read_g2o(out)
    assert solved.n_edges == read_g2o(pose_graph_dir / name).n_edges
    # The written vertices are the optimum (to the 15 printed digits).
    assert chi2_cost(solved) == pytest.approx(summary["cost_after"], rel=1e-6)


def test_human_output_and_robust_rejections(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], small_survey: SyntheticPoseGraph
) -> None:
    graph_file = tmp_path / "survey.g2o"
    write_g2o(small_survey.graph, graph_file)
    out = tmp_path / "out.g2o"
    assert main(["graph", "optimize", str(graph_file), "--out", str(out), "--robust", "cauchy"]) == 0
    text = capsys.readouterr().out
    assert "cost before" in text and "cost after" in text and "iterations" in text
    assert "cauchy kernel rejects 10 of 50 loop closures" in text
    assert out.exists()


def test_refuses_to_overwrite(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], small_survey: SyntheticPoseGraph
) -> None:
    graph_file = tmp_path / "survey.g2o"
    write_g2o(small_survey.graph, graph_file)
    out = tmp_path / "out.g2o"
    out.write_text("precious")
    assert main(["graph", "optimize", str(graph_file), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert err == f"auvnav: error: {out}: exists (use --overwrite to replace it)"
    assert out.read_text() == "precious"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 5 1 0 0 1 0 0 1 0 1\n",
            "line 3: edge names vertex 5",
        ),
        (
            "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 2 0 1 0 1\n",
            "line 3: information matrix is not positive definite",
        ),
        (
            "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n",
            "disconnected pieces",
        ),
    ],
    ids=["missing vertex", "not positive definite", "disconnected"],
)
def test_bad_input_is_one_line_exit_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, message: str
) -> None:
    graph_file = tmp_path / "bad.g2o"
    graph_file.write_text(text)
    out = tmp_path / "out.g2o"
    assert main(["graph", "optimize", str(graph_file), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("auvnav: error: ")
    assert message in err and str(graph_file) in err
    assert not out.exists()


def test_missing_file_is_exit_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["graph", "optimize", str(tmp_path / "nope.g2o"), "--out", str(tmp_path / "o.g2o")]) == 1
    assert "nope.g2o" in capsys.readouterr().err
