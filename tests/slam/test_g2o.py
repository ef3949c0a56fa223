"""The g2o/TORO reader and writer: cross-check against GTSAM's readG2o, round trips, bad input."""

from __future__ import annotations

from pathlib import Path

import gtsam
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from auvnav.errors import OutputExistsError
from auvnav.frames import euler2rot, se3
from auvnav.slam.g2o import PoseGraph, PoseGraphFormatError, read_g2o, write_g2o
from auvnav.slam.solve import chi2_cost

# Reference files with vertex lines, and their size (PROVENANCE.md of pose_graph_g2o).
REFERENCE_FILES = [
    ("parking-garage.g2o", 3, 1661, 6275),
    ("sphere2500.g2o", 3, 2500, 4949),
    ("smallGrid3D.g2o", 3, 125, 297),
    ("gtsam_pose3example-offdiagonal.txt", 3, 2, 1),
    ("intel.g2o", 2, 1728, 2512),
    ("MIT.g2o", 2, 808, 827),
    ("gtsam_pose2example.txt", 2, 11, 12),
]

TINY_2D = """\
VERTEX_SE2 0 0 0 0
VERTEX_SE2 1 1 0 0.1
VERTEX_SE2 2 2 0.1 0.2
EDGE_SE2 0 1 1 0 0.1 100 0 0 100 0 400
EDGE_SE2 1 2 1 0 0.1 100 0 0 100 0 400
EDGE_SE2 0 2 2 0.2 0.2 50 0 0 50 0 200
"""


def _write(tmp_path: Path, text: str, name: str = "graph.g2o") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(("name", "dim", "n_poses", "n_edges"), REFERENCE_FILES)
def test_reader_matches_gtsam_readG2o(
    pose_graph_dir: Path, name: str, dim: int, n_poses: int, n_edges: int
) -> None:
    """Same vertices, edges, measurements and information as GTSAM's own reader."""
    graph = read_g2o(pose_graph_dir / name)
    assert (graph.dim, graph.n_poses, graph.n_edges) == (dim, n_poses, n_edges)
    theirs, values = gtsam.readG2o(str(pose_graph_dir / name), dim == 3)
    assert theirs.size() == n_edges
    at = values.atPose2 if dim == 2 else values.atPose3
    T_theirs = np.stack([at(int(k)).matrix() for k in graph.ids])
    np.testing.assert_allclose(graph.T_world_pose, T_theirs, atol=1e-12)
    perm = [0, 1, 2] if dim == 2 else [3, 4, 5, 0, 1, 2]  # GTSAM's Pose3 tangent is rotation first
    factors = [theirs.at(e) for e in range(n_edges)]
    keys = np.array([f.keys() for f in factors])
    np.testing.assert_array_equal(keys, np.column_stack([graph.edge_i, graph.edge_j]))
    np.testing.assert_allclose(graph.T_ij, np.stack([f.measured().matrix() for f in factors]), atol=1e-12)
    info_theirs = np.stack([f.noiseModel().information() for f in factors])
    info = graph.information[:, perm][:, :, perm]
    np.testing.assert_allclose(info, info_theirs, rtol=1e-9, atol=1e-9 * np.abs(info).max())
    # The whole cost agrees too (chi2 = 2 x GTSAM error).
    assert chi2_cost(graph) == pytest.approx(2.0 * theirs.error(values), rel=1e-9)


def test_offdiagonal_information_keeps_its_blocks(pose_graph_dir: Path) -> None:
    """The translation-rotation block of a full 6x6 information lands where g2o puts it."""
    graph = read_g2o(pose_graph_dir / "gtsam_pose3example-offdiagonal.txt")
    info = graph.information[0]
    # File row 1 (x) is "10000 1 1 1 1 1", row 4 (rx) starts at column 4 with "10000 4 4".
    np.testing.assert_array_equal(info[0], [10000, 1, 1, 1, 1, 1])
    np.testing.assert_array_equal(info[3, 3:], [10000, 4, 4])
    np.testing.assert_array_equal(info, info.T)


def test_edges_only_files_compose_odometry(pose_graph_dir: Path) -> None:
    """manhattan has no VERTEX lines: the initial guess is the composed edges, first pose at the origin."""
    graph = read_g2o(pose_graph_dir / "manhattan.g2o")
    assert graph.initial_from_edges
    assert graph.n_poses == 3500
    np.testing.assert_array_equal(graph.T_world_pose[0], np.eye(3))
    # Each odometry edge i -> i+1 is exact at the composed initial guess (the spanning tree uses it).
    odo = np.flatnonzero(graph.edge_j - graph.edge_i == 1)[:50]
    Ti, Tj = graph.T_world_pose[graph.edge_i[odo]], graph.T_world_pose[graph.edge_j[odo]]
    np.testing.assert_allclose(np.linalg.inv(Ti) @ Tj, graph.T_ij[odo], atol=1e-9)


def test_toro_edge3_order_matches_g2o_version(pose_graph_dir: Path) -> None:
    """TORO EDGE3 (roll pitch yaw, information translation first) describes the same edges as g2o.

    gtsam_sphere2500.txt and sphere2500.g2o hold the same measurements; the g2o file's rotational
    information is 4x TORO's (g2o weights the quaternion vector part, half the angle), its
    translational information equal.
    """
    toro = read_g2o(pose_graph_dir / "gtsam_sphere2500.txt")
    g2o = read_g2o(pose_graph_dir / "sphere2500.g2o")
    row_of = {(int(i), int(j)): e for e, (i, j) in enumerate(zip(g2o.edge_i, g2o.edge_j, strict=True))}
    rows = [row_of[int(i), int(j)] for i, j in zip(toro.edge_i, toro.edge_j, strict=True)]
    np.testing.assert_allclose(toro.T_ij, g2o.T_ij[rows], atol=2e-5)  # 6 printed digits
    diag_toro = np.diagonal(toro.information, axis1=1, axis2=2)
    diag_g2o = np.diagonal(g2o.information[rows], axis1=1, axis2=2)
    np.testing.assert_allclose(diag_g2o[:, :3], diag_toro[:, :3], rtol=1e-3)
    np.testing.assert_allclose(diag_g2o[:, 3:], 4 * diag_toro[:, 3:], rtol=0.05)


def test_toro_2d_information_order(tmp_path: Path) -> None:
    """EDGE2 lists inf_xx inf_xy inf_yy inf_tt inf_xt inf_yt (TORO), unlike EDGE_SE2."""
    path = _write(tmp_path, "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 10 1 20 30 2 3\n", "w.graph")
    info = read_g2o(path).information[0]
    np.testing.assert_array_equal(info, [[10, 1, 2], [1, 20, 3], [2, 3, 30]])


@pytest.mark.parametrize("name", ["sphere2500.g2o", "intel.g2o"])
def test_write_read_round_trip(pose_graph_dir: Path, tmp_path: Path, name: str) -> None:
    """write then read gives the same graph to ~1e-13 (15 printed digits)."""
    graph = read_g2o(pose_graph_dir / name)
    out = tmp_path / "out.g2o"
    write_g2o(graph, out)
    again = read_g2o(out)
    np.testing.assert_array_equal(again.ids, graph.ids)
    np.testing.assert_array_equal(again.edge_i, graph.edge_i)
    np.testing.assert_array_equal(again.edge_j, graph.edge_j)
    np.testing.assert_allclose(again.T_world_pose, graph.T_world_pose, atol=1e-13)
    np.testing.assert_allclose(again.T_ij, graph.T_ij, atol=1e-13)
    np.testing.assert_allclose(again.information, graph.information, rtol=1e-14)


@settings(max_examples=30, deadline=None)
@given(
    xyz=st.lists(st.floats(-1e4, 1e4), min_size=3, max_size=3),
    ypr=st.lists(st.floats(-3.14, 3.14), min_size=3, max_size=3),
)
def test_round_trip_property_3d(
    tmp_path_factory: pytest.TempPathFactory, xyz: list[float], ypr: list[float]
) -> None:
    """Any rigid transform survives write + read to 1e-12 (15 printed digits)."""
    T = se3(euler2rot(*ypr), xyz)
    graph = PoseGraph(
        3,
        np.array([0, 1]),
        np.stack([np.eye(4), T]),
        np.array([0]),
        np.array([1]),
        T[None],
        np.eye(6)[None] * 7.0,
    )
    out = tmp_path_factory.mktemp("rt") / "g.g2o"
    write_g2o(graph, out)
    again = read_g2o(out)
    np.testing.assert_allclose(
        again.T_world_pose, graph.T_world_pose, atol=1e-11 * max(1.0, np.abs(xyz).max())
    )
    np.testing.assert_allclose(again.T_ij, graph.T_ij, atol=1e-11 * max(1.0, np.abs(xyz).max()))


def test_write_refuses_to_overwrite(tmp_path: Path) -> None:
    graph = read_g2o(_write(tmp_path, TINY_2D))
    out = _write(tmp_path, "keep me", "out.g2o")
    with pytest.raises(OutputExistsError, match=r"out\.g2o"):
        write_g2o(graph, out)
    assert out.read_text() == "keep me"
    write_g2o(graph, out, overwrite=True)
    assert read_g2o(out).n_edges == 3
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temp file left


BAD_FILES = [
    ("unknown tag", TINY_2D + "FIX 0\n", 7, "unknown record 'FIX'"),
    (
        "too few fields",
        TINY_2D.replace("EDGE_SE2 1 2 1 0 0.1 100 0 0 100 0 400", "EDGE_SE2 1 2 1 0 0.1 100 0"),
        5,
        "needs 11 fields after the tag; found 7",
    ),
    (
        "missing vertex",
        TINY_2D + "EDGE_SE2 0 7 1 0 0 1 0 0 1 0 1\n",
        7,
        "edge names vertex 7, which the file does not define",
    ),
    ("not positive definite", TINY_2D + "EDGE_SE2 0 2 1 0 0 1 0 0 -1 0 1\n", 7, "not positive definite"),
    ("singular", TINY_2D + "EDGE_SE2 0 2 1 0 0 1 0 0 0 0 1\n", 7, "not positive definite"),
    (
        "not a number",
        TINY_2D.replace("VERTEX_SE2 2 2 0.1 0.2", "VERTEX_SE2 2 2 abc 0.2"),
        3,
        "field 3 'abc' is not a number",
    ),
    ("not finite", TINY_2D.replace("VERTEX_SE2 2 2 0.1 0.2", "VERTEX_SE2 2 2 nan 0.2"), 3, "not finite"),
    (
        "bad id",
        TINY_2D.replace("VERTEX_SE2 2 ", "VERTEX_SE2 -2 "),
        3,
        "vertex id '-2' is not a non-negative integer",
    ),
    ("duplicate vertex", TINY_2D + "VERTEX_SE2 1 0 0 0\n", 7, "vertex 1 is defined again (line 2)"),
    ("self loop", TINY_2D + "EDGE_SE2 1 1 0 0 0 1 0 0 1 0 1\n", 7, "joins a vertex to itself"),
    ("mixed dimensions", TINY_2D + "VERTEX_SE3:QUAT 5 0 0 0 0 0 0 1\n", 7, "is 3D but line 1 is 2D"),
    ("bad quaternion", "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 2\n", 1, "quaternion norm 2 is not 1"),
    ("toro equiv", "VERTEX2 0 0 0 0\nEQUIV 0 1\n", 2, "EQUIV"),
]


@pytest.mark.parametrize(("case", "text", "line", "message"), BAD_FILES, ids=[c[0] for c in BAD_FILES])
def test_bad_files_are_one_line_errors(tmp_path: Path, case: str, text: str, line: int, message: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(PoseGraphFormatError) as info:
        read_g2o(path)
    text_of_error = str(info.value)
    assert "\n" not in text_of_error
    assert text_of_error.startswith(f"{path}: line {line}: ")
    assert message in text_of_error


def test_empty_and_disconnected_edge_only_files(tmp_path: Path) -> None:
    with pytest.raises(PoseGraphFormatError, match="no vertices or edges"):
        read_g2o(_write(tmp_path, "# nothing\n\n"))
    two_pieces = "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 2 3 1 0 0 1 0 0 1 0 1\n"
    with pytest.raises(PoseGraphFormatError, match="do not connect vertex 2 to vertex 0"):
        read_g2o(_write(tmp_path, two_pieces))


def test_posegraph_validates_shapes() -> None:
    with pytest.raises(ValueError, match="T_world_pose must have shape"):
        PoseGraph(
            3,
            np.array([0]),
            np.eye(3)[None],
            np.zeros(0, int),
            np.zeros(0, int),
            np.zeros((0, 4, 4)),
            np.zeros((0, 6, 6)),
        )
    with pytest.raises(ValueError, match="not both vertices"):
        PoseGraph(
            2, np.array([0]), np.eye(3)[None], np.array([0]), np.array([4]), np.eye(3)[None], np.eye(3)[None]
        )
