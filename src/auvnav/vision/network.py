"""The images of a dive as one network: a pose graph of the dead reckoning and the loops registered so
far, whose solution places pairs far apart along the track.

Two images on passes far apart along the track (a lawnmower's legs hundreds of images apart) have a
prior through the dead reckoning, or through a loop near them
(:meth:`auvnav.vision.loops._Priors.anchored`), that is off by several centimetres: on a ripple field,
a crest or more. The loops registered from features elsewhere tie the passes together all along
them; solved together with the dead reckoning they place the two images within a centimetre or two.
On the simulated check dive in turbid water, for the ripple-field pairs the loop stage missed before
the network, with the loops of a whole run: 1.3 cm median, 3.1 cm at the 90th percentile, against
4.3 and 10.2 cm through the loops nearest them (one, or two on either side averaged).

The graph is two-dimensional (north, east, heading of each image; depth and tilt stay the prior's),
solved by GTSAM (:func:`auvnav.slam.solve.optimize_batch`, loops behind a Huber kernel): between
consecutive images, the step of the dead reckoning with :data:`STEP_DRIFT_FRACTION` of its length
(and at least :data:`STEP_FLOOR_M`) on each axis and :data:`STEP_HEADING_SIGMA_RAD` plus
:data:`TURN_HEADING_FRACTION` of its turn on the heading; each loop with its own covariance. A pair's
relative uncertainty is its joint marginal covariance (``gtsam.Marginals``) carried through the
relative pose: the lateral 1-sigma is the square root of its larger eigenvalue. Against the truth
(the same ripple-field pairs, sampled) the position error is 1.08 such sigmas at the median and 1.98
at the 90th percentile (a Rayleigh distribution gives 1.18 and 2.15).
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray

from auvnav.frames import FloatArray, rot2euler, rot_z, se3_inverse
from auvnav.slam.g2o import PoseGraph, inverse_rigid, se2
from auvnav.slam.solve import optimize_batch, solution_marginals

#: The dead reckoning's error over one step between consecutive images, 1-sigma per axis, as a fraction of
#: the step's length (the DVL's scale error and the compass's noise turning it; see
#: :data:`auvnav.vision.loops.SHORT_DRIFT_FRACTION`) ...
STEP_DRIFT_FRACTION = 0.01
#: ... and at least this, metres.
STEP_FLOOR_M = 0.002
#: The heading's error over one step, 1-sigma, radians (the compass's noise between two images) ...
STEP_HEADING_SIGMA_RAD = 0.002
#: ... and this fraction of the step's turn (the compass's deviation changes with the heading).
TURN_HEADING_FRACTION = 0.05


@dataclass(frozen=True)
class Network:
    """A solved network of images.

    Parameters
    ----------
    T_ned_body : ndarray, shape (N, 4, 4)
        The images' body poses: the prior's, moved and turned about the vertical to the solution.
    loops : int
        Loops in the graph.
    marginals : gtsam.Marginals
        Of the solution (keys: image positions 0..N-1).
    solution : gtsam.Values
    """

    T_ned_body: FloatArray
    loops: int
    marginals: gtsam.Marginals
    solution: gtsam.Values

    def relative(
        self, a: NDArray[np.intp], b: NDArray[np.intp], T_body_cam: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """The camera pose of image b in image a (K, 4, 4) and its lateral 1-sigma (K,), metres.

        The pairs' joint marginal covariances come from GTSAM's joint over up to
        :data:`JOINT_IMAGES` images at a time, the pairs grouped by their first image: over the whole
        check dive in turbid water, its networks' 15,124 pairs take 5.4 CPU s instead of 42.9 as one
        joint a pair, the same sigmas to 1e-9."""
        sigma = np.empty(len(a))
        for chunk in _chunks(a, b, JOINT_IMAGES):
            keys = gtsam.KeyVector()
            for key in np.unique(np.concatenate([a[chunk], b[chunk]])).tolist():
                keys.append(key)
            joint = self.marginals.jointMarginalCovariance(keys)
            for k in chunk.tolist():
                i, j = int(a[k]), int(b[k])
                C = np.block([[joint.at(i, i), joint.at(i, j)], [joint.at(j, i), joint.at(j, j)]])
                between = self.solution.atPose2(i).between(self.solution.atPose2(j))
                H = np.hstack([-between.inverse().AdjointMap(), np.eye(3)])
                cov = H @ C @ H.T
                sigma[k] = np.sqrt(max(np.linalg.eigvalsh(cov[:2, :2])[-1], 0.0))
        T_a, T_b = self.T_ned_body[a] @ T_body_cam, self.T_ned_body[b] @ T_body_cam
        return se3_inverse(T_a) @ T_b, sigma


#: :meth:`Network.relative` asks GTSAM for the joint marginal covariance of this many images at most at
#: once (whole check dive, turbid water, its largest network's pairs: 3.1 CPU s at 32, 2.4 at 64 and
#: 128, 4.1 at 256, 4.6 for each round's pairs at once).
JOINT_IMAGES = 64


def _chunks(a: NDArray[np.intp], b: NDArray[np.intp], limit: int) -> list[NDArray[np.intp]]:
    """Indices of pairs (a, b), ordered by a then b, in consecutive runs that each hold at most ``limit``
    distinct images (or a single pair)."""
    chunks: list[NDArray[np.intp]] = []
    run: list[int] = []
    images: set[int] = set()
    for k in np.lexsort((b, a)).tolist():
        pair = {int(a[k]), int(b[k])}
        if run and len(images | pair) > limit:
            chunks.append(np.array(run, dtype=np.intp))
            run, images = [], set()
        run.append(k)
        images |= pair
    if run:
        chunks.append(np.array(run, dtype=np.intp))
    return chunks


def solve_network(
    T_ned_body: FloatArray,
    i: NDArray[np.intp],
    j: NDArray[np.intp],
    T_i_j: FloatArray,
    cov6: FloatArray,
) -> Network:
    """The network of images whose prior body poses are ``T_ned_body`` (N, 4, 4) with loops (K) from
    image ``i`` to image ``j`` (positions in ``T_ned_body``; ``T_i_j``: body j in body i, (K, 4, 4);
    ``cov6``: their covariances of ``(x, y, z, roll, pitch, yaw)``, (K, 6, 6)). See the module
    docstring."""
    yaw, _, _ = rot2euler(T_ned_body[:, :3, :3])
    # the tilt of each image, R = Rz(yaw) @ tilt: loops are levelled with it
    tilt = np.swapaxes(rot_z(yaw), 1, 2) @ T_ned_body[:, :3, :3]
    p = T_ned_body[:, :3, 3]
    poses = se2(p[:, 0], p[:, 1], yaw)
    steps = inverse_rigid(poses[:-1]) @ poses[1:]
    length = np.hypot(steps[:, 0, 2], steps[:, 1, 2])
    turn = np.abs(np.arctan2(steps[:, 1, 0], steps[:, 0, 0]))
    xy = np.maximum(STEP_DRIFT_FRACTION * length, STEP_FLOOR_M)
    heading = STEP_HEADING_SIGMA_RAD + TURN_HEADING_FRACTION * turn
    step_info = np.zeros((len(steps), 3, 3))
    step_info[:, 0, 0] = step_info[:, 1, 1] = xy**-2
    step_info[:, 2, 2] = heading**-2
    # each loop levelled: its rotation and translation in the level frame of image i
    R_level = tilt[i] @ T_i_j[:, :3, :3] @ np.swapaxes(tilt[j], 1, 2)
    t_level = (tilt[i] @ T_i_j[:, :3, 3, None])[:, :, 0]
    loop_yaw = np.arctan2(R_level[:, 1, 0], R_level[:, 0, 0])
    # the upper triangle, as the verification cache keeps it: a rerun from the cache solves the same
    # network to the bit, and its priors find their verifications in the cache
    upper = np.triu(cov6) + np.swapaxes(np.triu(cov6, 1), 1, 2)
    planar = upper[:, [0, 1, 5]][:, :, [0, 1, 5]] + np.diag([1e-8, 1e-8, 1e-10])
    n = len(T_ned_body)
    graph = PoseGraph(
        2,
        np.arange(n, dtype=np.int64),
        poses,
        np.concatenate([np.arange(n - 1), i]).astype(np.int64),
        np.concatenate([np.arange(1, n), j]).astype(np.int64),
        np.concatenate([steps, se2(t_level[:, 0], t_level[:, 1], loop_yaw)]),
        np.concatenate([step_info, np.linalg.inv(planar)]),
        "the loop stage's network of images",
    )
    solved = optimize_batch(graph, robust="huber")
    marginals, values = solution_marginals(solved.graph, exclude_edges=solved.rejected, robust="huber")
    X = solved.graph.T_world_pose
    turned = np.arctan2(X[:, 1, 0], X[:, 0, 0]) - yaw
    T = T_ned_body.copy()
    T[:, :3, :3] = rot_z(turned) @ T_ned_body[:, :3, :3]
    T[:, :2, 3] = X[:, :2, 2]
    return Network(T, len(i), marginals, values)
