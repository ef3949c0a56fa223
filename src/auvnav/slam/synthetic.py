"""Synthetic 3D pose graphs with a known truth, for tests and benchmarks of the solvers.

The vehicle flies a lawnmower survey: parallel track lines along north, alternating direction, one pose
every ``step_m``, the next line ``line_spacing_m`` to the east, with small random roll, pitch and depth
changes. Odometry edges join consecutive poses; loop closures join poses on different track lines that
lie within ``loop_radius_m`` of each other horizontally (the overlapping images of adjacent lines), as
the visual loop closures of a real survey do. A fraction of the loop closures can be replaced by gross
false ones: random pose pairs with a random relative pose metres away from the truth.

Measurements are the true relative poses perturbed on the right, ``T_ij = T_ij_true @ Exp(xi)``, with
``xi`` drawn from the edge's covariance through GTSAM's exponential map, so the graph's chi-square at
the truth follows the chi-square distribution GTSAM's cost assumes. The initial guess (the graph's
``T_world_pose``) is dead reckoning: the odometry measurements composed from the true first pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from auvnav.frames import euler2rot, se3, se3_inverse
from auvnav.slam.g2o import FloatArray, PoseGraph


@dataclass(frozen=True)
class SyntheticPoseGraph:
    """A synthetic pose graph and its truth.

    Parameters
    ----------
    graph : PoseGraph
        The 3D graph; ``T_world_pose`` is dead reckoning (composed odometry).
    T_world_true : ndarray, shape (N, 4, 4)
        The true poses, metres, world frame x north, y east, z down.
    is_outlier : ndarray of bool, shape (M,)
        Which edges are false loop closures.
    """

    graph: PoseGraph
    T_world_true: FloatArray
    is_outlier: NDArray[np.bool_]

    def __post_init__(self) -> None:
        if self.T_world_true.shape != self.graph.T_world_pose.shape:
            raise ValueError(
                f"T_world_true must have shape {self.graph.T_world_pose.shape}; found {self.T_world_true.shape}"
            )
        if self.is_outlier.shape != (self.graph.n_edges,):
            raise ValueError(
                f"is_outlier must have shape ({self.graph.n_edges},); found {self.is_outlier.shape}"
            )


def _lawnmower(
    n_poses: int, per_line: int, step_m: float, spacing_m: float, rng: np.random.Generator
) -> FloatArray:
    """True survey poses (N, 4, 4): lines along north, alternating, small roll/pitch/depth wander."""
    k = np.arange(n_poses)
    line, along = np.divmod(k, per_line)
    reverse = line % 2 == 1
    s = np.where(reverse, (per_line - 1 - along), along) * step_m
    yaw = np.where(reverse, np.pi, 0.0)
    roll, pitch = rng.normal(0.0, np.radians(2.0), (2, n_poses))  # passively stable vehicle
    depth = 20.0 + 0.5 * np.sin(2 * np.pi * s / (per_line * step_m)) + 0.3 * np.sin(line)
    p = np.column_stack([s, line * spacing_m, depth])
    return se3(euler2rot(yaw, pitch, roll), p)


def _perturbed(T_true: FloatArray, sigma: FloatArray, rng: np.random.Generator) -> FloatArray:
    """``T_true @ Exp(xi)`` for xi ~ N(0, diag(sigma^2)), sigma in order (x, y, z, rx, ry, rz)."""
    xi = rng.normal(size=(len(T_true), 6)) * sigma
    out = np.empty_like(T_true)
    for r, (T, x) in enumerate(zip(T_true, xi, strict=True)):
        out[r] = T @ gtsam.Pose3.Expmap(np.concatenate([x[3:], x[:3]])).matrix()
    return out


def survey_pose_graph(
    n_poses: int,
    n_loops: int,
    *,
    per_line: int = 100,
    step_m: float = 1.0,
    line_spacing_m: float = 1.0,
    loop_radius_m: float = 2.3,
    outlier_fraction: float = 0.0,
    sigma_odometry: tuple[float, float] = (0.02, np.radians(0.2)),
    sigma_loop: tuple[float, float] = (0.05, np.radians(0.5)),
    seed: int = 0,
) -> SyntheticPoseGraph:
    """A lawnmower-survey pose graph with loop closures between adjacent track lines.

    Parameters
    ----------
    n_poses : int
        Number of poses N (ids 0..N-1).
    n_loops : int
        Number of loop closures, false ones included.
    per_line : int
        Poses per track line.
    step_m, line_spacing_m : float
        Distance between poses along a line, and between lines, metres.
    loop_radius_m : float
        Poses on different lines closer than this (horizontally) are loop-closure candidates, metres.
    outlier_fraction : float
        Fraction of the loop closures that are false, in [0, 1).
    sigma_odometry, sigma_loop : (float, float)
        Standard deviations (translation metres, rotation radians, per axis) of odometry and loop
        closures; the edges' information is their inverse square.
    seed : int
        Seed of the random generator.

    Returns
    -------
    SyntheticPoseGraph
        Edges: N-1 odometry edges, then the loop closures.

    Raises
    ------
    ValueError
        When the survey has fewer loop-closure candidates than ``n_loops`` asks for.
    """
    if not 0.0 <= outlier_fraction < 1.0:
        raise ValueError(f"outlier_fraction must lie in [0, 1); found {outlier_fraction}")
    rng = np.random.default_rng(seed)
    T_true = _lawnmower(n_poses, per_line, step_m, line_spacing_m, rng)
    line = np.arange(n_poses) // per_line
    pairs = cKDTree(T_true[:, :2, 3]).query_pairs(loop_radius_m, output_type="ndarray")
    pairs = pairs[line[pairs[:, 0]] != line[pairs[:, 1]]]
    n_false = round(outlier_fraction * n_loops)
    n_true = n_loops - n_false
    if len(pairs) < n_true:
        raise ValueError(f"the survey has {len(pairs)} loop-closure candidates; {n_true} asked for")
    loops = pairs[rng.choice(len(pairs), n_true, replace=False)]
    false_i = rng.integers(0, n_poses, n_false)
    false_j = (false_i + rng.integers(2, n_poses - 1, n_false)) % n_poses
    edge_i = np.concatenate([np.arange(n_poses - 1), loops[:, 0], false_i])
    edge_j = np.concatenate([np.arange(1, n_poses), loops[:, 1], false_j])

    def relative(i: NDArray[np.int64], j: NDArray[np.int64]) -> FloatArray:
        return se3_inverse(T_true[i]) @ T_true[j]

    sig_odo = np.repeat(sigma_odometry, 3)
    sig_loop = np.repeat(sigma_loop, 3)
    T_odo = _perturbed(relative(edge_i[: n_poses - 1], edge_j[: n_poses - 1]), sig_odo, rng)
    T_loop = _perturbed(relative(loops[:, 0], loops[:, 1]), sig_loop, rng)
    # A false loop closure claims a relative pose metres and tens of degrees away from the truth.
    T_wrong = se3(
        euler2rot(rng.uniform(-np.pi, np.pi, n_false), 0.0, 0.0),
        rng.uniform(3.0, 20.0, (n_false, 3)) * rng.choice([-1.0, 1.0], (n_false, 3)),
    )
    T_false = relative(false_i, false_j) @ T_wrong
    info = np.concatenate(
        [
            np.broadcast_to(np.diag(sig_odo**-2), (n_poses - 1, 6, 6)),
            np.broadcast_to(np.diag(sig_loop**-2), (n_loops, 6, 6)),
        ]
    )
    T_dr = np.empty_like(T_true)
    T_dr[0] = T_true[0]
    for r in range(1, n_poses):
        T_dr[r] = T_dr[r - 1] @ T_odo[r - 1]
    graph = PoseGraph(
        3,
        np.arange(n_poses, dtype=np.int64),
        T_dr,
        edge_i.astype(np.int64),
        edge_j.astype(np.int64),
        np.concatenate([T_odo, T_loop, T_false]),
        np.ascontiguousarray(info),
        source=f"synthetic survey ({n_poses} poses, {n_loops} loop closures, seed {seed})",
    )
    is_outlier = np.zeros(graph.n_edges, dtype=bool)
    is_outlier[n_poses - 1 + n_true :] = True
    return SyntheticPoseGraph(graph, T_true, is_outlier)
