"""Outlier-robust loop-closure selection by pairwise consistency against the odometry.

A robust kernel (Cauchy) decides loop by loop at the solution, so when false loop closures outnumber
the true ones somewhere (the raw compass spreads a survey's lines apart, so the lines barely overlap
and the true cross-line loops are few while a front end's false ones are not), the optimum follows the
false ones. Pairwise consistency maximisation (Mangelson et al. 2018, "Pairwise Consistent
Measurement Set Maximization for Robust Multi-robot Map Merging", ICRA; Kimera-RPGO's outlier
rejection) looks at loop closures in pairs instead: two loop closures ``a = (i, j)`` and ``b = (k, l)``
with the odometry between their ends close a cycle

    C = Z_a O(j -> l) Z_b^-1 O(k -> i),

the identity when both are right. Its residual ``Log(C)`` (rotation vector, translation) is tested
against its covariance, propagated to first order (right perturbations, adjoints) from the two loop
closures' covariances and the odometry chains' (DVL odometry between consecutive poses, accumulated
once for the whole dive: :func:`_chain_covariance`). The test is sharp only for loop closures whose
ends are near each other in time (the odometry between them is then centimetres and tenths of a
degree whatever the compass: a compass's deviation changes only through turns), so each loop closure
is tested against its :data:`NEIGHBOURS` nearest loop closures in pose-index space, within
:data:`WINDOW_POSES` poses at both ends (loop closures far apart in time would pass any test: the
odometry between them knows nothing). The consistent pairs make a graph whose large cliques are the
true loop closures (a true loop closure agrees with its true neighbours; a false one, a wrong offset
and any yaw, agrees with nothing); the exact maximum clique being expensive on tens of thousands of
loop closures, the selection is local: a loop closure is kept when at least :data:`MIN_SUPPORT` of
its tested neighbours agree with it and no fewer agree than disagree, iterated with the rejected
ones removed until nothing changes. A loop closure with no neighbour to test against is rejected (a
lone claim nothing corroborates, as PCM's maximum clique would leave it out).

Every test looks only at loop closures within :data:`WINDOW_POSES` poses of a loop closure's later
end, so a vehicle can make the same decision :data:`WINDOW_POSES` poses after it finds a loop closure
(:mod:`auvnav.slam.online`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from scipy.stats import chi2 as chi2_distribution

from auvnav.frames import FloatArray, skew
from auvnav.slam.g2o import PoseGraph

#: Loop closures tested against a loop closure: its nearest ones in pose-index space.
NEIGHBOURS = 8
#: Neighbours lie within this many poses at both ends.
WINDOW_POSES = 10
#: Chi-square quantile (6 degrees of freedom) of the cycle test: a pair whose cycle residual exceeds
#: it is inconsistent. Generous (the DVL's scale and mounting errors are modelled only in part); the
#: false loop closures miss by metres and tens of degrees.
CONSISTENCY_QUANTILE = 0.9999
#: Consistent neighbours a loop closure needs.
MIN_SUPPORT = 1
#: Online (causal) selection: a loop closure is kept as soon as this many neighbours agree with it and
#: none disagrees, without waiting for the rest of its window.
EARLY_SUPPORT = 2

# g2o's tangent (translation first) <-> GTSAM's (rotation first); the permutation is its own inverse.
_PERM = np.array([3, 4, 5, 0, 1, 2])
_CHUNK = 20000


@dataclass(frozen=True)
class LoopSelection:
    """Pairwise-consistency decisions on a graph's loop closures (in the graph's loop order).

    Parameters
    ----------
    keep : ndarray of bool, shape (L,)
    consistent, tested : ndarray of int64, shape (L,)
        Consistent neighbours and neighbours tested, at the final iteration.
    decided_at : ndarray of int64, shape (L,)
        The latest pose any test of the loop closure looked at: when a vehicle could decide it.
    pairs : int
        Pairs tested.
    """

    keep: NDArray[np.bool_]
    consistent: NDArray[np.int64]
    tested: NDArray[np.int64]
    decided_at: NDArray[np.int64]
    pairs: int

    def summary(self) -> dict[str, int]:
        return {
            "method": "pcm",
            "kept": int(np.count_nonzero(self.keep)),
            "rejected": int(np.count_nonzero(~self.keep)),
            "pairs_tested": self.pairs,
            "unsupported": int(np.count_nonzero(self.tested == 0)),
        }


def adjoint(T: FloatArray) -> FloatArray:
    """GTSAM's Pose3 adjoint (tangent rotation first): ``[[R, 0], [t^ R, R]]``, shape (..., 6, 6)."""
    R, t = T[..., :3, :3], T[..., :3, 3]
    A = np.zeros((*T.shape[:-2], 6, 6))
    A[..., :3, :3] = R
    A[..., 3:, 3:] = R
    A[..., 3:, :3] = skew(t) @ R
    return A


def _inverse(T: FloatArray) -> FloatArray:
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def _congruence(A: FloatArray, S: FloatArray) -> FloatArray:
    return A @ S @ np.swapaxes(A, -1, -2)


@dataclass(frozen=True)
class _Chain:
    """The odometry composed from the first pose (``W``) and its covariance accumulated in that frame."""

    W: FloatArray  # (P, 4, 4): pose k in the frame of pose 0, by the odometry alone
    S: FloatArray  # (P, 6, 6): sum over m < k of Ad(W_m+1) Sigma_m Ad(W_m+1)^T

    def relative(self, x: NDArray[np.int64], y: NDArray[np.int64]) -> tuple[FloatArray, FloatArray]:
        """Pose ``y`` in the frame of pose ``x`` by the odometry, and its covariance (right perturbation)."""
        lo, hi = np.minimum(x, y), np.maximum(x, y)
        W_hi_inv = _inverse(self.W[hi])
        T_lo_hi = _inverse(W_hi_inv @ self.W[lo])  # hi in the frame of lo
        cov = _congruence(adjoint(W_hi_inv), self.S[hi] - self.S[lo])
        backward = x > y
        if np.any(backward):  # lo in the frame of hi: the inverse, its covariance through Ad(T_lo_hi)
            cov[backward] = _congruence(adjoint(T_lo_hi[backward]), cov[backward])
            T_lo_hi[backward] = _inverse(T_lo_hi[backward])
        return T_lo_hi, cov


def odometry_chain(T_odo: FloatArray, C_odo: FloatArray) -> _Chain:
    """The chain of relative poses ``T_odo`` (pose k+1 in pose k) with covariances ``C_odo`` (GTSAM's
    tangent, right perturbation)."""
    P = len(T_odo) + 1
    W = np.empty((P, 4, 4))
    W[0] = np.eye(4)
    for k in range(P - 1):
        W[k + 1] = W[k] @ T_odo[k]
    S = np.zeros((P, 6, 6))
    S[1:] = np.cumsum(_congruence(adjoint(W[1:]), C_odo), axis=0)
    return _Chain(W, S)


def graph_chain(pose_graph: PoseGraph, n_odometry: int) -> _Chain:
    """The odometry chain of a pose graph whose first ``n_odometry`` edges join consecutive poses."""
    return odometry_chain(pose_graph.T_ij[:n_odometry], gtsam_covariance(pose_graph.information[:n_odometry]))


def _log(T: FloatArray) -> FloatArray:
    """Rotation vector and translation of each pose (GTSAM's order); the translation is not corrected
    by the left Jacobian (a residual near the identity, or far from it and rejected either way)."""
    return np.concatenate([Rotation.from_matrix(T[:, :3, :3]).as_rotvec(), T[:, :3, 3]], axis=1)


def gtsam_covariance(information: FloatArray) -> FloatArray:
    """Covariances in GTSAM's Pose3 tangent (rotation first) from g2o-ordered information matrices."""
    C = np.linalg.inv(information)
    return C[:, _PERM][:, :, _PERM]


def neighbour_pairs(
    a: NDArray[np.int64], b: NDArray[np.int64], *, neighbours: int, window: int, ordered: bool = False
) -> NDArray[np.int64]:
    """Pairs (p, q), p < q, of loop closures among each one's ``neighbours`` nearest in (earlier pose,
    later pose) space (``ordered``: in (a, b) space, for loop closures between two chains), within
    ``window`` poses at both ends."""
    n = len(a)
    if n < 2:
        return np.zeros((0, 2), dtype=np.int64)
    if ordered:
        pts = np.column_stack([a, b]).astype(float)
    else:
        pts = np.column_stack([np.minimum(a, b), np.maximum(a, b)]).astype(float)
    tree = cKDTree(pts)
    k = min(neighbours + 1, n)
    dist, idx = tree.query(pts, k=k, p=np.inf, distance_upper_bound=window + 0.5)
    rows = np.repeat(np.arange(n), k).reshape(n, k)
    ok = np.isfinite(dist) & (idx != rows) & (idx < n)
    p, q = rows[ok], idx[ok]
    pairs = np.unique(np.column_stack([np.minimum(p, q), np.maximum(p, q)]), axis=0)
    return pairs.astype(np.int64)


def cycle_chi2(
    chain_i: _Chain,
    chain_j: _Chain,
    i: NDArray[np.int64],
    j: NDArray[np.int64],
    Z: FloatArray,
    C: FloatArray,
    pairs: NDArray[np.int64],
) -> FloatArray:
    """Mahalanobis squared norm of each pair's cycle residual (module docstring): loop closures from
    pose ``i`` of ``chain_i`` to pose ``j`` of ``chain_j`` (the same chain within a dive)."""
    out = np.empty(len(pairs))
    for s in range(0, len(pairs), _CHUNK):
        p, q = pairs[s : s + _CHUNK, 0], pairs[s : s + _CHUNK, 1]
        X1, S1 = Z[p], C[p]
        X2, S2 = chain_j.relative(j[p], j[q])
        X3 = _inverse(Z[q])
        S3 = _congruence(adjoint(Z[q]), C[q])
        X4, S4 = chain_i.relative(i[q], i[p])
        suffix4 = X4
        suffix3 = X3 @ suffix4
        suffix2 = X2 @ suffix3
        cycle = X1 @ suffix2
        cov = (
            _congruence(adjoint(_inverse(suffix2)), S1)
            + _congruence(adjoint(_inverse(suffix3)), S2)
            + _congruence(adjoint(_inverse(suffix4)), S3)
            + S4
        )
        r = _log(cycle)
        out[s : s + _CHUNK] = np.einsum("ni,ni->n", r, np.linalg.solve(cov, r[:, :, None])[:, :, 0])
    return out


def select_loops(
    pose_graph: PoseGraph,
    n_odometry: int,
    *,
    neighbours: int = NEIGHBOURS,
    window: int = WINDOW_POSES,
    quantile: float = CONSISTENCY_QUANTILE,
    min_support: int = MIN_SUPPORT,
    max_rounds: int = 10,
    causal: bool = False,
) -> LoopSelection:
    """Pairwise-consistency selection of a graph's loop closures (module docstring).

    Parameters
    ----------
    pose_graph : PoseGraph
        Poses in a chain: edges ``0 .. n_odometry - 1`` the odometry between consecutive poses
        (``edge k`` joins poses k and k+1), the rest loop closures; information in g2o's tangent order.
    n_odometry : int
    neighbours, window, quantile, min_support, max_rounds
        As the module's constants; ``max_rounds`` bounds the iterations.
    causal : bool
        Decide each loop closure once, in the order of ``decided_at``, from the tests with the loop
        closures not already rejected (a vehicle's decision: nothing later changes it), instead of
        iterating over the whole dive.

    Returns
    -------
    LoopSelection
        Decisions for the edges after the odometry, in their order.
    """
    ei, ej = pose_graph.edge_i[n_odometry:], pose_graph.edge_j[n_odometry:]
    chain = graph_chain(pose_graph, n_odometry)
    return select_pairwise(
        chain,
        chain,
        ei.astype(np.int64),
        ej.astype(np.int64),
        pose_graph.T_ij[n_odometry:],
        gtsam_covariance(pose_graph.information[n_odometry:]),
        neighbours=neighbours,
        window=window,
        quantile=quantile,
        min_support=min_support,
        max_rounds=max_rounds,
        causal=causal,
    )


def select_pairwise(
    chain_i: _Chain,
    chain_j: _Chain,
    ei: NDArray[np.int64],
    ej: NDArray[np.int64],
    Z: FloatArray,
    C: FloatArray,
    *,
    neighbours: int = NEIGHBOURS,
    window: int = WINDOW_POSES,
    quantile: float = CONSISTENCY_QUANTILE,
    min_support: int = MIN_SUPPORT,
    max_rounds: int = 10,
    causal: bool = False,
) -> LoopSelection:
    """:func:`select_loops` for loop closures ``Z`` (covariance ``C``, GTSAM's tangent) from pose
    ``ei`` of ``chain_i`` to pose ``ej`` of ``chain_j``: two dives' chains for inter-dive loop closures
    (neighbours then in (ei, ej) space; ``decided_at`` counts in ``ej``'s chain)."""
    L = len(ei)
    if L == 0:
        empty = np.zeros(0, dtype=np.int64)
        return LoopSelection(np.zeros(0, dtype=bool), empty, empty, empty, 0)
    two = chain_i is not chain_j
    pairs = neighbour_pairs(ei, ej, neighbours=neighbours, window=window, ordered=two)
    threshold = float(chi2_distribution.ppf(quantile, 6))
    good = cycle_chi2(chain_i, chain_j, ei, ej, Z, C, pairs) <= threshold
    later = ej if two else np.maximum(ei, ej)
    decided_at = later.astype(np.int64).copy()
    if len(pairs):
        reach = np.maximum(later[pairs[:, 0]], later[pairs[:, 1]])
        np.maximum.at(decided_at, pairs[:, 0], reach)
        np.maximum.at(decided_at, pairs[:, 1], reach)
    if causal:
        return _causal(pairs, good, later.astype(np.int64), decided_at, min_support)
    keep = np.ones(L, dtype=bool)
    for _ in range(max_rounds):
        live = keep[pairs[:, 0]] & keep[pairs[:, 1]]
        tested = np.bincount(pairs[live].ravel(), minlength=L)
        consistent = np.bincount(pairs[live & good].ravel(), minlength=L)
        new_keep = keep & (consistent >= min_support) & (2 * consistent >= tested)
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
    live = keep[pairs[:, 0]] & keep[pairs[:, 1]] if len(pairs) else np.zeros(0, dtype=bool)
    return LoopSelection(
        keep=keep,
        consistent=np.bincount(pairs[live & good].ravel(), minlength=L).astype(np.int64),
        tested=np.bincount(pairs.ravel(), minlength=L).astype(np.int64),
        decided_at=decided_at,
        pairs=len(pairs),
    )


def _causal(
    pairs: NDArray[np.int64],
    good: NDArray[np.bool_],
    later: NDArray[np.int64],
    decided_at: NDArray[np.int64],
    min_support: int,
) -> LoopSelection:
    """:func:`select_loops` as a vehicle decides, in pose order: a pair is tested once both its loop
    closures are known (at their later poses); a loop closure is kept as soon as :data:`EARLY_SUPPORT`
    known neighbours agree with it and none disagrees, else decided at ``decided_at`` by the batch
    rule from its neighbours not already rejected. Nothing decided changes later. The result's
    ``decided_at`` is when each decision was made."""
    L = len(decided_at)
    both = np.concatenate([pairs, pairs[:, ::-1]])
    ok = np.concatenate([good, good])
    by_first = np.argsort(both[:, 0], kind="stable")
    both, ok = both[by_first], ok[by_first]
    start = np.searchsorted(both[:, 0], np.arange(L + 1))
    state = np.zeros(L, dtype=np.int8)  # 0 pending, 1 kept, -1 rejected
    when = decided_at.copy()
    agree = np.zeros(L, dtype=np.int64)
    disagree = np.zeros(L, dtype=np.int64)
    pair_time = np.maximum(later[pairs[:, 0]], later[pairs[:, 1]]) if len(pairs) else np.zeros(0, np.int64)
    pair_order = np.argsort(pair_time, kind="stable")
    final_order = np.argsort(decided_at, kind="stable")
    n_pairs, fi, pi = len(pairs), 0, 0
    for now in np.unique(np.concatenate([pair_time, decided_at])):
        while pi < n_pairs and pair_time[pair_order[pi]] == now:
            k = pair_order[pi]
            p, q = int(pairs[k, 0]), int(pairs[k, 1])
            for x, y in ((p, q), (q, p)):
                if state[y] >= 0:
                    if good[k]:
                        agree[x] += 1
                    else:
                        disagree[x] += 1
                if state[x] == 0 and agree[x] >= max(EARLY_SUPPORT, min_support) and disagree[x] == 0:
                    state[x], when[x] = 1, now
            pi += 1
        while fi < L and decided_at[final_order[fi]] == now:
            e = final_order[fi]
            if state[e] == 0:
                partner, fits = both[start[e] : start[e + 1], 1], ok[start[e] : start[e + 1]]
                live = state[partner] >= 0
                n_live, n_fit = np.count_nonzero(live), np.count_nonzero(fits & live)
                state[e] = 1 if n_fit >= min_support and 2 * n_fit >= n_live else -1
            fi += 1
    consistent = np.zeros(L, dtype=np.int64)
    tested = np.bincount(pairs.ravel(), minlength=L).astype(np.int64) if len(pairs) else np.zeros(L, np.int64)
    if len(pairs):
        live = (state[pairs[:, 0]] > 0) & (state[pairs[:, 1]] > 0) & good
        consistent = np.bincount(pairs[live].ravel(), minlength=L).astype(np.int64)
    return LoopSelection(state > 0, consistent, tested, when, n_pairs)
