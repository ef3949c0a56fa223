"""Pose-graph files: a strict reader and a writer for g2o (and TORO) text.

A pose graph is a set of poses (vertices) and relative-pose measurements between them (edges), each
with an information matrix. The formats read here, one record per line:

- ``VERTEX_SE2 id x y theta``: g2o 2D pose.
- ``EDGE_SE2 i j dx dy dtheta`` + 6 values: g2o 2D edge, upper-triangular information row by row.
- ``VERTEX_SE3:QUAT id x y z qx qy qz qw``: g2o 3D pose, Hamilton quaternion with the scalar last.
- ``EDGE_SE3:QUAT i j x y z qx qy qz qw`` + 21 values: g2o 3D edge, upper-triangular 6x6
  information row by row, order (x, y, z, rx, ry, rz).
- ``VERTEX2 id x y theta``: TORO 2D pose.
- ``EDGE2 i j dx dy dtheta Ixx Ixy Iyy Itt Ixt Iyt``: TORO 2D edge, TORO's information order.
- ``VERTEX3 id x y z roll pitch yaw``: TORO 3D pose, ``R = Rz(yaw) Ry(pitch) Rx(roll)``.
- ``EDGE3 i j x y z roll pitch yaw`` + 21 values: TORO 3D edge, information laid out as g2o's
  (translation first; the g2o and TORO versions of sphere2500 agree on this. GTSAM 4.3's
  ``readG2o`` takes this block rotation first instead).

Blank lines and lines starting with ``#`` are skipped. Anything else (an unknown tag, a wrong number
of fields, a number that does not parse, a duplicate vertex, an edge naming a vertex the file does not
define, an information matrix that is not symmetric positive definite, 2D and 3D records mixed) is a
:class:`PoseGraphFormatError` naming the file and line. TORO's ``EQUIV`` (vertex merging) is not
supported and is reported as such.

Files with edges but no vertex lines (e.g. manhattan, CSAIL) are accepted: the initial poses are then
composed from the edges, odometry first, from the lowest id placed at the origin (the odometry
initialisation every reader of these files uses).

Conventions of :class:`PoseGraph`: a pose ``T_world_pose`` maps coordinates in the pose's frame to the
world frame of the file, homogeneous, shape (3, 3) for SE(2) and (4, 4) for SE(3); an edge ``T_ij``
is pose j expressed in pose i, ``T_ij = inv(T_world_i) @ T_world_j`` when the edge is exact. The
information matrices keep the file's order, translation first: (x, y, theta) in 2D and
(x, y, z, rx, ry, rz) in 3D. As in GTSAM's ``readG2o`` (and the reference costs of
``../shared/reference/pose_graph_g2o``), the rotational block applies to the rotation vector of the
pose error (GTSAM's ``Pose3`` local coordinates), not to g2o's quaternion vector part.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from auvnav.config import quote
from auvnav.errors import AuvnavError
from auvnav.frames import euler2rot, quat_wxyz2rot, rot2quat_wxyz, se3, se3_inverse
from auvnav.streams import atomic_write, ensure_writable

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: A quaternion whose norm differs from 1 by more than this is an error, not a rounding artefact
#: (files print 6 to 9 significant digits, so honest norms are within ~1e-6 of 1).
QUATERNION_NORM_TOLERANCE = 1e-2
#: Longest line read, characters (an EDGE_SE3:QUAT record with 30 numbers is under 1000).
MAX_LINE_CHARS = 2**16
#: Vertex ids must be below this (they are held as int64).
MAX_VERTEX_ID = 2**63 - 1


class PoseGraphFormatError(AuvnavError):
    """A pose-graph file breaks its format; the message names the file and line."""


@dataclass(frozen=True)
class _Record:
    """How one tag is laid out: dimension, number of fields after the tag, vertex or edge."""

    dim: int
    n_fields: int
    is_edge: bool


_RECORDS: dict[str, _Record] = {
    "VERTEX_SE2": _Record(2, 4, False),
    "EDGE_SE2": _Record(2, 11, True),
    "VERTEX_SE3:QUAT": _Record(3, 8, False),
    "EDGE_SE3:QUAT": _Record(3, 30, True),
    "VERTEX2": _Record(2, 4, False),
    "EDGE2": _Record(2, 11, True),
    "VERTEX3": _Record(3, 7, False),
    "EDGE3": _Record(3, 29, True),
}

# Positions of the upper-triangular information values in the flattened k x k matrix, per tag.
_UPPER_3 = [(r, c) for r in range(3) for c in range(r, 3)]
_UPPER_6 = [(r, c) for r in range(6) for c in range(r, 6)]
# TORO 2D: inf_ff inf_fs inf_ss inf_rr inf_fr inf_sr (f = forward x, s = sideways y, r = rotation).
_TORO_2D = [(0, 0), (0, 1), (1, 1), (2, 2), (0, 2), (1, 2)]


def se2(x: FloatArray, y: FloatArray, theta: FloatArray) -> FloatArray:
    """Homogeneous SE(2) matrices (..., 3, 3) from position and heading (radians)."""
    c, s = np.cos(theta), np.sin(theta)
    T = np.zeros((*np.shape(x), 3, 3))
    T[..., 0, 0], T[..., 0, 1], T[..., 1, 0], T[..., 1, 1] = c, -s, s, c
    T[..., 0, 2], T[..., 1, 2], T[..., 2, 2] = x, y, 1.0
    return T


def inverse_rigid(T: FloatArray) -> FloatArray:
    """Inverse of rigid transforms of either dimension, (..., d+1, d+1)."""
    if T.shape[-1] == 4:
        return se3_inverse(T)
    Rt = np.swapaxes(T[..., :2, :2], -1, -2)
    out = np.zeros_like(T)
    out[..., :2, :2] = Rt
    out[..., :2, 2] = -(Rt @ T[..., :2, 2, None])[..., 0]
    out[..., 2, 2] = 1.0
    return out


@dataclass(frozen=True)
class PoseGraph:
    """A 2D or 3D pose graph: poses, relative-pose edges and their information.

    Parameters
    ----------
    dim : int
        2 (SE(2) poses) or 3 (SE(3) poses).
    ids : ndarray of int64, shape (N,)
        Vertex ids, unique, non-negative, ascending.
    T_world_pose : ndarray, shape (N, d+1, d+1)
        Poses (initial guess or solution), homogeneous rigid transforms from each pose's frame to the
        world frame of the graph; d = ``dim``; translations in the file's unit (metres for our graphs).
    edge_i, edge_j : ndarray of int64, shape (M,)
        Vertex ids joined by each edge (members of ``ids``, ``edge_i != edge_j``).
    T_ij : ndarray, shape (M, d+1, d+1)
        Measured pose j in the frame of pose i.
    information : ndarray, shape (M, k, k)
        Information (inverse covariance) of each edge, symmetric positive definite, k = 3 with order
        (x, y, theta) or k = 6 with order (x, y, z, rx, ry, rz); metres and radians.
    source : str
        Where the graph came from (a file path or a description), for messages.
    initial_from_edges : bool
        True when the file had no vertices and ``T_world_pose`` was composed from the edges.
    """

    dim: int
    ids: IntArray
    T_world_pose: FloatArray
    edge_i: IntArray
    edge_j: IntArray
    T_ij: FloatArray
    information: FloatArray
    source: str = ""
    initial_from_edges: bool = False

    def __post_init__(self) -> None:
        if self.dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3; found {self.dim}")
        d, k = self.dim + 1, 3 * (self.dim - 1)
        n, m = len(self.ids), len(self.edge_i)
        expected = {
            "ids": ((n,), np.shape(self.ids)),
            "T_world_pose": ((n, d, d), np.shape(self.T_world_pose)),
            "edge_i": ((m,), np.shape(self.edge_i)),
            "edge_j": ((m,), np.shape(self.edge_j)),
            "T_ij": ((m, d, d), np.shape(self.T_ij)),
            "information": ((m, k, k), np.shape(self.information)),
        }
        for name, (want, found) in expected.items():
            if want != found:
                raise ValueError(f"{name} must have shape {want} for a {self.dim}D graph; found {found}")
        if n == 0:
            raise ValueError("a pose graph needs at least one pose")
        if np.any(np.diff(self.ids) <= 0) or self.ids[0] < 0:
            raise ValueError("ids must be non-negative and strictly ascending")
        known = np.isin(self.edge_i, self.ids) & np.isin(self.edge_j, self.ids)
        if not np.all(known):
            bad = int(np.flatnonzero(~known)[0])
            raise ValueError(f"edge {bad} joins {self.edge_i[bad]} and {self.edge_j[bad]}, not both vertices")
        if np.any(self.edge_i == self.edge_j):
            raise ValueError(f"edge {int(np.flatnonzero(self.edge_i == self.edge_j)[0])} is a self loop")
        spd = _is_spd(self.information)
        if not spd.all():
            bad = int(np.flatnonzero(~spd)[0])
            raise ValueError(f"information of edge {bad} is not symmetric positive definite")

    @property
    def n_poses(self) -> int:
        """Number of vertices N."""
        return len(self.ids)

    @property
    def n_edges(self) -> int:
        """Number of edges M."""
        return len(self.edge_i)

    def rows(self, ids: IntArray) -> IntArray:
        """Row numbers in ``ids``/``T_world_pose`` of the given vertex ids, shape as ``ids``."""
        wanted = np.asarray(ids, dtype=np.int64)
        rows = np.clip(np.searchsorted(self.ids, wanted), 0, len(self.ids) - 1)
        missing = self.ids[rows] != wanted
        if np.any(missing):
            raise ValueError(f"vertex {wanted[missing].flat[0]} is not in the graph")
        return rows

    @property
    def is_odometry(self) -> NDArray[np.bool_]:
        """Edges joining poses adjacent in id order (odometry); the others are loop closures."""
        return np.abs(self.rows(self.edge_i) - self.rows(self.edge_j)) == 1

    def with_poses(self, T_world_pose: FloatArray) -> PoseGraph:
        """The same graph with other poses (e.g. a solution), shape (N, d+1, d+1)."""
        return PoseGraph(
            self.dim,
            self.ids,
            np.asarray(T_world_pose, dtype=float),
            self.edge_i,
            self.edge_j,
            self.T_ij,
            self.information,
            self.source,
            initial_from_edges=False,
        )

    def subgraph(self, keep_edges: NDArray[np.bool_]) -> PoseGraph:
        """The same poses with only the edges where ``keep_edges`` (shape (M,)) is true."""
        keep = np.asarray(keep_edges, dtype=bool)
        return PoseGraph(
            self.dim,
            self.ids,
            self.T_world_pose,
            self.edge_i[keep],
            self.edge_j[keep],
            self.T_ij[keep],
            self.information[keep],
            self.source,
            self.initial_from_edges,
        )


def _is_spd(information: FloatArray) -> NDArray[np.bool_]:
    """Which of a stack of (k, k) matrices are symmetric positive definite."""
    info = np.asarray(information, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        sym = np.all(
            np.abs(info - np.swapaxes(info, -1, -2))
            <= 1e-9 * np.abs(info).max(axis=(-2, -1))[..., None, None],
            axis=(-2, -1),
        )
        sym &= np.isfinite(info).all(axis=(-2, -1)) & (np.abs(info).max(axis=(-2, -1)) < 1e150)
        safe = np.where(sym[..., None, None], info, np.eye(info.shape[-1]))
        try:
            eig = np.linalg.eigvalsh(safe)
        except np.linalg.LinAlgError:  # a matrix LAPACK cannot decompose: judge each on its own
            eig = np.array([_eigvalsh_or_nan(m) for m in safe.reshape(-1, *info.shape[-2:])])
            eig = eig.reshape(*info.shape[:-1])
    # Positive beyond rounding: a condition number past 1e12 cannot be factored reliably.
    return sym & np.isfinite(eig).all(axis=-1) & (eig[..., 0] > 1e-12 * np.abs(eig[..., -1]))


def _eigvalsh_or_nan(matrix: FloatArray) -> FloatArray:
    try:
        return np.linalg.eigvalsh(matrix)
    except np.linalg.LinAlgError:
        return np.full(matrix.shape[-1], np.nan)


def _fail(path: Path, line_no: int, message: str) -> PoseGraphFormatError:
    return PoseGraphFormatError(f"{path}: line {line_no}: {message}")


def _parse_numbers(path: Path, rows: list[tuple[int, list[str]]]) -> FloatArray:
    """Fields of many lines as a float array; on failure, name the first bad line and field."""
    try:
        values = np.array([fields for _, fields in rows], dtype=float)
    except ValueError:
        for line_no, fields in rows:
            for col, text in enumerate(fields, start=2):
                try:
                    float(text)
                except ValueError:
                    raise _fail(path, line_no, f"field {col} {quote(text)} is not a number") from None
        raise
    finite = np.isfinite(values).all(axis=1)
    if not finite.all():
        raise _fail(path, rows[int(np.flatnonzero(~finite)[0])][0], "a value is not finite")
    return values


def _parse_ids(path: Path, rows: list[tuple[int, list[str]]], n_ids: int) -> IntArray:
    """The leading integer id fields of many lines; a non-integer or negative id names its line."""
    out = np.empty((len(rows), n_ids), dtype=np.int64)
    for r, (line_no, fields) in enumerate(rows):
        for c in range(n_ids):
            text = fields[c]
            if not (text.isascii() and text.isdigit()):
                raise _fail(path, line_no, f"vertex id {quote(text)} is not a non-negative integer")
            if len(text) > 19 or int(text) > MAX_VERTEX_ID:
                raise _fail(path, line_no, f"vertex id {quote(text)} is too large (at most 2^63 - 1)")
            out[r, c] = int(text)
    return out


def _rotations(tag: str, values: FloatArray, path: Path, line_nos: list[int]) -> FloatArray:
    """Rotation matrices from a record's rotation fields (theta, quaternion x y z w, or roll pitch yaw)."""
    if tag in ("VERTEX_SE3:QUAT", "EDGE_SE3:QUAT"):
        q_xyzw = values[:, 3:7]
        norm = np.linalg.norm(q_xyzw, axis=1)
        bad = np.abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE
        if bad.any():
            r = int(np.flatnonzero(bad)[0])
            raise _fail(path, line_nos[r], f"quaternion norm {norm[r]:.6g} is not 1")
        return quat_wxyz2rot(q_xyzw[:, [3, 0, 1, 2]])
    if tag in ("VERTEX3", "EDGE3"):
        roll, pitch, yaw = values[:, 3], values[:, 4], values[:, 5]
        return euler2rot(yaw, pitch, roll)
    raise AssertionError(f"no rotation layout for {tag}")  # pragma: no cover - table above is closed


def _poses(tag: str, values: FloatArray, path: Path, line_nos: list[int]) -> FloatArray:
    """Homogeneous transforms from the pose fields (after the ids) of one tag's records."""
    if _RECORDS[tag].dim == 2:
        return se2(values[:, 0], values[:, 1], values[:, 2])
    return se3(_rotations(tag, values, path, line_nos), values[:, :3])


def _information(tag: str, values: FloatArray) -> FloatArray:
    """Symmetric information matrices from the trailing upper-triangular fields of edge records."""
    k = 3 if _RECORDS[tag].dim == 2 else 6
    layout = _TORO_2D if tag == "EDGE2" else _UPPER_3 if k == 3 else _UPPER_6
    tri = values[:, -len(layout) :]
    info = np.zeros((len(values), k, k))
    for col, (r, c) in enumerate(layout):
        info[:, r, c] = tri[:, col]
        info[:, c, r] = tri[:, col]
    return info


def _compose_from_edges(
    ids: IntArray, edge_i: IntArray, edge_j: IntArray, T_ij: FloatArray, path: Path
) -> FloatArray:
    """Initial poses composed from edges, from the lowest id at the origin.

    The edges used form a spanning tree grown from the first vertex that takes odometry edges (between
    consecutive ids) before any loop closure (Prim's algorithm with weights 0 and 1), so the initial
    guess is the odometry chain wherever there is one.
    """
    index = {int(v): r for r, v in enumerate(ids)}
    neighbours: list[list[tuple[int, int, int, bool]]] = [[] for _ in ids]
    for e, (a, b) in enumerate(zip(edge_i, edge_j, strict=True)):
        ra, rb = index[int(a)], index[int(b)]
        weight = 0 if abs(ra - rb) == 1 else 1
        neighbours[ra].append((weight, e, rb, True))
        neighbours[rb].append((weight, e, ra, False))
    T = np.full((len(ids), *T_ij.shape[1:]), np.nan)
    T[0] = np.eye(T_ij.shape[-1])
    reached = np.zeros(len(ids), dtype=bool)
    reached[0] = True
    frontier = [(w, e, 0, other, fwd) for w, e, other, fwd in neighbours[0]]
    heapq.heapify(frontier)
    while frontier:
        _, e, r, other, forward = heapq.heappop(frontier)
        if reached[other]:
            continue
        with np.errstate(over="ignore", invalid="ignore"):
            T[other] = T[r] @ (T_ij[e] if forward else inverse_rigid(T_ij[e]))
        reached[other] = True
        for w, e2, nxt, fwd in neighbours[other]:
            if not reached[nxt]:
                heapq.heappush(frontier, (w, e2, other, nxt, fwd))
    unreached = ~reached
    if unreached.any():
        raise PoseGraphFormatError(
            f"{path}: the file has no vertices and its edges do not connect vertex "
            f"{ids[np.flatnonzero(unreached)[0]]} to vertex {ids[0]}: no initial guess"
        )
    return T


def read_g2o(path: str | os.PathLike[str]) -> PoseGraph:
    """Read a g2o or TORO pose-graph file strictly.

    Parameters
    ----------
    path : path-like
        The file (see the module docstring for the records accepted).

    Returns
    -------
    PoseGraph
        Vertices sorted by id; edges in file order; ``source`` is the path.

    Raises
    ------
    PoseGraphFormatError
        One line naming the file, the line number and the problem.
    FileNotFoundError
        When the file does not exist.
    """
    path = Path(path)
    if path.exists() and not path.is_file():  # a named pipe would block for ever
        raise PoseGraphFormatError(f"{path}: not a regular file")
    by_tag: dict[str, list[tuple[int, list[str]]]] = {}
    dim: int | None = None
    dim_line = 0
    with path.open("r", encoding="utf-8", errors="replace") as handle:
        for line_no, line in enumerate(iter(lambda: handle.readline(MAX_LINE_CHARS + 1), ""), start=1):
            if len(line) > MAX_LINE_CHARS:
                raise _fail(
                    path, line_no, f"longer than {MAX_LINE_CHARS} characters: not a pose-graph record"
                )
            fields = line.split()
            if not fields or fields[0].startswith("#"):
                continue
            tag = fields[0]
            record = _RECORDS.get(tag)
            if record is None:
                if tag == "EQUIV":
                    raise _fail(path, line_no, "TORO EQUIV (vertex merging) is not supported")
                known = ", ".join(_RECORDS)
                raise _fail(path, line_no, f"unknown record {quote(tag)} (expected one of {known})")
            if len(fields) - 1 != record.n_fields:
                raise _fail(
                    path,
                    line_no,
                    f"{tag} needs {record.n_fields} fields after the tag; found {len(fields) - 1}",
                )
            if dim is None:
                dim, dim_line = record.dim, line_no
            elif record.dim != dim:
                raise _fail(path, line_no, f"{tag} is {record.dim}D but line {dim_line} is {dim}D")
            by_tag.setdefault(tag, []).append((line_no, fields[1:]))
    if dim is None:
        raise PoseGraphFormatError(f"{path}: no vertices or edges")

    vertex_ids: list[IntArray] = []
    vertex_T: list[FloatArray] = []
    vertex_lines: list[int] = []
    edges: list[tuple[IntArray, FloatArray, FloatArray, list[int]]] = []
    for tag, rows in by_tag.items():
        record = _RECORDS[tag]
        n_ids = 2 if record.is_edge else 1
        line_nos = [line_no for line_no, _ in rows]
        ids = _parse_ids(path, rows, n_ids)
        values = _parse_numbers(path, [(n, f[n_ids:]) for n, f in rows])
        T = _poses(tag, values, path, line_nos)
        if record.is_edge:
            info = _information(tag, values)
            spd = _is_spd(info)
            if not spd.all():
                r = int(np.flatnonzero(~spd)[0])
                smallest = np.linalg.eigvalsh(info[r])[0]
                raise _fail(
                    path,
                    line_nos[r],
                    f"information matrix is not positive definite (smallest eigenvalue {smallest:.4g})",
                )
            self_loop = ids[:, 0] == ids[:, 1]
            if self_loop.any():
                raise _fail(
                    path, line_nos[int(np.flatnonzero(self_loop)[0])], "edge joins a vertex to itself"
                )
            edges.append((ids, T, info, line_nos))
        else:
            vertex_ids.append(ids[:, 0])
            vertex_T.append(T)
            vertex_lines.extend(line_nos)

    if edges:
        order = np.argsort(np.concatenate([e[3] for e in edges]), kind="stable")
        e_ids = np.concatenate([e[0] for e in edges])[order]
        T_ij = np.concatenate([e[1] for e in edges])[order]
        info = np.concatenate([e[2] for e in edges])[order]
        e_lines = np.concatenate([e[3] for e in edges])[order]
    else:
        k, d = 3 * (dim - 1), dim + 1
        e_ids, T_ij, info = np.zeros((0, 2), np.int64), np.zeros((0, d, d)), np.zeros((0, k, k))
        e_lines = np.zeros(0, np.int64)

    if vertex_ids:
        v_ids = np.concatenate(vertex_ids)
        v_T = np.concatenate(vertex_T)
        order = np.argsort(v_ids, kind="stable")
        v_ids, v_T = v_ids[order], v_T[order]
        dup = np.flatnonzero(np.diff(v_ids) == 0)
        if dup.size:
            lines = np.asarray(vertex_lines)[order]
            raise _fail(
                path,
                int(lines[dup[0] + 1]),
                f"vertex {v_ids[dup[0]]} is defined again (line {lines[dup[0]]})",
            )
        missing = ~np.isin(e_ids, v_ids)
        if missing.any():
            r, c = np.argwhere(missing)[0]
            raise _fail(
                path, int(e_lines[r]), f"edge names vertex {e_ids[r, c]}, which the file does not define"
            )
        from_edges = False
    else:
        v_ids = np.unique(e_ids)
        v_T = _compose_from_edges(v_ids, e_ids[:, 0], e_ids[:, 1], T_ij, path)
        from_edges = True
        log.info("%s: no vertices; composed %d initial poses from the edges", path, len(v_ids))

    return PoseGraph(dim, v_ids, v_T, e_ids[:, 0], e_ids[:, 1], T_ij, info, str(path), from_edges)


def _fmt(values: FloatArray) -> str:
    """Numbers as text with 15 significant digits (doubles round-trip to ~1e-15 relative)."""
    return " ".join(f"{v:.15g}" for v in values)


def _pose_fields(T: FloatArray) -> FloatArray:
    """g2o pose fields: (x, y, theta) for SE(2) or (x, y, z, qx, qy, qz, qw) for SE(3); shape (N, 3|7)."""
    if T.shape[-1] == 3:
        return np.column_stack([T[:, 0, 2], T[:, 1, 2], np.arctan2(T[:, 1, 0], T[:, 0, 0])])
    q_wxyz = rot2quat_wxyz(T[:, :3, :3])
    return np.column_stack([T[:, :3, 3], q_wxyz[:, [1, 2, 3, 0]]])


def write_g2o(graph: PoseGraph, path: str | os.PathLike[str], *, overwrite: bool = False) -> None:
    """Write a pose graph as g2o text (``VERTEX_SE2``/``EDGE_SE2`` or ``VERTEX_SE3:QUAT``/``EDGE_SE3:QUAT``).

    Numbers are printed with 15 significant digits, so reading the file back gives the same graph to
    ~1e-15 relative. The file is written to a temporary file in the same folder and renamed into
    place, so a reader never sees half a file.

    Parameters
    ----------
    graph : PoseGraph
        The graph; its ``T_world_pose`` become the vertices.
    path : path-like
        The output file.
    overwrite : bool
        Replace an existing file; otherwise an existing file is an error.

    Raises
    ------
    OutputExistsError
        When ``path`` exists and ``overwrite`` is false.
    """
    vertex_tag, edge_tag = (
        ("VERTEX_SE2", "EDGE_SE2") if graph.dim == 2 else ("VERTEX_SE3:QUAT", "EDGE_SE3:QUAT")
    )
    upper = _UPPER_3 if graph.dim == 2 else _UPPER_6
    rows, cols = zip(*upper, strict=True)
    info_tri = graph.information[:, list(rows), list(cols)]
    vertex_fields = _pose_fields(graph.T_world_pose)
    edge_fields = np.column_stack([_pose_fields(graph.T_ij), info_tri]) if graph.n_edges else []
    vertices = (f"{vertex_tag} {v} {_fmt(f)}\n" for v, f in zip(graph.ids, vertex_fields, strict=True))
    edges = (
        f"{edge_tag} {a} {b} {_fmt(f)}\n"
        for a, b, f in zip(graph.edge_i, graph.edge_j, edge_fields, strict=True)
    )
    text = "".join(itertools.chain(vertices, edges))
    atomic_write(
        ensure_writable(Path(path), overwrite=overwrite), lambda p: p.write_text(text, encoding="utf-8")
    )
