"""Loop-closure selection by pairwise consistency (auvnav.slam.pcm) and the online replay
(``auvnav slam --online``, auvnav.slam.online) on a small simulated navigation check dive flown with
the raw compass, a third of its loop closures false."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from auvnav.cli import main
from auvnav.dive import read_dive
from auvnav.evaluate import evaluate_dive
from auvnav.frames import se3
from auvnav.slam.g2o import PoseGraph
from auvnav.slam.graph import SlamOptions
from auvnav.slam.pcm import adjoint, select_loops
from auvnav.slam.result import slam
from auvnav.trajectory import read_trajectory
from auvnav.vision.loopfile import read_loops

GEOMETRY = ["--headings", "4", "--leg-m", "8", "--grid-m", "2"]


@pytest.fixture(scope="module")
def dive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("pcm") / "navcheck"
    args = ["simulate", "navcheck", "--out", str(out), "--seed", "4", *GEOMETRY, "--no-images"]
    assert main([*args, "--truth-loops", "--false-loops", "0.33", "-q", "--json"]) == 0
    return out


def _false_rows(dive: Path) -> set[int]:
    """0-based rows of the false loop closures."""
    info = yaml.safe_load((dive / "truth" / "loops.yaml").read_text(encoding="utf-8"))
    return {r - 1 for r in info["false_rows"]}


def test_adjoint_moves_a_perturbation_across_a_pose() -> None:
    """exp(Ad(T) xi) T = T exp(xi): checked to first order with a small twist."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(0)
    T = se3(Rotation.from_rotvec(rng.normal(size=3)).as_matrix(), rng.normal(size=3) * 5)
    xi = rng.normal(size=6) * 1e-6

    def exp(x: np.ndarray) -> np.ndarray:
        return se3(Rotation.from_rotvec(x[:3]).as_matrix(), x[3:])

    left = exp(adjoint(T) @ xi) @ T
    right = T @ exp(xi)
    np.testing.assert_allclose(left, right, atol=1e-10)


def test_pairwise_consistency_rejects_every_false_loop(dive: Path) -> None:
    d = read_dive(dive)
    loops = read_loops(dive / "truth" / "loops.csv", n_poses=len(d.images.t_s))
    result = slam(d, d.images.t_s, loops=loops, options=SlamOptions(marginal_every=0))
    selection = result.solution.selection
    assert selection is not None
    rows = result.solution.graph.loop_rows
    false = np.isin(rows, sorted(_false_rows(dive)))
    assert false.sum() > 100
    assert not np.any(selection.keep[false])  # recall 1
    assert np.count_nonzero(~selection.keep[~false]) < 0.02 * np.count_nonzero(~false)
    # The causal decisions (a vehicle's) agree with the batch ones but for a few.
    pg, n_odometry = result.solution.graph.pose_graph, len(result.solution.graph.times) - 1
    causal = select_loops(pg, n_odometry, causal=True)
    assert not np.any(causal.keep[false])
    assert np.count_nonzero(causal.keep != selection.keep) < 0.02 * len(rows)
    assert np.all(causal.decided_at >= np.maximum(pg.edge_i, pg.edge_j)[n_odometry:])


def test_a_lone_loop_closure_is_not_trusted() -> None:
    """Three poses on a line, one loop closure: nothing corroborates it, so it is rejected."""
    T = np.stack([se3(np.eye(3), np.array([k, 0.0, 0.0])) for k in range(3)])
    step = se3(np.eye(3), np.array([1.0, 0.0, 0.0]))
    info = np.broadcast_to(np.eye(6) * 1e4, (3, 6, 6)).copy()
    graph = PoseGraph(
        3,
        np.arange(3),
        T,
        np.array([0, 1, 0]),
        np.array([1, 2, 2]),
        np.stack([step, step, step @ step]),
        info,
    )
    selection = select_loops(graph, 2)
    assert selection.keep.tolist() == [False]
    assert selection.tested.tolist() == [0]


@pytest.fixture(scope="module")
def online(dive: Path) -> dict:
    args = [
        "slam",
        str(dive),
        "--loops",
        str(dive / "truth" / "loops.csv"),
        "--online",
        "--marginal-every",
        "0",
    ]
    assert main([*args, "--loop-latency-s", "2", "-q", "--json"]) == 0
    products = dive / "products" / "slam"
    return {
        "summary": json.loads((products / "summary.json").read_text(encoding="utf-8")),
        "online": read_trajectory(products / "online.csv"),
        "scores": evaluate_dive(dive),
    }


def test_online_replay_writes_the_estimate_known_at_each_moment(dive: Path, online: dict) -> None:
    summary, scores = online["summary"], online["scores"]
    np.testing.assert_allclose(online["online"].t_s, read_dive(dive).images.t_s)
    assert summary["solver"] == "isam2-online"
    stats = summary["online"]
    assert stats["loop_latency_s"] == 2.0
    assert stats["loop_delay_median_s"] >= 2.0  # found after the latency, decided after the window
    assert stats["loops_added"] == summary["loops"]["used"] - summary["loops"]["selection"]["rejected"]
    assert 0 < stats["update_median_ms"] <= stats["update_p95_ms"]
    rejected = set(np.array(summary["loops"]["rejected_rows"]) - 1)
    assert _false_rows(dive) <= rejected
    # The smoothed estimate is centimetres from the truth; the one known at each moment close to it.
    assert scores["slam"]["ate_aligned_rmse_m"] < 0.05
    assert set(scores["online"]) >= {"ate_aligned_rmse_m", "update_median_ms", "update_p95_ms"}
    assert scores["online"]["ate_aligned_rmse_m"] < 0.15
    assert scores["online"]["ate_aligned_rmse_m"] >= scores["slam"]["ate_aligned_rmse_m"] * 0.9


def test_online_schedule_adds_loop_closures_when_found_and_decided(dive: Path) -> None:
    from auvnav.slam.online import schedule
    from auvnav.slam.result import sensor_graph

    d = read_dive(dive)
    loops = read_loops(dive / "truth" / "loops.csv", n_poses=len(d.images.t_s))
    sg = sensor_graph(d, d.images.t_s, loops=loops, options=SlamOptions(marginal_every=0))
    plan = schedule(sg, 10, 2.0)
    is_loop = np.array([kind == "loop" for kind in sg.kinds])
    t = sg.times.t_s
    # A loop closure joins the update after its decision plus the latency; a sensor factor its pose's.
    decided = t[np.minimum(plan.selection.decided_at, len(t) - 1)] + 2.0
    assert np.all(t[plan.lasts[plan.update_of[is_loop]]] >= np.minimum(decided, t[-1]))
    assert np.all(plan.lasts[plan.update_of[~is_loop]] >= np.maximum(sg.last_pose[~is_loop], 0))
    assert np.array_equal(plan.skip[is_loop], ~plan.selection.keep)
    known = [len(plan.known_by(u)) for u in range(len(plan.firsts))]
    assert np.all(np.diff(known) >= 0) and known[-1] == np.count_nonzero(~plan.skip)


def test_online_with_an_earlier_correction_beats_the_raw_compass(
    dive: Path, online: dict, tmp_path: Path
) -> None:
    """A correction exported by SLAM (here the dive's own, estimated in the graph) given to the online
    replay: the compass is then trusted and the estimate known at each moment is closer to the truth."""
    import shutil

    copy = tmp_path / "dive"
    shutil.copytree(dive, copy, ignore=shutil.ignore_patterns("products"))
    loops = ["--loops", str(copy / "truth" / "loops.csv"), "--marginal-every", "0", "-q", "--json"]
    assert main(["slam", str(copy), "--estimate-compass", *loops]) == 0
    correction = tmp_path / "correction.yaml"
    shutil.copyfile(copy / "products" / "slam" / "correction.yaml", correction)
    args = ["slam", str(copy), "--online", "--loop-latency-s", "2", "--compass-correction", str(correction)]
    assert main([*args, *loops]) == 0
    summary = json.loads((copy / "products" / "slam" / "summary.json").read_text(encoding="utf-8"))
    assert summary["compass"]["mode"] == "corrected" and summary["solver"] == "isam2-online"
    evaluated = evaluate_dive(copy)
    scores, raw = evaluated["online"], online["scores"]["online"]
    assert scores["ate_aligned_rmse_m"] < 0.8 * raw["ate_aligned_rmse_m"]
    # The ratio is to the same run's smoothed estimate; the quarters split the same aligned errors.
    slam_rmse = evaluated["slam"]["ate_aligned_rmse_m"]
    assert scores["ratio_to_smoothed"] == pytest.approx(scores["ate_aligned_rmse_m"] / slam_rmse)
    quarters = np.array(scores["aligned_rmse_by_quarter_m"])
    assert quarters.shape == (4,) and np.all(np.isfinite(quarters))
    assert min(quarters) <= scores["ate_aligned_rmse_m"] <= max(quarters)
